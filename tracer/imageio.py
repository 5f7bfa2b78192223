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
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
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


def ppm_values(image: np.ndarray) -> np.ndarray:
    """The numbers minray prints for a linear image: 255 x value, rounded, no gamma, no clamp.

    minray prints ``"%.0f"`` of 255 x the colour computed in double precision:
    rounded to the nearest integer (exact ties to even, as C's printf and
    Python's format both do), and values above 255 printed as they come (a
    colour above 1 is not clamped). Negative values cannot come out of a
    renderer; NaN and negative zero are written as 0.
    """
    v = np.maximum(np.nan_to_num(image.astype(np.float64), nan=0.0), 0.0) * 255.0
    return np.rint(v).astype(np.int64)  # rint: round half to even, as "%.0f"


def write_ppm(path: str | Path, image: np.ndarray) -> None:
    """Plain-text PPM with the pixel lines of Heckbert's minray.

    minray prints ``"%d %d\\n"`` (width, height) and then, per pixel, top row
    first, ``"%.0f %.0f %.0f\\n"`` of 255 x the linear colour, without gamma
    (:func:`ppm_values`). The same lines are written here after the ``P3``
    magic and a maxval of 255, which make it a PPM (netpbm's plain format,
    ``man 5 ppm``). Like minray, values above 255 are written as they are,
    not clamped; netpbm's readers refuse such a file, :func:`read_ppm` reads
    them back as written.
    """
    h, w, _ = image.shape
    v = ppm_values(image)
    lines = [f"P3\n{w} {h}\n255\n"]
    lines += [f"{r} {g} {b}\n" for r, g, b in v.reshape(-1, 3).tolist()]
    text = "".join(lines)
    _atomic_write(Path(path), lambda tmp: Path(tmp).write_text(text))


def read_ppm(path: str | Path) -> np.ndarray:
    """The numbers of a PPM file (H x W x 3 integers as written), plain P3 or binary P6.

    A ``.gz`` file is decompressed first. Comments (``#`` to the end of a line)
    may stand between the header's fields, as netpbm allows. Values above
    maxval, which minray prints for colours above 1, are kept as written
    rather than refused. Divide by the maxval (255) for linear colours.
    """
    import gzip

    raw = Path(path).read_bytes()
    if str(path).endswith(".gz"):
        raw = gzip.decompress(raw)
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:  # magic, width, height, maxval
        while pos < len(raw) and raw[pos:pos + 1].isspace():
            pos += 1
        if raw[pos:pos + 1] == b"#":
            pos = raw.index(b"\n", pos) + 1 if b"\n" in raw[pos:] else len(raw)
            continue
        end = pos
        while end < len(raw) and not raw[end:end + 1].isspace() and raw[end:end + 1] != b"#":
            end += 1
        if end == pos:
            raise UserError(f"{path}: not a PPM file (header ends early)")
        fields.append(raw[pos:end])
        pos = end
    magic = fields[0]
    try:
        w, h, maxval = (int(x) for x in fields[1:])
    except ValueError:
        raise UserError(f"{path}: not a PPM file (bad header)") from None
    if magic == b"P6":
        body = np.frombuffer(raw[pos + 1:], dtype=">u2" if maxval > 255 else np.uint8)
    elif magic == b"P3":
        text = b"\n".join(line.split(b"#")[0] for line in raw[pos:].splitlines())
        body = np.array(text.split(), dtype=np.int64)
    else:
        raise UserError(f"{path}: not a PPM file (magic {magic[:2]!r}, expected P3 or P6)")
    if body.size < w * h * 3:
        raise UserError(f"{path}: {body.size} values, expected {w * h * 3} ({w} x {h} x 3)")
    return body[:w * h * 3].astype(np.int64).reshape(h, w, 3)


def write_image(path: str | Path, image: np.ndarray) -> None:
    """Write by extension: .exr (linear float32), .png (sRGB 8-bit), .ppm (minray's)."""
    suffix = Path(path).suffix.lower()
    {".exr": write_exr, ".png": write_png, ".ppm": write_ppm}[suffix](path, image)
