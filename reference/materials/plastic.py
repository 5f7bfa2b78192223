"""Mitsuba conversion of ``plastic`` (tracer/materials/plastic.py): Mitsuba's smooth ``plastic``,
both indices set, wrapped in ``twosided`` unless ``two_sided = false``."""

from __future__ import annotations

from whitted.reference.materials.textures import texture_tree
from whitted.tracer.materials.plastic import Plastic


def mitsuba(m: Plastic) -> dict:
    bsdf = {"type": "plastic", "diffuse_reflectance": texture_tree(m.diffuse_reflectance),
            "specular_reflectance": texture_tree(m.specular_reflectance),
            "int_ior": ("float", m.ior), "ext_ior": ("float", m.ext_ior),
            "nonlinear": ("boolean", m.nonlinear)}
    return {"type": "twosided", "material": bsdf} if m.two_sided else bsdf
