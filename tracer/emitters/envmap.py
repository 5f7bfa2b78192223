"""``type = "envmap"``: an environment map at infinity (Mitsuba's ``envmap``), a lat-long image.

A ray that escapes brings back the image's radiance in its direction d,
L(d) = ``scale`` x image(u, v) (an image infinite light: pbrt-v4, section
12.5.2, whose map is equal-area octahedral, not lat-long; Mitsuba 3's plugin
reference, ``envmap``), looked up as Mitsuba 3.9.1's ``envmap`` looks it up
(:func:`tracer.texture.latlong`): in the map's own frame (``to_world``'s
inverse applied to d), u = atan2(d.x, -d.z) / (2 pi) runs along the columns
and v = acos(d.y) / pi down the rows, +y the top row; bilinear between texel
centres at u = (i + 1/2) / W, v = j / (H - 1), periodic in u.

Shading points sample it as a light with one direction uniform on the
sphere per sample (pdf 1 / (4 pi); estimate 4 pi L(d) scale), as the
``constant`` light does: unbiased, but without importance sampling of bright
texels (Mitsuba's own envmap samples by luminance; the deterministic
reference evaluates Mitsuba's map at the tracer's directions instead,
``reference/emitters/envmap.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from whitted.tracer.backend import deferred, jit, upload_rows
from whitted.tracer.emitters import base
from whitted.tracer.settings import Table, as_tuple, read_steps

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")
texture = deferred("whitted.tracer.texture")

Matrix = tuple[tuple[float, ...], ...]


@dataclass(frozen=True, eq=False)
class EnvMap(base.LightModel):
    filename: str              # absolute path
    texels: np.ndarray         # H x W x 3, linear
    scale: float = 1.0
    to_world: Matrix = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0),
                        (0.0, 0.0, 0.0, 1.0))
    #: ``to_world``'s steps as the file gives them (:data:`tracer.settings.Step`), from
    #: which the Mitsuba side builds its own; None: made in code
    steps: tuple | None = None


MODEL = EnvMap


def parse(t: Table) -> EnvMap:
    from whitted.tracer.materials.textures import load_bitmap

    # Every key is read before the file is (the schema records the keys a parser reads).
    path = (Path(t.path).parent / t.string("filename")).resolve()
    scale = t.number("scale", 1.0, lo=0)
    m, steps = read_steps(t, "to_world") if t.has("to_world") else (np.eye(4), ())
    r = np.asarray(m)[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-5):
        t.fail("to_world", "an environment map's to_world must be a rotation")
    texels = load_bitmap(t, "filename", path, raw=False)
    if texels.shape[0] < 2 or texels.shape[1] < 1:
        t.fail("filename", f"{path.name}: an environment map needs at least 2 rows")
    if not np.isfinite(texels).all() or texels.min() < 0:
        t.fail("filename", f"{path.name}: texel values must be finite and >= 0")
    return EnvMap(str(path), texels, scale, as_tuple(m), steps)


class Emitter(base.Emitter):
    delta = False
    infinite = True
    aim = (0.5, 0.5)

    def __init__(self, light: EnvMap):
        h, w = light.texels.shape[:2]
        # The periodic column: column W repeats column 0 (as Mitsuba pads its map).
        padded = np.concatenate([light.texels, light.texels[:, :1]], axis=1)
        self.texels = upload_rows(jit.Array3f, padded.reshape(-1, 3) * np.float32(light.scale))
        self.width, self.height = w, h
        inv = np.linalg.inv(np.asarray(light.to_world)[:3, :3])
        self.rows = [base.vec(inv[k]) for k in range(3)]

    def background(self, d):
        local = jit.Array3f(dr.dot(self.rows[0], d), dr.dot(self.rows[1], d),
                            dr.dot(self.rows[2], d))
        return texture.latlong(local, self.texels, self.width, self.height)

    def sample(self, p, origin, u):
        x, y, z = lights.sample_uniform_direction(u)
        wi = jit.Array3f(x, y, z)
        return (wi, dr.full(jit.Float, dr.inf, dr.width(p)),
                self.background(wi) * (4 * math.pi))
