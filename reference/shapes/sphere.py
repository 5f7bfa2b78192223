"""Conversions of ``sphere`` shapes: Mitsuba's ``sphere``, a tessellated mesh for LuxCore."""

from __future__ import annotations

import math

import numpy as np

from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes.meshes import TESSELLATION, grid_faces, normals_outward, segments
from whitted.tracer import transform as tf
from whitted.tracer.shapes.sphere import Sphere


def mitsuba(shape: Sphere, name: str) -> dict:
    # The centre, radius and to_world steps as the file gives them: Mitsuba composes
    # to_world x translate(center) x scale(radius) itself (src/shapes/sphere.cpp). A sphere
    # made in code has only the tracer's world-space centre, radius and rotation.
    p = shape.placement
    if p is None:
        return {"type": "sphere", "to_world": transforms.tree(transforms.matrix_step(
            shape.to_world()))}
    t = {"type": "sphere", "center": ("point", p.center), "radius": ("float", p.radius)}
    if p.steps:
        t["to_world"] = transforms.tree(p.steps)
    return t


def sphere_mesh(s: Sphere):
    """(vertices, faces, normals) of a UV sphere, faces within TESSELLATION x radius of it.

    A face of a quad cell of side a = R dphi (the rings use the same step) has a
    circumradius up to a / sqrt(2), so its deepest point lies a^2 / (4 R) =
    R dphi^2 / 4 inside: twice the chord depth of one step, hence the steps of
    a chord depth TESSELLATION / 2.
    """
    n = segments(1.0, 1.0, TESSELLATION / 2)
    rings = max(8, n // 2)
    theta = np.linspace(0, math.pi, rings + 1)
    phi = np.linspace(0, 2 * math.pi, n + 1)
    T, P = np.meshgrid(theta, phi, indexing="ij")
    unit = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    m = np.asarray(s.to_world(), dtype=np.float64)
    verts = tf.apply_point(m, unit)
    normals = tf.apply_normal(m, unit)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return verts, grid_faces(rings, n, verts), normals


def luxcore(shape: Sphere):
    v, f, n = sphere_mesh(shape)
    return v, normals_outward(v, f, n), n
