"""Mitsuba conversion of texture parameters (tracer/materials/textures.py)."""

from __future__ import annotations

from whitted.reference.renderers.mitsuba.tree import rgb
from whitted.tracer.materials.textures import Bitmap, Checkerboard, Texture


def texture_tree(tex: Texture) -> dict:
    """Mitsuba's ``bitmap``, ``checkerboard`` (``to_uv`` a scale) or an ``rgb`` colour."""
    if isinstance(tex, Bitmap):
        out = {"type": "bitmap", "filename": ("string", tex.filename),
               "filter_type": ("string", tex.filter_type), "raw": ("boolean", tex.raw),
               "wrap_mode": ("string", tex.wrap_mode)}
        if tex.to_uv != ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
            out["to_uv"] = ("uvmatrix", tuple(tex.to_uv) + ((0.0, 0.0, 1.0),))
        return out
    if isinstance(tex, Checkerboard):
        return {"type": "checkerboard", "color0": rgb(tex.color0), "color1": rgb(tex.color1),
                "to_uv": ("uvscale", tex.scale)}
    return rgb(tex)
