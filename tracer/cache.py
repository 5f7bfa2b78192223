"""Caches hold data: where they live and how an entry is checked.

whitted keeps four caches on disk, all data, never code: the answers of the
libLLVM probe (:mod:`tracer.llvm`, one JSON file), the scenes' images with a
formula bug (:mod:`reference.check.suspects`, .npy files), large meshes parsed
and their computed vertex normals (:mod:`tracer.meshio`, ``meshes/``) and the
BVHs built over them (:mod:`tracer.bvh`, ``bvh/``), the last two as arrays
entries (:func:`pack_arrays`: a JSON table of names, dtypes and shapes, then
raw numbers; read by :func:`read_arrays`, which checks the table against the
file before reading any data). They live under
``$XDG_CACHE_HOME/whitted`` (``~/.cache/whitted``; the XDG Base Directory
Specification), in folders this module makes 0700, with files written 0600
through a temporary file and a rename (whole or absent, also with processes
writing at once), whatever the umask.

Before a folder or an entry is used it is checked as OpenSSH checks a user's
``authorized_keys`` (``StrictModes``, sshd_config(5)): owned by this user
(:func:`os.geteuid`), writable by no group or other user, and a real folder or
regular file, not a symbolic link (:func:`os.lstat`, ``O_NOFOLLOW``). A folder
that fails is not used: the work is done afresh and one line says why, once
a process. An entry that fails is a miss. Whatever an entry holds, its reader
checks it (type, shape, values) and treats anything else as a miss, to be
computed again and overwritten. Folders above the cache's own (``~/.cache``,
or the parent of a folder named by the user) are not checked.
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import math
import os
import stat
import sys
from pathlib import Path

import numpy as np

#: Folders made for a cache, and files written into one.
FOLDER_MODE = 0o700
FILE_MODE = 0o600

_warned: set[str] = set()


def home() -> Path:
    """whitted's cache folder: ``$XDG_CACHE_HOME/whitted``, else ``~/.cache/whitted``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "whitted"


def _warn(path: Path, why: str) -> None:
    key = str(path)
    if key not in _warned:
        _warned.add(key)
        print(f"whitted: cache {path} not used ({why}); working without it", file=sys.stderr)


def _refusal(st: os.stat_result, kind: str) -> str | None:
    """Why a folder or file with this lstat/fstat may not hold this user's cache, or None."""
    if kind == "folder" and not stat.S_ISDIR(st.st_mode):
        return "not a folder" if not stat.S_ISLNK(st.st_mode) else "a symbolic link"
    if kind == "file" and not stat.S_ISREG(st.st_mode):
        return "not a regular file"
    if st.st_uid != os.geteuid():
        return f"owned by uid {st.st_uid}, not {os.geteuid()}"
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"writable by others (mode {stat.S_IMODE(st.st_mode):04o}; chmod 700 it)"
    return None


def folder(path: Path, top: Path | None = None, create: bool = True) -> Path | None:
    """``path`` if this user's cache may live there, else None (with a line on stderr).

    Every folder from :func:`home` (when ``path`` lies in it) or from ``top``
    (a cache's own folder, named by the user), whichever is higher, down to
    ``path`` is checked (:func:`_refusal`); those missing are made 0700 when
    ``create`` (with any missing above, also 0700). None too when ``create``
    is false and a folder is missing, or when one cannot be made (a read-only
    disk): a cache only saves time.
    """
    path = Path(path)
    levels = [path, *path.parents]
    tops = [t for t in (home(), top) if t is not None and Path(t) in levels]
    levels = levels[:max(levels.index(Path(t)) for t in tops) + 1] if tops else [path]
    for level in reversed(levels):
        try:
            st = os.lstat(level)
        except FileNotFoundError:
            if not create:
                return None
            try:
                _make(level)
                st = os.lstat(level)
            except OSError:
                return None
        except OSError:
            return None
        why = _refusal(st, "folder")
        if why:
            _warn(level, why)
            return None
    return path


def _make(path: Path) -> None:
    """Make ``path`` and any missing folder above it, each 0700 whatever the umask."""
    missing = [p for p in (path, *path.parents) if not os.path.lexists(p)]
    for p in reversed(missing):
        try:
            os.mkdir(p, FOLDER_MODE)
        except FileExistsError:
            continue   # made by another process at the same moment; checked by the caller
        os.chmod(p, FOLDER_MODE)


