"""Files read as data: what a path is, and a regular file read within a bound.

Scenes, includes, meshes, images and suite manifests are read only from regular files:
a FIFO would block, ``/dev/zero`` never ends, a device is no file at all. Each reader
keeps its own error type and wording (a scene's, a mesh's, an image's one-line
errors); this module tells them what a path is and reads it without blocking.
"""

from __future__ import annotations

import os
import stat


def special_kind(st: os.stat_result) -> str | None:
    """None for a regular file; otherwise what the path is, for a one-line refusal:
    "a folder", "a FIFO", "a socket" or "a device"."""
    mode = st.st_mode
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a device"


class NotRegularFile(Exception):
    """The path was no longer a regular file once opened (``kind``: :func:`special_kind`)."""

    def __init__(self, kind: str):
        super().__init__(kind)
        self.kind = kind


def read_regular(path: str | os.PathLike, limit: int) -> bytes:
    """At most ``limit + 1`` bytes of ``path`` (one more than allowed, so that a caller
    sees a file that grew, or reported a wrong size, past its bound).

    Opened without blocking and checked again once open: a FIFO swapped in after the
    caller's own check neither hangs the open nor is read (:class:`NotRegularFile`).
    The system's errors come as :class:`OSError`.
    """
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    with os.fdopen(fd, "rb") as f:
        kind = special_kind(os.fstat(f.fileno()))
        if kind is not None:
            raise NotRegularFile(kind)
        return f.read(limit + 1)
