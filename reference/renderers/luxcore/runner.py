"""LuxCore's side of a comparison, run in a child process:
``python -m whitted.reference.renderers.luxcore.runner``.

LuxCore's allocator and thread pool never share a process with Dr.Jit:
:mod:`reference.renderers.luxcore.render` writes each job (the scene description of
:mod:`reference.renderers.luxcore.scene` and the passes' seeds) to an ``.npz`` file, its
meshes to binary PLY files beside it that LuxCore reads itself, and starts
this module on the list of jobs; each job's passes
come back in ``<job>.out.npz``, summed over each image pixel's k x k film pixels
(:func:`pass_moments`): ``sums`` (P x H x W x 3, each pass's sums) and ``squares``
(H x W x 3, the sums of squares over every pass), in float64.

Rules measured on pyluxcore 2.11.2:

* ``numpy`` is imported before ``pyluxcore`` (the other order aborts with
  "free(): invalid pointer");
* ``pyluxcore.Init()`` without a Python log callback (one aborts at exit);
* ``RenderSession.WaitForDone()`` alone never returns: the halt test
  (``batch.haltspp``) runs inside ``UpdateStats()``, so the session is polled.

A pass is limited by the CPU time this process spends on it (the job's
``pass_cpu``, reference.renderers.luxcore.render.pass_cpu_limit), not by the wall clock: at
``nice`` 19 beside a busy machine a pass may wait minutes for a core, which is
not LuxCore being slow. A pass past its limit ends the child with one line.
"""

from __future__ import annotations

import sys
import time

import numpy as np  # before pyluxcore, always


def pass_moments(film: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """A film of kH x kW pixels as the sums and the sums of squares (H x W x 3, float64)
    of each image pixel's k x k film pixels, read in place (rows as H x k x W x k)."""
    h, w = film.shape[0] // k, film.shape[1] // k
    f = np.asarray(film, dtype=np.float64).reshape(h, k, w, k, 3)
    return f.sum(axis=(1, 3)), np.einsum("hiwjc,hiwjc->hwc", f, f)


def run_job(pyluxcore, path: str) -> None:
    job = np.load(path, allow_pickle=False)
    scene = pyluxcore.Scene()   # its meshes: PLY files that LuxCore reads (scene.shapes.*)
    props = pyluxcore.Properties()
    props.SetFromString(str(job["props"]))
    scene.Parse(props)
    width, height = (int(x) for x in job["film"])
    seeds = [int(s) for s in job["seeds"]]
    k = int(job["subsamples"])
    sums = np.zeros((len(seeds), height // k, width // k, 3))
    squares = np.zeros((height // k, width // k, 3))
    cpu_limit = float(job["pass_cpu"])
    for i, seed in enumerate(seeds):
        cfg = pyluxcore.Properties()
        cfg.SetFromString(str(job["config"]).replace("@SEED@", str(seed)))
        session = pyluxcore.RenderSession(pyluxcore.RenderConfig(cfg, scene))
        start = time.process_time()   # every thread of this process, LuxCore's included
        session.Start()
        while True:
            session.UpdateStats()
            if session.HasDone():
                break
            if time.process_time() - start > cpu_limit:
                session.Stop()
                raise SystemExit(f"a pass of a {width} x {height} film took more than "
                                 f"{cpu_limit:g} s of CPU time")
            time.sleep(0.005)
        session.Stop()
        img = np.zeros((height, width, 3), dtype=np.float32)
        session.GetFilm().GetOutputFloat(pyluxcore.FilmOutputType.RGB, img)
        # LuxCore's film rows run bottom to top. Summed here, in the child, which renders
        # beside the report's other work, rather than read back whole by the report after
        # it (1.5 s of the report's end for 9 films of 1024 x 768 x 4 passes).
        sums[i], sq = pass_moments(img[::-1], k)
        squares += sq
        spp = session.GetStats().Get("stats.renderengine.pass").GetInt()
        print(f"@pass {i + 1}/{len(seeds)} spp {spp}", file=sys.stderr, flush=True)
        del session
    np.savez(path[:-4] + ".out.npz", sums=sums, squares=squares)


def main(argv: list[str]) -> int:
    """``[--nice N] JOB...``: render each job; ``--nice`` lowers this process's priority
    by N first (``whitted report`` starts LuxCore at 19, see reference.report.build)."""
    import os

    from whitted.reference.malloc import keep_freed_memory

    if argv[:1] == ["--nice"]:
        os.nice(int(argv[1]))
        argv = argv[2:]
    keep_freed_memory()
    import pyluxcore

    pyluxcore.Init()
    for path in argv:
        run_job(pyluxcore, path)
        print(f"@done {path}", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
