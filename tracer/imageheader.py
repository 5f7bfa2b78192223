"""Image files checked before any decoder runs: a regular file, its format, its size.

Every image the project reads (a scene's bitmap texture or environment map,
``whitted check``'s input, a stored reference) passes :func:`check_image_file`
first. It refuses in one line, before a byte of pixel data is decoded:

* anything but a regular file (a FIFO would block the reader for ever, a
  device such as ``/dev/zero`` never ends);
* a file whose first bytes are no OpenEXR, PNG, PFM, Radiance HDR or PPM
  header (the format is told from the bytes, not the name);
* an image whose decoding would take more memory than ``WHITTED_MAX_MEMORY``
  (:func:`tracer.limits.check_image_memory`): the width, height and channels
  come from the header alone, so a 1 KB PNG whose IHDR claims
  100000 x 100000 pixels (a "decompression bomb") is refused before libpng or
  Pillow allocate anything.

The headers, as their specifications define them:

* PNG (ISO/IEC 15948, section 11.2.2): the 8-byte signature, then the IHDR
  chunk: width and height as big-endian uint32, bit depth, colour type
  (0 grey, 2 RGB, 3 palette, 4 grey + alpha, 6 RGBA).
* OpenEXR ("The OpenEXR File Layout"): magic ``76 2f 31 01``, a version word
  (bit 11 deep data, bit 12 multi-part), then attributes ``name\\0 type\\0
  size value`` up to an empty name; ``dataWindow`` (box2i: xMin, yMin, xMax,
  yMax, int32) gives the size, ``channels`` (chlist) the channels. A
  multi-part file has one such header per part and an empty one after them.
* PFM (Paul Debevec's page, netpbm's ``pfm``): ``PF`` (RGB) or ``Pf`` (grey),
  width, height and scale as text.
* Radiance HDR (Ward, "Real Pixels", Graphics Gems II; Radiance's
  ``color.c``): ``#?RADIANCE`` or ``#?RGBE``, lines up to an empty one, then
  the resolution ``-Y height +X width`` (or another orientation).
* PPM (netpbm's ``man 5 ppm``): ``P3`` or ``P6``, width, height and maxval
  as text, comments allowed between them; a ``.ppm.gz`` file's are read from
  the start of its decompressed stream.
* JPEG (ITU-T T.81, annex B): SOI ``FF D8``, then marker segments ``FF xx``
  with a big-endian length (which counts itself) up to the first frame header
  SOFn (``C0``-``CF`` but ``C4`` DHT, ``C8`` JPG, ``CC`` DAC): precision,
  height, width, components (1 grey, 3 YCbCr, 4 CMYK). The segments are
  walked with seeks, so large APPn blocks (Exif, ICC profiles) before the
  frame header are skipped unread. JPEG is read only where a reader asks for
  it (bitmap textures and environment maps, as Mitsuba reads them); other
  readers (``whitted check``) refuse it by name.

A ``.png`` texture that is a JPEG inside is refused by its first bytes.
"""

from __future__ import annotations

import contextlib
import os
import re
import struct
import sys
import tempfile
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from whitted.tracer.errors import UserError
from whitted.tracer.files import NotRegularFile, read_regular, special_kind

#: Formats by their first bytes (the magic numbers of their specifications).
MAGIC = ((b"v/1\x01", "exr"), (b"\x89PNG\r\n\x1a\n", "png"), (b"PF", "pfm"), (b"Pf", "pfm"),
         (b"#?RADIANCE", "hdr"), (b"#?RGBE", "hdr"), (b"P3", "ppm"), (b"P6", "ppm"),
         (b"\x1f\x8b", "gz"), (b"\xff\xd8\xff", "jpeg"))

FORMAT_NAMES = {"exr": "OpenEXR", "png": "PNG", "pfm": "PFM", "hdr": "Radiance HDR",
                "ppm": "PPM", "jpeg": "JPEG"}

#: The formats a reader takes unless it names others (JPEG only where asked for).
DEFAULT_FORMATS = ("exr", "png", "pfm", "hdr", "ppm")

#: JPEG frame headers (SOF0-SOF15 less DHT C4, JPG C8, DAC CC), ITU-T T.81 table B.1.
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
#: Marker segments walked before the frame header is given up (a file of empty segments).
JPEG_MAX_SEGMENTS = 4096

