"""Conversions of ``polygon`` shapes: a mesh by ear clipping, uvs = the plane's coordinates."""

from __future__ import annotations

import numpy as np

from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes.meshes import mesh_node
from whitted.tracer.shapes.polygon import Polygon, ear_clip, plane_frame


def polygon_mesh(poly: Polygon):
    """(vertices, faces, uvs) of a polygon by ear clipping, uvs = its plane's 2D coordinates."""
    pts = np.asarray(poly.vertices, dtype=np.float64)
    origin, u, v, _ = plane_frame(pts)
    xy = (pts - origin) @ np.stack([u, v], axis=1)
    return pts, np.asarray(ear_clip(xy)), xy


def mitsuba(shape: Polygon, name: str) -> dict:
    # The vertices as the file gives them, moved by Mitsuba's composition of to_world;
    # the triangles (ear clipping) and uvs (the plane's coordinates) are the tracer's
    # (docs/verdicts.md, "What both sides share"): an affine map keeps a triangulation one.
    verts, faces, uvs = polygon_mesh(shape)
    p = shape.placement
    if p is None:
        return mesh_node(name, verts, faces, None, uvs)
    return mesh_node(name, p.points, faces, None, uvs, to_world=transforms.of(shape))


def luxcore(shape: Polygon):
    v, f, _ = polygon_mesh(shape)
    return v, np.asarray(f), None
