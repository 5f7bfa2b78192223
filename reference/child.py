"""A child process at work beside the caller, with a folder of its own and a log file
that the caller reads (LuxCore's renders, reference.renderers.luxcore.render; a quick
report's formula-bug sweep, reference.report.sweep_worker)."""

from __future__ import annotations

import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path


@dataclass
class Child:
    proc: subprocess.Popen
    #: the child's folder (its jobs, its log, its results), removed by :meth:`close`
    tmp: Path
    #: the caller's handle on the child's log
    log: object

    def __post_init__(self) -> None:
        self._part = ""   # the log's last line, while the child has not ended it

    def running(self) -> bool:
        return self.proc.poll() is None

    def new_lines(self) -> list[str]:
        """The lines the child has written to its log since the last call (whole lines
        only: a line still being written waits for the next call)."""
        self._part += self.log.read()
        *lines, self._part = self._part.split("\n")
        return lines

    def close(self) -> None:
        """Stop the child if it still runs, and remove its files."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.log.close()
        shutil.rmtree(self.tmp, ignore_errors=True)
