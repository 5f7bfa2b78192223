"""Mitsuba conversion of ``constant`` lights (tracer/emitters/constant.py): Mitsuba's ``constant``.

Mitsuba samples it with ``square_to_uniform_sphere``, the map the tracer
uses, so the deterministic reference hands it the tracer's own sample
(:func:`sample_map`) and both follow the same shadow rays.
"""

from __future__ import annotations

from whitted.reference.renderers.mitsuba.tree import rgb
from whitted.tracer.emitters.constant import ConstantLight


def mitsuba(light: ConstantLight) -> dict:
    return {"type": "constant", "radiance": rgb(light.radiance)}


def sample_map(u, mi):
    """The tracer's light sample -> the sample for which Mitsuba picks the same direction."""
    return mi.Point2f(u.x, u.y)
