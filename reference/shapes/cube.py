"""Conversions of ``cube`` shapes: Mitsuba's ``cube`` with ``to_world``; its 12 triangles for
LuxCore (a mesh's conversion)."""

from __future__ import annotations

from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes import mesh
from whitted.tracer.shapes.cube import Cube


def mitsuba(shape: Cube, name: str) -> dict:
    return {"type": "cube", "to_world": transforms.tree(transforms.of(shape))}


luxcore = mesh.luxcore
