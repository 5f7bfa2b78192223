"""Writing and reading images: linear EXR, sRGB PNG, and PPM as Heckbert's minray writes it.

Images are numpy arrays of shape (height, width, 3), float32, linear radiance.
Writes go to a temporary file in the target's folder that is renamed over the
target only when complete, so a failed run never leaves a clobbered file; the
file then gets the mode the umask gives (0666 less the umask), as a file
created with ``open`` would.

Output paths and folders are checked before any work (:func:`check_output_path`,
:func:`check_output_folder`): a missing folder, a file where a folder should
be, a name too long, a folder that cannot be written (read-only, immutable,
under /proc or /sys) are refused in one line, by trying to create a file
there; an error of the operating system while writing is one line too.
A job that writes many files over a long time writes them into a
:class:`StagedFolder`, which moves them into place only when all are written.
"""

from __future__ import annotations

import io
import os
import shutil
import stat
import tempfile
from pathlib import Path

import numpy as np

from whitted.tracer import faults
from whitted.tracer.errors import UserError

FORMATS = (".exr", ".png", ".ppm")


#: Prefix of temporary files and folders: short, so that a long target name never
#: makes a temporary name too long.
TEMP_PREFIX = ".whitted-"


def _os_error(path, e: OSError, doing: str = "cannot write") -> UserError:
    return UserError(f"{path}: {doing}: {e.strerror or e}")


def _name_max(folder: Path) -> tuple[int, int]:
    try:
        return os.pathconf(folder, "PC_NAME_MAX"), os.pathconf(folder, "PC_PATH_MAX")
    except (OSError, ValueError):
        return 255, 4096


def _nearest_existing(p: Path, path) -> Path:
    """The nearest of p and its ancestors that exists; it must be a folder unless it is p."""
    q = p
    while True:
        try:
            st = os.stat(q)
        except FileNotFoundError:
            if q.parent == q:
                raise UserError(f"{path}: no such folder") from None
            q = q.parent
            continue
        except NotADirectoryError:
            q = q.parent
            continue
        except OSError as e:
            raise _os_error(path, e, f"cannot use {q}") from None
        if q != p and not stat.S_ISDIR(st.st_mode):
            raise UserError(f"{path}: {q} is a file, not a folder")
        return q


def _probe(folder: Path, path) -> None:
    """Create and remove a temporary file in ``folder``: proof that it can be written."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=TEMP_PREFIX, dir=folder)
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        raise _os_error(path, e, f"cannot write into {folder}") from None


def _check_names(p: Path, base: Path, path) -> None:
    """Every name from ``base`` down to ``p`` within the file system's name and path limits."""
    name_max, path_max = _name_max(base)
    for part in p.relative_to(base).parts if p != base else ():
        if len(os.fsencode(part)) > name_max:
            raise UserError(f"{path}: a name in it is longer than {name_max} bytes")
    if len(os.fsencode(os.path.abspath(p))) >= path_max:
        raise UserError(f"{path}: the path is longer than {path_max - 1} bytes")


def check_output_path(path: str | Path, formats: tuple[str, ...] = FORMATS,
                      what: str = "image format") -> Path:
    """Refuse an output file before any work: unknown extension, missing or unwritable folder.

    The folder must exist; a file is created and removed there to prove it can
    be written (no other test tells a read-only, immutable or virtual folder).
    """
    p = Path(path)
    if p.suffix.lower() not in formats:
        raise UserError(f"{path}: unknown {what} {p.suffix or '(none)'!r} "
                        f"(expected one of: {', '.join(formats)})")
    parent = p.parent if str(p.parent) else Path(".")
    found = _nearest_existing(p, path)
    if found != p and found != parent:
        raise UserError(f"{path}: folder {parent} does not exist")
    if found == p:
        if p.is_dir():
            raise UserError(f"{path}: is a folder, expected a file name")
        if not p.is_file():
            raise UserError(f"{path}: exists and is not a regular file")
    _check_names(p, parent, path)
    _probe(parent, path)
    return p


def check_output_folder(path: str | Path) -> Path:
    """Refuse an output folder before any work: a file in the way, or nowhere to create it.

    The folder may exist (then it is written into) or not (then it is created
    when the outputs are written, with its missing parents); either way a
    temporary file is created and removed in the nearest existing folder.
    """
    p = Path(path)
    found = _nearest_existing(p, path)
    if not found.is_dir():
        raise UserError(f"{path}: exists and is not a folder")
    _check_names(p, found, path)
    _probe(found, path)
    return p


