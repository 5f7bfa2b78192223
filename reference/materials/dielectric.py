"""Mitsuba conversion of ``dielectric`` (tracer/materials/dielectric.py).

Mitsuba's ``dielectric`` with both indices set (its default ``ext_ior`` is
air, 1.000277, not 1). It is always exact Fresnel: Schlick's approximation is
tracer-only (``[compare] tracer_only = ["schlick"]``, see
:meth:`Dielectric.comparable`), and the conversion leaves it out.
"""

from __future__ import annotations

from tracer.materials.dielectric import Dielectric


def mitsuba(m: Dielectric) -> dict:
    return {"type": "dielectric", "int_ior": ("float", m.ior), "ext_ior": ("float", m.ext_ior)}
