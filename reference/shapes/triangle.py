"""Conversions of ``triangle`` shapes: a one-face mesh (an ``obj`` file in XML), for both."""

from __future__ import annotations

import numpy as np

from whitted.reference.shapes.meshes import mesh_node
from whitted.tracer.shapes.triangle import Triangle


def mitsuba(shape: Triangle, name: str) -> dict:
    return mesh_node(name, shape.vertices, [[0, 1, 2]])


def luxcore(shape: Triangle):
    return np.asarray(shape.vertices, dtype=np.float64), np.array([[0, 1, 2]]), None