def file_mode() -> int:
    """The mode ``open`` gives a new file: 0666 less the process's umask."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


class StagedFolder:
    """An output folder whose files appear only when the job has written all of them.

    Files are written into a hidden temporary folder (inside the target if it
    exists, else beside its nearest existing ancestor) and moved into the
    target by :meth:`commit`; leaving the ``with`` block without committing
    (an error, an interrupt) removes them, so that no partial output remains.
    """

    def __init__(self, target: str | Path):
        self.target = check_output_folder(target)
        base = self.target if self.target.is_dir() else _nearest_existing(self.target, target)
        try:
            self.path = Path(tempfile.mkdtemp(prefix=TEMP_PREFIX, dir=base))
        except OSError as e:
            raise _os_error(target, e) from None

    def __enter__(self) -> StagedFolder:
        return self

    def final(self, p: str | Path) -> Path:
        """Where a file written under :attr:`path` ends up."""
        return self.target / Path(p).relative_to(self.path)

    def commit(self) -> None:
        try:
            for src in sorted(self.path.rglob("*")):
                dst = self.final(src)
                if src.is_dir():
                    dst.mkdir(parents=True, exist_ok=True)
                else:
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(src, dst)
        except OSError as e:
            raise _os_error(self.target, e) from None
        finally:
            shutil.rmtree(self.path, ignore_errors=True)

    def __exit__(self, *exc) -> None:
        shutil.rmtree(self.path, ignore_errors=True)


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of values clipped to [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def to_srgb8(image: np.ndarray) -> np.ndarray:
    """8-bit sRGB codes of a linear image (IEC 61966-2-1), clipped to [0, 1] and rounded."""
    if faults.on("png-gamma-2.2"):
        x = np.clip(np.nan_to_num(image), 0, 1)
        return np.round(np.power(x, 1 / 2.2) * 255).astype(np.uint8)
    if faults.on("png-truncated"):
        return np.floor(srgb_encode(np.nan_to_num(image)) * 255).astype(np.uint8)
    return np.round(srgb_encode(np.nan_to_num(image)) * 255).astype(np.uint8)


def _atomic_write(path: Path, write) -> None:
    """Write through a temporary file renamed over ``path``; OS errors become one line."""
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=TEMP_PREFIX, suffix=".tmp",
                                   dir=str(path.parent) if str(path.parent) else ".")
        os.close(fd)
        write(tmp)
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
        tmp = None
    except OSError as e:
        raise _os_error(path, e) from None
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)


def write_exr(path: str | Path, image: np.ndarray,
              channels: dict[str, np.ndarray] | None = None) -> None:
    """Linear float32 RGB OpenEXR; ``channels`` adds H x W channels by name (``variance.R``)."""
    import OpenEXR

    # OpenEXR compresses blocks of scanlines in parallel when given threads: ZIP at
    # 800x480 took 40 ms on one thread, 22 ms on two (the same bytes).
    if hasattr(OpenEXR, "set_global_thread_count"):
        OpenEXR.set_global_thread_count(os.cpu_count() or 1)
    data = np.ascontiguousarray(image, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    planes = {"RGB": data}
    for name, plane in (channels or {}).items():
        planes[name] = np.ascontiguousarray(plane, dtype=np.float32)

    def write(tmp):
        # Through memory: OpenEXR takes only file names it can encode as UTF-8.
        buf = io.BytesIO()
        with OpenEXR.File(header, planes) as f:
            f.write(buf)
        Path(tmp).write_bytes(buf.getvalue())

    _atomic_write(Path(path), write)


def read_exr(path: str | Path) -> np.ndarray:
    """The R, G, B channels of an OpenEXR file as float32 (H x W x 3)."""
    from whitted.tracer.imageheader import ImageError

    channels, _ = read_exr_channels(path)
    if not {"R", "G", "B"} <= set(channels):
        shown = ", ".join(sorted(channels)[:8])
        raise ImageError(path, f"no R, G, B channels in this OpenEXR file (found: {shown})")
    return np.stack([np.asarray(channels[c], dtype=np.float32) for c in "RGB"], axis=-1)


def read_exr_channels(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Every channel of an OpenEXR file by its full name, as stored, and the header.

    Names are OpenEXR's, layers included (``R``, ``G``, ``B``, ``Y``,
    ``variance.R``); each array is H x W in the file's own type (float16 for
    HALF, float32 for FLOAT, uint32 for UINT), so that a caller can tell the
    precision a value was stored with. Read through memory: OpenEXR takes only
    file names it can encode as UTF-8. The file is checked first
    (:func:`tracer.imageheader.check_image_file`: a regular file, an OpenEXR
    header, a size within WHITTED_MAX_MEMORY), and what the library prints on
    stderr while it reads is kept from the terminal: a failure is one
    :class:`~tracer.imageheader.ImageError` line.
    """
    import OpenEXR

    from whitted.tracer.imageheader import (
        ImageError,
        captured_stderr,
        check_image_file,
        library_message,
        read_file,
    )

    data = read_file(path, check_image_file(path, ("exr",)))
    error = None
    with captured_stderr() as said:
        try:
            with OpenEXR.File(io.BytesIO(data), separate_channels=True) as f:
                channels = {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}
                header = dict(f.header())
        except (RuntimeError, ValueError, TypeError, KeyError, IndexError, OSError,
                EOFError) as e:
            error = e
    if error is not None:
        raise ImageError(path, f"unreadable OpenEXR file ({library_message(said, error)})")
    return channels, header


