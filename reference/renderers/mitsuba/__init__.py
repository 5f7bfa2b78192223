"""Mitsuba 3, the reference: the scene converted to Mitsuba's plugins (scene, tree),
rendered (render), the deterministic both-lobes reference (deterministic), the one-lobe
reference (onelobe), what both do at a hit (shading), and `whitted import` (importer)."""