#: How far into a file a text header (PFM, HDR, PPM: comments included) may reach.
TEXT_HEADER_BYTES = 64 << 10

#: PNG colour types (ISO/IEC 15948, table 11.1): channels, allowed bit depths.
_PNG_TYPES = {0: (1, (1, 2, 4, 8, 16)), 2: (3, (8, 16)), 3: (1, (1, 2, 4, 8)),
              4: (2, (8, 16)), 6: (4, (8, 16))}


class ImageError(UserError):
    """An image file that cannot be read; ``reason`` says why without the path."""

    def __init__(self, path: str | Path, reason: str):
        self.path, self.reason = str(path), reason
        super().__init__(f"{path}: {reason}")


@dataclass(frozen=True)
class ImageHeader:
    """What an image file's header says, read without decoding its pixels."""
    #: "exr", "png", "pfm", "hdr", "ppm" or "jpeg"
    format: str
    width: int
    height: int
    #: values per pixel as stored (grey 1, RGB 3, RGBA 4; an EXR's channel count)
    channels: int
    #: the file's size on disk
    file_bytes: int
    #: the pixels are stored gzip-compressed (a ``.ppm.gz``)
    gzip: bool = False
    #: values the file stores in all (every part of a multi-part EXR); 0: width x height
    #: x channels
    stored_values: int = 0

    @property
    def values(self) -> int:
        return self.stored_values or self.width * self.height * self.channels

    @property
    def name(self) -> str:
        return FORMAT_NAMES[self.format]


def sniff(head: bytes) -> str | None:
    """The format of a file from its first bytes, or None."""
    for magic, name in MAGIC:
        if head.startswith(magic):
            return name
    return None


