"""The quick report's formula-bug sweep, in a worker process beside the comparisons:
``python -m whitted.reference.report.sweep_worker``.

Why a second process. On a fresh machine (CI's case) most of a quick report is
Dr.Jit compiling kernels, one scene after another, and Dr.Jit compiles on the thread
that launches (one kernel at a time a process). In one process the second core waited
while the first compiled. In a quick report the sweep shares nothing with the
comparisons: it renders at its own size (64 pixels wide, against the comparisons' 96,
reference.mutants.sweep_size), so no reference or render of theirs serves it. So it
runs here, beside them, and each process compiles on its own core.

The worker sweeps the scenes from the last to the first while the comparisons go
from the first (``mutants.sweep(..., last_first=True)``). A kernel both need (a scene's
clean render, its deterministic reference) is then compiled by whichever gets there
first, and the other reads it from Dr.Jit's kernel cache on disk, which both processes
share (Dr.Jit writes each file under a temporary name and renames it).

It runs Dr.Jit on one thread while the report's process works beside it, and on all of
them once that process waits for it (the file ``--alone`` appears). It prints each
scene's line as the sweep finishes it, and writes the sweep's result
(:meth:`reference.mutants.SweepResult.to_json`) as JSON to ``--out``: data only, read
back by the report and checked.

The full report sweeps in its own process: at the scenes' own sizes the sweep reuses
the comparisons' references and renders (reference.shared).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from whitted.reference.child import Child
from whitted.tracer.errors import UserError, one_line


def start(scene_paths: list[Path], quick: bool = True) -> SweepWorker:
    """Start the worker on ``scene_paths`` (each a scene file, already validated by the
    caller) with the tracer's current Dr.Jit backend; :meth:`SweepWorker.result` waits
    for it."""
    from whitted.tracer import backend

    tmp = Path(tempfile.mkdtemp(prefix="whitted-sweep-worker-"))
    try:
        argv = [sys.executable, "-m", "whitted.reference.report.sweep_worker",
                "--backend", backend.name(), "--out", str(tmp / "sweep.json"),
                "--alone", str(tmp / "alone"), *(["--quick"] if quick else []), "--",
                *(str(Path(p).resolve()) for p in scene_paths)]
        # its lines go to a file, not a pipe that nobody reads while the report works
        with open(tmp / "worker.log", "a") as out:
            proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=out,
                                    stderr=subprocess.STDOUT, text=True,
                                    env=dict(os.environ))
        log = open(tmp / "worker.log")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return SweepWorker(proc, tmp, log)


@dataclass
class SweepWorker(Child):
    """A sweep at work in a worker process (:func:`start`)."""
    start: float = field(default_factory=time.perf_counter)

    def result(self, progress=print) -> dict:
        """Tell the worker it has the machine, wait for it, and return its sweep as JSON
        (``SweepResult.to_json``). ``progress(line)`` gets each scene's line, those
        already done first. A worker that fails raises UserError with its last line."""
        try:
            (self.tmp / "alone").touch()
            tail = []
            while True:
                exited = self.proc.poll() is not None
                for line in self.new_lines():
                    if line.startswith("@ "):
                        progress(line[2:])
                    elif line.strip():
                        tail = (tail + [line.strip()])[-5:]
                if exited:
                    break
                time.sleep(0.05)
            if self.proc.returncode != 0:
                why = tail[-1] if tail else f"exit status {self.proc.returncode}"
                raise UserError(f"the formula-bug sweep's worker failed: {one_line(why, 300)}")
            return read_result(self.tmp / "sweep.json")
        finally:
            self.close()


#: The keys of a sweep's JSON that the report reads, with their types.
RESULT_KEYS = {"pass": bool, "clean_passed": bool, "all_caught": bool, "quick": bool,
               "seconds": float, "scenes": list, "mutants": list}


def read_result(path: Path) -> dict:
    """The worker's sweep (JSON written by :func:`main`), its shape checked."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise UserError(f"the formula-bug sweep's worker wrote no readable result: "
                        f"{one_line(str(e), 200)}") from None
    bad = [k for k, t in RESULT_KEYS.items()
           if not isinstance(data.get(k) if isinstance(data, dict) else None,
                             (int, float) if t is float else t)]
    if bad or not all(isinstance(m, dict) and isinstance(m.get("caught"), bool)
                      for m in data["mutants"]):
        raise UserError("the formula-bug sweep's worker wrote a result of the wrong shape "
                        f"({', '.join(bad) or 'mutants'})")
    return data


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m whitted.reference.report.sweep_worker")
    parser.add_argument("--backend", required=True)
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--alone", required=True, type=Path)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("scenes", nargs="+", type=Path)
    args = parser.parse_args(argv)

    from whitted.reference.malloc import keep_freed_memory

    keep_freed_memory()
    try:
        from whitted.tracer import backend

        backend.use(args.backend)
        import drjit as dr

        from whitted.reference import mutants
        from whitted.reference.shared import shared

        threads = dr.thread_count()
        dr.set_thread_count(1)   # the report's process works on the other core

        def between() -> None:
            nonlocal threads
            if threads and args.alone.exists():
                dr.set_thread_count(threads)
                threads = 0

        with shared():
            result = mutants.sweep(args.scenes, quick=args.quick,
                                   log=lambda line: print("@ " + line, flush=True),
                                   between=between,
                                   xml_sources=mutants.structure_sources(), last_first=True)
        part = args.out.with_suffix(".part")
        part.write_text(json.dumps(result.to_json()))
        part.replace(args.out)
    except Exception as e:   # one line for the report, which raises it as a UserError
        print(one_line(f"{type(e).__name__}: {e}", 300), flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
