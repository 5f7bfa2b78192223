"""Mitsuba conversion of ``thindielectric`` (tracer/materials/thindielectric.py): Mitsuba's
``thindielectric``, both indices set (its default ``ext_ior`` is air, 1.000277)."""

from __future__ import annotations

from whitted.tracer.materials.thindielectric import ThinDielectric


def mitsuba(m: ThinDielectric) -> dict:
    return {"type": "thindielectric", "int_ior": ("float", m.ior),
            "ext_ior": ("float", m.ext_ior)}
