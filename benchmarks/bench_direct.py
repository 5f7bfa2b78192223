"""Time the tracer against Mitsuba's `direct` integrator on the same scene, in one run.

Both render the same scene at the same size and samples per pixel, on the same
backend. Each side renders once to compile its kernels (not timed), then
``--repeat`` times; the median is reported with the ratio. Mitsuba's own
`whitted` reference integrator (every light once per sample) is timed too.

    python benchmarks/bench_direct.py [SCENE] [--size 640x480] [--spp 64] [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)


def _time(fn, repeat: int) -> list[float]:
    fn()  # warm-up: compiles kernels (Dr.Jit caches them on disk as well)
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def main(argv=None) -> int:
    from whitted.reference.cli import _size, resolve_scene

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default="three_lights")
    p.add_argument("--size", type=_size, default=(640, 480))
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--backend", default=None)
    args = p.parse_args(argv)

    from whitted.tracer import backend, load_scene
    from whitted.tracer.integrator import Integrator

    name = backend.use(args.backend)
    scene = load_scene(resolve_scene(args.scene)).with_overrides(spp=args.spp, size=args.size)
    if scene.has_specular():
        print("note: `direct` ignores mirrors and glass; timing the tracer at max_depth 2")
        scene = scene.with_overrides(max_depth=2)

    import drjit as dr

    from whitted.reference import mitsuba
    from whitted.reference.renderers.mitsuba.scene import load

    mi = mitsuba()
    integ = Integrator(scene)
    ms_direct = load(scene, mi, "direct")
    ms_whitted = load(scene, mi, "whitted")
    spp = scene.film.strata ** 2

    def run_tracer():
        integ.render()

    def run_mitsuba(ms):
        def f():
            img = mi.render(ms, spp=spp)
            dr.eval(img)
            dr.sync_thread()
        return f

    t_tracer = _time(run_tracer, args.repeat)
    t_direct = _time(run_mitsuba(ms_direct), args.repeat)
    t_whitted = _time(run_mitsuba(ms_whitted), args.repeat)
    med = statistics.median
    w, h = scene.film.width, scene.film.height
    print(f"scene {scene.name}: {w}x{h}, {spp} spp, {len(scene.lights)} lights, "
          f"backend {name}, median of {args.repeat} after one warm-up")
    print(f"  tracer                     {med(t_tracer):8.3f} s   "
          f"({w * h * spp / med(t_tracer) / 1e6:6.1f} M camera samples/s)")
    print(f"  Mitsuba direct             {med(t_direct):8.3f} s")
    print(f"  Mitsuba whitted (ours)     {med(t_whitted):8.3f} s")
    print(f"  ratio Mitsuba direct / tracer = {med(t_direct) / med(t_tracer):.2f} "
          "(> 1: the tracer is faster)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
