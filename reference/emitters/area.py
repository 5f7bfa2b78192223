"""Mitsuba conversion of area emitters on shapes (tracer/emitters/area.py): ``area``.

Mitsuba's ``area`` emitter emits ``radiance`` from the front side of its
shape, as the tracer's does; the shape's conversion attaches it.

LuxCore: an emitting mesh, the shape's material with ``emission`` = L,
``emission.gain`` = 1 and no power or efficiency: radiance L from the side the
mesh's faces are wound towards, which the conversion orients along the shape's
normal (:func:`luxcore`, the material's extra keys; measured on
tests/data/luxcore/area_diffuse.toml: the lights seen directly and the light
they shed agree, the regions' sums within |Z| 2.2).
"""

from __future__ import annotations

from whitted.reference.renderers.mitsuba.tree import rgb
from whitted.tracer.emitters.area import AreaEmitter


def mitsuba(emitter: AreaEmitter) -> dict:
    return {"type": "area", "radiance": rgb(emitter.radiance)}


def luxcore(emitter: AreaEmitter) -> dict:
    return {"emission": tuple(emitter.radiance), "emission.gain": (1.0, 1.0, 1.0),
            "emission.power": 0.0, "emission.efficiency": 0.0}