def regular_file_size(path: str | Path) -> int:
    """The size of ``path``, which must be a regular file (no folder, FIFO, socket, device)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise ImageError(path, "cannot read: No such file or directory") from None
    except (OSError, ValueError) as e:  # too long, a loop of links, a NUL in the name, ...
        raise ImageError(path, f"cannot read: {getattr(e, 'strerror', None) or e}") from None
    kind = special_kind(st)
    if kind == "a folder":
        raise ImageError(path, "is a folder, expected an image file")
    if kind is not None:
        raise ImageError(path, f"is {kind}, expected a regular file (an image)")
    return st.st_size


def read_head(path: str | Path, n: int) -> bytes:
    """The first ``n`` bytes (or fewer) of a regular file."""
    return _read(path, n - 1)


def _read(path: str | Path, limit: int) -> bytes:
    """At most ``limit + 1`` bytes of the regular file ``path`` (:func:`tracer.files.
    read_regular`: opened without blocking, checked again once open)."""
    regular_file_size(path)
    try:
        return read_regular(path, limit)
    except NotRegularFile as e:
        raise ImageError(path, f"is {e.kind}, expected a regular file (an image)") from None
    except OSError as e:
        raise ImageError(path, f"cannot read: {e.strerror or e}") from None


def read_file(path: str | Path, header: ImageHeader) -> bytes:
    """The bytes of the file ``header`` was read from, no more than it measured: a file
    that has grown since (or is not the same file) is refused rather than read on."""
    data = _read(path, header.file_bytes)
    if len(data) > header.file_bytes:
        raise ImageError(path, f"the file grew beyond {header.file_bytes:,} bytes while it "
                               "was read")
    return data


def gunzip_bounded(path: str | Path, data: bytes, bytes_per_byte: int) -> bytes:
    """The gzip stream ``data`` decompressed; refused (WHITTED_MAX_MEMORY) once its
    decompressed bytes, at ``bytes_per_byte`` of memory each, pass the limit."""
    from whitted.tracer.limits import MAX_MEMORY, check_memory

    limit = MAX_MEMORY.value() // bytes_per_byte
    try:
        out = zlib.decompressobj(16 + zlib.MAX_WBITS).decompress(data, limit + 1)
    except zlib.error as e:
        raise ImageError(path, f"not a gzip file ({e})") from None
    if len(out) > limit:
        try:
            check_memory(len(out) * bytes_per_byte,
                         f"reading more than {limit:,} bytes decompressed from it")
        except UserError as e:
            raise ImageError(path, str(e)) from None
    return out


def ppm_fields(raw: bytes) -> tuple[list[bytes], int]:
    """The four fields of a PPM header (magic, width, height, maxval) and where they end.

    Comments (``#`` to the end of a line) may stand between fields (netpbm's
    ``man 5 ppm``). Fewer than four fields when the bytes end first.
    """
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:
        while pos < len(raw) and raw[pos:pos + 1].isspace():
            pos += 1
        if raw[pos:pos + 1] == b"#":
            nl = raw.find(b"\n", pos)
            pos = nl + 1 if nl >= 0 else len(raw)
            continue
        end = pos
        while end < len(raw) and not raw[end:end + 1].isspace() and raw[end:end + 1] != b"#":
            end += 1
        if end == pos:
            break
        fields.append(raw[pos:end])
        pos = end
    return fields, pos


def _dimensions(path, name: str, w: int, h: int) -> None:
    if w < 1 or h < 1:
        raise ImageError(path, f"unreadable {name} file (its header gives the size {w} x {h})")


def _png(path, head: bytes, size: int) -> ImageHeader:
    if len(head) < 33 or head[12:16] != b"IHDR":
        raise ImageError(path, "unreadable PNG file (no IHDR chunk after the signature)")
    w, h, depth, ctype = struct.unpack(">IIBB", head[16:26])
    if ctype not in _PNG_TYPES or depth not in _PNG_TYPES[ctype][1]:
        raise ImageError(path, f"unreadable PNG file (bit depth {depth} with colour type {ctype})")
    if w > 2**31 - 1 or h > 2**31 - 1:  # the specification's bound
        raise ImageError(path, f"unreadable PNG file (its header gives the size {w} x {h})")
    _dimensions(path, "PNG", w, h)
    return ImageHeader("png", w, h, _PNG_TYPES[ctype][0], size)


def _pfm(path, head: bytes, size: int) -> ImageHeader:
    tokens = head[2:256].split(maxsplit=3)
    try:
        w, h = int(tokens[0]), int(tokens[1])
        float(tokens[2])
    except (IndexError, ValueError):
        raise ImageError(path, "unreadable PFM file (bad header: expected PF, width, height, "
                               "scale)") from None
    _dimensions(path, "PFM", w, h)
    return ImageHeader("pfm", w, h, 3 if head[:2] == b"PF" else 1, size)


_RESOLUTION = re.compile(rb"([-+])([XY])[ \t]+(\d+)[ \t]+([-+])([XY])[ \t]+(\d+)")


def _hdr(path, head: bytes, size: int) -> ImageHeader:
    end = head.find(b"\n\n")
    m = _RESOLUTION.match(head, end + 2) if end >= 0 else None
    if m is None or m.group(2) == m.group(5):
        raise ImageError(path, "unreadable Radiance HDR file (no resolution line such as "
                               f"'-Y 480 +X 640' within its first {TEXT_HEADER_BYTES:,} bytes)")
    a, b = int(m.group(3)), int(m.group(6))
    w, h = (b, a) if m.group(2) == b"Y" else (a, b)  # the first axis is the slower one
    _dimensions(path, "Radiance HDR", w, h)
    return ImageHeader("hdr", w, h, 3, size)


def _ppm(path, head: bytes, size: int, gz: bool) -> ImageHeader:
    fields, _ = ppm_fields(head)
    if len(fields) < 4:
        raise ImageError(path, "unreadable PPM file (header ends early)")
    try:
        w, h = int(fields[1]), int(fields[2])
    except ValueError:
        raise ImageError(path, "unreadable PPM file (bad header)") from None
    _dimensions(path, "PPM", w, h)
    return ImageHeader("ppm", w, h, 3, size, gzip=gz)


def _jpeg(path, size: int) -> ImageHeader:
    """The JPEG frame header (SOFn): walked to segment by segment from SOI."""
    try:
        with open(path, "rb") as f:
            return _jpeg_frame(path, f, size)
    except OSError as e:
        raise ImageError(path, f"cannot read: {e.strerror or e}") from None
    except (struct.error, EOFError):
        raise ImageError(path, "unreadable JPEG file (it ends before its frame header)") \
            from None


def _jpeg_frame(path, f, size: int) -> ImageHeader:
    f.seek(2)  # after SOI
    for _ in range(JPEG_MAX_SEGMENTS):
        if _exact(f, 1) != b"\xff":
            raise ImageError(path, "unreadable JPEG file (a marker expected at byte "
                                   f"{f.tell() - 1:,})")
        marker = _exact(f, 1)[0]
        while marker == 0xFF:  # fill bytes before a marker (T.81 B.1.1.2)
            marker = _exact(f, 1)[0]
        if marker in (0x01, *range(0xD0, 0xD8)):  # TEM, RSTn: no length
            continue
        if marker in (0xD9, 0xDA):  # EOI, SOS: no frame header before the image data
            raise ImageError(path, "unreadable JPEG file (no frame header before its "
                                   "image data)")
        (length,) = struct.unpack(">H", _exact(f, 2))
        if length < 2 or f.tell() + length - 2 > size:
            raise ImageError(path, f"unreadable JPEG file (a segment of {length:,} bytes at "
                                   f"byte {f.tell() - 4:,} of {size:,})")
        if marker in _JPEG_SOF:
            if length < 8:
                raise ImageError(path, "unreadable JPEG file (a frame header of "
                                       f"{length} bytes)")
            _, h, w, n = struct.unpack(">BHHB", _exact(f, 6))
            if h == 0:
                raise ImageError(path, "a JPEG file whose height follows its image data "
                                       "(DNL marker): not read")
            _dimensions(path, "JPEG", w, h)
            return ImageHeader("jpeg", w, h, n, size)
        f.seek(length - 2, os.SEEK_CUR)
    raise ImageError(path, f"unreadable JPEG file (no frame header in its first "
                           f"{JPEG_MAX_SEGMENTS:,} segments)")


def _exr(path, size: int) -> ImageHeader:
    """The OpenEXR header(s): read attribute by attribute, skipping the values not needed."""
    try:
        with open(path, "rb") as f:
            return _exr_parts(path, f, size)
    except OSError as e:
        raise ImageError(path, f"cannot read: {e.strerror or e}") from None
    except (struct.error, EOFError):
        raise ImageError(path, "unreadable OpenEXR file (its header ends early)") from None


def _exr_parts(path, f, size: int) -> ImageHeader:
    bad = "unreadable OpenEXR file"
    f.seek(4)
    (version,) = struct.unpack("<I", _exact(f, 4))
    if version & 0x800:
        raise ImageError(path, "a deep OpenEXR image (deep data is not read: write a flat "
                               "image)")
    multipart = bool(version & 0x1000)
    parts: list[tuple[int, int, int]] = []
    while True:
        attrs = _exr_header(path, f, size)
        if not attrs and parts:
            break  # the empty header after a multi-part file's parts
        if "dataWindow" not in attrs:
            raise ImageError(path, f"{bad} (a header without a dataWindow)")
        x0, y0, x1, y1 = attrs["dataWindow"]
        w, h = x1 - x0 + 1, y1 - y0 + 1
        _dimensions(path, "OpenEXR", w, h)
        parts.append((w, h, max(attrs.get("channels", 0), 1)))
        if not multipart:
            break
    w, h, n = parts[0]
    return ImageHeader("exr", w, h, n, size, stored_values=sum(a * b * c for a, b, c in parts))


def _exact(f, n: int) -> bytes:
    b = f.read(n)
    if len(b) != n:
        raise EOFError
    return b


def _cstring(f, limit: int = 256) -> bytes:
    out = bytearray()
    while True:
        c = _exact(f, 1)
        if c == b"\0":
            return bytes(out)
        out += c
        if len(out) > limit:
            raise EOFError


def _exr_header(path, f, size: int) -> dict:
    """One header's dataWindow (4 ints) and channel count; {} for an empty header."""
    attrs: dict = {}
    while True:
        name = _cstring(f)
        if not name:
            return attrs
        kind = _cstring(f)
        (n,) = struct.unpack("<i", _exact(f, 4))
        if n < 0 or f.tell() + n > size:
            raise ImageError(path, f"unreadable OpenEXR file (attribute {name[:40]!r} of {n:,} "
                                   f"bytes in a file of {size:,})")
        if name == b"dataWindow" and kind == b"box2i" and n == 16:
            attrs["dataWindow"] = struct.unpack("<4i", _exact(f, 16))
        elif name == b"channels" and kind == b"chlist":
            # Each channel: name\0, pixel type, pLinear and 3 reserved bytes, x and y
            # sampling (16 bytes after the name); the list ends with an empty name.
            attrs["channels"] = len(re.findall(rb"[^\0]+\0.{16}", _exact(f, n), re.S))
        else:
            f.seek(n, os.SEEK_CUR)


