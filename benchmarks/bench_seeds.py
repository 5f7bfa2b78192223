"""The pooled renders of the statistical verdicts (16 seeds a render, shared ray trees):
what their kernels cost LLVM to compile and what they take warm, against a baseline commit.

Where a lane carries several seeds (`Integrator.render_seeds` on the stack schedule), a
sampled light casts one shadow ray per seed. This renders, with the report's 16 seeds at
the quick report's size, each built-in scene that does so (a sampled light, shared
trees), in a fresh process with an empty Dr.Jit kernel cache: the seconds LLVM spent on
the render's kernels (Dr.Jit's kernel history), then the median of warm renders in that
process. With --against, the same with that commit's tracer (a git worktree run with
this environment), alternating scene by scene.

    python benchmarks/bench_seeds.py [--against COMMIT] [--repeat 3] [--renders 3]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_speed import (  # noqa: E402
    _LLVM_SECONDS,
    _baseline_tree,
    _import_root,
    commit,
    compile_bytecode,
    machine_note,
)

#: Seeds a pooled render (reference/verdicts/compare.py's TRACER_SEEDS).
SEEDS = 16

#: A fresh process: the LLVM seconds of its first pooled render of the scene at the quick
#: report's size, then its warm renders' seconds.
CHILD = """
import json, sys, time
from whitted.reference.report.build import quick_overrides
from whitted.tracer import load_scene
from whitted.tracer.integrator import Integrator
import drjit as dr
""" + _LLVM_SECONDS + """integ = Integrator(quick_overrides(load_scene(sys.argv[1])))
seeds = list(range(int(sys.argv[2])))
llvm()
integ.render_seeds(seeds, moments=True)
compiled = llvm()
warm = []
for _ in range(int(sys.argv[3])):
    t = time.perf_counter()
    integ.render_seeds(seeds, moments=True)
    warm.append(time.perf_counter() - t)
print(json.dumps([compiled, warm]))
"""


def pooled_scenes() -> list[Path]:
    """The built-in scenes whose pooled renders share ray trees and sample a light."""
    from whitted.tracer import backend, load_scene
    from whitted.tracer.integrator import Integrator

    backend.use("llvm")
    out = []
    for path in sorted((ROOT / "scenes").glob("*.toml")):
        integ = Integrator(load_scene(path))
        if integ._shares_trees(tuple(range(SEEDS))) and any(
                not light.delta for light in integ.illuminating):
            out.append(path)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--against", metavar="COMMIT", help="also time this commit's tracer")
    p.add_argument("--repeat", type=int, default=3, help="fresh processes a scene and side")
    p.add_argument("--renders", type=int, default=3, help="warm renders a process")
    args = p.parse_args(argv)
    compile_bytecode(ROOT)
    print(f"pooled renders ({SEEDS} seeds, quick report's size): LLVM seconds of a fresh "
          f"process's first render, then warm renders, medians of {args.repeat} processes; "
          f"commit {commit()}; {machine_note()}", flush=True)
    scenes = pooled_scenes()
    with contextlib.ExitStack() as stack:
        sides = [(commit(), {})]
        if args.against:
            wt = stack.enter_context(_baseline_tree(args.against))
            sides.insert(0, (args.against, {"PYTHONPATH": str(_import_root(wt))}))
        tmp = stack.enter_context(tempfile.TemporaryDirectory())
        totals = {name: [0.0, 0.0] for name, _ in sides}
        for scene in scenes:
            llvm = {name: [] for name, _ in sides}
            warm = {name: [] for name, _ in sides}
            for _ in range(args.repeat):
                for name, extra in sides:
                    env = dict(os.environ, DRJIT_CACHE_DIR=tempfile.mkdtemp(dir=tmp), **extra)
                    out = subprocess.run([sys.executable, "-c", CHILD, str(scene), str(SEEDS),
                                          str(args.renders)], check=True, capture_output=True,
                                         text=True, env=env).stdout
                    secs, renders = json.loads(out.strip().splitlines()[-1])
                    llvm[name].append(secs)
                    warm[name].append(statistics.median(renders))
            for name, _ in sides:
                c, w = statistics.median(llvm[name]), statistics.median(warm[name])
                totals[name][0] += c
                totals[name][1] += w
                print(f"  {scene.stem:22s} {name:>12s}: LLVM {c:5.2f} s "
                      f"[{min(llvm[name]):.2f}-{max(llvm[name]):.2f}], warm {w:.3f} s "
                      f"[{min(warm[name]):.3f}-{max(warm[name]):.3f}]", flush=True)
        for name, _ in sides:
            print(f"  all {len(scenes)} scenes, {name}: LLVM {totals[name][0]:.2f} s, warm "
                  f"{totals[name][1]:.3f} s (sums of the medians)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
