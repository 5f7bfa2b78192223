"""LuxCoreRender as a third renderer: render a scene in a child process, with its noise.

LuxCore (``pyluxcore`` 2.11.2, the optional extra ``whitted[luxcore]``) is
the successor of LuxRender, the renderer of the course's later assignments.
It is independent of both the tracer and Mitsuba, so where those two
disagree a third image makes it a vote (:mod:`reference.renderers.luxcore.vote`).

How it renders (:mod:`reference.renderers.luxcore.scene` for the scene):

* ``PATHCPU`` with the ``RANDOM`` sampler, one sample per film pixel per
  pass, ``passes`` passes with different seeds. ``TILEPATHCPU`` would give
  exactly N^2 samples and the same image on every run, but it ignores
  ``renderengine.seed`` (measured: two seeds, the same image to the bit), so
  its repeats carry no noise estimate. PATHCPU is fast per sample on a large
  film at one sample per pass and slow at many samples per pixel of a small
  one (measured at 64 x 48: 0.2 s per sample per pixel, against 0.5 s for a
  448 x 336 film at one sample), so a pixel's samples are spread over a film
  ``SUBSAMPLES`` times larger on each side.
* Pixel = the mean of its SUBSAMPLES^2 sub-pixels (filter ``NONE``): a
  stratified estimate of the mean of radiance over the pixel's square, which
  the tracer's and Mitsuba's strata centres approximate by the midpoint rule
  (:mod:`reference.renderers.luxcore.vote` renders them with many strata).
* Noise, as Mitsuba's pooled reference (reference/verdicts/compare.py, rules 1 and
  4): the per-sample second moment over all N = passes x SUBSAMPLES^2
  samples, (E[x^2] - E[x]^2) / N, an upper bound for the variance of a
  stratified mean (it includes the variation across the pixel, edges
  included); and the spread of the passes' means / passes, unbiased, for the
  region sums.

LuxCore runs in ``python -m reference.renderers.luxcore.runner`` under time limits that
follow its work (:func:`pass_cpu_limit`, :func:`wait_limit`), one child for a
list of scenes (:func:`render_many`), so its allocator and threads never share
a process with Dr.Jit.

Time limits. The child of ``whitted report`` renders at the lowest priority
(``nice`` 19) beside the report's own work, so on a busy machine it may get
almost no CPU for minutes: its wall-clock time says nothing about whether it
is stuck. So a pass is limited by the CPU time the child spends on it
(:func:`pass_cpu_limit`: 60 s, or 20 microseconds per film sample where that
is more; a pass takes about 1-2 microseconds a sample here), and the caller
waits, once it has nothing else to do, at most WHITTED_LUXCORE_TIMEOUT seconds,
by default 60 s plus 60 s per pass still to render (:func:`wait_limit`). A
report that meets either limit goes on without LuxCore's vote
(reference.report.build).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from whitted.reference.child import Child
from whitted.reference.renderers.luxcore.scene import (
    Description,
    config_props,
    describe,
    props_text,
)
from whitted.tracer.errors import UserError
from whitted.tracer.meshio import write_ply

#: the pinned version (pyproject's extra)
VERSION = "2.11.2"
INSTALL_HINT = ("LuxCore is not installed: pip install 'whitted[luxcore]' "
                f"(pyluxcore {VERSION}), or `make setup`")
#: Independent passes per render (their spread has PASSES - 1 degrees of freedom per pixel).
PASSES = 4
#: Film sub-pixels per image pixel side: PASSES x SUBSAMPLES^2 = 1024 samples per pixel, as
#: Mitsuba's pooled sampling reference (reference.verdicts.compare.ZTEST_SAMPLES).
SUBSAMPLES = 16
#: Samples per film pixel per pass.
SPP_PER_PASS = 1
#: Seconds of wall-clock time the caller waits per pass still to render, once it waits
#: (:func:`wait_limit`), on top of a start-up allowance.
PASS_TIMEOUT = 60.0
STARTUP_TIMEOUT = 60.0
#: The wait's limit in seconds, where set (:func:`wait_limit`).
TIMEOUT_VARIABLE = "WHITTED_LUXCORE_TIMEOUT"
#: CPU seconds of the child a pass may take (:func:`pass_cpu_limit`): at least this ...
PASS_CPU_FLOOR = 60.0
#: ... or this per film sample of the pass, where that is more (measured: 0.6-1.5 s of CPU
#: time for a pass of 1024 x 768 film pixels, 0.8-2 microseconds a sample).
PASS_CPU_PER_SAMPLE = 20e-6


def pass_cpu_limit(film_size: tuple[int, int], spp_per_pass: int = SPP_PER_PASS) -> float:
    """CPU seconds (the child's, all its threads) that one pass of a film may take.

    CPU time, not wall-clock time: the work done, whatever else the machine runs (the
    report's child runs at the lowest priority). 10 to 25 times a pass's measured cost,
    and never below PASS_CPU_FLOOR.
    """
    samples = film_size[0] * film_size[1] * spp_per_pass
    return max(PASS_CPU_FLOOR, PASS_CPU_PER_SAMPLE * samples)


def wait_limit(passes_left: int) -> float:
    """Seconds the caller waits for the child once it waits, with ``passes_left`` passes
    still to render: WHITTED_LUXCORE_TIMEOUT if set (a positive number of seconds), else
    STARTUP_TIMEOUT plus PASS_TIMEOUT per pass left. A bad value is a one-line UserError."""
    text = os.environ.get(TIMEOUT_VARIABLE, "").strip()
    if not text:
        return STARTUP_TIMEOUT + PASS_TIMEOUT * passes_left
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not v > 0 or math.isinf(v):
        raise UserError(f"{TIMEOUT_VARIABLE}={text[:40]!r}: expected a positive number of "
                        "seconds")
    return v


def available() -> bool:
    """Whether pyluxcore is importable (checked without importing it here)."""
    import importlib.util

    return importlib.util.find_spec("pyluxcore") is not None


def require() -> None:
    """A one-line UserError naming how to install LuxCore when it is missing."""
    if not available():
        raise UserError(INSTALL_HINT)


@dataclass
class LuxResult:
    """LuxCore's image of a scene and the noise of that image."""
    image: np.ndarray          # H x W x 3 float32: mean of the passes
    variance: np.ndarray       # H x W x 3: of that mean, from the per-sample second moment
    pass_variance: np.ndarray | None  # H x W: channel sum, from the passes' spread
    passes: int
    samples: int               # samples per pixel over all passes
    seconds: float


def _write_job(path: Path, desc: Description, seeds: list[int], spp_per_pass: int,
               pass_cpu: float) -> None:
    """The job file of one scene, and its meshes as binary PLY files beside it.

    LuxCore reads each mesh itself (``scene.shapes.NAME.ply``): a tessellated sphere of
    98,491 triangles took the child 0.55-0.63 s as Python lists through
    ``Scene.DefineMesh`` (mirror_sphere's four meshes), against 0.08 s written here and
    0.08 s read by LuxCore (a throwaway script; the same image).
    """
    shapes = {}
    for i, (name, (v, f, n)) in enumerate(desc.meshes.items()):
        ply = path.with_name(f"{path.stem}_mesh{i}.ply")
        write_ply(ply, v, f, n)
        shapes[f"scene.shapes.{name}.type"] = "mesh"
        shapes[f"scene.shapes.{name}.ply"] = str(ply)
    arrays = {"props": np.array(props_text(shapes) + desc.text()),
              "config": np.array(props_text(config_props(desc, 0, spp_per_pass)).replace(
                  'renderengine.seed = 1\n', "renderengine.seed = @SEED@\n")),
              "film": np.array(desc.film_size), "seeds": np.array(seeds, dtype=np.int64),
              "subsamples": np.array(desc.subsamples),
              "pass_cpu": np.array(pass_cpu)}
    np.savez(path, **arrays)


def render_many(scenes: list, passes: int = PASSES, seed: int = 0,
                spp_per_pass: int = SPP_PER_PASS, progress=None,
                timeout: float | None = None, subsamples: int = SUBSAMPLES) -> list[LuxResult]:
    """Render every scene with LuxCore in one child process; results in the same order.

    ``progress(done, total)`` is called per pass. One-line UserError when
    pyluxcore is missing, a scene does not convert, or the child fails or
    runs past a time limit: a pass's CPU time (:func:`pass_cpu_limit`), or the
    wait (``timeout`` seconds, default :func:`wait_limit`).
    """
    return start_many(scenes, passes, seed, spp_per_pass, timeout,
                      subsamples).results(progress)


def start_many(scenes: list, passes: int = PASSES, seed: int = 0,
               spp_per_pass: int = SPP_PER_PASS, timeout: float | None = None,
               subsamples: int = SUBSAMPLES, nice: int = 0) -> LuxJob:
    """:func:`render_many` started: the child renders while the caller goes on, and
    :meth:`LuxJob.results` waits for it (``whitted report`` runs its comparisons and its
    formula-bug sweep meanwhile). A scene that does not convert is refused here, before
    the child starts. ``nice``: the child's priority lowered by that much (0-19)."""
    require()
    descs = [describe(s, subsamples=subsamples) for s in scenes]  # refuse before starting
    seeds = [seed * 1000 + k for k in range(passes)]
    total = passes * len(scenes)
    if timeout is None:
        wait_limit(total)   # a bad WHITTED_LUXCORE_TIMEOUT refused before the child starts
    tmp = Path(tempfile.mkdtemp(prefix="whitted-luxcore-"))
    try:
        jobs = []
        for i, d in enumerate(descs):
            job = tmp / f"job{i}.npz"
            _write_job(job, d, seeds, spp_per_pass, pass_cpu_limit(d.film_size, spp_per_pass))
            jobs.append(job)
        # the child's messages go to a file, not a pipe, which nobody reads while the
        # caller works and which would stop the child when full. The child appends through
        # a handle of its own and the caller reads through another: one shared handle
        # shares its offset, and the caller's seek put the child's last lines (why it
        # failed) over the first ones.
        with open(tmp / "child.log", "a") as child_log:
            proc = subprocess.Popen([sys.executable, "-m",
                                     "whitted.reference.renderers.luxcore.runner",
                                     *(["--nice", str(nice)] if nice else []),
                                     *map(str, jobs)], stdout=subprocess.DEVNULL,
                                    stderr=child_log, text=True, env=dict(os.environ))
        log = open(tmp / "child.log")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return LuxJob(proc, tmp, log, descs, jobs, total, timeout, spp_per_pass)


@dataclass
class LuxJob(Child):
    """A LuxCore child at work on a list of scenes (:func:`start_many`)."""
    descs: list
    jobs: list
    total: int
    #: seconds the caller waits once it waits (:meth:`results`); None: :func:`wait_limit`
    timeout: float | None
    spp_per_pass: int
    start: float = field(default_factory=time.perf_counter)

    def results(self, progress=None) -> list[LuxResult]:
        """Wait for the child; its images in the scenes' order (see :func:`render_many`).

        ``seconds`` of a result is the child's time since its start over the scenes,
        whatever else the machine did meanwhile. The wait is limited from this call on
        (before it the caller's own work legitimately takes the cores), to ``timeout``
        or :func:`wait_limit` of the passes not yet done."""
        try:
            done, tail = 0, []
            waited, limit = time.perf_counter(), None
            while True:
                exited = self.proc.poll() is not None
                for line in self.new_lines():
                    if line.startswith("@pass"):
                        done += 1
                        if progress is not None:
                            progress(done, self.total)
                    elif line.strip():
                        tail = (tail + [line.strip()])[-5:]
                if exited:
                    break
                if limit is None:   # the passes already done are known after the first read
                    limit = (self.timeout if self.timeout is not None
                             else wait_limit(self.total - done))
                if time.perf_counter() - waited > limit:
                    how = ("" if self.timeout is not None
                           or os.environ.get(TIMEOUT_VARIABLE, "").strip() else
                           f": {STARTUP_TIMEOUT:.0f} s + {PASS_TIMEOUT:.0f} s a pass left")
                    raise UserError(
                        f"LuxCore ran past its time limit of {limit:g} s of waiting{how} "
                        f"({done} of {self.total} passes done; set {TIMEOUT_VARIABLE} "
                        "to wait longer)")
                time.sleep(0.02)
            seconds = time.perf_counter() - self.start
            if self.proc.returncode != 0:
                why = next((t for t in reversed(tail) if not t.startswith("[")), None) or (
                    tail[-1] if tail else f"exit status {self.proc.returncode}")
                raise UserError(f"LuxCore failed: {why}")
            results = []
            for d, job in zip(self.descs, self.jobs, strict=True):
                with np.load(str(job)[:-4] + ".out.npz") as out:
                    sums, squares = out["sums"], out["squares"]
                results.append(_result(d, sums, squares, self.spp_per_pass,
                                       seconds / len(self.descs)))
            return results
        finally:
            self.close()


class SharedCores:
    """Dr.Jit on one thread while a LuxCore child renders beside this process.

    After each kernel, Dr.Jit's second thread (nanothread's worker) asks for work up to
    500,000 times before it sleeps: about 25 ms of a core here (a throwaway script:
    0.02-0.03 s of CPU time in a 0.5 s sleep after a render), taken from LuxCore's
    threads while this process traces its next kernel or judges an image. On one thread
    no core spins, and a kernel's work costs less CPU time (0.90 s against 0.95 s for
    five renders of whitted_mix, the same script). :meth:`poll`, called between pieces
    of work, gives Dr.Jit its threads back as soon as the child has exited; leaving the
    ``with`` block gives them back in any case.
    """

    def __init__(self, job: LuxJob | None):
        self.job = job
        self.threads = None      # Dr.Jit's thread count to give back, while it is taken

    def __enter__(self) -> SharedCores:
        import drjit as dr

        n = dr.thread_count()
        if self.job is not None and self.job.running() and n > 1:
            self.threads = n
            dr.set_thread_count(1)
        return self

    def poll(self) -> None:
        if self.threads is not None and not self.job.running():
            self._give_back()

    def _give_back(self) -> None:
        import drjit as dr

        dr.set_thread_count(self.threads)
        self.threads = None

    def __exit__(self, *exc) -> None:
        if self.threads is not None:
            self._give_back()


def _result(desc: Description, sums: np.ndarray, squares: np.ndarray, spp_per_pass: int,
            seconds: float) -> LuxResult:
    """The image, its variance and the passes' spread, from the child's sums over each
    pixel's k x k film pixels (reference.renderers.luxcore.runner.pass_moments): ``sums``
    P x H x W x 3
    per pass, ``squares`` H x W x 3 over all passes."""
    k = desc.subsamples
    p = len(sums)
    n = p * k * k * spp_per_pass
    mean = sums.sum(0) / (p * k * k)
    m2 = squares / (p * k * k)
    var = np.maximum(m2 - mean ** 2, 0) / n
    means = sums.sum(-1) / (k * k)                           # P x H x W: each pass's channel sum
    pass_var = means.var(0, ddof=1) / p if p > 1 else None
    return LuxResult(mean.astype(np.float32), var.astype(np.float32), pass_var, p, n, seconds)


def render(scene, passes: int = PASSES, seed: int = 0, spp_per_pass: int = SPP_PER_PASS,
           progress=None, subsamples: int = SUBSAMPLES) -> LuxResult:
    """LuxCore's image of one scene (:func:`render_many`)."""
    return render_many([scene], passes, seed, spp_per_pass, progress,
                       subsamples=subsamples)[0]
