"""Print the false-alarm rates and powers of ``whitted check``, measured on seeds.

    python docs/check_figures.py [--seeds 16] [--size 96x72] [SCENE ...]

A correct image from another renderer: Mitsuba 3's own ``path`` integrator on
the converted scene, 64 samples per pixel jittered in their strata, one seed
per trial. Default scenes: ``sphere_point``, ``three_lights`` and
``spot_floor`` (direct light, max_depth 2, where ``path`` computes Whitted's
image) and ``tests/data/glass_before_lights.toml`` (glass and a mirror before
emitting panels, nothing diffuse, where it does too, with one lobe per sample
at the glass). Each render is judged as it is (float) and as an 8-bit sRGB
PNG would store it, with the noise estimated locally (no variance, no
``--spp``), and with ``--spp 64`` (Mitsuba's path tracer's per-sample
variance / 64). Printed per scene and way:

* false alarms: trials failed by the per-pixel rule, by the region rule, and
  in all; the mean and largest fraction of pixels beyond the threshold (0.25 %
  allowed) and the largest region |Z| (against its Sidak level);
* power: trials failed when each render is made 0.5 %, 1 % and 2 % brighter
  (a bias over the whole image), when the first material's pixels are made
  2 % brighter, and when +30 % is put on 1 % of the pixels (a local error);
  and the median smallest bias the whole image's sum sees with 90 % power.
"""

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)

GLASS = ROOT / "tests" / "data" / "glass_before_lights.toml"


def main() -> None:
    import numpy as np

    from whitted.reference import mitsuba
    from whitted.reference.check.images import UserImage, code_steps, decode
    from whitted.reference.check.judge import judge_image, path_variance, tracer_reference
    from whitted.reference.renderers.mitsuba.scene import load
    from whitted.tracer import load_scene
    from whitted.tracer.imageio import to_srgb8
    from whitted.tracer.integrator import material_ids

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*",
                    default=["sphere_point", "three_lights", "spot_floor", str(GLASS)])
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--size", default="96x72")
    args = ap.parse_args()
    size = tuple(int(x) for x in args.size.split("x"))
    mi = mitsuba()

    def as_png(img):
        codes = to_srgb8(img).astype(np.int64)
        return UserImage("<png>", "png", "8-bit srgb", decode(codes, 255, "srgb"),
                         code_steps(codes, 255, "srgb"), clip=1.0, saturated=codes >= 255,
                         encoding="srgb")

    def as_float(img):
        return UserImage("<exr>", "exr", "float32", img)

    print(f"Mitsuba path, 64 spp jittered, {args.size}, {args.seeds} seeds per scene")
    for name in args.scenes:
        path = Path(name) if name.endswith(".toml") else ROOT / "scenes" / f"{name}.toml"
        scene = load_scene(path).with_overrides(size=size, spp=64)
        ref = tracer_reference(scene)
        ids, names = material_ids(scene), list(scene.materials)
        first = ids == np.unique(ids[ids >= 0])[0]
        model = path_variance(scene) / 64
        ms = load(scene, mi, "path", jitter=True)
        rng = np.random.default_rng(0)
        ways = {"float, local": (as_float, None), "8-bit sRGB, local": (as_png, None),
                "float, --spp 64": (as_float, model)}
        stats = {w: {"pixels": 0, "regions": 0, "any": 0, "frac": [], "z": [], "detect": [],
                     "power": {}} for w in ways}
        biases = {"+0.5 % image": lambda x: x * 1.005, "+1 % image": lambda x: x * 1.01,
                  "+2 % image": lambda x: x * 1.02,
                  "+2 % first material": lambda x, m=first: np.where(m[..., None], x * 1.02, x)}
        for k in range(args.seeds):
            img = np.asarray(mi.render(ms, seed=1000 + k, spp=64), dtype=np.float64)[..., :3]
            local = rng.random(img.shape[:2]) < 0.01
            injected = dict(biases)
            injected["+30 % on 1 % of pixels"] = lambda x, m=local: np.where(m[..., None],
                                                                              x * 1.3, x)
            for way, (wrap, mv) in ways.items():
                s = stats[way]
                r = judge_image(wrap(img), ref, ids, names, mv)
                s["pixels"] += not r.pixels["passed"]
                s["regions"] += not r.regions["passed"]
                s["any"] += not r.passed
                s["frac"].append(r.pixels["fraction"])
                s["z"].append(r.regions["max_abs_z"])
                limit = r.regions["limit"]
                whole = next(g for g in r.regions["regions"] if g["name"] == "image")
                s["detect"].append(whole["detectable_bias"])
                for label, f in injected.items():
                    rb = judge_image(wrap(f(img)), ref, ids, names, mv)
                    s["power"][label] = s["power"].get(label, 0) + (not rb.passed)
        print(f"\n{scene.name} (region |Z| limit {limit:.2f})")
        for way, s in stats.items():
            n = args.seeds
            print(f"  {way:<18} false alarms {s['any']}/{n} (pixels {s['pixels']}, regions "
                  f"{s['regions']}); pixels beyond threshold mean "
                  f"{100 * np.mean(s['frac']):.3f} %, max {100 * max(s['frac']):.3f} %; "
                  f"largest region |Z| {max(s['z']):.2f}")
            print(f"  {'':<18} power: " + ", ".join(f"{lab} {c}/{n}"
                                                      for lab, c in s["power"].items())
                  + f"; detectable bias over the image {100 * np.median(s['detect']):.2f} %")


if __name__ == "__main__":
    main()