def open_entry(path: Path) -> io.BufferedReader | None:
    """``path`` opened for reading if it is a regular file of this user's that no one else
    may write (no symbolic link followed), else None. The caller checks what it holds."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | os.O_NONBLOCK
                     | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return None
    try:
        st = os.fstat(fd)
    except OSError:
        os.close(fd)
        return None
    if _refusal(st, "file"):
        os.close(fd)
        return None
    return os.fdopen(fd, "rb")


def read_bytes(path: Path, limit: int = 1 << 20) -> bytes | None:
    """The bytes of an entry :func:`open_entry` accepts, or None (also when over ``limit``)."""
    f = open_entry(path)
    if f is None:
        return None
    with f:
        try:
            data = f.read(limit + 1)
        except OSError:
            return None
    return data if len(data) <= limit else None


def write_bytes(path: Path, data) -> bool:
    """Store ``data`` (bytes, or an iterable of byte chunks written one after another) as
    ``path``, mode 0600, through a temporary file and a rename.

    The folder must have been accepted by :func:`folder`. False when it could
    not be written (a full or read-only disk): a cache only saves time.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_CLOEXEC", 0), FILE_MODE)
    except OSError:
        return False
    try:
        with os.fdopen(fd, "wb") as f:
            os.fchmod(f.fileno(), FILE_MODE)   # a file left by a killed process keeps its mode
            for chunk in ((data,) if isinstance(data, (bytes, bytearray)) else data):
                f.write(chunk)
        os.replace(tmp, path)
        return True
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        return False


# ------------------------------------------------------------------ arrays

#: First line of an arrays entry; the version changes whenever the layout does.
ARRAYS_MAGIC = b"whitted-arrays 1\n"
#: The element types an arrays entry may hold (little-endian numbers, no objects).
ARRAY_DTYPES = frozenset({"<f8", "<f4", "<i8", "<i4", "<u4", "|u1"})
_JSON_LIMIT = 1 << 16


def pack_arrays(arrays: dict[str, np.ndarray]) -> bytes:
    """``arrays`` (name -> numeric array) as the bytes of one entry: the magic line,
    the length of a JSON table (8 bytes, little-endian) naming each array's dtype,
    shape and offset, the table, then each array's raw bytes in C order."""
    return b"".join(_array_chunks(arrays))


def write_arrays(path: Path, arrays: dict[str, np.ndarray]) -> bool:
    """:func:`write_bytes` of :func:`pack_arrays`, each array written from its own memory
    (no copy of the whole entry: a large BVH's arrays are hundreds of MB)."""
    try:
        chunks = _array_chunks(arrays)
    except ValueError:
        return False
    return write_bytes(path, chunks)


def _array_chunks(arrays: dict[str, np.ndarray]) -> list:
    table, parts, offset = {}, [], 0
    for name, a in arrays.items():
        a = np.ascontiguousarray(a)
        dt = a.dtype.newbyteorder("<") if a.dtype.byteorder == ">" else a.dtype
        a = a.astype(dt, copy=False)
        if dt.str not in ARRAY_DTYPES:
            raise ValueError(f"{name}: dtype {dt.str} cannot be kept in an arrays entry")
        table[name] = [dt.str, list(a.shape), offset]
        parts.append(memoryview(a).cast("B") if a.nbytes else b"")
        offset += a.nbytes
    head = json.dumps(table, separators=(",", ":")).encode()
    return [ARRAYS_MAGIC + len(head).to_bytes(8, "little") + head, *parts]


