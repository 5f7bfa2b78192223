"""Time the tracer alone on built-in scenes: the first render of a process and warm ones.

For each scene (at ``--size`` and ``--spp``): its first render (its kernels
read from Dr.Jit's cache or compiled; for the first scene, the process's
buffers touched for the first time too) and the median of ``--repeat`` later
renders, with the rays traced. It
compares the tracer with itself, before and after a change to it (run it in
both checkouts), where `bench_speed.py` compares it with Mitsuba and minray.

    python benchmarks/bench_scenes.py [SCENE ...] [--size 320x240] [--spp 64] [--repeat 3]
                                      [--schedule auto|wavefront|stack]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)

SCENES = ("three_lights", "glass_sphere", "whitted_1980", "tir_prisms", "emitter_in_glass",
          "phong_lobes", "sphere_point")


def main(argv=None) -> int:
    from whitted.reference.cli import _positive, _size, resolve_scene

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", metavar="SCENE", default=list(SCENES))
    p.add_argument("--size", type=_size, default=(320, 240))
    p.add_argument("--spp", type=_positive, default=64)
    p.add_argument("--repeat", type=_positive, default=3)
    p.add_argument("--backend", default=None)
    p.add_argument("--schedule", choices=("auto", "wavefront", "stack"), default="auto",
                   help="the recursion schedule (tracer.integrator.SCHEDULES)")
    args = p.parse_args(argv)

    from whitted.tracer import backend, load_scene
    from whitted.tracer.integrator import Integrator

    name = backend.use(args.backend)
    w, h = args.size
    print(f"tracer alone, {w}x{h}, {args.spp} spp, backend {name}; each scene's first render, "
          f"then the median of {args.repeat}")
    for scene_name in args.scenes:
        scene = load_scene(resolve_scene(scene_name)).with_overrides(size=args.size,
                                                                    spp=args.spp)
        integ = Integrator(scene, schedule=args.schedule)
        t0 = time.perf_counter()
        integ.render()
        first = time.perf_counter() - t0
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            result = integ.render()
            times.append(time.perf_counter() - t0)
        print(f"  {scene_name:<20} first {first:7.3f} s   warm {statistics.median(times):7.3f} s"
              f"   {result.rays_total:,} rays, {len(result.rays_per_level)} levels, "
              f"{integ.schedule}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
