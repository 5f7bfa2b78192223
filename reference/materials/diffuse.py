"""Mitsuba conversion of ``diffuse`` (tracer/materials/diffuse.py): a two-sided ``diffuse``.

Mitsuba's ``diffuse`` is one-sided (black from behind); the tracer's diffuse
surfaces are two-sided, as Mitsuba's ``twosided`` wrapper makes them.
"""

from __future__ import annotations

from reference.materials.textures import texture_tree
from tracer.materials.diffuse import Diffuse


def mitsuba(m: Diffuse) -> dict:
    return {"type": "twosided",
            "material": {"type": "diffuse", "reflectance": texture_tree(m.reflectance)}}
