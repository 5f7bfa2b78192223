"""Mitsuba conversion of ``mirror`` (tracer/materials/mirror.py).

A two-sided ``conductor`` with ``material = "none"`` (Fresnel reflectance 1)
and ``specular_reflectance`` the mirror's colour: one delta lobe of weight
``reflectance``, as in the tracer (one-sided with ``two_sided = false``).

LuxCore: ``mirror`` with ``kr`` the mirror's colour, the same single delta lobe
(no Fresnel term), reflecting on both sides; a one-sided mirror is refused.
"""

from __future__ import annotations

from whitted.reference.renderers.mitsuba.tree import rgb
from whitted.tracer.errors import UserError
from whitted.tracer.materials.mirror import Mirror


def mitsuba(m: Mirror) -> dict:
    bsdf = {"type": "conductor", "material": ("string", "none"),
            "specular_reflectance": rgb(m.reflectance)}
    return {"type": "twosided", "material": bsdf} if m.two_sided else bsdf


def luxcore(m: Mirror) -> dict:
    if not m.two_sided:
        raise UserError(f"material {m.name!r}: a one-sided mirror has no LuxCore equivalent here")
    return {"type": "mirror", "kr": tuple(m.reflectance)}
