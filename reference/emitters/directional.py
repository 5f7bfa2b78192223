"""Conversions of ``directional`` lights (tracer/emitters/directional.py).

LuxCore: ``sharpdistant`` light, light travelling along ``direction``, with
irradiance gain * color on a surface facing it (measured: ortho_transforms and
glass_sphere, lit by one, agree three ways).
"""

from __future__ import annotations

from whitted.reference.renderers.mitsuba.tree import rgb
from whitted.tracer.emitters.directional import DirectionalLight


def mitsuba(light: DirectionalLight) -> dict:
    return {"type": "directional", "direction": ("vector", light.direction),
            "irradiance": rgb(light.irradiance)}


def luxcore(light: DirectionalLight) -> dict:
    return {"type": "sharpdistant", "direction": tuple(light.direction),
            "color": tuple(light.irradiance), "gain": (1.0, 1.0, 1.0), "power": 0.0,
            "efficiency": 0.0}
