"""Time the tracer's BVH against Mitsuba (Embree on a CPU, OptiX on a GPU) on a large mesh.

Generates a torus-knot mesh of 2 x segments x sides triangles (default 144,000),
places it in a scene lit by a point light, and renders it with the tracer and
with Mitsuba's `direct` integrator at the same size and samples per pixel.
Prints the BVH build time, the median render times after a warm-up, and
their ratio (the target: the tracer within 1.5x of Mitsuba); and the time to
read the mesh file (tracer/meshio.py): parsed (the PLY, and the same mesh
written as OBJ), and loaded again (the cache's hit).

    python benchmarks/bench_mesh.py [--segments 1200] [--sides 60] [--size 640x480] [--spp 16]
    python benchmarks/bench_mesh.py --triangles 1000000   (sides 100, segments to match)
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)

SCENE = """
[film]
width = {w}
height = {h}
spp = {spp}
max_depth = 2

[camera]
origin = [0, 2.6, 6]
target = [0, 0.7, 0]
fov = 40

[materials.copper]
type = "diffuse"
reflectance = [0.6, 0.3, 0.15]

[materials.floor]
type = "diffuse"
reflectance = 0.5

[[lights]]
type = "point"
position = [-3, 5, 4]
intensity = 80

[[shapes]]
type = "mesh"
file = "{mesh}"
smooth = true
material = "copper"
to_world = [ {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }}, {{ translate = [0, 1.0, 0] }} ]

[[shapes]]
type = "rectangle"
material = "floor"
to_world = [ {{ scale = 6 }}, {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }} ]
"""


def main(argv=None) -> int:
    from whitted.reference.cli import _size

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--segments", type=int, default=1200)
    p.add_argument("--sides", type=int, default=60)
    p.add_argument("--triangles", type=int, default=None,
                   help="about this many triangles: 100 sides, segments = N / 200 "
                        "(overrides --segments and --sides)")
    p.add_argument("--size", type=_size, default=(640, 480))
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--backend", default=None)
    args = p.parse_args(argv)
    if args.triangles is not None:
        args.sides = 100
        args.segments = max(3, round(args.triangles / (2 * args.sides)))

    sys.path.insert(0, str(ROOT / "scenes" / "meshes"))
    import drjit as dr
    from generate import torus_knot, write_obj, write_ply

    from whitted.reference import mitsuba
    from whitted.reference.renderers.mitsuba.scene import load
    from whitted.tracer import backend, load_scene
    from whitted.tracer import bvh as bvh_module
    from whitted.tracer.bvh import sah_cost
    from whitted.tracer.integrator import Integrator

    name = backend.use(args.backend)
    with tempfile.TemporaryDirectory() as tmp:
        v, f = torus_knot(args.segments, args.sides)
        mesh = Path(tmp) / "knot.ply"
        write_ply(mesh, v, f)
        obj = Path(tmp) / "knot.obj"
        write_obj(obj, v, f)
        parse = {p.suffix: _load_times(p, args.repeat) for p in (mesh, obj)}
        scene_file = Path(tmp) / "scene.toml"
        w, h = args.size
        scene_file.write_text(SCENE.format(w=w, h=h, spp=args.spp, mesh=mesh))
        t0 = time.perf_counter()
        scene = load_scene(scene_file)
        load_s = time.perf_counter() - t0
        # The build itself, not a read of the tree kept on disk by an earlier run.
        bvh_module.DISK_MIN_TRIANGLES = len(f) + 1
        integ = Integrator(scene)
        bvh = next(b for b in integ.geo.blocks if hasattr(b, "bvh")).bvh
        a = bvh.arrays
        mi = mitsuba()
        t0 = time.perf_counter()
        ms = load(scene, mi, "direct")
        mi_load_s = time.perf_counter() - t0
        spp = scene.film.strata ** 2

        def timed(fn):
            fn()
            out = []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                fn()
                out.append(time.perf_counter() - t0)
            return statistics.median(out)

        def run_mitsuba():
            img = mi.render(ms, spp=spp)
            dr.eval(img)
            dr.sync_thread()

        t_tracer = timed(integ.render)
        t_mitsuba = timed(run_mitsuba)
    print(f"mesh: {len(f):,} triangles; scene {w}x{h}, {spp} spp, backend {name}")
    print(f"  BVH build (Dr.Jit)         {bvh.build_seconds:8.3f} s  ({bvh.node_count:,} nodes, "
          f"SAH cost {sah_cost(a.lo, a.hi, a.count, a.left >= 0):.1f}); scene load incl. PLY "
          f"{load_s:.3f} s; Mitsuba scene load {mi_load_s:.3f} s")
    for suffix, (cold, warm, size) in parse.items():
        print(f"  mesh file {suffix} ({size / 1e6:.1f} MB)   parsed {cold:8.4f} s, loaded again "
              f"(cached) {warm * 1e6:.0f} us (medians of {args.repeat})")
    print(f"  tracer render              {t_tracer:8.3f} s (median of {args.repeat})")
    accel = "OptiX" if name == "cuda" else "Embree"
    print(f"  Mitsuba direct ({accel})    {t_mitsuba:8.3f} s")
    print(f"  ratio tracer / Mitsuba = {t_tracer / t_mitsuba:.2f} (target <= 1.5: "
          f"{'met' if t_tracer <= 1.5 * t_mitsuba else 'NOT met'})")
    print(f"  BVH build / Mitsuba scene load = {bvh.build_seconds / mi_load_s:.2f} (target <= 1: "
          f"{'met' if bvh.build_seconds <= mi_load_s else 'NOT met'}; Mitsuba's load "
          "includes its conversion from the scene and Embree's build)")
    return 0


def _load_times(path: Path, repeat: int) -> tuple[float, float, int]:
    """Median seconds to parse the file (caches cleared first, the disk's kept out: the
    parse itself) and to load it again (the memory cache's hit)."""
    from whitted.tracer import meshio

    cold, warm = [], []
    saved, meshio.DISK_MIN_BYTES = meshio.DISK_MIN_BYTES, 1 << 62
    try:
        for _ in range(repeat):
            meshio.clear_cache()
            t0 = time.perf_counter()
            meshio.load_mesh(path)
            cold.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            meshio.load_mesh(path)
            warm.append(time.perf_counter() - t0)
    finally:
        meshio.DISK_MIN_BYTES = saved
        meshio.clear_cache()
    return statistics.median(cold), statistics.median(warm), path.stat().st_size


if __name__ == "__main__":
    sys.exit(main())
