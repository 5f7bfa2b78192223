"""Make docs/compare_<scene>.png (tracer | Mitsuba | relative difference) for the README.

    python docs/make_figure.py [SCENE]      # default: glass_sphere
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from whitted import tracer  # noqa: E402,F401  (chooses libLLVM before drjit loads)


def main() -> None:
    from PIL import Image, ImageDraw

    from whitted.reference.verdicts.compare import compare_scene
    from whitted.tracer import load_scene
    from whitted.tracer.imageio import to_srgb8

    name = sys.argv[1] if len(sys.argv) > 1 else "glass_sphere"
    scene = load_scene(ROOT / "scenes" / f"{name}.toml")
    work = ROOT / "out" / "figure" / name
    result, tracer_img, ref_img = compare_scene(scene, work)
    scale = 2
    tiles = [Image.fromarray(to_srgb8(x)).resize((x.shape[1] * scale, x.shape[0] * scale),
                                                 Image.NEAREST) for x in (tracer_img, ref_img)]
    diff = Image.open(work / "diff.png").convert("RGB")
    h = tiles[0].height
    diff = diff.resize((round(diff.width * h / diff.height), h), Image.LANCZOS)
    pad, label = 8, 22
    canvas = Image.new("RGB", (sum(t.width for t in tiles) + diff.width + 4 * pad, h + label + pad),
                       "white")
    draw = ImageDraw.Draw(canvas)
    x = pad
    for img, text in zip(tiles + [diff], ["tracer (whitted)", "Mitsuba 3", "difference"],
                         strict=True):
        canvas.paste(img, (x, label))
        draw.text((x, 4), text, fill="black")
        x += img.width + pad
    out = ROOT / "docs" / f"compare_{name}.png"
    canvas.save(out)
    print(f"wrote {out} ({result.test}: {'pass' if result.passed else 'FAIL'})")


if __name__ == "__main__":
    main()