def read_header(path: str | Path) -> ImageHeader:
    """The header of the regular file ``path`` (one-line :class:`ImageError` otherwise)."""
    size = regular_file_size(path)
    head = read_head(path, TEXT_HEADER_BYTES)
    fmt = sniff(head)
    gz = fmt == "gz"
    if gz:
        inner = zlib.decompressobj(16 + zlib.MAX_WBITS)
        try:
            head = inner.decompress(head, TEXT_HEADER_BYTES)
        except zlib.error as e:
            raise ImageError(path, f"not a gzip file ({e})") from None
        fmt = "ppm" if sniff(head) == "ppm" else None
    if fmt is None:
        raise ImageError(path, "not an image (its first bytes are no OpenEXR, PFM, Radiance "
                               "HDR, PNG, PPM P3/P6 or JPEG header)")
    if fmt == "jpeg":
        return _jpeg(path, size)
    if fmt == "exr":
        return _exr(path, size)
    if fmt == "png":
        return _png(path, head, size)
    if fmt == "pfm":
        return _pfm(path, head, size)
    if fmt == "hdr":
        return _hdr(path, head, size)
    return _ppm(path, head, size, gz)


def check_image_file(path: str | Path, formats: tuple[str, ...] | None = None,
                     work_bytes_per_value: int | None = None) -> ImageHeader:
    """The header of ``path`` once it is known that the image can be read (module docstring).

    ``formats`` (e.g. ``("png", "exr")``) refuses others (by default
    :data:`DEFAULT_FORMATS`: all but JPEG); ``work_bytes_per_value``
    overrides the reader's working memory per value in the estimate
    (:func:`tracer.limits.check_image_memory`).
    """
    from whitted.tracer.limits import check_image_memory

    header = read_header(path)
    formats = DEFAULT_FORMATS if formats is None else formats
    if header.format not in formats:
        names = " or ".join(FORMAT_NAMES[f] for f in formats)
        raise ImageError(path, f"a {header.name} file, expected {names}")
    try:
        check_image_memory(header, work_bytes_per_value)
    except UserError as e:
        raise ImageError(path, str(e)) from None
    return header


