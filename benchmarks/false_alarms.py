"""False-alarm rate of ``whitted compare`` on the stored real Mitsuba scenes.

Every scene of ``tests/data/real_scenes`` that imports as it stands (else with
``--approximate``) is compared, as ``whitted compare X --size 64x48 --spp 16
--seed S`` does, at seeds 0, 1000, 2000 (far enough apart that their samples are
independent). A correct tracer is assumed (the tracer as
written): every FAIL is a false alarm of the verdict's rules, or a real
disagreement to investigate. Usage (from the repository root)::

    .venv/bin/python benchmarks/false_alarms.py            # render (cached) and judge
    .venv/bin/python benchmarks/false_alarms.py --rules REV # judge with compare.py of REV

Rendering is the slow part (about 10 minutes on 2 cores), so each comparison's
inputs to :func:`reference.verdicts.compare.judge` (the two images and the noise)
are kept in ``out/false_alarms/`` (NumPy ``.npz`` files read without pickle, with
their metadata as JSON: data, checked when read, never code) and judged again by
the rules of the working
tree or, with ``--rules REV``, by ``reference/verdicts/compare.py`` as it was at
git revision REV (``--rules 2f3d0c0`` gives the rules before issue 28's
calibration): the same renders judged by both, so the two rates differ only by
the rules. Prints one row per scene and seed (the failing checks) and the
false-alarm rate, with its 95 % (Clopper-Pearson) upper bound.
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import importlib.util
import inspect
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "out" / "false_alarms"
#: Seeds far apart: ``compare --seed S`` averages the tracer over seeds S .. S+15 and renders
#: the reference's passes from S on, so seeds 0, 1, 2 would share most of their samples
#: and be one trial, not three.
SIZE, SPP, SEEDS = (64, 48), 16, (0, 1000, 2000)


def scenes() -> list[tuple[str, bool]]:
    """(path, approximate) of every stored scene that imports."""
    from whitted.tracer.scene import load_any

    out = []
    for x in sorted(glob.glob(str(ROOT / "tests/data/real_scenes/**/*.xml"), recursive=True)):
        if "/fragments/" in x or "/include/" in x:
            continue
        for approximate in (False, True):
            try:
                load_any(x, approximate, warn=lambda line: None)
            except Exception:  # noqa: BLE001 - refused: try the next way, or skip
                continue
            out.append((x, approximate))
            break
    return out


def render(path: str, approximate: bool, seed: int) -> list[tuple]:
    """compare_scene's calls of judge: (test, tracer image, reference image, noise)."""
    from whitted.reference.verdicts import compare
    from whitted.tracer.scene import load_any

    calls = []
    judge = compare.judge

    def capture(test_name, metrics, t, r, noise=None, scene=None):
        calls.append((test_name, np.asarray(t), np.asarray(r), noise))
        return judge(test_name, metrics, t, r, noise, scene=scene)

    scene = load_any(path, approximate, warn=lambda line: None).with_overrides(
        spp=SPP, size=SIZE)
    compare.judge = capture
    try:
        compare.compare_scene(scene, seed=seed)
    finally:
        compare.judge = judge
    return calls


