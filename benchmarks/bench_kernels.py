"""Where a cold formula-bug sweep's compile time goes: kernels compiled, by kind of bug.

Runs the quick sweep of the built-in scenes (what ``whitted report --quick`` sweeps,
without the XML files) in this process with Dr.Jit's kernel history on, and sums,
for the clean renders and references of each scene and for each bug's judgement,
the kernels launched, those compiled (not found in the kernel cache) and LLVM's
time on them. Run it with empty caches to see a fresh machine's (CI's) case:

    HOME=$(mktemp -d) python benchmarks/bench_kernels.py

(``DRJIT_CACHE_DIR`` and ``XDG_CACHE_HOME`` are set under that HOME unless given.)
Bugs decided by ``faults.pick`` share one kernel a scene in the sweep
(``faults.active(id, shared_kernel=True)``) and are counted together as "pick";
the others by stage and id.
"""

from __future__ import annotations

import ast
import collections
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
home = Path(os.environ.get("HOME", "~")).expanduser()
os.environ.setdefault("DRJIT_CACHE_DIR", str(home / ".drjit"))
os.environ.setdefault("XDG_CACHE_HOME", str(home / ".cache"))

from whitted import tracer  # noqa: E402,F401,I001  (chooses libLLVM before drjit loads)

import drjit as dr  # noqa: E402


def picked_ids() -> set[str]:
    """The ids of every ``faults.pick("id", ...)`` in the tracer."""
    out = set()
    for p in (ROOT / "tracer").rglob("*.py"):
        for c in ast.walk(ast.parse(p.read_text())):
            if (isinstance(c, ast.Call) and isinstance(c.func, ast.Attribute)
                    and c.func.attr == "pick" and c.args
                    and isinstance(c.args[0], ast.Constant)):
                out.add(c.args[0].value)
    return out


def main() -> int:
    from whitted.reference import mutants
    from whitted.reference.shared import shared

    picked = picked_ids()
    stats: dict[str, list] = collections.defaultdict(lambda: [0, 0, 0.0])

    def take(tag: str) -> None:
        for k in dr.kernel_history():
            if "hash" not in k:
                continue
            s = stats[tag]
            s[0] += 1
            if not k.get("cache_hit", 1):
                s[1] += 1
                s[2] += k.get("backend_time", 0.0) / 1000

    real = mutants._judge_mutant

    def judge(m, units, reread=None):
        take("clean renders and references")
        out = real(m, units, reread)
        take("pick (one kernel a scene)" if m.id in picked else f"{m.stage}: {m.id}")
        return out

    mutants._judge_mutant = judge
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    scenes = sorted((ROOT / "scenes").glob("*.toml"))
    t0 = time.perf_counter()
    with shared():
        mutants.sweep(scenes, quick=True, log=lambda line: None)
    take("clean renders and references")
    seconds = time.perf_counter() - t0
    print(f"quick sweep of {len(scenes)} scenes: {seconds:.1f} s; Dr.Jit's kernel cache "
          f"{os.environ['DRJIT_CACHE_DIR']}")
    print(f"  {'':44s} {'launched':>9s} {'compiled':>9s} {'LLVM s':>8s}")
    for tag, (n, miss, secs) in sorted(stats.items(), key=lambda kv: -kv[1][2]):
        print(f"  {tag:44s} {n:9d} {miss:9d} {secs:8.1f}")
    total = [sum(v[i] for v in stats.values()) for i in range(3)]
    print(f"  {'all':44s} {total[0]:9d} {total[1]:9d} {total[2]:8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
