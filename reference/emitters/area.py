"""Mitsuba conversion of area emitters on shapes (tracer/emitters/area.py): ``area``.

Mitsuba's ``area`` emitter emits ``radiance`` from the front side of its
shape, as the tracer's does; the shape's conversion attaches it.
"""

from __future__ import annotations

from reference.mitsuba_tree import rgb
from tracer.emitters.area import AreaEmitter


def mitsuba(emitter: AreaEmitter) -> dict:
    return {"type": "area", "radiance": rgb(emitter.radiance)}
