"""Exit statuses, and standard output whose errors are told apart from those of files.

0 success (for a comparison: within its tolerance), 1 a comparison or check that
fails, 2 bad input or a file (standard output included) that cannot be written,
130 interrupted (Ctrl-C), as shells report SIGINT.
"""

from __future__ import annotations

import io
import os
import sys

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2
EXIT_INTERRUPT = 130


class StdoutError(Exception):
    """Standard output cannot be written (a full device, a closed terminal)."""


class Stdout:
    """sys.stdout, with its OS errors told apart from those of output files."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text):
        try:
            return self.stream.write(text)
        except BrokenPipeError:
            raise
        except OSError as e:
            raise StdoutError(e.strerror or str(e)) from None

    def flush(self):
        try:
            self.stream.flush()
        except BrokenPipeError:
            raise
        except OSError as e:
            raise StdoutError(e.strerror or str(e)) from None

    def __getattr__(self, name):
        return getattr(self.stream, name)


def silence_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's last flush cannot fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        pass


def caused_by(e: BaseException, kind: type) -> bool:
    """Whether ``e``, or an exception it was raised from or while handling, is a ``kind``."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, kind):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False
