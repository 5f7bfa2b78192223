"""``type = "cube"``: Mitsuba's ``cube``, [-1, 1]^3 as 12 flat triangles placed by ``to_world``.

A mesh (:mod:`tracer.shapes.mesh`) made here rather than read from a file: it
is packed, intersected and sampled as a mesh.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from whitted.tracer import transform as tf
from whitted.tracer.settings import Table, as_tuple, check_extent
from whitted.tracer.shapes import base, mesh


@dataclass(frozen=True, eq=False)
class Cube(mesh.Mesh):
    """Mitsuba's ``cube``: [-1, 1]^3 as 12 flat triangles, placed by ``to_world``."""
    shape_type: ClassVar[str] = "cube"


MODEL = Cube


def cube_mesh() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, uvs) of [-1, 1]^3: four vertices a face, faces wound outwards.

    The same surface as Mitsuba's ``cube`` (a mesh of 24 vertices and 12 triangles
    with face normals); each face's uv spans [0, 1]^2.
    """
    verts, faces, uvs = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u_ax, v_ax = (axis + 1) % 3, (axis + 2) % 3
            first = len(verts)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis], p[u_ax], p[v_ax] = sign, a * sign, b
                verts.append(p)
                uvs.append(((a + 1) / 2, (b + 1) / 2))
            # (u x v) = +axis; flipping u on the negative face keeps the winding outward
            faces += [[first, first + 1, first + 2], [first, first + 2, first + 3]]
    return np.asarray(verts), np.asarray(faces), np.asarray(uvs)


def parse(t: Table, ctx: base.Context) -> Cube:
    m = ctx.to_world()
    verts, faces, uvs = cube_mesh()
    world = tf.apply_point(m, verts)
    check_extent(t, "to_world", world, "vertices")
    return Cube("cube", False, world, faces, None, uvs, as_tuple(m), ctx.material,
                ctx.emitter, ctx.placement())


bounds = mesh.bounds
pack = mesh.pack
Block = mesh.Block
Sampler = mesh.Sampler   # Mitsuba's cube: a mesh of 12 triangles
