"""What several commands do alike: read SCENE with its options, check an output
folder, refuse an overflowed image, print paths, show progress, choose the backend.

The built-in scenes' registry is :mod:`whitted.scenes`; SCENE may name one of them.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from whitted import scenes
from whitted.reference.commands.options import max_depth


def resolve_scene(name: str) -> Path:
    """A scene path, or a built-in scene's name (``sphere_point``: scenes/sphere_point.toml)."""
    return scenes.resolve(name)


def output_folder(path) -> Path:
    """An output folder that may exist already, but not as a file, and that can be written."""
    from whitted.tracer.imageio import check_output_folder

    return check_output_folder(path)


def load_scene_arg(args):
    """SCENE as given: a TOML scene, a built-in name, or Mitsuba XML (read without Mitsuba)."""
    from whitted.tracer.scene import load_any

    return load_any(resolve_scene(args.scene), getattr(args, "approximate", False),
                    warn=lambda line: print(f"warning: {line}", flush=True))


def load_with_options(args):
    """SCENE with ``--spp``, ``--max-depth`` (or ``--depth``) and ``--size`` applied."""
    scene = load_scene_arg(args)
    return scene.with_overrides(spp=args.spp, max_depth=max_depth(args), size=args.size)


def check_finite(image, what: str = "the render") -> None:
    """Refuse to write an image with infinite or NaN pixels (float32 overflowed)."""
    import numpy as np

    from whitted.tracer.errors import UserError

    bad = int(np.count_nonzero(~np.isfinite(image)))
    if bad:
        raise UserError(f"{what} overflowed float32 in {bad:,} pixel values (light this strong "
                        "exceeds 3.4e38 once it reaches a surface: scale intensities and "
                        "radiances down); nothing was written")


def shown(path) -> str:
    """A path as printed: bytes that are not UTF-8 escaped."""
    from whitted.tracer.errors import one_line

    return one_line(str(path), 300)


def note_spp(scene) -> None:
    """Say so when the samples per pixel are rounded up to a square."""
    n = scene.film.strata
    if n * n != scene.film.spp:
        # On stdout: stderr holds nothing but the one line of an error.
        print(f"note: spp {scene.film.spp} is not a square; using {n * n} "
              f"({n}x{n} strata), as Mitsuba's stratified sampler does", flush=True)


class Progress:
    """A one-line progress bar on stderr, shown only on a terminal."""

    def __init__(self, label: str, enabled: bool | None = None):
        self.label = label
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.start = time.perf_counter()

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled or total <= 0:
            return
        frac = done / total
        bar = "#" * int(30 * frac)
        sys.stderr.write(f"\r{self.label} [{bar:<30}] {100 * frac:5.1f}% "
                         f"{time.perf_counter() - self.start:6.1f}s")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()


def use_backend(args) -> str:
    """Start the Dr.Jit backend of ``--backend``; its name."""
    from whitted.tracer import backend

    return backend.use(args.backend)


def film_summary(scene) -> str:
    """The film as the commands print it: ``320x240, 16 spp, max_depth 6 (DEPTH 5)``."""
    f = scene.film
    return (f"{f.width}x{f.height}, {f.strata ** 2} spp, max_depth {f.max_depth} "
            f"(DEPTH {f.depth})")


_CHECK_LABELS = {"median_rel": "median rel. difference", "frac_over_5pct": "pixels beyond 5 %",
                 "frac_over_01pct": "pixels beyond 0.1 %",
                 "mean_rel_diff": "image means differ by",
                 "z_fraction_passed": "z-test pixels passing",
                 "block_median_rel": "4x4 blocks: median rel.",
                 "block_frac_over_5pct": "4x4 blocks beyond 5 %",
                 "region_max_z": "regions: largest |Z|"}
_PCT_CHECKS = ("frac_over_5pct", "frac_over_01pct", "z_fraction_passed", "block_frac_over_5pct")


def check_lines(checks: dict) -> list[str]:
    """A verdict's checks as the table compare and check print: value, limit, pass."""
    lines = [f"  {'check':<26}{'value':>12}  {'limit':>10}"]
    for k, ch in checks.items():
        rel = ">=" if k == "z_fraction_passed" else "<"
        pct = k in _PCT_CHECKS
        val = f"{100 * ch['value']:.3f} %" if pct else f"{ch['value']:.2e}"
        lim = f"{100 * ch['limit']:.2f} %" if pct else f"{ch['limit']:.0e}"
        if k == "region_max_z":
            val, lim = f"{ch['value']:.2f}", f"{ch['limit']:.2f}"
        lines.append(f"  {_CHECK_LABELS.get(k, k):<26}{val:>12}  {rel} {lim:>8}  "
                     f"{'pass' if ch['pass'] else 'FAIL'}")
        if k == "region_max_z" and ch.get("regions"):
            seen = [g for g in ch["regions"] if g["detectable_bias"] <= 0.01]
            worst = max(ch["regions"], key=lambda g: abs(g["z"]))
            lines.append(f"    {len(ch['regions'])} regions tested (largest |Z| in "
                         f"{worst['name']}); a 1 % bias is seen with 90 % power in "
                         f"{len(seen)} of them")
    return lines
