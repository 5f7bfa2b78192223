"""Reading another renderer's image: EXR, PFM, Radiance HDR, PNG and PPM, as linear radiance.

Which library reads what, and why:

* OpenEXR (``OpenEXR``, already pinned; :func:`tracer.imageio.read_exr_channels`):
  the reference implementation of the format. It gives every channel by
  name and in its stored type, so a HALF image's precision is known and a
  ``variance`` layer is found.
* PNG, PFM and Radiance HDR: Mitsuba 3's ``Bitmap`` (already pinned for the
  reference side): libpng for PNG (8 and 16 bits, grey, palette and alpha
  expanded), and its own PFM and RGBE readers (run-length encoded scanlines
  included). Pillow, also installed, reduces 16-bit RGB PNGs to 8 bits and
  reads neither PFM nor HDR.
* PPM: :func:`tracer.imageio.read_ppm_maxval`, the reader that matches
  Heckbert's minray, which prints values above 255 (colours above 1);
  netpbm-style readers (Pillow, Mitsuba) refuse or clip them.

Alpha. Where the file has an alpha channel (PNG RGBA or grey + alpha, an
EXR's ``A``) it is read into :attr:`UserImage.alpha` (PNG alpha is linear,
code / maxval, whatever the colours' encoding: PNG spec section 12.4) and
not applied: the colours are judged as stored, and a writer that multiplied
them by alpha is the "premultiplied alpha" convention of
:mod:`reference.check.conventions`. Images without alpha read as before.

The format is told from the file's first bytes, not its name, so that a
text file called ``x.png`` is "not an image" rather than a broken PNG.

Quantisation. Every stored value stands for a cell of values that round to
it; :class:`UserImage` records the width of that cell in linear units
(``step``), from which :mod:`reference.check.judge` takes the quantisation noise
(a uniform error over the cell: standard deviation step / sqrt(12),
Sheppard 1898; Widrow and Kollar, "Quantization Noise", 2008, ch. 4) and
the bound on what rounding can add up to where the image has no noise of
its own (half a step). The cells:

* 8- and 16-bit PNG and PPM: code c of maxval M stands for the encoded
  values (c - 1/2) / M to (c + 1/2) / M; decoded by ``--encoding``: ``srgb``
  (IEC 61966-2-1's curve; the default, as PNG viewers assume), ``linear``
  (c / M) or ``minray`` (c / 255, Heckbert's minray: 255 x linear printed with
  ``%.0f``, no gamma, no clamp, values above 255 allowed). The linear step is
  decode((c + 1/2) / M) - decode((c - 1/2) / M): a step of the sRGB curve is
  about 1 / (255 x 12.92) in the dark and 2.4 / 1.055 x^(1 - 1/2.4) / 255 at a
  linear value x, about 1.1 % of x at x = 0.5. ``srgb`` and ``linear``
  images are clipped to [0, 1] by their writer, so a value at M is saturated
  (the reference is clipped the same way before comparing).
* OpenEXR HALF: 11 significant bits, a step of 2^(floor(log2 |x|) - 10)
  (relative 2^-11 to 2^-10); FLOAT and PFM: float32, whose 2^-24 relative
  rounding stays far below the comparison's float floor.
* Radiance RGBE: one 8-bit mantissa per channel and a shared exponent E, the
  step 2^(E - 136), at most 1/128 of the pixel's brightest channel. Writers
  truncate the mantissa (Ward's ``setcolr``, Walter's ``rgbe.c``, stb, Mitsuba),
  and Radiance's own reader adds half a step (``colr_color``); Mitsuba's reader
  does not, so half a step is added here: read any other way, every value
  sits 0.2 to 0.4 % low, a bias the region sums of the check would see.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from whitted.tracer.errors import UserError
from whitted.tracer.imageheader import FORMAT_NAMES

ENCODINGS = ("srgb", "linear", "minray")
EIGHT_BIT = ("png", "ppm")


@dataclass
class UserImage:
    """Another renderer's image as linear radiance, and what its file could store."""
    path: str
    #: "exr", "pfm", "hdr", "png" or "ppm"
    format: str
    #: how the values were stored, in words ("float32", "half", "RGBE", "8-bit sRGB", ...)
    storage: str
    #: H x W x 3, float64, linear radiance (NaN or infinite where the file says so)
    image: np.ndarray
    #: H x W x 3: the linear width of the cell each value was rounded into; None where the
    #: file stores float32 (its rounding lies far below the comparison's float floor)
    step: np.ndarray | None = None
    #: H x W x 3 variance of each pixel's value, from a ``variance`` layer (EXR), or None
    variance: np.ndarray | None = None
    #: the level the writer clipped to (1.0 for sRGB and linear 8/16-bit), or None
    clip: float | None = None
    #: H x W x 3: values stored at the clip level (saturated: the true value may be higher)
    saturated: np.ndarray | None = None
    #: ``--encoding`` for 8-bit files, else None
    encoding: str | None = None
    #: notes for the user (an alpha channel not applied, a grey image widened)
    notes: tuple[str, ...] = ()
    #: H x W alpha in [0, 1] (PNG RGBA / grey + alpha, EXR ``A``), None where the file has none
    alpha: np.ndarray | None = None

    @property
    def size(self) -> tuple[int, int]:
        return self.image.shape[1], self.image.shape[0]


