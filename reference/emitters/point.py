"""Conversions of ``point`` lights (tracer/emitters/point.py): Mitsuba's and LuxCore's ``point``.

LuxCore's ``point`` emits intensity gain * color * k / (4 pi) W/sr, with
k = power * efficiency / Y(color) when both are set and 1 otherwise
(measured: a diffuse plane of reflectance rho under it is rho / pi * I cos / r^2
to 1e-5). With power and efficiency left at 0, color = I and gain = 4 pi give
intensity I.
"""

from __future__ import annotations

import math

from whitted.reference.renderers.mitsuba.tree import rgb
from whitted.tracer.emitters.point import PointLight


def mitsuba(light: PointLight) -> dict:
    return {"type": "point", "position": ("point", light.position),
            "intensity": rgb(light.intensity)}


def luxcore(light: PointLight) -> dict:
    return {"type": "point", "position": tuple(light.position), "color": tuple(light.intensity),
            "gain": (4 * math.pi,) * 3, "power": 0.0, "efficiency": 0.0}