#: A PNG texture's reading, per value beyond the decoded one: Pillow's image, its RGB
#: conversion, float64 codes, the sRGB curve's temporaries, the float32 texels (measured:
#: 34 bytes a value in all, 2000 x 1500 RGB or grey).
PNG_TEXTURE_WORK_BYTES_PER_VALUE = 44


#: A JPEG texture's reading, per value beyond the decoded one: as a PNG's (Pillow's image,
#: its RGB conversion, then the same float64 codes and sRGB curve).
JPEG_TEXTURE_WORK_BYTES_PER_VALUE = PNG_TEXTURE_WORK_BYTES_PER_VALUE
#: A Radiance HDR file's reading, per value beyond the float32 result: the RGBE bytes
#: (4 a pixel, 3 values) and float32 mantissas and scales.
HDR_TEXTURE_WORK_BYTES_PER_VALUE = 12

#: Bitmap files by suffix: the format their bytes must hold.
TEXTURE_SUFFIXES = {".png": "png", ".exr": "exr", ".jpg": "jpeg", ".jpeg": "jpeg",
                    ".hdr": "hdr"}


def read_texture_file(path: str | Path) -> np.ndarray:
    """A bitmap texture's or environment map's file, as Mitsuba's ``Bitmap`` decodes it:
    an 8-bit PNG or a JPEG as its codes (H x W x 3 uint8, grey, palette and alpha
    reduced to RGB; the caller decodes sRGB), an OpenEXR or Radiance HDR file as its
    linear R, G, B (float32). The format must agree with the suffix (``.png``,
    ``.jpg``/``.jpeg``, ``.exr``, ``.hdr``); the file is checked before it is decoded
    (:func:`tracer.imageheader.check_image_file`). Errors are one
    :class:`~tracer.imageheader.ImageError` line.
    """
    from whitted.tracer.imageheader import ImageError, check_image_file, read_file

    suffix = Path(path).suffix.lower()
    fmt = TEXTURE_SUFFIXES.get(suffix)
    if fmt is None:
        raise ImageError(path, "expected a .png, .jpg, .jpeg, .exr or .hdr image")
    if fmt == "exr":
        return np.ascontiguousarray(read_exr(path), dtype=np.float32)
    if fmt == "hdr":
        header = check_image_file(path, ("hdr",), HDR_TEXTURE_WORK_BYTES_PER_VALUE)
        return read_rgbe(path, read_file(path, header), header.width, header.height)
    work = PNG_TEXTURE_WORK_BYTES_PER_VALUE if fmt == "png" else \
        JPEG_TEXTURE_WORK_BYTES_PER_VALUE
    data = read_file(path, check_image_file(path, (fmt,), work))
    return _pillow_codes(path, data, fmt)


