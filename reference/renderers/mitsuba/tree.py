"""The plugin tree: Mitsuba 3 plugins described as plain data, for ``load_dict`` and for XML.

A plugin is ``{"type": ..., key: value | nested plugin}``. Values are tagged
tuples so that one tree serves both ``mi.load_dict`` and the XML writer
(:mod:`reference.renderers.mitsuba.scene`): ``("rgb", (r, g, b))``, ``("point", (x, y, z))``,
``("vector", ...)``, ``("steps", to_world steps)`` (composed by Mitsuba:
:mod:`reference.renderers.mitsuba.transforms`), ``("uvscale", (su, sv))``, ``("uvmatrix", 3x3)``,
``("float", x)``, ``("integer", n)``, ``("boolean", b)``, ``("string", s)``.
The conversions of the material and emitter kinds (``reference/materials/``,
``reference/emitters/``) build their trees with these helpers.
"""

from __future__ import annotations

import numpy as np


def rgb(c) -> dict:
    """An ``rgb`` texture of a colour."""
    return {"type": "rgb", "value": ("rgb", tuple(float(x) for x in c))}


def any_up(axis) -> np.ndarray:
    """An up vector not parallel to ``axis`` (for look_at frames of lights)."""
    a = np.asarray(axis, dtype=np.float64)
    return np.array([0.0, 1.0, 0.0]) if abs(a[1]) < 0.9 * np.linalg.norm(a) else \
        np.array([1.0, 0, 0])


def per_variant(define):
    """``plugin_class(mi)``: the class ``define(mi)`` makes for Mitsuba's current variant,
    defined once per variant (a plugin written on Mitsuba's API subclasses the variant's
    ``mi.BSDF`` or ``mi.Emitter``, so each variant needs its own class)."""
    classes: dict = {}

    def plugin_class(mi):
        variant = mi.variant()
        if variant not in classes:
            classes[variant] = define(mi)
        return classes[variant]

    return plugin_class
