"""Conversions of ``disk`` shapes: Mitsuba's ``disk``, a tessellated fan for LuxCore."""

from __future__ import annotations

import math

import numpy as np

from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes.meshes import orient, segments
from whitted.tracer import transform as tf
from whitted.tracer.shapes.disk import Disk


def mitsuba(shape: Disk, name: str) -> dict:
    return {"type": "disk", "to_world": transforms.tree(transforms.of(shape))}


def disk_mesh(d: Disk):
    m = np.asarray(d.to_world, dtype=np.float64)
    n = segments(1.0, 1.0)
    phi = np.linspace(0, 2 * math.pi, n, endpoint=False)
    local = np.concatenate([[[0.0, 0.0, 0.0]], np.stack([np.cos(phi), np.sin(phi),
                                                          np.zeros(n)], -1)])
    verts = tf.apply_point(m, local)
    i = np.arange(n)
    faces = np.stack([np.zeros(n, int), 1 + i, 1 + (i + 1) % n], -1)
    return verts, orient(verts, faces, np.broadcast_to(d.normal(), (n, 3))), None


luxcore = disk_mesh
