"""Texture parameters of materials: the model, its TOML form and one lookup for every kind.

A texture parameter (a diffuse ``reflectance``, a Phong ``diffuse``) is a
colour or a texture model. Every material kind reads it with
:func:`parse_texture` and evaluates it per lane through one
:class:`TextureTable`, which calls the formula of :mod:`tracer.texture`;
no kind has its own copy of a texture lookup.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from whitted.tracer.backend import deferred, jit, upload, upload_rows
from whitted.tracer.materials.base import gather
from whitted.tracer.settings import Table, show

dr = deferred("drjit")
texture = deferred("whitted.tracer.texture")

#: Bitmap wrap modes (the kernel's codes are their indices; tracer.texture.WRAP_MODES).
WRAP_MODES = ("repeat", "mirror", "clamp")

Color = tuple[float, float, float]


@dataclass(frozen=True)
class Checkerboard:
    """Mitsuba's checkerboard texture: color0 where frac(u') > 1/2 equals frac(v') > 1/2.

    (u', v') = (scale_u u, scale_v v) for the shape's own texture coordinates.
    """
    color0: Color = (0.4, 0.4, 0.4)
    color1: Color = (0.2, 0.2, 0.2)
    scale: tuple[float, float] = (1.0, 1.0)

    def max(self) -> float:
        return max(max(self.color0), max(self.color1))


@dataclass(frozen=True, eq=False)
class Bitmap:
    """Mitsuba's bitmap texture: an image file looked up at the shape's uv.

    ``texels`` are the linear RGB values (H x W x 3, float32, row 0 the image's top
    row): an 8-bit PNG decoded from sRGB unless ``raw`` (then value / 255), an
    OpenEXR file as stored.
    """
    filename: str                 # absolute path
    texels: np.ndarray
    filter_type: str = "bilinear"  # or "nearest"
    raw: bool = False
    wrap_mode: str = "repeat"      # or "mirror", "clamp"
    #: Mitsuba's ``to_uv``, its first two rows: uv' = (a u + b v + c, d u + e v + f)
    to_uv: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))

    def max(self) -> float:
        return float(self.texels.max()) if self.texels.size else 0.0


Texture = Color | Checkerboard | Bitmap


def texture_max(t: Texture) -> float:
    return t.max() if isinstance(t, (Checkerboard, Bitmap)) else max(t)


def srgb_decode(v: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] to linear (IEC 61966-2-1: the linear toe below
    0.04045, else ((v + 0.055) / 1.055)^2.4), in float64."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def load_bitmap(t: Table, key: str, path: Path, raw: bool) -> np.ndarray:
    """The texels of an image file (PNG or OpenEXR) as linear float32 RGB; one-line errors
    (the file is checked before it is decoded: :func:`tracer.imageio.read_texture_file`)."""
    from whitted.tracer.imageheader import ImageError
    from whitted.tracer.imageio import read_texture_file

    if not os.path.exists(path):  # False, not an error, for a name too long
        t.fail(key, f"no such image file: {path}")
    try:
        data = read_texture_file(path)
    except ImageError as e:
        t.fail(key, f"cannot read {path.name}: {e.reason}")
    if data.dtype != np.uint8:
        return data
    rgb = data / 255.0
    return (rgb if raw else srgb_decode(rgb)).astype(np.float32)


def _parse_bitmap(bm: Table, hi: float | None) -> Bitmap:
    name = bm.string("filename")
    path = (Path(bm.path).parent / name).resolve()
    filter_type = bm.string("filter_type", "bilinear", ("bilinear", "nearest"))
    raw = bm.boolean("raw", False)
    wrap = bm.string("wrap_mode", "repeat", WRAP_MODES)
    to_uv = _parse_to_uv(bm)
    texels = load_bitmap(bm, "filename", path, raw)
    if not np.isfinite(texels).all() or texels.min() < 0:
        bm.fail("filename", f"{path.name}: texel values must be finite and >= 0")
    if hi is not None and texels.max() > hi:
        bm.fail("filename", f"{path.name}: texel values must be <= {hi:g} here, the largest "
                            f"is {texels.max():g}")
    bm.finish()
    return Bitmap(str(path), texels, filter_type, raw, wrap, to_uv)


def _parse_to_uv(bm: Table) -> tuple:
    """A bitmap's ``to_uv = [[a, b, c], [d, e, f]]`` (Mitsuba's ``to_uv``, an affine map of
    the uv plane: uv' = (a u + b v + c, d u + e v + f)); identity by default."""
    what = "[[a, b, c], [d, e, f]] (uv' = (a u + b v + c, d u + e v + f))"
    row = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}
    m = bm.raw("to_uv", None, what, {"type": "array", "items": row, "minItems": 2,
                                     "maxItems": 2})
    if m is None:
        return ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    if (not isinstance(m, list) or len(m) != 2 or
            any(not isinstance(r, list) or len(r) != 3 for r in m) or
            any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x)
                for r in m for x in r)):
        bm.fail("to_uv", f"expected {what}, got {show(m)}")
    return tuple(tuple(float(x) for x in r) for r in m)