def _pillow_codes(path, data: bytes, fmt: str) -> np.ndarray:
    """An 8-bit PNG's or a JPEG's codes through Pillow (H x W x 3 uint8).

    JPEG: Pillow's libjpeg(-turbo) with its defaults (the accurate integer IDCT,
    fancy chroma upsampling), as Mitsuba's libjpeg decodes; grey and YCbCr only
    (Mitsuba reads one or three components), no colour management.
    """
    from PIL import Image

    from whitted.tracer.imageheader import ImageError

    name = "PNG" if fmt == "png" else "JPEG"
    allowed = ("L", "LA", "RGB", "RGBA", "P") if fmt == "png" else ("L", "RGB")
    # The size was checked against WHITTED_MAX_MEMORY: Pillow's own limit on pixels
    # (a warning, then an exception, at 89 and 179 million) would only differ.
    bomb_limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
    try:
        with Image.open(io.BytesIO(data), formats=[name]) as im:
            if im.mode not in allowed:
                expected = "an 8-bit PNG" if fmt == "png" else "a grey or RGB (YCbCr) JPEG"
                raise ImageError(path, f"{expected} is expected, got mode {im.mode}")
            return np.asarray(im.convert("RGB"), dtype=np.uint8)
    except (OSError, ValueError, SyntaxError, EOFError) as e:
        from whitted.tracer.errors import one_line

        raise ImageError(path, f"unreadable {name} file ({one_line(str(e), 160)})") from None
    finally:
        Image.MAX_IMAGE_PIXELS = bomb_limit


def read_rgbe(path, data: bytes, width: int, height: int) -> np.ndarray:
    """The pixels of a Radiance HDR file (its bytes ``data``; the size from its checked
    header) as linear float32 R, G, B, H x W x 3, top row first.

    Greg Ward's RGBE ("Real Pixels", Graphics Gems II, 1991), read as Bruce Walter's
    ``rgbe.c`` reads it, which Mitsuba's ``Bitmap`` follows: a value is
    m 2^(E - 136) for a mantissa m and a shared exponent E > 0, and 0 where E = 0
    (exact in float32). Scanlines 8 to 32767 pixels wide may be run-length encoded
    per channel (``2 2`` and the width, then runs: a count above 128 repeats one byte
    count - 128 times, else that many bytes follow); others, and files whose first
    scanline is not so marked, are flat RGBE quadruples. Only the standard orientation
    ``-Y height +X width`` and ``FORMAT=32-bit_rle_rgbe`` (or none) are read.
    """
    from whitted.tracer.imageheader import ImageError

    def bad(why: str) -> ImageError:
        return ImageError(path, f"unreadable Radiance HDR file ({why})")

    end = data.find(b"\n\n")
    for line in data[:end].split(b"\n")[1:]:
        if line.startswith(b"FORMAT=") and line.strip() != b"FORMAT=32-bit_rle_rgbe":
            raise bad(f"{line.strip()[:40].decode('ascii', 'replace')}; only "
                      "32-bit_rle_rgbe is read")
    nl = data.find(b"\n", end + 2)
    res = data[end + 2:nl if nl >= 0 else len(data)].split()
    if res[:1] != [b"-Y"] or res[2:3] != [b"+X"]:
        raise bad(f"orientation {b' '.join(res[0:4:2]).decode('ascii', 'replace')[:20]}; "
                  "only -Y height +X width is read")
    pos = nl + 1
    n = width * height
    out = np.empty((height, width, 4), dtype=np.uint8)
    rle = 8 <= width <= 0x7FFF and len(data) >= pos + 4 and \
        data[pos:pos + 2] == b"\x02\x02" and not data[pos + 2] & 0x80
    if not rle:
        flat = np.frombuffer(data, np.uint8, 4 * n, pos) if len(data) - pos >= 4 * n else None
        if flat is None:
            raise bad(f"{width} x {height} pixels, the file ends before them")
        out[:] = flat.reshape(height, width, 4)
    else:
        for y in range(height):
            head = data[pos:pos + 4]
            if len(head) < 4 or head[:2] != b"\x02\x02" or (head[2] << 8 | head[3]) != width:
                raise bad(f"scanline {y}: wrong run-length header")
            pos += 4
            for c in range(4):
                x = 0
                row = out[y, :, c]
                while x < width:
                    if pos >= len(data):
                        raise bad(f"scanline {y}: the file ends inside it")
                    count = data[pos]
                    if count > 128:
                        count -= 128
                        if x + count > width or pos + 1 >= len(data):
                            raise bad(f"scanline {y}: a run beyond its width")
                        row[x:x + count] = data[pos + 1]
                        pos += 2
                    else:
                        if count == 0 or x + count > width or pos + 1 + count > len(data):
                            raise bad(f"scanline {y}: a run beyond its width")
                        row[x:x + count] = np.frombuffer(data, np.uint8, count, pos + 1)
                        pos += 1 + count
                    x += count
    e = out[..., 3].astype(np.int32)
    scale = np.where(e > 0, np.ldexp(np.float32(1), e - 136), np.float32(0)).astype(np.float32)
    return out[..., :3].astype(np.float32) * scale[..., None]


