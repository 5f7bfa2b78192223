"""Mitsuba conversion of ``blend`` (tracer/materials/blend.py): Mitsuba's ``blendbsdf``.

``bsdf_0`` and ``bsdf_1`` are the conversions of ``first`` and ``second`` without their
``twosided`` wrapper (Mitsuba's bare BSDFs, black from behind), the weight a float;
the blend is wrapped in ``twosided`` unless ``two_sided = false``, so that both parts
are lit from both sides together, as in the tracer.
"""

from __future__ import annotations

from whitted.reference.materials import diffuse, phong
from whitted.tracer.materials.blend import Blend, kind_of

#: The conversions of the kinds a blend may mix (tracer.materials.blend.SMOOTH).
PARTS = {"diffuse": diffuse, "phong": phong}


def _bare(material) -> dict:
    tree = PARTS[kind_of(material)].mitsuba(material)
    return tree["material"] if tree.get("type") == "twosided" else tree


def mitsuba(m: Blend) -> dict:
    bsdf = {"type": "blendbsdf", "weight": ("float", m.weight),
            "bsdf_0": _bare(m.first), "bsdf_1": _bare(m.second)}
    return {"type": "twosided", "material": bsdf} if m.two_sided else bsdf
