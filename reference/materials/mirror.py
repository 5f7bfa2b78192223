"""Mitsuba conversion of ``mirror`` (tracer/materials/mirror.py).

A two-sided ``conductor`` with ``material = "none"`` (Fresnel reflectance 1)
and ``specular_reflectance`` the mirror's colour: one delta lobe of weight
``reflectance``, as in the tracer.

LuxCore: ``mirror`` with ``kr`` the mirror's colour, the same single delta lobe
(no Fresnel term).
"""

from __future__ import annotations

from reference.mitsuba_tree import rgb
from tracer.materials.mirror import Mirror


def mitsuba(m: Mirror) -> dict:
    return {"type": "twosided",
            "material": {"type": "conductor", "material": ("string", "none"),
                         "specular_reflectance": rgb(m.reflectance)}}


def luxcore(m: Mirror) -> dict:
    return {"type": "mirror", "kr": tuple(m.reflectance)}
