"""Conversions of ``cylinder`` shapes: Mitsuba's ``cylinder``, a tessellated tube for LuxCore."""

from __future__ import annotations

import math

import numpy as np

from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes.meshes import grid_faces, normals_outward, segments
from whitted.tracer import transform as tf
from whitted.tracer.shapes.cylinder import Cylinder


def mitsuba(shape: Cylinder, name: str) -> dict:
    # p0, p1 and radius as read; Mitsuba composes to_world x its frame from p0 to p1
    return {"type": "cylinder", "p0": ("point", shape.p0), "p1": ("point", shape.p1),
            "radius": ("float", shape.radius),
            "to_world": transforms.tree(transforms.of(shape))}


def cylinder_mesh(c: Cylinder):
    m = c.local_to_world()
    n = segments(1.0, 1.0)
    phi = np.linspace(0, 2 * math.pi, n + 1)
    Z, P = np.meshgrid(np.array([0.0, 1.0]), phi, indexing="ij")
    local = np.stack([np.cos(P), np.sin(P), Z], -1).reshape(-1, 3)
    grad = np.stack([np.cos(P), np.sin(P), np.zeros_like(P)], -1).reshape(-1, 3)
    verts = tf.apply_point(m, local)
    normals = tf.apply_normal(m, grad)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    faces = grid_faces(1, n, verts)
    return verts, normals_outward(verts, faces, normals), normals


luxcore = cylinder_mesh