def write_png(path: str | Path, image: np.ndarray) -> None:
    """8-bit sRGB PNG (linear values clipped to [0, 1], then the sRGB curve)."""
    from PIL import Image

    rgb = to_srgb8(image) if image.dtype != np.uint8 else image
    _atomic_write(Path(path), lambda tmp: _write_png_file(tmp, Image.fromarray(rgb, "RGB")))


def _write_png_file(tmp: str, image) -> None:
    image.save(tmp, format="PNG")


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
    rather than refused. Divide by the maxval (255) for linear colours
    (:func:`read_ppm_maxval` returns it).
    """
    return read_ppm_maxval(path)[0]


def read_ppm_maxval(path: str | Path) -> tuple[np.ndarray, int]:
    """:func:`read_ppm`'s numbers and the file's maxval (netpbm's ``man 5 ppm``).

    P6 stores one byte per value for a maxval below 256 and two (most
    significant first) otherwise; P3 stores decimal numbers, which may exceed
    the maxval (minray's colours above 1).
    """
    from whitted.tracer.imageheader import (
        ImageError,
        check_image_file,
        gunzip_bounded,
        ppm_fields,
        read_file,
    )
    from whitted.tracer.limits import PPM_TEXT_BYTES_PER_BYTE, check_memory

    header = check_image_file(path, ("ppm",))
    raw = read_file(path, header)
    if header.gzip:
        raw = gunzip_bounded(path, raw, PPM_TEXT_BYTES_PER_BYTE)
    fields, pos = ppm_fields(raw)
    if len(fields) < 4:
        raise UserError(f"{path}: not a PPM file (header ends early)")
    if fields[0] == b"P3":
        try:  # text: every number a Python object on the way (see PPM_TEXT_BYTES_PER_BYTE)
            check_memory(len(raw) * PPM_TEXT_BYTES_PER_BYTE,
                         f"reading this {len(raw):,}-byte plain PPM text")
        except UserError as e:
            raise ImageError(path, str(e)) from None
    magic = fields[0]
    try:
        w, h, maxval = (int(x) for x in fields[1:])
    except ValueError:
        raise UserError(f"{path}: not a PPM file (bad header)") from None
    if w < 1 or h < 1 or not 1 <= maxval <= 65535:
        raise UserError(f"{path}: not a PPM file (size {w} x {h}, maxval {maxval}: expected "
                        "a positive size and a maxval from 1 to 65535)")
    if magic == b"P6":
        body = raw[pos + 1:]
        wide = maxval > 255
        body = body[:len(body) - len(body) % 2] if wide else body
        body = np.frombuffer(body, dtype=">u2" if wide else np.uint8)
    elif magic == b"P3":
        text = b"\n".join(line.split(b"#")[0] for line in raw[pos:].splitlines())
        try:
            body = np.array(text.split(), dtype=np.int64)
        except (ValueError, OverflowError):
            raise UserError(f"{path}: a PPM value is not a whole number") from None
    else:
        raise UserError(f"{path}: not a PPM file (magic {magic[:2]!r}, expected P3 or P6)")
    if body.size < w * h * 3:
        raise UserError(f"{path}: {body.size} values, expected {w * h * 3} ({w} x {h} x 3)")
    return body[:w * h * 3].astype(np.int64).reshape(h, w, 3), maxval


def write_image(path: str | Path, image: np.ndarray) -> None:
    """Write by extension: .exr (linear float32), .png (sRGB 8-bit), .ppm (minray's)."""
    suffix = Path(path).suffix.lower()
    {".exr": write_exr, ".png": write_png, ".ppm": write_ppm}[suffix](path, image)
