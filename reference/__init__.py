"""whitted's harness: the same scenes rendered on Mitsuba 3, compared with the tracer.

Importing this package imports :mod:`tracer` first, so that a usable libLLVM
is chosen before Dr.Jit (and Mitsuba, which loads it) start. Mitsuba itself is
imported on demand by :func:`mitsuba`, never by ``whitted render``.
"""

from whitted import tracer  # noqa: F401  (chooses libLLVM before drjit loads)


def mitsuba():
    """Mitsuba, with the variant of the tracer's backend set and our plugins registered."""
    from whitted.tracer import backend

    backend.use()
    import mitsuba as mi

    variant = backend.mitsuba_variant()
    if mi.variant() != variant:
        mi.set_variant(variant)
    from whitted.reference import emitters, materials
    from whitted.reference.renderers.mitsuba import onelobe  # noqa: F401  (registers `whitted`)

    # Plugins written on Mitsuba's API by material and emitter kinds (e.g. `whitted_phong`).
    if variant not in _registered:
        materials.register_plugins(mi)
        emitters.register_plugins(mi)
        _registered.add(variant)
    return mi


_registered: set[str] = set()


def mitsuba_error(e: Exception) -> str:
    """Mitsuba's message of an exception: its last line that says something, cut."""
    from whitted.tracer.errors import one_line

    lines = [x.strip() for x in str(e).splitlines() if x.strip()]
    return one_line(lines[-1] if lines else type(e).__name__, 300)