def parse_texture(t: Table, key: str, default, hi: float | None = 1.0) -> Texture:
    """A colour, or a texture: a table whose one key names its kind (:data:`TEXTURES`),
    e.g. ``{ checkerboard = { color0, color1, scale } }``."""
    if not t.is_table(key):
        return t.color(key, default, hi=hi)
    tex = t.table(key)
    kind = tex.choose(tuple(TEXTURES), "texture")
    texture = TEXTURES[kind](tex.table(kind), hi)
    tex.finish()
    return texture


def _parse_checkerboard(cb: Table, hi: float | None) -> Checkerboard:
    what = "a positive number or [su, sv]"
    positive = {"type": "number", "exclusiveMinimum": 0}
    sc = cb.raw("scale", 1.0, what, {"anyOf": [
        positive, {"type": "array", "items": positive, "minItems": 2, "maxItems": 2}]})
    if isinstance(sc, (int, float)) and not isinstance(sc, bool):
        sc = [sc, sc]
    if (not isinstance(sc, list) or len(sc) != 2 or
            any(isinstance(x, bool) or not isinstance(x, (int, float)) or
                not math.isfinite(x) or x <= 0 for x in sc)):
        cb.fail("scale", f"expected {what}, got {show(sc)}")
    board = Checkerboard(cb.color("color0", 0.4, hi=hi), cb.color("color1", 0.2, hi=hi),
                         (float(sc[0]), float(sc[1])))
    cb.finish()
    return board


#: Rec. 709 luminance weights of linear RGB (Mitsuba's ``luminance()``, used by its
#: ``bitmap`` texture's one-value lookup ``eval_1``).
LUMINANCE = (0.212671, 0.715160, 0.072169)


def scalar_texture(tex: Texture) -> float | Checkerboard | Bitmap:
    """A texture parameter read as one value per point, as Mitsuba's ``Texture.eval_1``
    reads it (the ``opacity`` of its ``mask``: src/bsdfs/mask.cpp, ``eval_opacity``).

    Mitsuba 3's ``eval_1`` of an ``srgb`` colour is the mean of its channels
    (src/textures/srgb.cpp), of an RGB ``bitmap`` the luminance of the interpolated
    texel (src/textures/bitmap.cpp; luminance is linear, so the luminance of each
    texel interpolated is the same), of a ``checkerboard`` its colours' ``eval_1``.
    A constant comes back as a float; a texture as one whose three channels are equal.
    """
    if isinstance(tex, Bitmap):
        grey = np.asarray(tex.texels, np.float64) @ np.asarray(LUMINANCE)
        texels = np.repeat(grey[..., None], 3, axis=-1).astype(np.float32)
        return Bitmap(tex.filename, texels, tex.filter_type, tex.raw, tex.wrap_mode, tex.to_uv)
    if isinstance(tex, Checkerboard):
        c0, c1 = scalar_texture(tex.color0), scalar_texture(tex.color1)
        return Checkerboard((c0,) * 3, (c1,) * 3, tex.scale)
    r, g, b = tex
    return r if r == g == b else (r + g + b) / 3


