"""Time the tracer on n instances of one sphere: the cost should grow like log n, not n.

Places n instances of a one-sphere group on a square grid over a floor, lit by
a point light, and for each n prints: the time to build the geometry (the
instances' hierarchy included) and compile the kernels (the first render),
the median of three warm renders, and the time to convert the scene to
Mitsuba and load it there. With a hierarchy over the instances a ray visits
about log n of them; without one it tests all n.

    python benchmarks/bench_instances.py [--counts 200 1000 2000] [--size 64x48] [--spp 4]
        [--no-mitsuba]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)


def instances_scene_text(n: int, width: int = 64, height: int = 48, spp: int = 4) -> str:
    """A TOML scene: n instances of one unit sphere on a grid over a floor."""
    side = math.ceil(math.sqrt(n))
    spacing = 2.5
    extent = side * spacing
    lines = [
        "[film]", f"width = {width}", f"height = {height}", f"spp = {spp}", "max_depth = 2", "",
        "[camera]", f"origin = [0, {0.9 * extent:.3f}, {1.1 * extent:.3f}]", "target = [0, 0, 0]",
        "fov = 50", "",
        "[materials.red]", 'type = "diffuse"', "reflectance = [0.7, 0.2, 0.2]", "",
        "[materials.floor]", 'type = "diffuse"', "reflectance = 0.5", "",
        "[[lights]]", 'type = "point"', f"position = [0, {extent:.3f}, {0.5 * extent:.3f}]",
        f"intensity = {0.5 * extent * extent:.3f}", "",
        "[[groups.ball.shapes]]", 'type = "sphere"', "radius = 1", 'material = "red"', "",
        "[[shapes]]", 'type = "rectangle"', 'material = "floor"',
        f"to_world = [ {{ scale = {extent:.3f} }}, "
        "{ rotate = { axis = [1, 0, 0], angle = -90 } }, { translate = [0, -1, 0] } ]", "",
    ]
    for i in range(n):
        x = (i % side - (side - 1) / 2) * spacing
        z = (i // side - (side - 1) / 2) * spacing
        lines += ["[[shapes]]", 'type = "instance"', 'group = "ball"',
                  f"to_world = [ {{ translate = [{x:.3f}, 0, {z:.3f}] }} ]", ""]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[200, 1000, 2000])
    ap.add_argument("--size", default="64x48")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--no-mitsuba", action="store_true")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.lower().split("x"))

    from whitted.tracer.integrator import Integrator
    from whitted.tracer.scene import parse_scene

    try:
        import tomllib
    except ImportError:  # pragma: no cover
        raise
    print(f"{'instances':>9} {'load_s':>8} {'build+first_s':>14} {'render_s':>9} "
          f"{'mitsuba_load_s':>15}")
    for n in args.counts:
        t0 = time.perf_counter()
        scene = parse_scene(tomllib.loads(instances_scene_text(n, w, h, args.spp)),
                            f"instances_{n}.toml")
        t1 = time.perf_counter()
        integ = Integrator(scene)
        image = integ.render().image
        t2 = time.perf_counter()
        times = []
        for _ in range(3):
            s = time.perf_counter()
            integ.render()
            times.append(time.perf_counter() - s)
        m = "-"
        if not args.no_mitsuba:
            from whitted.reference import mitsuba
            from whitted.reference.renderers.mitsuba.scene import load

            mi = mitsuba()
            s = time.perf_counter()
            load(scene, mi, "direct")
            m = f"{time.perf_counter() - s:.3f}"
        lit = float((image.sum(-1) > 0).mean())
        print(f"{n:>9} {t1 - t0:>8.3f} {t2 - t1:>14.3f} {statistics.median(times):>9.3f} "
              f"{m:>15}   (lit pixels {100 * lit:.0f} %)", flush=True)


if __name__ == "__main__":
    main()
