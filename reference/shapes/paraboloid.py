"""Conversions of ``paraboloid`` shapes: Mitsuba has none, so a smooth mesh, for both.

The mesh is fine enough that its chords stay within ``PARABOLOID_DEVIATION`` of
the shape's size, with exact normals at its vertices.
"""

from __future__ import annotations

import math

import numpy as np

from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes.meshes import mesh_node
from whitted.tracer import transform as tf
from whitted.tracer.shapes.paraboloid import Paraboloid

#: Largest distance of a paraboloid's chords from the surface, relative to its size.
PARABOLOID_DEVIATION = 1e-4


def paraboloid_mesh(par: Paraboloid, world: bool = True):
    """(vertices, faces, normals, uvs, rings, segments) of a paraboloid, tessellated.

    The surface is x = a s cos(phi), y = b s sin(phi), z = s^2 for
    0 <= s <= sqrt(height). A chord across an angle step of a circle of radius R
    lies R (1 - cos(dphi / 2)) ~ R dphi^2 / 8 inside it, and across a radial
    step ds of the parabola z = s^2 (curvature <= 2) at most ds^2 / 4, so
    dphi = sqrt(8 e / R) and ds = sqrt(4 e) keep both within e =
    PARABOLOID_DEVIATION x the shape's size. Vertex normals are the exact
    gradients, interpolated across each triangle like the tracer's smooth meshes.
    ``world`` False: vertices and normals in the shape's own space (before to_world).
    """
    m = np.asarray(par.to_world, dtype=np.float64)
    s_max = math.sqrt(par.height)
    r = max(par.a, par.b) * s_max
    size = max(r, par.height)
    e = PARABOLOID_DEVIATION * size
    segments = max(16, math.ceil(2 * math.pi / math.sqrt(8 * e / r)))
    rings = max(8, math.ceil(s_max / math.sqrt(4 * e)))
    s_vals = np.linspace(0, s_max, rings + 1)
    phi = np.linspace(0, 2 * math.pi, segments + 1)
    S, P = np.meshgrid(s_vals, phi, indexing="ij")
    local = np.stack([par.a * S * np.cos(P), par.b * S * np.sin(P), S * S], axis=-1)
    grad = np.stack([2 * local[..., 0] / par.a ** 2, 2 * local[..., 1] / par.b ** 2,
                     -np.ones_like(S)], axis=-1)
    uvs = np.stack([S / s_max, P / (2 * math.pi)], axis=-1)
    if not world:
        m = np.eye(4)
    verts = tf.apply_point(m, local.reshape(-1, 3))
    normals = tf.apply_normal(m, grad.reshape(-1, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    idx = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b = idx[:-1, :-1], idx[1:, :-1]
    c, d = idx[1:, 1:], idx[:-1, 1:]
    # Counter-clockwise seen along the gradient (the outside, down and out).
    faces = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3),
                            np.stack([a, d, c], -1).reshape(-1, 3)])
    area = np.linalg.norm(np.cross(verts[faces[:, 1]] - verts[faces[:, 0]],
                                   verts[faces[:, 2]] - verts[faces[:, 0]]), axis=1)
    faces = faces[area > 0]  # the apex ring collapses to a point
    return verts, faces, normals, uvs.reshape(-1, 2), rings, segments


def mitsuba(shape: Paraboloid, name: str) -> dict:
    # tessellated in its own space, moved by Mitsuba's composition of to_world
    if shape.placement is None:
        verts, faces, normals, uvs, _, _ = paraboloid_mesh(shape)
        return mesh_node(name, verts, faces, normals, uvs)
    verts, faces, normals, uvs, _, _ = paraboloid_mesh(shape, world=False)
    return mesh_node(name, verts, faces, normals, uvs, to_world=transforms.of(shape))


def luxcore(shape: Paraboloid):
    v, f, n, _, _, _ = paraboloid_mesh(shape)
    return v, f, n