#: Texture kinds: the key that names each in TOML -> its parser (sub-table, highest value).
TEXTURES = {
    "checkerboard": _parse_checkerboard,
    "bitmap": _parse_bitmap,
}


class TextureTable:
    """One texture parameter of a kind's materials, packed as Dr.Jit tables (a row each)."""

    def __init__(self, textures: list[Texture]):
        rows = [(t, None) if not isinstance(t, (Checkerboard, Bitmap)) else ((0, 0, 0), t)
                for t in textures]

        def col(values):
            return upload_rows(jit.Array3f, values)

        self.color = col([c for c, _ in rows])
        bitmaps = [b if isinstance(b, Bitmap) else None for _, b in rows]
        rows = [(c, b if isinstance(b, Checkerboard) else None) for c, b in rows]
        self.has_bitmap = any(b is not None for b in bitmaps)
        if self.has_bitmap:
            offsets, sizes, data, offset = [], [], [], 0
            for b in bitmaps:
                h, w = (1, 1) if b is None else b.texels.shape[:2]
                offsets.append(offset)
                sizes.append((w, h))
                data.append(np.zeros((1, 3), np.float32) if b is None else
                            b.texels.reshape(-1, 3))
                offset += w * h
            self.is_bitmap = upload(jit.Bool, [b is not None for b in bitmaps], bool)
            self.texels = col(np.concatenate(data))
            self.offset = upload(jit.UInt32, offsets, np.uint32)
            self.size = upload_rows(jit.Array2f, sizes)
            self.bilinear = upload(jit.Bool, [b is not None and b.filter_type == "bilinear"
                                              for b in bitmaps], bool)
            self.wrap = upload(jit.UInt32, [0 if b is None else WRAP_MODES.index(b.wrap_mode)
                                            for b in bitmaps], np.uint32)
            ident = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
            self.uv_moved = any(b is not None and b.to_uv != ident for b in bitmaps)
            if self.uv_moved:   # Mitsuba's to_uv: an affine map of uv before the lookup
                self.uv_u = col([ident[0] if b is None else b.to_uv[0] for b in bitmaps])
                self.uv_v = col([ident[1] if b is None else b.to_uv[1] for b in bitmaps])
        boards = [b for _, b in rows]
        self.has_checker = any(b is not None for b in boards)
        if self.has_checker:
            blank = Checkerboard((0, 0, 0), (0, 0, 0), (1, 1))
            boards_or_blank = [b or blank for b in boards]
            self.checker = upload(jit.Bool, [b is not None for b in boards], bool)
            self.c0 = col([b.color0 for b in boards_or_blank])
            self.c1 = col([b.color1 for b in boards_or_blank])
            self.scale = upload_rows(jit.Array2f, [b.scale for b in boards_or_blank])

    def eval(self, row, uv, active) -> Any:
        """The texture's colour at ``uv`` for each lane's material ``row`` (Array3f)."""
        value = gather(self.color, row, active)
        if self.has_checker:
            board = texture.checkerboard(uv, gather(self.scale, row, active),
                                         gather(self.c0, row, active),
                                         gather(self.c1, row, active))
            value = dr.select(gather(self.checker, row, active), board, value)
        if self.has_bitmap:
            on = gather(self.is_bitmap, row, active)
            size = gather(self.size, row, active)
            if self.uv_moved:
                ru, rv = gather(self.uv_u, row, active), gather(self.uv_v, row, active)
                uv = type(uv)(dr.fma(ru.x, uv.x, dr.fma(ru.y, uv.y, ru.z)),
                              dr.fma(rv.x, uv.x, dr.fma(rv.y, uv.y, rv.z)))
            image = texture.bitmap(uv, self.texels, gather(self.offset, row, active), size.x,
                                   size.y, gather(self.bilinear, row, active),
                                   gather(self.wrap, row, active), active & on)
            value = dr.select(on, image, value)
        return value