def read_arrays(path: Path, expect: dict[str, str], optional: dict[str, str] | None = None,
                limit: int = 1 << 34) -> dict[str, np.ndarray] | None:
    """The arrays of an entry :func:`pack_arrays` wrote, or None for anything else.

    ``expect`` maps each name the entry must hold to its dtype (``"<f8"`` ...),
    ``optional`` each name it may hold. The entry must pass :func:`open_entry`,
    hold those names with those dtypes, and its table's shapes and offsets must
    tile the data to the last byte (the header is checked before any data is
    read; ``limit`` bounds the file's size). Values are the caller's to check
    (ranges, finiteness, consistency).
    """
    f = open_entry(path)
    if f is None:
        return None
    with f:
        try:
            size = os.fstat(f.fileno()).st_size
            if size > limit or f.read(len(ARRAYS_MAGIC)) != ARRAYS_MAGIC:
                return None
            n = int.from_bytes(f.read(8), "little")
            if not 2 <= n <= _JSON_LIMIT:
                return None
            table = json.loads(f.read(n))
            start = len(ARRAYS_MAGIC) + 8 + n
            kinds = {**(optional or {}), **expect}
            if not isinstance(table, dict) or not set(expect) <= set(table) <= set(kinds):
                return None
            spans = []
            for name, entry in table.items():
                if (not isinstance(entry, list) or len(entry) != 3 or entry[0] != kinds[name]
                        or not isinstance(entry[1], list) or len(entry[1]) > 4
                        or not all(type(k) is int and 0 <= k < 1 << 40 for k in entry[1])
                        or type(entry[2]) is not int):
                    return None
                nbytes = np.dtype(entry[0]).itemsize * math.prod(entry[1])
                spans.append((entry[2], nbytes, name))
            spans.sort()
            at = 0
            for offset, nbytes, _ in spans:
                if offset != at:
                    return None
                at += nbytes
            if start + at != size:
                return None
            data = f.read(at)
        except (OSError, ValueError, UnicodeDecodeError, RecursionError):
            return None
    if len(data) != at:
        return None
    out = {}
    for offset, _, name in spans:
        dtype, shape, _ = table[name]
        out[name] = np.frombuffer(data, dtype=np.dtype(dtype), count=math.prod(shape),
                                  offset=offset).reshape(shape)
    return out


def read_entry(path: Path, expect: dict[str, str], optional: dict[str, str] | None = None
               ) -> dict[str, np.ndarray] | None:
    """:func:`read_arrays` of an entry whose folder :func:`folder` accepts (never made
    here), else None. The caller checks the values, then :func:`touch`es a hit."""
    if folder(Path(path).parent, create=False) is None:
        return None
    return read_arrays(path, expect, optional)


def keep_entry(path: Path, arrays: dict[str, np.ndarray], max_bytes: int) -> None:
    """Store ``arrays`` at ``path`` (:func:`write_arrays`, its folder made and checked by
    :func:`folder`), then :func:`prune` the folder to ``max_bytes``; a cache only saves
    time, so a failure is silent."""
    path = Path(path)
    if folder(path.parent) is not None and write_arrays(path, arrays):
        prune(path.parent, max_bytes, keep=path)


@functools.cache
def source_digest(file: str) -> str:
    """:func:`content_key` of a module's source file, read once a process: part of the key
    of what that module computes, so that another version's entries are never used."""
    return content_key(Path(file).read_bytes())


def content_key(*parts) -> str:
    """A hex SHA-256 over ``parts`` (bytes, or arrays by their raw bytes, or text), each
    prefixed by its length so that no two sequences of parts give the same stream. SHA-256
    because CPUs with SHA extensions (x86 SHA-NI, ARMv8) hash it faster than hashlib's
    other strong hashes."""
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, np.ndarray):
            p = np.ascontiguousarray(p)
            h.update(f"{p.dtype.str}{p.shape}".encode())
            p = memoryview(p).cast("B")
        elif isinstance(p, str):
            p = p.encode()
        h.update(len(p).to_bytes(8, "little"))
        h.update(p)
    return h.hexdigest()


def prune(folder: Path, max_bytes: int, keep: Path | None = None) -> None:
    """Delete the least recently used entries of ``folder`` (by modification time, which a
    hit renews) until the rest take at most ``max_bytes``; ``keep`` is never deleted."""
    try:
        entries = []
        with os.scandir(folder) as it:
            for e in it:
                if e.is_file(follow_symlinks=False) and not e.name.startswith("."):
                    st = e.stat(follow_symlinks=False)
                    entries.append((st.st_mtime_ns, st.st_size, e.path))
    except OSError:
        return
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries):
        if total <= max_bytes:
            break
        if keep is not None and Path(p) == Path(keep):
            continue
        try:
            os.unlink(p)
            total -= size
        except OSError:
            pass


def touch(path: Path) -> None:
    """Mark an entry as just used (for :func:`prune`); a failure only costs its place."""
    try:
        os.utime(path, follow_symlinks=False)
    except (OSError, NotImplementedError):
        pass