def rules_module(rev: str | None):
    """reference.verdicts.compare as in the working tree, or as it was at git ``rev``."""
    from whitted.reference.verdicts import compare

    if rev is None:
        return compare
    src = subprocess.run(["git", "show", f"{rev}:reference/verdicts/compare.py"], cwd=ROOT,
                         check=True, capture_output=True, text=True).stdout
    f = Path(tempfile.mkdtemp()) / "compare_at_rev.py"
    f.write_text(src)
    spec = importlib.util.spec_from_file_location("compare_at_rev", f)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod          # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def save_calls(path: Path, calls: list) -> None:
    """The calls as one .npz: arrays by name, the rest as JSON (no pickle)."""
    arrays, meta = {}, []
    for i, (test_name, t, r, noise) in enumerate(calls):
        arrays[f"{i}.t"], arrays[f"{i}.r"] = t, r
        entry = {"test": test_name, "noise": None}
        if noise is not None:
            fields = {}
            for f in dataclasses.fields(noise):
                v = getattr(noise, f.name)
                if isinstance(v, np.ndarray):
                    arrays[f"{i}.{f.name}"] = v
                    fields[f.name] = "array"
                elif isinstance(v, dict):
                    for k, m in v.items():
                        arrays[f"{i}.{f.name}.{k}"] = m
                    fields[f.name] = {"regions": list(v)}
                else:
                    fields[f.name] = v
            entry["noise"] = fields
        meta.append(entry)
    arrays["meta"] = np.array(json.dumps(meta))
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def load_calls(path: Path) -> list | None:
    """The calls kept at ``path``, or None for anything unreadable (then rendered again)."""
    from whitted.reference.verdicts.compare import Noise

    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            calls = []
            for i, entry in enumerate(meta):
                t, r = z[f"{i}.t"], z[f"{i}.r"]
                if t.shape != r.shape or t.ndim != 3 or not isinstance(entry["test"], str):
                    return None
                noise = None
                if entry["noise"] is not None:
                    kw = {}
                    for name, v in entry["noise"].items():
                        if v == "array":
                            kw[name] = z[f"{i}.{name}"]
                        elif isinstance(v, dict):
                            kw[name] = {k: z[f"{i}.{name}.{k}"] for k in v["regions"]}
                        else:
                            kw[name] = v
                    noise = Noise(**kw)
                calls.append((entry["test"], t, r, noise))
            return calls
    except (OSError, ValueError, KeyError, TypeError):
        return None


def judged(mod, calls, scene=None) -> tuple[bool, list[str]]:
    """All calls passed by ``mod``'s rules, and the failing checks; ``scene`` for rules
    whose exact-strata median depends on it."""
    failed = []
    takes_scene = "scene" in inspect.signature(mod.judge).parameters
    for test_name, t, r, noise in calls:
        metrics = mod.image_metrics(t, r, with_flip=False)
        verdict, _ = (mod.judge(test_name, metrics, t, r, noise, scene=scene) if takes_scene
                      else mod.judge(test_name, metrics, t, r, noise))
        failed += [f"{test_name}:{k}={c['value']:.4g}" for k, c in verdict.checks.items()
                   if not c["pass"]]
    return not failed, failed


def upper_95(k: int, n: int) -> float:
    """One-sided 95 % Clopper-Pearson upper bound of a rate seen k times in n trials."""
    from math import comb

    if k >= n:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(60):  # P(X <= k | n, p) falls with p: bisect for 0.05
        p = (lo + hi) / 2
        cdf = sum(comb(n, i) * p ** i * (1 - p) ** (n - i) for i in range(k + 1))
        lo, hi = (p, hi) if cdf > 0.05 else (lo, p)
    return hi


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rules", metavar="REV", help="judge with compare.py at git revision REV")
    p.add_argument("--only", help="only scenes whose path contains this")
    args = p.parse_args(argv)
    from whitted.tracer import backend

    backend.use("llvm")
    mod = rules_module(args.rules)
    CACHE.mkdir(parents=True, exist_ok=True)
    rows, fails = [], 0
    for path, approximate in scenes():
        if args.only and args.only not in path:
            continue
        name = Path(path).relative_to(ROOT / "tests/data/real_scenes").as_posix()
        from whitted.tracer.scene import load_any

        scene = load_any(path, approximate, warn=lambda line: None)
        for seed in SEEDS:
            key = CACHE / (name.replace("/", "__") + f".seed{seed}.npz")
            calls = load_calls(key) if key.exists() else None
            if calls is None:
                try:
                    calls = render(path, approximate, seed)
                except Exception as e:  # noqa: BLE001 - reported, not counted
                    print(f"{name} seed {seed}: not compared ({type(e).__name__}: {e})",
                          flush=True)
                    continue
                save_calls(key, calls)
            ok, failed = judged(mod, calls, scene)
            fails += not ok
            rows.append((name, approximate, seed, ok, failed))
            print(f"{'pass' if ok else 'FAIL'}  {name}{' (--approximate)' if approximate else ''}"
                  f"  seed {seed}  {' '.join(failed)}", flush=True)
    n = len(rows)
    scenes_n = len({r[0] for r in rows})
    print(f"\nrules: {'working tree' if args.rules is None else args.rules}; {scenes_n} scenes x "
          f"{len(SEEDS)} seeds at {SIZE[0]}x{SIZE[1]}, {SPP} spp: {fails} of {n} comparisons "
          f"failed ({100 * fails / max(n, 1):.1f} %; 95 % upper bound "
          f"{100 * upper_95(fails, n):.1f} %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
