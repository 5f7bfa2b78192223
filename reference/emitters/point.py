"""Mitsuba conversion of ``point`` lights (tracer/emitters/point.py): Mitsuba's ``point``."""

from __future__ import annotations

from reference.mitsuba_tree import rgb
from tracer.emitters.point import PointLight


def mitsuba(light: PointLight) -> dict:
    return {"type": "point", "position": ("point", light.position),
            "intensity": rgb(light.intensity)}
