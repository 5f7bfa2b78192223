"""Textures: Mitsuba's checkerboard and bitmap, looked up at a hit's texture coordinates."""

import math

import drjit as dr

from whitted.tracer import faults


def checkerboard(uv, scale, color0, color1):
    """color0 where frac(u') > 1/2 equals frac(v') > 1/2, else color1, with (u', v') = scale * uv.

    The same rule as Mitsuba's ``checkerboard`` texture (with ``to_uv`` a scale),
    so the two renderers paint the same squares: uv = (0.25, 0.25) and
    (0.75, 0.75) are color0, (0.25, 0.75) and (0.75, 0.25) color1.
    """
    u = uv.x * scale.x
    v = uv.y * scale.y
    u, v = faults.pick("checkerboard-uv-swap", lambda: (uv.y * scale.x, uv.x * scale.y), (u, v))
    mu = (u - dr.floor(u)) > 0.5
    mv = (v - dr.floor(v)) > 0.5
    return dr.select(mu == mv, color0, color1)


#: Wrap modes of bitmaps, by their code in the kernel (Mitsuba's ``wrap_mode`` names).
WRAP_MODES = ("repeat", "mirror", "clamp")


def wrap_index(i, n, mode):
    """Integer texel index ``i`` wrapped into [0, n): repeat (i mod n), mirror (period 2n,
    the second copy reversed) or clamp (the edge texel), ``mode`` a code of WRAP_MODES."""
    m = i - n * dr.floor(i / n)                 # repeat
    m2 = i - (2 * n) * dr.floor(i / (2 * n))    # mirror: 0..2n-1, the upper half reversed
    m2 = dr.select(m2 >= n, 2 * n - 1 - m2, m2)
    c = dr.clip(i, 0, n - 1)                    # clamp
    return dr.select(mode == 0, m, dr.select(mode == 1, m2, c))


def bitmap(uv, texels, offset, width, height, bilinear, mode, active):
    """A bitmap's colour at ``uv`` (Mitsuba's ``bitmap`` texture).

    Texel (column x, row y) covers [x, x + 1) / width by [y, y + 1) / height of
    the uv square, row 0 being the image's top row, as Mitsuba maps u to
    columns and v to rows. ``nearest``: the texel containing uv. Bilinear:
    the texel centres around (u width - 1/2, v height - 1/2), weighted by
    the fractional parts (pbrt-v4, section 10.4.3). Indices outside the image
    are wrapped by ``mode`` (:func:`wrap_index`). ``texels`` holds every
    bitmap of the table in rows, this one from ``offset``; ``width``,
    ``height`` are floats (exact for any image size below 2^24).
    """
    v = uv.y
    v = faults.pick("bitmap-v-flipped", lambda: 1 - uv.y, v)
    x = uv.x * width
    y = v * height
    xb, yb = x - 0.5, y - 0.5
    x0 = dr.select(bilinear, dr.floor(xb), dr.floor(x))
    y0 = dr.select(bilinear, dr.floor(yb), dr.floor(y))
    fx = dr.select(bilinear, xb - x0, 0)
    fy = dr.select(bilinear, yb - y0, 0)

    def texel(ix, iy):
        cx = wrap_index(ix, width, mode)
        cy = wrap_index(iy, height, mode)
        index = offset + type(offset)(cy * width + cx)
        return dr.gather(type(texels), texels, index, active)

    t00, t10 = texel(x0, y0), texel(x0 + 1, y0)
    t01, t11 = texel(x0, y0 + 1), texel(x0 + 1, y0 + 1)
    top = dr.fma(fx, t10 - t00, t00)
    bottom = dr.fma(fx, t11 - t01, t01)
    return dr.fma(fy, bottom - top, top)


def latlong(d, texels, width: int, height: int):
    """A lat-long environment map's radiance in the unit direction ``d`` (its own frame).

    u = atan2(d.x, -d.z) / (2 pi), v = acos(d.y) / pi (+y the top row, -z the
    map's centre column), Mitsuba 3's ``envmap`` convention. Texel centres sit at
    u = (i + 1/2) / W (so u is shifted by half a texel and wrapped) and at
    v = j / (H - 1) (the first and last rows on the poles); bilinear between them.
    ``texels`` holds H rows of W + 1 texels, the last column repeating the first
    (periodic in u).
    """
    u = dr.atan2(d.x, -d.z) * (0.5 / math.pi)
    v = dr.safe_acos(d.y) * (1 / math.pi)
    u = faults.pick("latlong-z-not-negated", lambda: dr.atan2(d.x, d.z) * (0.5 / math.pi), u)
    u = u - 0.5 / width
    u = u - dr.floor(u)
    x = u * width
    y = v * (height - 1)
    px = dr.minimum(dr.floor(x), width - 1)
    py = dr.minimum(dr.floor(y), height - 2)
    wx, wy = x - px, y - py
    row = width + 1
    i = dr.fma(py, row, px)
    UInt = dr.uint32_array_t(type(d.x))
    i = UInt(i)
    v00 = dr.gather(type(texels), texels, i)
    v10 = dr.gather(type(texels), texels, i + 1)
    v01 = dr.gather(type(texels), texels, i + row)
    v11 = dr.gather(type(texels), texels, i + row + 1)
    top = dr.fma(wx, v10 - v00, v00)
    bottom = dr.fma(wx, v11 - v01, v01)
    return dr.fma(wy, bottom - top, top)