def srgb_decode(e: np.ndarray) -> np.ndarray:
    """The inverse of the sRGB curve (IEC 61966-2-1), for encoded values in [0, 1] and above."""
    e = np.asarray(e, dtype=np.float64)
    return np.where(e <= 0.04045, e / 12.92, ((np.maximum(e, 0.04045) + 0.055) / 1.055) ** 2.4)


def decode(codes: np.ndarray, maxval: int, encoding: str) -> np.ndarray:
    """Linear values of integer codes under an encoding (see the module docstring)."""
    c = np.asarray(codes, dtype=np.float64)
    if encoding == "srgb":
        return srgb_decode(c / maxval)
    if encoding == "linear":
        return c / maxval
    if encoding == "minray":
        return c / 255.0
    raise ValueError(f"unknown encoding {encoding!r}")


def code_steps(codes: np.ndarray, maxval: int, encoding: str) -> np.ndarray:
    """The linear width of each code's cell: decode(c + 1/2) - decode(c - 1/2).

    At code 0 the cell's lower half holds no light (a renderer writes no
    negative values), but the code still stands for anything up to half a step:
    the full width keeps |value - decode(c)| <= step / 2 (the curves extend
    linearly below 0).
    """
    c = np.asarray(codes, dtype=np.float64)
    return decode(c + 0.5, maxval, encoding) - decode(c - 0.5, maxval, encoding)


