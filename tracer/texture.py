"""Textures: Mitsuba's checkerboard, looked up at a hit's texture coordinates."""

import drjit as dr

from tracer import faults


def checkerboard(uv, scale, color0, color1):
    """color0 where frac(u') > 1/2 equals frac(v') > 1/2, else color1, with (u', v') = scale * uv.

    The same rule as Mitsuba's ``checkerboard`` texture (with ``to_uv`` a scale),
    so the two renderers paint the same squares: uv = (0.25, 0.25) and
    (0.75, 0.75) are color0, (0.25, 0.75) and (0.75, 0.25) color1.
    """
    u = uv.x * scale.x
    v = uv.y * scale.y
    if faults.on("checkerboard-uv-swap"):
        u, v = uv.y * scale.x, uv.x * scale.y
    mu = (u - dr.floor(u)) > 0.5
    mv = (v - dr.floor(v)) > 0.5
    return dr.select(mu == mv, color0, color1)
