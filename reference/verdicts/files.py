"""The image files the tracer writes, judged against an independent encoder.

Every comparison of images reads the tracer's float32 arrays, so a bug in the code that
writes them to disk (gamma 2.2 for the sRGB curve, truncation instead of rounding)
leaves every verdict green. :func:`png_checks` writes the tracer's image through its own
PNG writer (:func:`tracer.imageio.write_png`), reads the file back, and compares its
codes with Mitsuba's own sRGB conversion of the same linear image
(``mi.Bitmap.convert(..., srgb_gamma=True)``; the curve is IEC 61966-2-1's: 12.92 x
below 0.0031308, else 1.055 x^(1/2.4) - 0.055, clipped to [0, 1], 8 bits).

The two rules, as ``tests/e2e/test_image_files.py`` derives them: Mitsuba evaluates the
curve by an approximation that lands one code either side of the exact rounding on
about 19 % of values and never two, with no bias (measured on 4,000 values from 0 to
1.2: mean signed difference +0.019 code). So

* ``png_max_code``: the largest difference in codes stays below 1.5 (one code apart is
  Mitsuba's rounding, two is not);
* ``png_mean_code``: the mean signed difference stays within 0.1 code (truncation shows
  as about -0.5, gamma 2.2 as several codes in the dark values).

Each check is ``{"value", "limit", "pass"}``, as the image verdicts' are
(:func:`reference.mutants.margin` reads them alike).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

#: Largest difference in 8-bit codes between the tracer's PNG and Mitsuba's conversion.
MAX_CODE = 1.5
#: Largest mean signed difference in codes (a bias).
MEAN_CODE = 0.1


def png_checks(image: np.ndarray, mi) -> dict:
    """The PNG the tracer writes of ``image`` (H x W x 3, linear) against Mitsuba's."""
    from PIL import Image

    from whitted.tracer.imageio import write_png

    linear = np.ascontiguousarray(np.asarray(image, dtype=np.float32)[..., :3])
    with tempfile.TemporaryDirectory(prefix="whitted-png-") as folder:
        path = Path(folder) / "image.png"
        write_png(path, linear)
        with Image.open(path) as f:
            ours = np.asarray(f.convert("RGB"), dtype=np.int64)
    bitmap = mi.Bitmap(linear)
    theirs = np.asarray(bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8,
                                       srgb_gamma=True), dtype=np.int64)
    diff = ours - theirs
    worst = float(np.abs(diff).max()) if diff.size else 0.0
    bias = abs(float(diff.mean())) if diff.size else 0.0
    return {"png_max_code": {"value": worst, "limit": MAX_CODE, "pass": worst < MAX_CODE},
            "png_mean_code": {"value": bias, "limit": MEAN_CODE, "pass": bias <= MEAN_CODE}}