@contextlib.contextmanager
def captured_stderr() -> Iterator[list[str]]:
    """File descriptor 2 sent to a temporary file while the block runs; the list yielded
    receives what was written there.

    C libraries (OpenEXR, libpng) print their own messages on the process's
    stderr, where Python cannot catch them; a failure is then reported as one
    line made from them instead.
    """
    out: list[str] = []
    try:
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    with tempfile.TemporaryFile() as tmp:
        saved = os.dup(2)
        os.dup2(tmp.fileno(), 2)
        try:
            yield out
        finally:
            try:
                sys.stderr.flush()
            except (OSError, ValueError):
                pass
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            out.append(tmp.read(1 << 16).decode("utf-8", "replace"))


def library_message(captured: list[str], exc: BaseException | None) -> str:
    """One line from a C library's printed messages and its exception: the first
    message line (less ``<python_buffer>: ``), else the exception's text."""
    from whitted.tracer.errors import one_line

    lines = [ln.strip() for text in captured for ln in text.splitlines() if ln.strip()]
    text = lines[0] if lines else str(exc or "").strip()
    text = re.sub(r"^<python_buffer>:\s*", "", text)
    text = re.sub(r"^\[[^\]]*\]\s*", "", text)  # Mitsuba's "[file.cpp:123] "
    return one_line(text, 160) or (type(exc).__name__ if exc else "")
