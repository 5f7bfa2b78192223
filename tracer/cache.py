"""Caches hold data: where they live and how an entry is checked.

whitted keeps two caches on disk, both data, never code: the answers of the
libLLVM probe (:mod:`tracer.llvm`, one JSON file) and the scenes' images with
a formula bug (:mod:`reference.check.suspects`, .npy files). They live under
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

import io
import os
import stat
import sys
from pathlib import Path

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


def write_bytes(path: Path, data: bytes) -> bool:
    """Store ``data`` as ``path``, mode 0600, through a temporary file and a rename.

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
            f.write(data)
        os.replace(tmp, path)
        return True
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        return False
