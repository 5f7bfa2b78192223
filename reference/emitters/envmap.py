"""Mitsuba conversion of ``envmap`` lights (tracer/emitters/envmap.py): Mitsuba's ``envmap``.

Mitsuba samples its map by luminance; the tracer samples directions uniformly
on the sphere. So that both are compared at the same directions, the
deterministic reference hands the tracer's sample to :func:`direct_sample`:
the direction by Mitsuba's own ``square_to_uniform_sphere`` (the map the
tracer uses), the radiance by Mitsuba's ``envmap`` itself (``Emitter.eval``
of a ray leaving in that direction), divided by the pdf 1 / (4 pi).
"""

from __future__ import annotations

import math

from whitted.reference.renderers.mitsuba import transforms
from whitted.tracer.emitters.envmap import EnvMap


def mitsuba(light: EnvMap) -> dict:
    return {"type": "envmap", "filename": ("string", light.filename),
            "scale": ("float", light.scale),
            # the file's own steps, composed by Mitsuba (made in code: the matrix)
            "to_world": transforms.tree(transforms.of(light))}


def sample_map(u, mi):
    """The tracer's light sample, as the sample :func:`direct_sample` reads."""
    return mi.Point2f(u.x, u.y)


def direct_sample(emitter, si, u, mi):
    """(direction, L / pdf) at the tracer's sample ``u``: uniform on the sphere, L by Mitsuba."""
    import drjit as dr

    d = mi.warp.square_to_uniform_sphere(u)
    seen = dr.zeros(mi.SurfaceInteraction3f, dr.width(d))
    seen.wi = -d
    return d, emitter.eval(seen) * (4 * math.pi)
