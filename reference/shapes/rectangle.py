"""Conversions of ``rectangle`` shapes: Mitsuba's ``rectangle``, two triangles for LuxCore."""

from __future__ import annotations

import numpy as np

from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes.meshes import orient
from whitted.tracer import transform as tf
from whitted.tracer.shapes.rectangle import Rectangle


def mitsuba(shape: Rectangle, name: str) -> dict:
    return {"type": "rectangle", "to_world": transforms.tree(transforms.of(shape))}


def rectangle_mesh(r: Rectangle):
    m = np.asarray(r.to_world, dtype=np.float64)
    verts = tf.apply_point(m, np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]]))
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    return verts, orient(verts, faces, np.broadcast_to(r.normal(), (2, 3))), None


luxcore = rectangle_mesh
