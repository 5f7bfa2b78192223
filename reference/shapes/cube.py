"""Conversions of ``cube`` shapes: Mitsuba's ``cube`` with ``to_world``; its 12 triangles for
LuxCore (a mesh's conversion)."""

from __future__ import annotations

from whitted.reference.renderers.mitsuba.tree import matrix
from whitted.reference.shapes import mesh
from whitted.tracer.shapes.cube import Cube


def mitsuba(shape: Cube, name: str) -> dict:
    return {"type": "cube", "to_world": matrix(shape.to_world)}


luxcore = mesh.luxcore
