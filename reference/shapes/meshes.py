"""What several shape kinds' conversions share: Mitsuba's in-memory meshes, LuxCore's
tessellation.

LuxCore takes every shape as a triangle mesh: the curved ones are tessellated
so that their chords stay within ``TESSELLATION`` x the shape's size
(positions off by at most that, shading by ~(pi / N)^2 / 8 for N segments
through interpolated exact normals), their faces wound along their normals.
"""

from __future__ import annotations

import math

import numpy as np

#: Largest distance of a tessellated shape's chords from the surface, relative to its size.
TESSELLATION = 1e-4


def mesh_node(name, vertices, faces, normals=None, uvs=None, to_world=()) -> dict:
    """An in-memory Mitsuba mesh (an ``obj`` file beside the XML): ``vertices`` and
    ``normals`` in the shape's own space, moved by Mitsuba's composition of the steps
    ``to_world`` (:mod:`reference.renderers.mitsuba.transforms`; none: already in world
    space)."""
    return {"type": "mesh", "name": name, "vertices": np.asarray(vertices, dtype=np.float64),
            "faces": np.asarray(faces, dtype=np.int64).reshape(-1, 3),
            "normals": None if normals is None else np.asarray(normals, dtype=np.float64),
            "uvs": None if uvs is None else np.asarray(uvs, dtype=np.float64),
            "to_world": tuple(to_world)}


def segments(radius: float, size: float, e: float = TESSELLATION) -> int:
    """Angle steps of a circle of ``radius`` whose chords lie within e x size of it.

    A chord across dphi lies R (1 - cos(dphi / 2)) ~ R dphi^2 / 8 inside.
    """
    return max(16, math.ceil(2 * math.pi / math.sqrt(8 * e * size / radius)))


def grid_faces(rows: int, cols: int, verts: np.ndarray) -> np.ndarray:
    idx = np.arange((rows + 1) * (cols + 1)).reshape(rows + 1, cols + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    area = np.linalg.norm(np.cross(verts[faces[:, 1]] - verts[faces[:, 0]],
                                   verts[faces[:, 2]] - verts[faces[:, 0]]), axis=1)
    return faces[area > 0]   # poles collapse to points


def orient(verts, faces, normal_of_face) -> np.ndarray:
    """Faces wound so that their geometric normals point along ``normal_of_face`` (F x 3)."""
    g = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    flip = (g * normal_of_face).sum(1) < 0
    faces = faces.copy()
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


def normals_outward(verts, faces, normals):
    """Wind each face so that its geometric normal agrees with its vertices' normals."""
    avg = normals[faces].sum(1)
    return orient(verts, faces, avg)

