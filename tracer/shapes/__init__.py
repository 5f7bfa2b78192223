"""Ray-shape intersection formulas, one module per shape, as pure functions over Dr.Jit arrays."""
