"""Camera rays a lane (K) on this CPU: what each K costs LLVM to compile and what it gains
in the render.

A lane's K rays walk a mesh's BVH as a packet (tracer/integrator.py's GROUPS); a larger
K reads each node once for more rays but makes a larger kernel. This writes `bench_speed.py
process`'s two scenes (the instanced 160,000-triangle torus, the 1,000,000-triangle knot
placed twice) and `bench_mesh.py`'s (one 1,000,000-triangle knot, placed once, filling
the frame), takes the built-in mesh scenes (scenes/mesh_*.toml), all at 640x480, 16 spp,
and, for each K, runs a fresh process with an empty Dr.Jit kernel cache: the seconds LLVM
spent on the first render's kernels (Dr.Jit's kernel history), then the median of warm
renders in that process. The Ks run alternating, round after round.

    python benchmarks/bench_group.py [--repeat 3] [--groups 1 2 4 8] [--renders 5]
"""

from __future__ import annotations

import argparse
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
    commit,
    compile_bytecode,
    machine_note,
    write_process_scenes,
)

#: A fresh process (empty kernel cache): the LLVM seconds of its first render with K rays a
#: lane, then its warm renders' seconds.
CHILD = """
import json, sys, time
from whitted.reference.malloc import keep_freed_memory
keep_freed_memory()
from whitted.tracer import backend, load_scene
from whitted.tracer.integrator import Integrator
import drjit as dr
""" + _LLVM_SECONDS + """scene = load_scene(sys.argv[1]).with_overrides(size=(640, 480), spp=16)
integ = Integrator(scene, group=int(sys.argv[2]))
llvm()
integ.render()
compiled = llvm()
warm = []
for _ in range(int(sys.argv[3])):
    t = time.perf_counter()
    integ.render()
    warm.append(time.perf_counter() - t)
print(json.dumps([compiled, warm, backend.llvm_vector_width()]))
"""


def _scenes(folder: Path) -> list[Path]:
    """`bench_speed.py process`'s two scenes, `bench_mesh.py`'s, and the built-in mesh
    scenes."""
    sys.path.insert(0, str(ROOT / "scenes" / "meshes"))
    from bench_mesh import SCENE
    from generate import torus_knot, write_ply

    scenes = write_process_scenes(folder, 160_000, 1_000_000, (640, 480), 16)
    v, f = torus_knot(5000, 100)   # bench_mesh.py --triangles 1000000
    write_ply(folder / "mesh_bench_knot.ply", v, f)
    one = folder / "one_knot.toml"
    one.write_text(SCENE.format(w=640, h=480, spp=16, mesh=folder / "mesh_bench_knot.ply"))
    return [*scenes, one, *sorted((ROOT / "scenes").glob("mesh_*.toml"))]


def main(argv=None) -> int:
    from whitted.tracer import backend
    from whitted.tracer.integrator import default_group

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=3, help="fresh processes a K and scene")
    p.add_argument("--groups", type=int, nargs="+", default=[1, 2, 4, 8])
    p.add_argument("--renders", type=int, default=5, help="warm renders a process")
    args = p.parse_args(argv)
    compile_bytecode(ROOT)
    backend.use("llvm")
    print(f"rays a lane: LLVM seconds of a fresh process's first render, then warm renders "
          f"(640x480, 16 spp), medians of {args.repeat} processes (alternating); Dr.Jit's "
          f"packets {backend.llvm_vector_width()} lanes, the tracer's K here "
          f"{default_group()}; commit {commit()}; {machine_note()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for scene in _scenes(Path(tmp)):
            subprocess.run([sys.executable, "-c", CHILD, str(scene), "1", "0"], check=True,
                           capture_output=True)   # the scene's mesh and tree caches filled
            llvm = {k: [] for k in args.groups}
            warm = {k: [] for k in args.groups}
            for _ in range(args.repeat):
                for k in args.groups:
                    env = dict(os.environ, DRJIT_CACHE_DIR=tempfile.mkdtemp(dir=tmp))
                    out = subprocess.run([sys.executable, "-c", CHILD, str(scene), str(k),
                                          str(args.renders)], check=True, capture_output=True,
                                         text=True, env=env).stdout
                    secs, renders, _ = json.loads(out.strip().splitlines()[-1])
                    llvm[k].append(secs)
                    warm[k].append(statistics.median(renders))
            for k in args.groups:
                print(f"  {scene.stem}: K = {k}: LLVM {statistics.median(llvm[k]):.2f} s "
                      f"[{min(llvm[k]):.2f}-{max(llvm[k]):.2f}], warm render "
                      f"{statistics.median(warm[k]):.3f} s [{min(warm[k]):.3f}-"
                      f"{max(warm[k]):.3f}]", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
