"""``type = "spot"``: a point light restricted to a cone, Mitsuba's profile.

Incident factor I falloff(theta) / r^2: full intensity inside ``beam_width``,
falling linearly in the angle to zero at ``cutoff_angle`` (lecture 2,
"Falloff, spot lights"; :func:`tracer.lights.spot`):

    falloff(theta) = 1 for theta <= beam_width,
                     (cutoff_angle - theta) / (cutoff_angle - beam_width) up to cutoff_angle,
                     0 beyond.

Mitsuba's ``spot`` emitter is the same profile (Mitsuba 3's plugin
reference, ``spot``; ``reference/emitters/spot.py``), not pbrt-v4's
smoothstep (section 12.2.1).

An optional ``texture`` (a slide projected by the spot, Mitsuba's textured
spot) multiplies the intensity by its colour at
uv = (1/2 + x / (2 z tan(cutoff)), 1/2 + y / (2 z tan(cutoff))) for the
direction (x, y, z) from the light in its frame (:meth:`SpotLight.frame`):
the cutoff cone's square cross-section maps onto the unit uv square.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from whitted.tracer.backend import deferred, jit
from whitted.tracer.emitters import base
from whitted.tracer.materials.textures import Texture, TextureTable, parse_texture
from whitted.tracer.settings import Table

dr = deferred("drjit")
lights = deferred("whitted.tracer.lights")

Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]


@dataclass(frozen=True)
class SpotLight(base.LightModel):
    position: Vec3
    target: Vec3
    intensity: Color  # W/sr on the axis
    cutoff_angle: float = 20.0
    beam_width: float = 15.0
    texture: Texture | None = None

    def frame(self) -> np.ndarray:
        """The spot's frame (4 x 4, columns x, y, z = axis, position): Mitsuba's look_at from
        the position to the target, with up = +y unless the axis is within 26 degrees of it
        (then +x)."""
        from whitted.tracer import transform as tf

        a = np.asarray(self.axis)
        up = (0.0, 1.0, 0.0) if abs(a[1]) < 0.9 else (1.0, 0.0, 0.0)
        return tf.look_at(self.position, self.target, up)

    @property
    def axis(self) -> Vec3:
        d = np.subtract(self.target, self.position)
        return tuple(float(x) for x in d / np.linalg.norm(d))


MODEL = SpotLight


def parse(t: Table) -> SpotLight:
    position, target = t.vec3("position"), t.vec3("target")
    t.distinct("target", position, target, "position")
    cutoff = t.number("cutoff_angle", 20.0, lo=0, hi=180, lo_open=True, hi_open=True)
    beam = t.number("beam_width", 0.75 * cutoff, lo=0, hi=cutoff)
    texture = None
    if t.has("texture"):
        texture = parse_texture(t, "texture", 1.0, hi=None)
    return SpotLight(position, target, t.color("intensity"), cutoff, beam, texture)


class Emitter(base.Emitter):
    def __init__(self, light: SpotLight):
        self.light = light
        self.position = base.vec(light.position)
        self.axis = base.vec(light.axis)
        self.intensity = base.color(light.intensity)
        self.texture = None
        if light.texture is not None:
            m = light.frame()
            self.x, self.y = base.vec(m[:3, 0]), base.vec(m[:3, 1])
            self.uv_factor = float(np.tan(np.radians(light.cutoff_angle)))
            self.texture = TextureTable([light.texture])

    def sample(self, p, origin, u):
        L = self.light
        wi, _, e = lights.spot(p, self.position, self.axis, self.intensity, L.cutoff_angle,
                               L.beam_width)
        if self.texture is not None:
            d = -wi  # from the light towards p, in the spot's frame
            z = dr.dot(d, self.axis) * self.uv_factor
            uv = lights.spot_uv(dr.dot(d, self.x), dr.dot(d, self.y), z)
            lit = dr.max(e) > 0
            row = dr.zeros(jit.UInt32, dr.width(p))
            e = dr.select(lit, e * self.texture.eval(row, uv, lit), 0)
        return wi, dr.norm(self.position - origin), e
