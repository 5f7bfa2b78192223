"""Mitsuba conversion of ``directional`` lights (tracer/emitters/directional.py)."""

from __future__ import annotations

from reference.mitsuba_tree import rgb
from tracer.emitters.directional import DirectionalLight


def mitsuba(light: DirectionalLight) -> dict:
    return {"type": "directional", "direction": ("vector", light.direction),
            "irradiance": rgb(light.irradiance)}
