"""Print the false-alarm counts and powers of the statistical verdict, measured on seeds.

    python docs/verdict_figures.py [--seeds 24] [--size 96x72] [SCENE ...]

For each scene (default: glass_sphere emitter_in_glass area_lights whitted_mix)
a correct tracer is judged against the one-lobe reference on independent
seeds (reference passes and tracer seeds), as ``tests/reference/verdicts/test_statistics.py``
does, and known errors are injected into its image. Printed per scene:

* fails: trials failed by each rule (z: per pixel, with the zero-variance rule;
  blocks; regions), and by the per-pixel rule without the zero-variance rule;
* tiles: mean of Z^2 and of Z over the disjoint tiles of all trials (1 and 0
  for a standard normal), with their count;
* power: trials in which a 1 % bias over the image (and over the glass, where
  there is glass) fails the region rule, with the true variance and with a
  variance 1024 times too large; the median detectable bias (90 % power) of
  those regions; trials in which +30 % on 1 % of the random pixels fails the
  per-pixel rule, both ways.
"""

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)


def main() -> None:
    import numpy as np

    from whitted.reference.verdicts.compare import (
        image_metrics,
        judge,
        region_test,
        statistical_comparison,
        z_test,
    )
    from whitted.tracer import load_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*", default=["glass_sphere", "emitter_in_glass",
                                                  "area_lights", "whitted_mix"])
    ap.add_argument("--seeds", type=int, default=24)
    ap.add_argument("--size", default="96x72")
    args = ap.parse_args()
    size = tuple(int(x) for x in args.size.split("x"))
    for name in args.scenes:
        scene = load_scene(ROOT / "scenes" / f"{name}.toml").with_overrides(size=size, spp=64)
        fails = {"z": 0, "blocks": 0, "regions": 0, "z without rule 2": 0}
        tiles, power, power_big, detect, local, local_big = [], {}, {}, {}, 0, 0
        for k in range(args.seeds):
            t = statistical_comparison(scene, seed=1000 * (k + 1), tracer_seed=16 * (k + 1))
            c, nz = t.verdict.checks, t.noise
            fails["z"] += not c["z_fraction_passed"]["pass"]
            fails["blocks"] += not (c["block_median_rel"]["pass"] and
                                    c["block_frac_over_5pct"]["pass"])
            fails["regions"] += not c["region_max_z"]["pass"]
            fails["z without rule 2"] += not z_test(t.tracer_image, t.ref.image, nz.ref_var,
                                                    nz.tracer_var).passed
            rt = region_test(t.tracer_image, t.ref.image, nz)
            tiles += [g["z"] for g in rt.regions if g["name"].startswith("tile")]
            for region in ("image", "material glass"):
                if region not in nz.regions:
                    continue
                img = t.tracer_image.copy()
                img[nz.regions[region]] *= 1.01
                for scale, out in ((1, power), (1024, power_big)):
                    r = region_test(img, t.ref.image, nz.scaled(scale))
                    out[region] = out.get(region, 0) + (not r.passed)
                    if scale == 1:
                        g = next((g for g in r.regions if g["name"] == region), None)
                        if g is not None:
                            detect.setdefault(region, []).append(g["detectable_bias"])
            floor = (1e-4 * np.abs(t.ref.image.astype(np.float64)).sum(-1)) ** 2
            rnd = np.argwhere(nz.ref_pass_var > floor)
            pick = rnd[:: max(1, len(rnd) // (t.tracer_image.shape[0] *
                                              t.tracer_image.shape[1] // 100))]
            img = t.tracer_image.copy()
            img[pick[:, 0], pick[:, 1]] *= 1.3
            for scale in (1, 1024):
                s = nz.scaled(scale)
                v, _ = judge("z-test", image_metrics(img, t.ref.image, with_flip=False), img,
                             t.ref.image, s)
                hit = not v.checks["z_fraction_passed"]["pass"]
                if scale == 1:
                    local += hit
                else:
                    local_big += hit
        z = np.array(tiles)
        print(f"{name} ({size[0]}x{size[1]}, 64 spp, {args.seeds} seeds; 1024 reference "
              f"samples per pixel)")
        print("  fails: " + ", ".join(f"{k} {v}/{args.seeds}" for k, v in fails.items()))
        print(f"  tiles: mean Z^2 {np.mean(z * z):.3f}, mean Z {np.mean(z):+.3f} over {len(z)}")
        for region in power:
            print(f"  1 % over {region}: caught {power[region]}/{args.seeds}, with variance "
                  f"x1024 {power_big[region]}/{args.seeds}; detectable bias (median) "
                  f"{100 * np.median(detect.get(region, [np.nan])):.3f} %")
        print(f"  +30 % on 1 % of the random pixels: per-pixel rule fails {local}/{args.seeds},"
              f" with variance x1024 {local_big}/{args.seeds}")


if __name__ == "__main__":
    main()
