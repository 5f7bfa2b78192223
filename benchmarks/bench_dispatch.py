"""Material dispatch: per-kind masks (the tracer's) against Dr.Jit's ``dr.switch``, in one run.

The tracer evaluates every material kind present in a scene under its own
mask and selects per lane (tracer/materials/dispatch.py). The alternative
written here sends each lane through ``dr.switch``: an indirect call per
lane to its kind's code, which gathers that kind's parameters inside the
call. Both render each scene; the images must be identical, and the script
prints the median render time of each and their ratio.

Times are process CPU time (all threads) as well as wall time: on a shared
machine the wall time measures the neighbours, the CPU time much less so.
The two variants alternate, ``--rounds`` times, each rendering ``--repeat``
times after a warm-up render (kernels compiled).

    python benchmarks/bench_dispatch.py [SCENE ...] [--rounds 4] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)

SCENES = ("three_lights", "sphere_point", "phong_lobes", "shapes_zoo", "whitted_mix",
          "heckbert_physical_hd", "whitted_1980", "mesh_knot", "area_lights")
#: the ShadingPoint fields, passed through dr.switch as arrays
FIELDS = ("p", "n", "ns", "uv", "d", "nl", "ng", "cos_i")


def switch_dispatch():
    """``SceneMaterials.at`` built on ``dr.switch`` (same interface, same results)."""
    import drjit as dr

    from whitted.tracer.backend import jit
    from whitted.tracer.materials import dispatch
    from whitted.tracer.materials.base import ShadingPoint

    def si_of(args):
        return ShadingPoint(*args)

    class SwitchClosure(dispatch.Closure):
        def __init__(self, parts, si, valid, kind, row):
            super().__init__(parts, si, valid)
            self.kind, self.row = kind, row

        def _targets(self, pred):
            kinds = [i for i, (b, _, _) in enumerate(self.parts) if pred(b)]
            index = dr.zeros(jit.UInt32, dr.width(self.kind))
            for j, i in enumerate(kinds):
                index = dr.select(self.kind == i, j, index)
            return [self.parts[i][0] for i in kinds], index

        def _args(self):
            return [getattr(self.si, k) for k in FIELDS]

        def eval(self, wi):
            bsdfs, index = self._targets(lambda b: b.smooth)

            def target(b):
                def f(row, *args, active=True):
                    si = si_of(args[:-1])
                    return b.eval(b.params(row, si, active), si, args[-1])
                return f

            return dr.switch(index, [target(b) for b in bsdfs], self.row, *self._args(), wi,
                             active=self.smooth)

        def delta_lobes(self, throughput):
            bsdfs, index = self._targets(lambda b: bool(b.lobes))
            slots = max(len(b.lobes) for b in bsdfs)
            mask = dr.zeros(jit.Bool, dr.width(self.kind))
            for b, m, _ in self.parts:
                if b.lobes:
                    mask |= m

            def target(b):
                def f(row, *args, active=True):
                    si = si_of(args)
                    lobes = b.delta_lobes(b.params(row, si, active), si)
                    out = []
                    for k in range(slots):
                        d, w = lobes[k] if k < len(lobes) else (0, 0)
                        out += [jit.Array3f(d), jit.Array3f(w)]
                    return tuple(out)
                return f

            res = dr.switch(index, [target(b) for b in bsdfs], self.row, *self._args(),
                            active=mask)
            out = []
            for k in range(slots):
                s = dispatch.Slot(res[2 * k], dr.select(mask, throughput * res[2 * k + 1], 0))
                for b, m, _ in self.parts:
                    if k < len(b.lobes):
                        lobe = b.lobes[k]
                        s.letters[lobe.letter] = m | s.letters.get(lobe.letter, m)
                        s.kinds[lobe.kind] = m | s.kinds.get(lobe.kind, m)
                out.append(s)
            return out

    def at(self, mid, si, valid):
        kind = dr.gather(jit.UInt32, self.kind, mid, valid)
        row = dr.gather(jit.UInt32, self.row, mid, valid)
        # Parameters outside the calls only for emission (unused ones are never computed).
        parts = [(b, valid & (kind == i), b.params(row, si, valid & (kind == i)))
                 for i, b in enumerate(self.kinds)]
        return SwitchClosure(parts, si, valid, kind, row)

    return at


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=list(SCENES))
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--backend", default=None)
    args = p.parse_args(argv)

    import numpy as np

    from whitted.reference.cli import resolve_scene
    from whitted.tracer import backend, load_scene
    from whitted.tracer.integrator import Integrator
    from whitted.tracer.materials import dispatch

    name = backend.use(args.backend)
    variants = {"masks": dispatch.SceneMaterials.at, "switch": switch_dispatch()}
    print(f"material dispatch, backend {name}: median of {args.rounds} x {args.repeat} warm "
          f"renders per variant, alternating")
    print(f"{'scene':<20} {'masks cpu':>10} {'switch cpu':>11} {'ratio':>6}   "
          f"{'masks wall':>10} {'switch wall':>11} {'ratio':>6}  images")
    try:
        for scene_name in args.scenes:
            scene = load_scene(resolve_scene(scene_name))
            cpu: dict = {k: [] for k in variants}
            wall: dict = {k: [] for k in variants}
            images = {}
            for _ in range(args.rounds):
                for key, at in variants.items():
                    dispatch.SceneMaterials.at = at
                    integ = Integrator(scene)
                    images[key] = integ.render().image  # warm-up: compiles the kernels
                    for _ in range(args.repeat):
                        c0, w0 = time.process_time(), time.perf_counter()
                        integ.render()
                        cpu[key].append(time.process_time() - c0)
                        wall[key].append(time.perf_counter() - w0)
            med = {k: (statistics.median(cpu[k]), statistics.median(wall[k])) for k in variants}
            same = "identical" if np.array_equal(images["masks"], images["switch"]) else \
                "DIFFER"
            (mc, mw), (sc, sw) = med["masks"], med["switch"]
            print(f"{scene.name:<20} {mc:9.4f}s {sc:10.4f}s {sc / mc:6.2f}   {mw:9.4f}s "
                  f"{sw:10.4f}s {sw / mw:6.2f}  {same}", flush=True)
    finally:
        dispatch.SceneMaterials.at = variants["masks"]
    print("ratio = switch / masks (> 1: the masks are faster)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
