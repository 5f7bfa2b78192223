"""How often `whitted check` names a known formula bug first: the suspects' hit rate.

For each bug of the catalog (``reference/mutants.py``) the first built-in
scene (in ``whitted scenes`` order) where the tracer with that bug fails
``whitted check`` stands in for a user's renderer: the image is the tracer's
render with the bug switched on (at another seed than the reference's where
lights are sampled, so its light samples are its own), plus Gaussian noise of
``--noise`` times the image's mean (a renderer's own sampling noise; its
variance is left for the check to estimate from the image, as for any image
without a variance layer, or given to it with ``--variance``, as an EXR's
variance layer gives it). The same noise on the tracer as written must
pass the check (the control; a scene where it does not is left out and
listed). The check then ranks the catalog's bugs that
reach the scene (:func:`reference.check.suspects.rank_catalog`), and the bug's rank
is counted:

* a hit at rank 1 when it is first, or tied with the first (a tie: the two
  bugs give the very same image on that scene, or the same pattern at
  strengths that agree within their errors, so the image cannot tell them
  apart; reported as such);
* a hit in the top three likewise;
* a miss otherwise, printed with the bug that came first and the shares
  both explain.

Bugs the tracer's image does not show on any scene (the check passes
everywhere) are listed apart: they cannot be named from an image.

    python benchmarks/bench_suspects.py [--width 64] [--spp 16] [--noise 0.01] [--variance]
                                        [--only ID,...]
    python benchmarks/bench_suspects.py --calibrate [--noise 0.01,0.05,0.2]

``--calibrate``: the rates of the verdict on images whose cause is known
(``docs/check.md``, "Naming the cause"). Each catalog bug on its first
failing scene as above, and each convention of
``reference/check/conventions.py`` on every scene of :data:`CALIBRATION_SCENES`
(a correct render at the user's seed, written as an 8-bit sRGB PNG under the
convention; the conventions of float files as a float image), with noise of
standard deviation F sqrt(value x mean) (F x the mean at the mean, none on
black, as a renderer's noise; Gaussian of F x the mean everywhere would put
noise on black pixels, which no renderer has and which a curve then bends).
Counted: the first suspect right (the cause, or tied with it), no cause named,
the first suspect wrong; images that pass (the scene does not show the
cause) apart.

The sizes are the catalog sweep's quick ones (``reference.mutants.sweep_size``).
Each bug's image is kept in the suspects' cache (``~/.cache/whitted/suspects``;
``--cache DIR`` for another), so a second run takes a fraction of the first.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)

#: The user's image's seed where the tracer samples lights (the reference's is 0).
USER_SEED = 7
#: Scenes the conventions are calibrated on (glass, mirrors, point, spot, area and sphere
#: lights, several materials).
CALIBRATION_SCENES = ("glass_sphere", "sphere_point", "three_lights", "mirror_sphere",
                      "area_lights", "spot_floor", "tir_prisms")


def _quick(scene, width, spp):
    w, h = scene.film.width, scene.film.height
    if w > width:
        scene = scene.with_overrides(size=(width, max(8, round(h * width / w))))
    return scene.with_overrides(spp=min(scene.film.spp, spp))


def _outcome(run, truth: str, kind: str) -> str:
    """'right', 'curve' (an unnamed output curve for a transfer curve), 'none' or 'wrong'
    for a failing image whose cause is ``truth`` (of ``kind``: a convention's class)."""
    sp = run.suspects
    if not sp["named"]:
        return "none"
    first = sp["ranked"][0]
    if first["id"] == truth or truth in first["ties"]:
        return "right"
    if first["id"] == "monotone-curve" and kind == "transfer curve":
        return "curve"      # right in kind: an output curve, not named
    return "wrong"


def calibrate(noise: float, width: int, spp: int, only: list[str] | None = None) -> dict:
    """The verdict's rates at one noise level (module docstring); prints each wrong one."""
    import numpy as np

    from whitted.reference import mutants
    from whitted.reference.check import conventions as cv
    from whitted.reference.check.judge import check_image, tracer_reference
    from whitted.reference.check.suspects import mutated_image, reached_faults
    from whitted.scenes import builtin_scenes
    from whitted.tracer import load_scene

    srgb8 = cv.FileEncoding("srgb", 255, 1.0)
    flt = cv.FileEncoding("float", None, None)
    rng = np.random.default_rng(1)
    tally = {"convention": {"right": 0, "curve": 0, "none": 0, "wrong": 0, "passed": 0},
             "formula bug": {"right": 0, "curve": 0, "none": 0, "wrong": 0, "passed": 0}}
    wrong, nones = [], []

    def noisy(img):
        return img + rng.normal(0, 1, img.shape) * noise * np.sqrt(
            np.maximum(img, 0) * max(float(img.mean()), 1e-12))

    paths = {p.stem: p for p in builtin_scenes()}
    for name in CALIBRATION_SCENES:
        scene = _quick(load_scene(paths[name]), width, spp)
        ref = tracer_reference(scene)
        seed = USER_SEED if scene.samples_lights() else 0
        img = noisy(mutated_image(scene, None, seed)[0].astype(np.float64))
        w, h = scene.film.width, scene.film.height
        fine = noisy(mutated_image(scene.with_overrides(size=(2 * w, 2 * h)), None, seed)[0]
                     .astype(np.float64))
        if not check_image(cv.write_as(None, img, srgb8), scene, reference=ref,
                           decompose=False).passed:
            print(f"{name}: the correct image fails (left out)")
            continue
        for c in cv.CONVENTIONS:
            if only and c.id not in only:
                continue
            enc = srgb8 if c.applies(srgb8) else flt
            if not c.applies(enc):
                continue
            run = check_image(cv.write_as(c, img, enc, fine=fine), scene, reference=ref,
                              decompose=False)
            if run.passed:
                tally["convention"]["passed"] += 1
                continue
            o = _outcome(run, c.id, c.kind)
            tally["convention"][o] += 1
            if o not in ("right", "curve"):
                f = run.suspects["ranked"][0]
                (wrong if o == "wrong" else nones).append(
                    f"{c.id} on {name}: {o}; first {f['id']} ({100 * f['explains']:.0f} %, "
                    f"{'at' if f['at_noise'] else 'beyond'} the noise)")
    todo = [m.id for m in mutants.CATALOG if not only or m.id in only]
    for path in builtin_scenes():
        if not todo:
            break
        scene = _quick(load_scene(path), width, spp)
        here = [i for i in todo if i in reached_faults(scene)]
        if not here:
            continue
        ref = tracer_reference(scene)
        seed = USER_SEED if scene.samples_lights() else 0
        clean = mutated_image(scene, None, seed)[0].astype(np.float64)
        n = rng.normal(0, 1, clean.shape) * noise * np.sqrt(
            np.maximum(clean, 0) * max(float(clean.mean()), 1e-12))
        if not check_image(cv.write_as(None, clean + n, flt), scene, reference=ref,
                           decompose=False).passed:
            continue
        for fid in here:
            img = mutated_image(scene, fid, seed)[0].astype(np.float64)
            run = check_image(cv.write_as(None, img + n, flt), scene, reference=ref,
                              decompose=False)
            if run.passed:
                continue
            todo.remove(fid)
            o = _outcome(run, fid, "formula bug")
            tally["formula bug"][o] += 1
            if o != "right":
                f = run.suspects["ranked"][0]
                (wrong if o == "wrong" else nones).append(
                    f"{fid} on {scene.name}: {o}; first {f['id']} ({100 * f['explains']:.0f} "
                    f"%, {'at' if f['at_noise'] else 'beyond'} the noise)")
    tally["formula bug"]["passed"] = len(todo)
    for line in wrong:
        print("WRONG  " + line)
    for line in nones:
        print("none   " + line)
    return tally


def print_rates(noise: float, tally: dict) -> None:
    print(f"noise {noise:g} x sqrt(value x mean):")
    total = {"right": 0, "curve": 0, "none": 0, "wrong": 0}
    for kind, t in tally.items():
        n = t["right"] + t["curve"] + t["none"] + t["wrong"]
        for k in total:
            total[k] += t[k]
        print(f"  {kind + 's':<13} {n:>4} failing images: right first {t['right']:>3} "
              f"({100 * t['right'] / max(n, 1):5.1f} %), an unnamed output curve "
              f"{t['curve']:>2}, no cause named {t['none']:>3} "
              f"({100 * t['none'] / max(n, 1):5.1f} %), wrong first {t['wrong']:>3} "
              f"({100 * t['wrong'] / max(n, 1):4.1f} %); {t['passed']} pass (not shown)")
    n = sum(total.values())
    print(f"  {'all':<13} {n:>4} failing images: right first {total['right']:>3} "
          f"({100 * total['right'] / max(n, 1):5.1f} %), an unnamed output curve "
          f"{total['curve']:>2}, no cause named {total['none']:>3} "
          f"({100 * total['none'] / max(n, 1):5.1f} %), wrong first {total['wrong']:>3} "
          f"({100 * total['wrong'] / max(n, 1):4.1f} %)", flush=True)


def main(argv=None) -> int:
    import numpy as np

    from whitted.reference import mutants
    from whitted.reference.check.images import UserImage
    from whitted.reference.check.judge import check_image, tracer_reference
    from whitted.reference.check.suspects import mutated_image, reached_faults
    from whitted.scenes import builtin_scenes
    from whitted.tracer import load_scene

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--width", type=int, default=mutants.QUICK_WIDTH)
    p.add_argument("--spp", type=int, default=mutants.QUICK_SPP)
    p.add_argument("--noise", default="0.01",
                   help="Gaussian noise added to the bug's image, times the image's mean "
                        "(--calibrate: a comma-separated list)")
    p.add_argument("--calibrate", action="store_true",
                   help="the verdict's rates on bugs and conventions (module docstring)")
    p.add_argument("--variance", action="store_true",
                   help="give the check the noise's variance (as an EXR variance layer) "
                        "instead of letting it estimate the noise from the image")
    p.add_argument("--only", default=None, help="comma-separated bug ids (default: all)")
    p.add_argument("--cache", type=Path, default=None, help="cache folder of the bugs' images")
    args = p.parse_args(argv)

    if args.cache is not None:
        import os

        os.environ["WHITTED_SUSPECTS_CACHE"] = str(args.cache)
    if args.calibrate:
        start = time.perf_counter()
        for f in (float(x) for x in args.noise.split(",")):
            tally = calibrate(f, args.width, args.spp,
                              args.only.split(",") if args.only else None)
            print_rates(f, tally)
        print(f"{time.perf_counter() - start:.0f} s")
        return 0
    args.noise = float(args.noise)
    todo = [m.id for m in (mutants.get(args.only.split(",")) if args.only else mutants.CATALOG)]
    start = time.perf_counter()
    rng = np.random.default_rng(1)
    results = {}          # id -> (scene, rank, top id, top share, own share, ties)
    false_alarms = []     # scenes whose tracer as written fails with the noise added
    for path in builtin_scenes():
        if not todo:
            break
        scene = load_scene(path)
        w, h = scene.film.width, scene.film.height
        if w > args.width:
            scene = scene.with_overrides(size=(args.width, max(8, round(h * args.width / w))))
        scene = scene.with_overrides(spp=min(scene.film.spp, args.spp))
        here = [i for i in todo if i in reached_faults(scene)]
        if not here:
            continue
        ref = tracer_reference(scene)
        seed = USER_SEED if scene.samples_lights() else 0
        clean, _ = mutated_image(scene, None, seed)
        sigma = args.noise * abs(float(clean.mean()))
        noise = rng.normal(0, sigma, clean.shape) if sigma > 0 else 0.0

        var = np.full(clean.shape, sigma ** 2) if args.variance and sigma > 0 else None

        def check(img, label, scene=scene, ref=ref, noise=noise, var=var):
            return check_image(UserImage(label, "array", "float32",
                                         img.astype(np.float64) + noise, variance=var),
                               scene, reference=ref, decompose=False)

        # The control: the tracer as written with the same noise must pass, or a failure
        # with a bug on says nothing about the bug.
        if not check(clean, "<as written>").passed:
            false_alarms.append(scene.name)
            continue
        for fid in here:
            img, _ = mutated_image(scene, fid, seed)
            run = check(img, f"<{fid}>")
            if run.passed:
                continue       # this scene does not show the bug: try the next one
            todo.remove(fid)
            ranked = run.suspects["ranked"]
            ids = [f["id"] for f in ranked]
            rank = ids.index(fid) + 1 if fid in ids else None
            top = ranked[0] if ranked else None
            first_ties = set(top["ties"]) | {top["id"]} if top else set()
            top3 = set()
            for f in ranked[:3]:
                top3 |= {f["id"], *f["ties"]}
            own = ranked[rank - 1]["explains"] if rank else 0.0
            results[fid] = {"scene": scene.name, "rank": rank, "first": fid in first_ties,
                            "top3": fid in top3, "top": top["id"] if top else None,
                            "top_explains": top["explains"] if top else 0.0,
                            "explains": own, "ties": ranked[rank - 1]["ties"] if rank else [],
                            "strength": ranked[rank - 1]["scale"] if rank else None}
            r = results[fid]
            print(f"{fid:<38} {scene.name:<22} rank {rank if rank else '-':>2}  "
                  f"explains {100 * own:5.1f} %  strength {r['strength'] or 0:5.2f}"
                  + (f"  tied with {', '.join(r['ties'])}" if r["ties"] else "")
                  + ("" if r["first"] else
                     f"  first: {r['top']} ({100 * r['top_explains']:.1f} %)"),
                  flush=True)
    shown = len(results)
    first = sum(r["first"] for r in results.values())
    top3 = sum(r["top3"] for r in results.values())
    tied = [i for i, r in results.items() if r["first"] and r["ties"]]
    print()
    print(f"hit rate: {first}/{shown} bugs named first ({100 * first / max(shown, 1):.0f} %), "
          f"{top3}/{shown} in the top three ({100 * top3 / max(shown, 1):.0f} %); "
          f"noise {args.noise:g} x the mean"
          + (", its variance given" if args.variance else ", estimated by the check")
          + f", width {args.width}, at most {args.spp} spp; "
          f"{time.perf_counter() - start:.0f} s")
    if tied:
        print("named first in a tie (another bug's image on that scene is the same, or the "
              "same pattern at a strength within the errors): "
              + "; ".join(f"{i} = {', '.join(results[i]['ties'])} ({results[i]['scene']})"
                          for i in tied))
    misses = [i for i, r in results.items() if not r["first"]]
    for i in misses:
        r = results[i]
        print(f"miss: {i} on {r['scene']}: rank {r['rank']}, explains {100 * r['explains']:.1f} %"
              f"; first {r['top']} explains {100 * r['top_explains']:.1f} %")
    if false_alarms:
        print("scenes left out: the tracer as written with the same noise fails the check "
              f"there (a false alarm): {', '.join(false_alarms)}")
    if todo:
        print(f"not shown by any scene (the check passes with the bug on): {', '.join(todo)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
