"""Generate the built-in textures (run from anywhere; writes beside this file).

* tiles.png: 24 x 16 sRGB texels, a lettered pattern that is different in every
  row and column (an arrow pointing to the image's top-left corner on a
  gradient), so that a texture read upside down, mirrored or transposed shows.
"""

from pathlib import Path

import numpy as np
from PIL import Image


def tiles(width: int = 24, height: int = 16) -> np.ndarray:
    y, x = np.mgrid[0:height, 0:width]
    r = 40 + 200 * x / (width - 1)
    g = 40 + 180 * y / (height - 1)
    b = np.full_like(r, 90.0)
    arrow = (x + y < 9) & (np.abs(x - y) < 3) | ((x < 6) & (y < 2)) | ((y < 6) & (x < 2))
    img = np.stack([r, g, b], axis=-1)
    img[arrow] = (250, 240, 60)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


if __name__ == "__main__":
    out = Path(__file__).with_name("tiles.png")
    Image.fromarray(tiles()).save(out)
    print(f"wrote {out}")
