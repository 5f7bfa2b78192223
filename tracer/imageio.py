"""Writing and reading images: linear EXR, sRGB PNG, and PPM as Heckbert's minray writes it.

Images are numpy arrays of shape (height, width, 3), float32, linear radiance.
Writes go to a temporary file in the target's folder that is renamed over the
target only when complete, so a failed run never leaves a clobbered file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from tracer.errors import UserError

FORMATS = (".exr", ".png", ".ppm")


def check_output_path(path: str | Path, formats: tuple[str, ...] = FORMATS,
                      what: str = "image format") -> Path:
    """Refuse an output path before any work: unknown extension or a missing folder."""
    p = Path(path)
    if p.suffix.lower() not in formats:
        raise UserError(f"{path}: unknown {what} {p.suffix or '(none)'!r} "
                        f"(expected one of: {', '.join(formats)})")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise UserError(f"{path}: folder {parent} does not exist")
    if p.is_dir():
        raise UserError(f"{path}: is a folder, expected an image file name")
    return p


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of values clipped to [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def to_srgb8(image: np.ndarray) -> np.ndarray:
    return np.round(srgb_encode(np.nan_to_num(image)) * 255).astype(np.uint8)


def _atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix,
                               dir=str(path.parent) if str(path.parent) else ".")
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_exr(path: str | Path, image: np.ndarray) -> None:
    """Linear float32 RGB OpenEXR."""
    import OpenEXR

    data = np.ascontiguousarray(image, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def write(tmp):
        with OpenEXR.File(header, {"RGB": data}) as f:
            f.write(tmp)

    _atomic_write(Path(path), write)


def read_exr(path: str | Path) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        if "RGB" in ch:
            return np.asarray(ch["RGB"].pixels, dtype=np.float32)
        return np.stack([np.asarray(ch[c].pixels, dtype=np.float32) for c in "RGB"], axis=-1)


def write_png(path: str | Path, image: np.ndarray) -> None:
    """8-bit sRGB PNG (linear values clipped to [0, 1], then the sRGB curve)."""
    from PIL import Image

    rgb = to_srgb8(image) if image.dtype != np.uint8 else image
    _atomic_write(Path(path), lambda tmp: Image.fromarray(rgb, "RGB").save(tmp, format="PNG"))


def write_ppm(path: str | Path, image: np.ndarray) -> None:
    """Plain-text PPM with the pixel lines of Heckbert's minray.

    minray prints ``"%d %d\\n"`` (width, height) and then, per pixel, top row
    first, ``"%.0f %.0f %.0f\\n"`` of 255 x the linear colour, without gamma.
    The same lines are written here after the ``P3`` magic and a maxval of 255,
    which make it a valid PPM; values are clipped to [0, 255].
    """
    h, w, _ = image.shape
    v = np.clip(np.nan_to_num(image) * 255.0, 0, 255)
    lines = [f"P3\n{w} {h}\n255\n"]
    lines += [f"{r:.0f} {g:.0f} {b:.0f}\n" for r, g, b in v.reshape(-1, 3)]
    text = "".join(lines)
    _atomic_write(Path(path), lambda tmp: Path(tmp).write_text(text))


def write_image(path: str | Path, image: np.ndarray) -> None:
    """Write by extension: .exr (linear float32), .png (sRGB 8-bit), .ppm (minray's)."""
    suffix = Path(path).suffix.lower()
    {".exr": write_exr, ".png": write_png, ".ppm": write_ppm}[suffix](path, image)
