"""Conversions of ``mesh`` shapes: Mitsuba's ``obj`` / ``ply`` with ``face_normals`` = !smooth;
the same triangles for LuxCore."""

from __future__ import annotations

import numpy as np

from whitted.reference.renderers.mitsuba import transforms
from whitted.tracer.shapes.mesh import Mesh


def mitsuba(shape: Mesh, name: str) -> dict:
    # Mitsuba reads the file itself and moves its points (normals by the inverse
    # transpose) by the to_world it composes from the file's steps.
    kind = "ply" if shape.file.lower().endswith(".ply") else "obj"
    return {"type": kind, "filename": ("string", shape.file),
            "face_normals": ("boolean", not shape.smooth),
            "to_world": transforms.tree(transforms.of(shape))}


def luxcore(shape: Mesh):
    return (np.asarray(shape.vertices, dtype=np.float64), np.asarray(shape.faces),
            None if shape.normals is None else np.asarray(shape.normals, dtype=np.float64))
