"""Mitsuba conversion of ``diffuse`` (tracer/materials/diffuse.py): a two-sided ``diffuse``.

Mitsuba's ``diffuse`` is one-sided (black from behind); the tracer's diffuse
surfaces are two-sided, as Mitsuba's ``twosided`` wrapper makes them, unless
``two_sided = false``.
"""

from __future__ import annotations

from reference.materials.textures import texture_tree
from tracer.materials.diffuse import Diffuse


def mitsuba(m: Diffuse) -> dict:
    bsdf = {"type": "diffuse", "reflectance": texture_tree(m.reflectance)}
    return {"type": "twosided", "material": bsdf} if m.two_sided else bsdf
