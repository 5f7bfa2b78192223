"""Generate the built-in textures (run from anywhere; writes beside this file).

* tiles.png: 24 x 16 sRGB texels, a lettered pattern that is different in every
  row and column (an arrow pointing to the image's top-left corner on a
  gradient), so that a texture read upside down, mirrored or transposed shows;
* sky.exr: a 48 x 24 lat-long environment (linear float32 OpenEXR): a blue sky
  brightening towards the horizon, a brownish ground, and a broad warm sun 40 degrees
  above the horizon, off the map's centre, so that a map turned or mirrored shows.
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


def sky(width: int = 48, height: int = 24) -> np.ndarray:
    v = np.arange(height)[:, None] / (height - 1)        # 0: zenith, 1: nadir
    u = (np.arange(width)[None, :] + 0.5) / width
    theta, phi = v * np.pi, u * 2 * np.pi
    d = np.stack(np.broadcast_arrays(np.sin(phi) * np.sin(theta), np.cos(theta),
                                     -np.cos(phi) * np.sin(theta)), axis=-1)
    up = np.clip(d[..., 1], 0, 1)[..., None]
    img = np.where(d[..., 1:2] >= 0, (0.25, 0.45, 0.9) * (1 - up) + (0.1, 0.2, 0.6) * up,
                   np.broadcast_to((0.18, 0.13, 0.08), d.shape))
    sun = np.array([np.sin(1.1) * np.cos(np.radians(40)), np.sin(np.radians(40)),
                    -np.cos(1.1) * np.cos(np.radians(40))])
    img = img + 2.5 * (d @ sun > 0.9)[..., None] * np.array([1.0, 0.9, 0.7])
    return img.astype(np.float32)


if __name__ == "__main__":
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from whitted.tracer.imageio import write_exr

    out = Path(__file__).with_name("tiles.png")
    Image.fromarray(tiles()).save(out)
    print(f"wrote {out}")
    out = Path(__file__).with_name("sky.exr")
    write_exr(out, sky())
    print(f"wrote {out}")
