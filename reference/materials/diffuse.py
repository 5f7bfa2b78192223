"""Conversions of ``diffuse`` (tracer/materials/diffuse.py): Mitsuba and LuxCore.

Mitsuba's ``diffuse`` is one-sided (black from behind); the tracer's diffuse
surfaces are two-sided, as Mitsuba's ``twosided`` wrapper makes them, unless
``two_sided = false``.

LuxCore's ``matte`` is the Lambertian BRDF rho / pi (``kd`` = rho), lit from
both sides as the tracer's two-sided surfaces; a texture and a one-sided surface
are refused (LuxCore's ``checkerboard2d`` maps uv by its own rules, not verified
to match).
"""

from __future__ import annotations

from whitted.reference.materials.textures import texture_tree
from whitted.tracer.errors import UserError
from whitted.tracer.materials.diffuse import Diffuse


def mitsuba(m: Diffuse) -> dict:
    bsdf = {"type": "diffuse", "reflectance": texture_tree(m.reflectance)}
    return {"type": "twosided", "material": bsdf} if m.two_sided else bsdf


def luxcore(m: Diffuse) -> dict:
    """LuxCore ``matte``: f = kd / pi, the same Lambertian BRDF."""
    if not isinstance(m.reflectance, tuple):
        raise UserError(f"material {m.name!r}: a textured diffuse reflectance has no LuxCore "
                        "equivalent here (only plain colours convert)")
    if not m.two_sided:
        raise UserError(f"material {m.name!r}: a one-sided diffuse surface has no LuxCore "
                        "equivalent here (its matte is lit from both sides)")
    return {"type": "matte", "kd": tuple(m.reflectance)}
