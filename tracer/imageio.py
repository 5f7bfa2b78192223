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

from tracer.errors import UserError

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


def write_exr(path: str | Path, image: np.ndarray) -> None:
    """Linear float32 RGB OpenEXR."""
    import OpenEXR

    data = np.ascontiguousarray(image, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def write(tmp):
        # Through memory: OpenEXR takes only file names it can encode as UTF-8.
        buf = io.BytesIO()
        with OpenEXR.File(header, {"RGB": data}) as f:
            f.write(buf)
        Path(tmp).write_bytes(buf.getvalue())

    _atomic_write(Path(path), write)


def read_exr(path: str | Path) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(io.BytesIO(Path(path).read_bytes())) as f:
        ch = f.channels()
        if "RGB" in ch:
            return np.asarray(ch["RGB"].pixels, dtype=np.float32)
        return np.stack([np.asarray(ch[c].pixels, dtype=np.float32) for c in "RGB"], axis=-1)


def write_png(path: str | Path, image: np.ndarray) -> None:
    """8-bit sRGB PNG (linear values clipped to [0, 1], then the sRGB curve)."""
    from PIL import Image

    rgb = to_srgb8(image) if image.dtype != np.uint8 else image
    _atomic_write(Path(path), lambda tmp: _write_png_file(tmp, Image.fromarray(rgb, "RGB")))


def _write_png_file(tmp: str, image) -> None:
    image.save(tmp, format="PNG")


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
