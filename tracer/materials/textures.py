"""Texture parameters of materials: the model, its TOML form and one lookup for every kind.

A texture parameter (a diffuse ``reflectance``, a Phong ``diffuse``) is a
colour or a texture model. Every material kind reads it with
:func:`parse_texture` and evaluates it per lane through one
:class:`TextureTable`, which calls the formula of :mod:`tracer.texture`;
no kind has its own copy of a texture lookup.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from tracer.backend import deferred, jit
from tracer.materials.base import gather

if TYPE_CHECKING:
    from tracer.scene import _Table

dr = deferred("drjit")
texture = deferred("tracer.texture")

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


Texture = Color | Checkerboard


def texture_max(t: Texture) -> float:
    return t.max() if isinstance(t, Checkerboard) else max(t)


def parse_texture(t: _Table, key: str, default, hi: float | None = 1.0) -> Texture:
    """A colour, or a texture: a table whose one key names its kind (:data:`TEXTURES`),
    e.g. ``{ checkerboard = { color0, color1, scale } }``."""
    if not t.is_table(key):
        return t.color(key, default, hi=hi)
    tex = t.table(key)
    kind = tex.choose(tuple(TEXTURES), "texture")
    texture = TEXTURES[kind](tex.table(kind), hi)
    tex.finish()
    return texture


def _parse_checkerboard(cb: _Table, hi: float | None) -> Checkerboard:
    from tracer.scene import _show

    what = "a positive number or [su, sv]"
    positive = {"type": "number", "exclusiveMinimum": 0}
    sc = cb.raw("scale", 1.0, what, {"anyOf": [
        positive, {"type": "array", "items": positive, "minItems": 2, "maxItems": 2}]})
    if isinstance(sc, (int, float)) and not isinstance(sc, bool):
        sc = [sc, sc]
    if (not isinstance(sc, list) or len(sc) != 2 or
            any(isinstance(x, bool) or not isinstance(x, (int, float)) or
                not math.isfinite(x) or x <= 0 for x in sc)):
        cb.fail("scale", f"expected {what}, got {_show(sc)}")
    board = Checkerboard(cb.color("color0", 0.4, hi=hi), cb.color("color1", 0.2, hi=hi),
                         (float(sc[0]), float(sc[1])))
    cb.finish()
    return board


#: Texture kinds: the key that names each in TOML -> its parser (sub-table, highest value).
TEXTURES = {
    "checkerboard": _parse_checkerboard,
}


class TextureTable:
    """One texture parameter of a kind's materials, packed as Dr.Jit tables (a row each)."""

    def __init__(self, textures: list[Texture]):
        rows = [(t, None) if not isinstance(t, Checkerboard) else ((0, 0, 0), t)
                for t in textures]

        def col(values):
            a = np.asarray(values, dtype=np.float32).reshape(-1, 3)
            return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])

        self.color = col([c for c, _ in rows])
        boards = [b for _, b in rows]
        self.has_checker = any(b is not None for b in boards)
        if self.has_checker:
            blank = Checkerboard((0, 0, 0), (0, 0, 0), (1, 1))
            boards_or_blank = [b or blank for b in boards]
            self.checker = jit.Bool(np.asarray([b is not None for b in boards]))
            self.c0 = col([b.color0 for b in boards_or_blank])
            self.c1 = col([b.color1 for b in boards_or_blank])
            sc = np.asarray([b.scale for b in boards_or_blank], dtype=np.float32)
            self.scale = jit.Array2f(sc[:, 0], sc[:, 1])

    def eval(self, row, uv, active) -> Any:
        """The texture's colour at ``uv`` for each lane's material ``row`` (Array3f)."""
        value = gather(self.color, row, active)
        if not self.has_checker:
            return value
        board = texture.checkerboard(uv, gather(self.scale, row, active),
                                     gather(self.c0, row, active), gather(self.c1, row, active))
        return dr.select(gather(self.checker, row, active), board, value)
