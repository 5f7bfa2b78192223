"""The first render of a process at two chunk sizes: what tracing each chunk's kernel costs
against what a larger chunk's fresh memory costs.

A render traces its kernel from Python once a chunk; a larger chunk traces fewer, but the
first render of a process (what `whitted render` does) faults in all of its buffers' pages
at once, where smaller chunks reuse the first chunk's. This writes `bench_speed.py
process`'s two scenes (the instanced 160,000-triangle torus, the 1,000,000-triangle knot
placed twice) and times, alternating, a fresh process's first render (caches warm) with
chunks of each size; it prints the medians, the ranges and each process's peak memory.

    python benchmarks/bench_chunks.py [--repeat 10] [--chunks 2097152 4194304 8388608]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_speed import commit, compile_bytecode, machine_note, write_process_scenes  # noqa: E402

from whitted.tracer.limits import CHUNK_SAMPLES, FLAT_CHUNK_SAMPLES  # noqa: E402

#: A fresh process's first render of a scene with chunks of the given size (None: the
#: tracer's own rule): its seconds and the process's peak resident memory.
CHILD = """
import json, resource, sys, time
from whitted.reference.malloc import keep_freed_memory
keep_freed_memory()
from whitted.tracer import load_scene
from whitted.tracer.integrator import Integrator
integ = Integrator(load_scene(sys.argv[1]), chunk_samples=json.loads(sys.argv[2]))
t = time.perf_counter()
integ.render()
print(json.dumps([time.perf_counter() - t,
                  resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024]))
"""


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=10)
    p.add_argument("--chunks", type=int, nargs="+",
                   default=[CHUNK_SAMPLES, FLAT_CHUNK_SAMPLES],
                   help="chunk sizes in samples (default: the tracer's chunk where rays "
                        "spawn others, limits.CHUNK_SAMPLES, and where none does, "
                        "limits.FLAT_CHUNK_SAMPLES)")
    args = p.parse_args(argv)
    compile_bytecode(ROOT)
    print(f"first render of a process, chunk sizes {args.chunks}, medians of {args.repeat} "
          f"(alternating); commit {commit()}; {machine_note()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for scene in write_process_scenes(Path(tmp), 160_000, 1_000_000, (640, 480), 16):
            run = [sys.executable, "-c", CHILD, str(scene)]
            for c in args.chunks:   # a first run each fills the caches (meshes, trees, kernels)
                subprocess.run([*run, json.dumps(c)], check=True, capture_output=True)
            times = {c: [] for c in args.chunks}
            peaks = {c: [] for c in args.chunks}
            for _ in range(args.repeat):
                for c in args.chunks:
                    out = subprocess.run([*run, json.dumps(c)], check=True, capture_output=True,
                                         text=True).stdout
                    secs, peak = json.loads(out.strip().splitlines()[-1])
                    times[c].append(secs)
                    peaks[c].append(peak)
            for c in args.chunks:
                print(f"  {scene.stem}: chunk {c:>9,}: {statistics.median(times[c]):.3f} s "
                      f"[{min(times[c]):.3f}-{max(times[c]):.3f}], peak "
                      f"{max(peaks[c]) / 2**20:.0f} MB", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
