"""Conversions of ``triangle`` shapes: a one-face mesh (an ``obj`` file in XML), for both."""

from __future__ import annotations

import numpy as np

from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes.meshes import mesh_node
from whitted.tracer.shapes.triangle import Triangle


def mitsuba(shape: Triangle, name: str) -> dict:
    # the vertices as the file gives them, moved by Mitsuba's composition of to_world
    p = shape.placement
    if p is None:
        return mesh_node(name, shape.vertices, [[0, 1, 2]])
    return mesh_node(name, p.points, [[0, 1, 2]], to_world=transforms.of(shape))


def luxcore(shape: Triangle):
    return np.asarray(shape.vertices, dtype=np.float64), np.array([[0, 1, 2]]), None