def half_steps(values: np.ndarray) -> np.ndarray:
    """The spacing of float16 values near each value: 2^(floor(log2|x|) - 10), 2^-24 below 2^-14."""
    a = np.abs(np.asarray(values, dtype=np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.floor(np.log2(np.where(a > 0, a, 1.0)))
    return np.where(a >= 2.0 ** -14, 2.0 ** (e - 10), 2.0 ** -24)


def read_user_image(path: str | Path, encoding: str | None = None) -> UserImage:
    """Read an image as linear radiance (see the module docstring); one-line errors.

    ``encoding`` (``srgb``, ``linear`` or ``minray``) says how an 8-bit file
    (PNG, PPM) encodes light; default ``srgb``. It is refused for formats that
    store linear floating-point values.
    """
    from whitted.tracer.imageheader import check_image_file, library_message

    p = Path(path)
    if encoding is not None and encoding not in ENCODINGS:
        raise UserError(f"--encoding: expected one of {', '.join(ENCODINGS)}, got {encoding!r}")
    # A regular file, a known header, a size whose reading fits WHITTED_MAX_MEMORY; the
    # format is told from the first bytes (a .ppm.gz by those of its decompressed data).
    fmt = check_image_file(p).format
    if encoding is not None and fmt not in EIGHT_BIT:
        raise UserError(f"{path}: --encoding {encoding} applies to 8-bit PNG and PPM files; "
                        f"a {FORMAT_NAMES[fmt]} file stores linear values")
    try:
        reader = {"exr": _read_exr, "png": _read_png, "pfm": _read_bitmap, "hdr": _read_bitmap,
                  "ppm": _read_ppm}[fmt]
        img = reader(p, fmt, encoding or "srgb")
    except UserError:
        raise
    except OSError as e:
        raise UserError(f"{path}: cannot read: {e.strerror or e}") from None
    except (RuntimeError, ValueError, KeyError, TypeError, EOFError) as e:
        raise UserError(f"{path}: unreadable {FORMAT_NAMES[fmt]} file "
                        f"({library_message([], e)})") from None
    if img.image.ndim != 3 or img.image.shape[0] < 1 or img.image.shape[1] < 1:
        raise UserError(f"{path}: an empty image")
    return img


ALPHA_NOTE = ("the image's alpha channel is not applied: its colours are judged as stored "
              "(premultiplied alpha is tried as a cause)")


def _alpha_plane(a: np.ndarray) -> np.ndarray | None:
    """The last channel of grey + alpha or RGBA (H x W), else None."""
    return a[..., -1] if a.ndim == 3 and a.shape[-1] in (2, 4) else None


def _rgb(a: np.ndarray, notes: list[str], what: str, keep_alpha: bool = False) -> np.ndarray:
    """H x W x 3 from grey (H x W or H x W x 1), grey + alpha, RGB or RGBA."""
    if a.ndim == 2:
        a = a[..., None]
    n = a.shape[-1]
    if n in (2, 4):
        notes.append(ALPHA_NOTE if keep_alpha else f"the {what}'s alpha channel is ignored")
        a = a[..., :n - 1]
    if a.shape[-1] == 1:
        notes.append(f"the {what} is grey: its value is used for R, G and B")
        a = np.repeat(a, 3, axis=-1)
    if a.shape[-1] != 3:
        raise UserError(f"{a.shape[-1]} channels per pixel, expected 1 to 4")
    return a


def _read_exr(p: Path, fmt: str, encoding: str) -> UserImage:
    from whitted.tracer.imageio import read_exr_channels

    channels, header = read_exr_channels(p)
    data, display = header.get("dataWindow"), header.get("displayWindow")
    if data is not None and display is not None and not all(
            np.array_equal(np.asarray(a), np.asarray(b)) for a, b in zip(data, display,
                                                                         strict=True)):
        raise UserError(f"{p}: its data window {np.asarray(data).tolist()} differs from its "
                        f"display window {np.asarray(display).tolist()} (a cropped EXR); "
                        "write the whole image")
    names = set(channels)
    if {"R", "G", "B"} <= names:
        planes = [channels[c] for c in "RGB"]
    elif "Y" in names:
        planes = [channels["Y"]] * 3
    else:
        shown = ", ".join(sorted(names)[:8])
        raise UserError(f"{p}: no R, G, B (or Y) channels in this EXR (found: {shown})")
    half = any(pl.dtype == np.float16 for pl in planes)
    image = np.stack([pl.astype(np.float64) for pl in planes], axis=-1)
    step = None
    if half:
        step = np.stack([half_steps(pl) if pl.dtype == np.float16 else np.zeros(pl.shape)
                         for pl in planes], axis=-1)
    variance = None
    var_names = [f"variance.{c}" for c in "RGB"]
    if all(v in names for v in var_names):
        variance = np.stack([channels[v].astype(np.float64) for v in var_names], axis=-1)
    elif "variance.Y" in names or "variance" in names:
        v = channels.get("variance.Y", channels.get("variance"))
        variance = np.repeat(v.astype(np.float64)[..., None], 3, axis=-1)
    if variance is not None and not (np.isfinite(variance).all() and (variance >= 0).all()):
        raise UserError(f"{p}: its variance layer has negative or non-finite values")
    notes = ("Y channel used for R, G and B",) if "R" not in names else ()
    alpha = None
    if "A" in names:
        a = channels["A"].astype(np.float64)
        alpha = np.clip(np.where(np.isfinite(a), a, 1.0), 0.0, 1.0)
        notes += (ALPHA_NOTE,)
    return UserImage(str(p), fmt, "half" if half else "float32", image, step, variance,
                     notes=notes, alpha=alpha)


def _bitmap_array(p: Path, fmt: str):
    """Mitsuba's Bitmap of a file and its array.

    Read from the file itself: Mitsuba's file stream refuses a file that ends
    early, where its memory stream reads on past the end. A name that is not
    UTF-8 (which Mitsuba cannot open) is read through a temporary copy. What
    libpng or Mitsuba print on stderr while reading is kept from the terminal;
    a failure is one line.
    """
    import shutil
    import tempfile

    from whitted.reference import mitsuba
    from whitted.tracer.imageheader import ImageError, captured_stderr, library_message

    mi = mitsuba()
    error = None
    with captured_stderr() as said:
        try:
            try:
                str(p).encode("utf-8")
                return np.array(mi.Bitmap(str(p)))
            except UnicodeEncodeError:
                with tempfile.TemporaryDirectory() as tmp:
                    copy = Path(tmp) / ("image" + "".join(c for c in p.suffix
                                                          if c.isalnum() or c == "."))
                    shutil.copyfile(p, copy)
                    return np.array(mi.Bitmap(str(copy)))
        except (RuntimeError, ValueError, TypeError, EOFError) as e:
            error = e
    raise ImageError(p, f"unreadable {FORMAT_NAMES[fmt]} file "
                        f"({library_message(said, error)})")


def _read_bitmap(p: Path, fmt: str, encoding: str) -> UserImage:
    """PFM (float32) and Radiance RGBE through Mitsuba's Bitmap."""
    a = _bitmap_array(p, fmt)
    notes: list[str] = []
    image = _rgb(a.astype(np.float64), notes, "image")
    if fmt == "pfm":
        return UserImage(str(p), fmt, "float32", image, notes=tuple(notes))
    # RGBE: Mitsuba decodes m 2^(E - 136); the brightest mantissa lies in [128, 256), so
    # the step 2^(E - 136) is 2^(floor(log2 max) - 7). Cell centres, as Radiance reads them.
    top = image.max(axis=-1)
    with np.errstate(divide="ignore"):
        step = np.where(top > 0, 2.0 ** (np.floor(np.log2(np.where(top > 0, top, 1))) - 7), 0.0)
    step = np.repeat(step[..., None], 3, axis=-1)
    return UserImage(str(p), fmt, "RGBE", image + 0.5 * step, step, notes=tuple(notes))


def _integer_image(p: Path, fmt: str, codes: np.ndarray, maxval: int, encoding: str,
                   bits: str, notes: list[str]) -> UserImage:
    if (codes < 0).any():
        raise UserError(f"{p}: negative values")
    over = codes > maxval
    if over.any() and encoding != "minray":
        raise UserError(f"{p}: {int(over.sum()):,} values above its maxval {maxval} (as "
                        "Heckbert's minray prints colours above 1: use --encoding minray)")
    if encoding == "minray" and maxval != 255:
        raise UserError(f"{p}: --encoding minray means 255 x linear, but the file's maxval is "
                        f"{maxval}")
    image = decode(codes, maxval, encoding)
    step = code_steps(codes, maxval, encoding)
    clip = None if encoding == "minray" else 1.0
    saturated = None if clip is None else codes >= maxval
    return UserImage(str(p), fmt, f"{bits} {encoding}", image, step, clip=clip,
                     saturated=saturated, encoding=encoding, notes=tuple(notes))


def _read_png(p: Path, fmt: str, encoding: str) -> UserImage:
    a = _bitmap_array(p, fmt)
    notes: list[str] = []
    codes = _rgb(a, notes, "image", keep_alpha=True)
    maxval = 65535 if codes.dtype == np.uint16 else 255
    img = _integer_image(p, fmt, codes.astype(np.int64), maxval, encoding,
                         "16-bit" if maxval > 255 else "8-bit", notes)
    alpha = _alpha_plane(a)
    if alpha is not None:       # linear whatever the colours' encoding (PNG spec 12.4)
        img.alpha = np.clip(alpha.astype(np.float64) / maxval, 0.0, 1.0)
    return img


def _read_ppm(p: Path, fmt: str, encoding: str) -> UserImage:
    from whitted.tracer.imageio import read_ppm_maxval

    codes, maxval = read_ppm_maxval(p)
    bits = "16-bit" if maxval > 255 else "8-bit"
    return _integer_image(p, fmt, codes, maxval, encoding, bits, [])
