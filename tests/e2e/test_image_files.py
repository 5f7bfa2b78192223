"""The image files `whitted render` writes are judged, not only its arrays: the PNG against
Mitsuba's own sRGB conversion of the same linear image, the PPM against its stated
encoding (minray's: 255 x linear, ``%.0f``, no gamma, no clamp).

A bug in an image writer (gamma 2.2 for the sRGB curve, a missing clamp, truncation
instead of rounding) leaves every comparison of arrays green; these laws catch it.
"""

from __future__ import annotations

import numpy as np
from conftest import run_cli, write_scene
from PIL import Image

from whitted.tracer.imageio import read_exr, read_ppm

# Values over the whole range: a floor lit by a point light close to it, from well above 1
# under the light to nearly black at the far corners, where the curve's linear part lies.
SCENE = """
[film]
width = 64
height = 48
spp = 1
max_depth = 2

[camera]
origin = [0, 4, 6]
target = [0, 0, 0]

[materials.grey]
type = "diffuse"
reflectance = 0.8

[[lights]]
type = "point"
position = [0, 0.6, 0]
intensity = 4

[[shapes]]
type = "rectangle"
to_world = [{ scale = [20, 20, 1] }, { rotate = { axis = [1, 0, 0], angle = -90 } }]
material = "grey"
"""


def _render(tmp_path, suffix):
    out = tmp_path / f"img.{suffix}"
    r = run_cli("render", write_scene(tmp_path, SCENE), "-o", out)
    assert r.returncode == 0, r.stderr
    return out


def test_png_equals_mitsubas_srgb_conversion_of_the_same_render(tmp_path, mi):
    """sRGB, IEC 61966-2-1: 12.92 x below 0.0031308, else 1.055 x^(1/2.4) - 0.055, clipped
    to [0, 1] and rounded to 8 bits. Mitsuba's Bitmap.convert(..., srgb_gamma=True) is the
    independent side. It evaluates the curve by an approximation that lands one code
    either side of the exact rounding on about 19 % of values, with no bias (measured
    on 4,000 values from 0 to 1.2: mean signed difference +0.019 code, never 2). So the
    law is: never more than one code apart, and no bias beyond 0.1 code in the mean.
    Truncation instead of rounding shows as a bias of -0.56 code; gamma 2.2 for the
    curve as 8 codes in the dark values; a missing clamp as a wrap-around above 1."""
    linear = read_exr(_render(tmp_path, "exr"))
    png = np.asarray(Image.open(_render(tmp_path, "png")).convert("RGB"))
    assert png.shape == linear.shape
    bitmap = mi.Bitmap(np.ascontiguousarray(linear, dtype=np.float32))
    expected = np.asarray(bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8,
                                         srgb_gamma=True))
    diff = png.astype(int) - expected.astype(int)
    # the render must span the curve's range for the law to say something
    assert (linear < 0.0031308).any() and (linear > 1).any()
    assert ((linear > 0.05) & (linear < 0.5)).mean() > 0.1
    assert np.abs(diff).max() <= 1, np.abs(diff).max()
    assert abs(diff.mean()) <= 0.1, diff.mean()


def test_ppm_holds_minrays_numbers_of_the_same_render(tmp_path):
    """The plain PPM's values are rint(255 x linear) of the EXR's float32 values, with
    values above 255 kept (no clamp): exactly, as the writer states."""
    linear = read_exr(_render(tmp_path, "exr"))
    ppm = read_ppm(_render(tmp_path, "ppm"))
    expected = np.rint(np.maximum(linear.astype(np.float64), 0.0) * 255.0)
    assert (expected > 255).any()  # the scene has values above 1: the no-clamp case is seen
    np.testing.assert_array_equal(np.asarray(ppm, dtype=np.float64), expected)
