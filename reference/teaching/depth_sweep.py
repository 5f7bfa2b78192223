"""The first assignment's study: runtime against recursion depth, with the rays behind it.

DEPTH is Heckbert's: his ``trace(DEPTH, ...)`` with DEPTH 1 shades the first
hit only, so DEPTH n is ``max_depth`` n + 1 in Mitsuba's counting of path
segments. For every DEPTH the tracer renders the scene ``repeat`` times after a
warm-up (kernels compiled) and the median is kept, with the rays it traced:
camera and specular rays per recursion level, and shadow rays. Mitsuba's
Whitted reference is timed at the same depths alongside.

Whether runtime "deteriorates" with depth follows from the rays: each level
costs about as much as the rays it traces, and a level has only as many rays
as the previous level had specular hits (two at glass, one at a mirror,
none at a diffuse surface or in empty space). :func:`explain` states what the
measured numbers say.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from pathlib import Path

from whitted.tracer.errors import UserError

#: Deepest DEPTH a sweep renders (max_depth = DEPTH + 1).
MAX_SWEEP_DEPTH = 200


def parse_depths(text: str) -> list[int]:
    """``"1-5,10,20,25"`` -> [1, 2, 3, 4, 5, 10, 20, 25] (Heckbert's DEPTH, 1 to 200).

    Bounds are checked before a range is expanded, so ``1-300000000`` is
    refused at once rather than built.
    """
    out: set[int] = set()
    shown = text if len(text) <= 60 else text[:60] + "..."
    for part in text.split(","):
        part = part.strip()
        try:
            a, b = (int(x) for x in part.split("-", 1)) if "-" in part[1:] else (int(part),) * 2
            if a > b:
                raise ValueError
        except ValueError:
            raise UserError(f"--depths: expected numbers and ranges like 1-5,10,20, got "
                            f"{shown!r}") from None
        if a < 1 or b > MAX_SWEEP_DEPTH:
            raise UserError(f"--depths: expected depths from 1 to {MAX_SWEEP_DEPTH}, got "
                            f"{shown!r}")
        out.update(range(a, b + 1))
    return sorted(out)


@dataclass
class DepthRow:
    depth: int                    # Heckbert's DEPTH
    max_depth: int
    seconds: float                # median of the tracer's timed renders
    rays_total: int               # camera + specular + shadow rays
    rays_per_level: list[int]     # camera and specular rays per recursion level
    significant_per_level: list[int]  # of those, rays with a weight above 1e-3
    shadow_rays: int
    mitsuba_seconds: float | None
    image_file: str


def depth_sweep(scene, depths: list[int], repeat: int, outdir: Path, mitsuba: bool = True,
                log=print, min_weight: float = 0.0, seed: int = 0) -> list[DepthRow]:
    from whitted.reference.renderers.mitsuba.render import render_reference
    from whitted.tracer.imageio import write_png
    from whitted.tracer.integrator import Integrator

    outdir.mkdir(parents=True, exist_ok=True)
    rows = []
    for depth in depths:
        s = scene.with_overrides(max_depth=depth + 1)
        integ = Integrator(s, seed=seed, min_weight=min_weight)
        integ.render()  # warm-up
        times, result = [], None
        for _ in range(repeat):
            t0 = time.perf_counter()
            result = integ.render()
            times.append(time.perf_counter() - t0)
        name = f"depth_{depth:02d}.png"
        write_png(outdir / name, result.image)
        m_sec = None
        if mitsuba:
            ref = render_reference(s, seed=seed, passes=repeat + 1)  # median of warm passes
            m_sec = ref.seconds
            write_png(outdir / f"depth_{depth:02d}_mitsuba.png", ref.image)
        row = DepthRow(depth, depth + 1, statistics.median(times), result.rays_total,
                       result.rays_per_level, result.significant_rays_per_level,
                       sum(result.shadow_rays_per_level), m_sec, name)
        rows.append(row)
        log(f"DEPTH {depth:3d} (max_depth {depth + 1:3d}): {row.seconds:8.4f} s, "
            f"{row.rays_total:>11,} rays" +
            (f", Mitsuba {m_sec:8.4f} s" if m_sec is not None else ""))
    return rows


def explain(rows: list[DepthRow]) -> str:
    """What the measurements say about runtime against depth, in a few sentences."""
    first, last = rows[0], rows[-1]
    growth = last.seconds / first.seconds if first.seconds else float("inf")
    levels = last.rays_per_level
    camera = levels[0] if levels else 0
    active = [i + 1 for i, n in enumerate(levels) if n > 0]
    deepest = active[-1] if active else 0
    # The level after which fewer than 1 % of the camera rays remain.
    fade = next((i + 1 for i, n in enumerate(levels) if camera and n < 0.01 * camera), None)
    lines = [
        f"Runtime grows from {first.seconds:.4f} s at DEPTH {first.depth} to "
        f"{last.seconds:.4f} s at DEPTH {last.depth} ({growth:.2f}x), while the rays traced "
        f"grow from {first.rays_total:,} to {last.rays_total:,} "
        f"({last.rays_total / max(first.rays_total, 1):.2f}x): the cost follows the rays.",
    ]
    if fade is not None and fade < len(levels):
        lines.append(
            f"Rays die out with depth: by level {fade} fewer than 1 % of the camera rays "
            f"remain (they escape the scene, end on diffuse surfaces, or carry zero weight), "
            f"so beyond DEPTH {max(fade - 1, 1)} more recursion adds almost no work and "
            f"runtime levels off: it does not deteriorate.")
    else:
        per_level = [n for n in levels[1:] if n > 0]
        lines.append(
            f"Rays survive to level {deepest} ({per_level[-1] if per_level else 0:,} at the "
            f"deepest): specular paths trapped between glass or mirrors keep spawning rays, "
            f"so runtime keeps growing about linearly with DEPTH (not as 2^DEPTH: each "
            f"level holds only the rays that survived, and zero-weight branches are dropped).")
        sig = last.significant_per_level
        gone = next((i + 1 for i, n in enumerate(sig) if camera and n < 0.01 * camera), None)
        if gone is not None and gone < len(sig):
            lines.append(
                f"But their weights fade: from level {gone} on fewer than 1 % of the camera "
                f"rays' worth carry more than 1e-3 of their camera ray's weight (rays bouncing "
                f"inside glass lose a factor R at every internal reflection), so beyond "
                f"DEPTH {max(gone - 1, 1)} the picture no longer changes visibly while the "
                f"runtime still grows; a Whitted tracer that stops at such weights "
                f"(--min-weight) levels off.")
    return " ".join(lines)


def write_outputs(rows: list[DepthRow], outdir: Path, scene_name: str) -> list[Path]:
    txt = outdir / "runtimes.txt"
    lines = [f"# whitted depth-sweep of {scene_name}",
             "# depth: Heckbert's DEPTH (max_depth = DEPTH + 1); median_s: median of the "
             "tracer's timed renders",
             "# rays_total: camera + specular + shadow rays; rays_per_level: camera and "
             "specular rays at recursion levels 1, 2, ...",
             "# weighty_per_level: of those, rays whose weight exceeds 1e-3",
             "# mitsuba_s: Mitsuba's Whitted reference, median of warm passes, same size and spp",
             f"{'depth':>5} {'median_s':>10} {'rays_total':>12} {'mitsuba_s':>10}  "
             "rays_per_level  weighty_per_level"]
    for r in rows:
        m = "nan" if r.mitsuba_seconds is None else f"{r.mitsuba_seconds:.5f}"
        lines.append(f"{r.depth:>5} {r.seconds:>10.5f} {r.rays_total:>12} {m:>10}  "
                     + ",".join(str(n) for n in r.rays_per_level) + "  "
                     + ",".join(str(n) for n in r.significant_per_level))
    lines.append("# " + explain(rows))
    txt.write_text("\n".join(lines) + "\n")
    png = outdir / "runtimes.png"
    plot(rows, png, scene_name)
    return [txt, png]


def plot(rows: list[DepthRow], path: Path, scene_name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = [r.depth for r in rows]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), dpi=100)
    ax.plot(d, [r.seconds for r in rows], "o-", label="tracer (median)")
    if rows[0].mitsuba_seconds is not None:
        ax.plot(d, [r.mitsuba_seconds for r in rows], "s--", label="Mitsuba Whitted reference")
    ax.set_xlabel("DEPTH (Heckbert's; max_depth = DEPTH + 1)")
    ax.set_ylabel("seconds per render")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax3 = ax.twinx()
    ax3.plot(d, [r.rays_total / 1e6 for r in rows], "^:", color="tab:green",
             label="rays traced (right axis)")
    ax3.set_ylabel("million rays traced")
    ax3.set_ylim(bottom=0)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax3.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper left")
    ax.set_title(f"{scene_name}: runtime and rays against DEPTH", fontsize=10)
    deepest = rows[-1]
    ax2.semilogy(range(1, len(deepest.rays_per_level) + 1),
                 [max(n, 0.5) for n in deepest.rays_per_level], "o-", label="all rays")
    ax2.semilogy(range(1, len(deepest.significant_per_level) + 1),
                 [max(n, 0.5) for n in deepest.significant_per_level], "s--",
                 label="rays with weight > 1e-3")
    ax2.legend(fontsize=8)
    ax2.set_xlabel("recursion level (1 = camera rays)")
    ax2.set_ylabel("rays at this level")
    ax2.set_title(f"rays per level at DEPTH {deepest.depth}", fontsize=10)
    ax2.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
