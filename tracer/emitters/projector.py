"""``type = "projector"``: an image projected by a pinhole, Mitsuba 3's ``projector`` emitter.

The reciprocal of a perspective camera (lecture 1, "Perspective camera construction"):
the projector sits at ``to_world``'s origin and looks along its +z, and a shading point
p, in the projector's own frame q = to_world^-1 p, receives the ``irradiance`` texture's
value at the point where the ray from the pinhole through q meets the image plane z = 1,

    u = 1/2 - x / (2 z tan(fov_x / 2)),  v = 1/2 - aspect y / (2 z tan(fov_x / 2)),

(q = (x, y, z); local +x is the image's left, as for Mitsuba's cameras; aspect = the
texture's width / height, 1 for a colour), nothing outside [0, 1]^2 or behind the
pinhole (z <= 0). The incident quantity that multiplies f cos is

    E = pi scale irradiance(u, v) / (z^2 cos_n),  cos_n = n . (p - o) / |p - o|,

with o the pinhole and n = to_world (0, 0, 1): the inverse of a perspective camera's
importance, so that a constant texture projected onto a plane facing the projector at
distance 1 gives irradiance pi scale irradiance (Mitsuba 3.9.1, ``src/emitters/projector.cpp``,
``sample_direction``: "dist^2 cos_theta^3 == it_local.z^2 cos_theta"). ``fov`` is the
field of view along ``fov_axis`` of that image (:func:`tracer.fov.horizontal`).
A delta light: one direction per shading point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from whitted.tracer import faults
from whitted.tracer import fov as fovs
from whitted.tracer.backend import deferred, jit
from whitted.tracer.emitters import base
from whitted.tracer.materials.textures import (
    Bitmap,
    Checkerboard,
    Texture,
    TextureTable,
    parse_texture,
)
from whitted.tracer.settings import Matrix, Table, as_tuple, read_steps

dr = deferred("drjit")


@dataclass(frozen=True, eq=False)
class Projector(base.LightModel):
    to_world: Matrix
    irradiance: Texture
    fov: float = 45.0
    fov_axis: str = "x"
    scale: float = 1.0
    #: ``to_world``'s steps as the file gives them (:data:`tracer.settings.Step`), from
    #: which the Mitsuba side builds its own; None: made in code
    steps: tuple | None = field(default=None, compare=False, repr=False)

    @property
    def aspect(self) -> float:
        """The projected image's width / height (its texture's; 1 for a colour)."""
        if isinstance(self.irradiance, Bitmap):
            h, w = self.irradiance.texels.shape[:2]
            return w / h
        return 1.0

    @property
    def tan_half_fov_x(self) -> float:
        return math.tan(math.radians(fovs.horizontal(self.fov, self.fov_axis, self.aspect)) / 2)


MODEL = Projector


def parse(t: Table) -> Projector:
    m, steps = read_steps(t, "to_world") if t.has("to_world") else (np.eye(4), ())
    irradiance = parse_texture(t, "irradiance", 1.0, hi=None)
    if isinstance(irradiance, Checkerboard):
        t.fail("irradiance", "expected a colour or a bitmap (Mitsuba's projector takes the "
                             "texture's resolution as the image's)")
    angle = t.number("fov", 45.0, lo=0, hi=180, lo_open=True, hi_open=True)
    axis = t.string("fov_axis", "x", fovs.FOV_AXES)
    scale = t.number("scale", 1.0, lo=0)
    return Projector(as_tuple(m), irradiance, angle, axis, scale, steps)


class Emitter(base.Emitter):
    def __init__(self, light: Projector):
        m = np.asarray(light.to_world, dtype=np.float64)
        self.inverse = np.linalg.inv(m)
        self.origin = base.vec(m[:3, 3])
        self.normal = base.vec(m[:3, 2])
        self.tan = light.tan_half_fov_x
        self.aspect = light.aspect
        self.scale = float(light.scale) * math.pi
        self.texture = TextureTable([light.irradiance])

    def sample(self, p, origin, u):
        inv = self.inverse    # p in the projector's frame: q = to_world^-1 p
        qx, qy, qz = (dr.dot(base.vec(inv[r, :3]), p) + faults.number(inv[r, 3])
                      for r in range(3))
        to_light = self.origin - p
        dist = dr.norm(to_light)
        wi = to_light / dist
        uu = 0.5 - 0.5 * qx / (qz * self.tan)
        vv = 0.5 - 0.5 * self.aspect * qy / (qz * self.tan)
        inside = (qz > 0) & (uu >= 0) & (uu <= 1) & (vv >= 0) & (vv <= 1)
        row = dr.zeros(jit.UInt32, dr.width(p))
        tex = self.texture.eval(row, jit.Array2f(uu, vv), inside)
        falloff = qz * qz * -dr.dot(self.normal, wi)     # z^2 cos_n = dist^2 cos_n^3
        falloff = faults.pick("projector-distance-squared", lambda: dist * dist, falloff)
        e = dr.select(inside, tex * (self.scale / falloff), 0)
        return wi, dr.norm(self.origin - origin), e
