"""The first lecture's assignment, in one run: what it asks for, under its file names.

The assignment (lecture 1, "Assignment #1") runs Heckbert's business-card ray
tracer at DEPTH 1 to 5 and at 20 or more, asks what changes visually and
whether the runtime deteriorates with DEPTH, wants the runtimes as
``heckbert_runtimes1.txt`` and a plot ``heckbert_runtimes1.png``, the light
paths LE, LDE, LSE, LDDE, LDSE and LSDE drawn onto the picture
(``light_paths.png``) and the observations written down. :func:`run` does all
of it with the tracer on ``scenes/heckbert_minray.toml``, the classic model
that prints minray's own numbers:

* ``heckbert_depth1.png`` ... ``heckbert_depth5.png`` and
  ``heckbert_depthNN.png`` (NN = the deepest DEPTH, 20 by default): the
  images as minray's PPM holds them (255 x linear colour, no gamma), saved
  as PNG without changing a number (the assignment: "convert them from
  uncompressed ppm to png");
* ``heckbert_runtimes1.txt`` / ``.png``: the tracer's time per DEPTH (median
  of ``repeat`` warm renders), the rays it traced, and the rays minray traces
  for the same image, counted exactly (:func:`reference.teaching.minray.ray_count`):
  minray follows both branches at every hit, so its count grows
  exponentially with DEPTH, while the tracer drops branches of weight zero;
* ``light_paths.png``: the DEPTH 5 picture with the ray trees of pixels
  that show LE, LDE, LSE and LDSE (:mod:`reference.teaching.paths`), one LDDE and one
  LSDE path found by sampling (:func:`reference.teaching.paths.example_paths`), marked
  as paths no Whitted tracer makes, and beside it where Mitsuba's path
  tracer finds them in the physically based version of the scene
  (``heckbert_physical``: path tracer minus Whitted, 3 segments each);
* ``observations.md``: the answers in plain words, written from this run's
  numbers.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: The DEPTHs whose pictures the assignment asks for, and the runtime sweep's default.
PICTURE_DEPTHS = (1, 2, 3, 4, 5)
SWEEP_DEPTHS = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 15, 20)


@dataclass
class SweepRow:
    depth: int
    seconds: float            # median of the timed renders
    rays: list[int]           # the tracer: camera and secondary rays per level
    shadow: int               # the tracer: shadow rays
    minray_trace: int         # minray: rays its trace routine intersects
    minray_shadow: int        # minray: shadow rays

    @property
    def rays_total(self) -> int:
        return sum(self.rays) + self.shadow

    @property
    def minray_total(self) -> int:
        return self.minray_trace + self.minray_shadow


@dataclass
class Result:
    outdir: Path
    size: int
    files: list[Path] = field(default_factory=list)
    sweep: list[SweepRow] = field(default_factory=list)
    pictures: dict[int, np.ndarray] = field(default_factory=dict)   # DEPTH -> PPM numbers
    count: object = None          # minray's RayCount at the deepest DEPTH
    glass: np.ndarray | None = None  # pixels whose camera ray hits a transparent sphere
    repeat: int = 3
    seconds: float = 0.0


def scene_at(size: int, depth: int | None = None):
    """heckbert_minray at size x size (and DEPTH)."""
    from whitted.scenes import SCENES_DIR
    from whitted.tracer import load_scene

    s = load_scene(SCENES_DIR / "heckbert_minray.toml").with_overrides(size=(size, size))
    return s if depth is None else s.with_overrides(max_depth=depth + 1)


def run(outdir: Path, size: int = 256, sweep: tuple[int, ...] = SWEEP_DEPTHS, repeat: int = 3,
        mitsuba: bool = True, log=print) -> Result:
    """Write the assignment's files into ``outdir`` (see the module docstring)."""
    from whitted.reference.teaching.minray import ray_count
    from whitted.tracer.imageio import ppm_values
    from whitted.tracer.integrator import Integrator

    start = time.perf_counter()
    outdir.mkdir(parents=True, exist_ok=True)
    res = Result(outdir, size, repeat=repeat)
    deepest = max(sweep)
    depths = sorted(set(sweep) | set(PICTURE_DEPTHS))
    log(f"minray's rays for {size}x{size} up to DEPTH {deepest}, counted exactly ...")
    t0 = time.perf_counter()
    count = ray_count(scene_at(size), deepest, chunk=2048)
    res.count = count
    res.glass = transparent_pixels(scene_at(size))
    log(f"  {count.total:,} rays at DEPTH {deepest} ({time.perf_counter() - t0:.1f} s)")
    for depth in depths:
        integ = Integrator(scene_at(size, depth))
        result = integ.render()          # the first render compiles the kernels
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            result = integ.render()
            times.append(time.perf_counter() - t0)
        values = ppm_values(result.image)
        res.pictures[depth] = values
        if depth in PICTURE_DEPTHS or depth == deepest:
            res.files.append(_save_picture(outdir / f"heckbert_depth{depth}.png", values))
        if depth in sweep:
            c = count.at_depth(depth)
            row = SweepRow(depth, statistics.median(times), list(result.rays_per_level),
                           sum(result.shadow_rays_per_level), sum(c.trace), sum(c.shadow))
            res.sweep.append(row)
            log(f"DEPTH {depth:3d}: {row.seconds:7.3f} s, {row.rays_total:>11,} rays traced; "
                f"minray traces {row.minray_total:>13,}")
    res.files += write_runtimes(res.sweep, outdir, size)
    log("light paths: ray trees, LDDE and LSDE examples"
        + (", Mitsuba's path tracer" if mitsuba else "") + " ...")
    res.files.append(light_paths(outdir / "light_paths.png", size, res.pictures[5], mitsuba))
    res.files.append(write_observations(res, outdir / "observations.md"))
    res.seconds = time.perf_counter() - start
    return res


def transparent_pixels(scene) -> np.ndarray:
    """H x W mask of the pixels whose camera ray first hits a transparent (kt > 0) surface."""
    from whitted.tracer.camera import generate_rays
    from whitted.tracer.geometry import Geometry
    from whitted.tracer.sampling import pixel_samples

    W, H = scene.film.width, scene.film.height
    geo = Geometry(scene)
    _, _, fx, fy = pixel_samples(W, 1, 0, W * H)
    o, d, tmax = generate_rays(scene.camera, W, H, fx, fy)
    hit = geo.closest_hit(o, d, tmax)
    mid = np.asarray(geo.material_id.numpy())
    prim = np.asarray(hit.prim)
    mats = list(scene.materials.values())
    clear = np.array([getattr(m, "kt", 0) > 0 for m in mats] + [False])
    valid = prim != 0xFFFFFFFF
    out = np.zeros(W * H, bool)
    out[valid] = clear[np.minimum(mid[prim[valid]], len(mats))]
    return out.reshape(H, W)


def _save_picture(path: Path, values: np.ndarray) -> Path:
    """An 8-bit PNG holding a PPM's numbers unchanged (values above 255 cannot be kept)."""
    from whitted.tracer.imageio import write_png

    write_png(path, np.clip(values, 0, 255).astype(np.uint8))
    return path


# ------------------------------------------------------------------ runtimes


def write_runtimes(rows: list[SweepRow], outdir: Path, size: int) -> list[Path]:
    txt = outdir / "heckbert_runtimes1.txt"
    lines = [
        f"# Heckbert's business-card scene (heckbert_minray), {size}x{size}, one ray per pixel",
        "# depth: Heckbert's DEPTH (trace calls); seconds: median of the tracer's timed renders",
        "# rays: rays the tracer traced (camera + reflected/refracted + shadow)",
        "# minray_rays: rays minray traces for the same image (both branches at every hit),",
        "#   counted exactly by reference.teaching.minray.ray_count; ratio = minray_rays / rays",
        "# rays_per_level: the tracer's camera and reflected/refracted rays at levels 1, 2, ...",
        f"{'depth':>5} {'seconds':>9} {'rays':>12} {'minray_rays':>13} {'ratio':>8}  "
        "rays_per_level",
    ]
    for r in rows:
        lines.append(f"{r.depth:>5} {r.seconds:>9.4f} {r.rays_total:>12} {r.minray_total:>13} "
                     f"{r.minray_total / r.rays_total:>8.2f}  " + ",".join(map(str, r.rays)))
    txt.write_text("\n".join(lines) + "\n")
    png = outdir / "heckbert_runtimes1.png"
    _plot_runtimes(rows, png, size)
    return [txt, png]


def _plot_runtimes(rows: list[SweepRow], path: Path, size: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = [r.depth for r in rows]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), dpi=100)
    ax.plot(d, [r.seconds for r in rows], "o-", label="tracer: seconds per render")
    ax.set_xlabel("DEPTH (Heckbert's: trace calls)")
    ax.set_ylabel("seconds (median of warm renders)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax3 = ax.twinx()
    ax3.plot(d, [r.rays_total / 1e6 for r in rows], "^:", color="tab:green",
             label="tracer: rays traced (right axis)")
    ax3.set_ylabel("million rays traced by the tracer")
    ax3.set_ylim(bottom=0)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax3.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper left")
    ax.set_title(f"heckbert_minray {size}x{size}: runtime against DEPTH", fontsize=10)
    ax2.semilogy(d, [r.rays_total for r in rows], "o-", label="tracer (drops zero-weight branches)")
    ax2.semilogy(d, [r.minray_total for r in rows], "s--",
                 label="minray (both branches at every hit), counted")
    ax2.set_xlabel("DEPTH")
    ax2.set_ylabel("rays traced (camera, secondary, shadow)")
    ax2.set_title("rays traced: linear for the tracer, exponential for minray", fontsize=10)
    ax2.grid(alpha=0.3, which="both")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# ------------------------------------------------------------------ light paths


def light_paths(path: Path, size: int, picture: np.ndarray, mitsuba: bool) -> Path:
    """The DEPTH 5 picture with LE, LDE, LSE, LDSE trees and LDDE, LSDE examples (module doc)."""
    from whitted.reference.teaching.paths import (
        WANTED,
        draw,
        example_paths,
        ldde_lsde_panel,
        pick_pixels,
        ray_trees,
    )
    from whitted.scenes import SCENES_DIR
    from whitted.tracer import load_scene

    scene = scene_at(size, 5)
    picked = pick_pixels(scene, spread=max(2, size // 12))
    notes = []
    for expr in WANTED:
        p = picked[expr]
        notes.append(f"{expr}: " + (f"pixel {p[0]},{p[1]}." if p else "no pixel shows it."))
    trees = ray_trees(scene, sorted({p for p in picked.values() if p is not None}))
    missing = [t for t in example_paths(scene).values() if t is not None]
    for t in missing:
        notes.append(f"{t.paths[0]}: pixel {t.pixel[0]},{t.pixel[1]}, found by sampling "
                     "directions from the diffuse point; no Whitted tracer makes it.")
    panel = None
    if mitsuba:
        physical = load_scene(SCENES_DIR / "heckbert_physical.toml").with_overrides(
            size=(size, size))
        panel = ldde_lsde_panel(physical)
        panel = (panel[0], panel[1].replace("LDDE + LSDE:", "LDDE + LSDE in heckbert_physical:"))
    draw(scene, picture / 255.0, trees, str(path), notes, panel, missing,
         shown=np.clip(picture, 0, 255).astype(np.uint8))
    return path


# ------------------------------------------------------------------ observations


def _changes(a: np.ndarray, b: np.ndarray, where: np.ndarray | None = None):
    """(% of values that differ by more than one step, largest difference, % of those
    values that lie in ``where``)."""
    d = np.abs(a.astype(np.int64) - b)
    moved = d > 1
    inside = (100.0 * float(moved[where].sum()) / max(int(moved.sum()), 1)
              if where is not None else float("nan"))
    return 100.0 * float(moved.mean()), int(d.max()), inside


def write_observations(res: Result, path: Path) -> Path:
    """observations.md: the assignment's questions answered from this run's numbers."""
    pics, rows = res.pictures, res.sweep
    deepest = max(pics)
    glass = None if res.glass is None else np.repeat(res.glass[..., None], 3, axis=-1)
    mean = {d: float(v.mean()) for d, v in pics.items()}
    step = {d: _changes(pics[d], pics[d + 1], glass) for d in range(1, 5)}
    later = [d for d in sorted(pics) if d > 5]
    tail = []
    prev = 5
    for d in later:
        if d in (10, deepest) or d == later[-1]:
            tail.append((prev, d, *_changes(pics[prev], pics[d], glass)))
            prev = d
    first, last = rows[0], rows[-1]
    by_depth = {r.depth: r for r in rows}
    r5 = by_depth.get(5, rows[min(4, len(rows) - 1)])
    c = res.count
    per_level = [b / a for a, b in zip(c.trace, c.trace[1:], strict=False)] if c else []
    level = last.rays[1:] if len(last.rays) > 1 else last.rays
    converged = next((f"from DEPTH {a} to {b} no value changes by more than one step"
                      for a, b, pct, _, _ in tail if pct == 0), None)
    lines = [
        "# Observations: Heckbert's business-card ray tracer",
        "",
        "Rendered by `whitted assignment` with the classic illumination model that prints "
        f"minray's own numbers (`scenes/heckbert_minray.toml`), {res.size}x{res.size} pixels, "
        "one ray through each pixel's corner. Every number below was measured in this run.",
        "",
        "## What changes from DEPTH 1 to 5, and why",
        "",
        "DEPTH counts the calls of the trace routine. DEPTH 1 shades only the points that "
        "the camera rays hit: the ambient term, the direct light of the two light spheres "
        "behind the camera (with shadows) and the orange sphere's faint glow. Each further "
        "DEPTH lets the reflected and refracted rays of the previous level be traced and "
        "shaded as well.",
        "",
        f"* DEPTH 1 (mean value {mean[1]:.1f} of 255): matt spheres. The cyan sphere and the "
        "glass sphere show only their diffuse parts (kd 0.3 and 0.05): their reflected and "
        "refracted rays are not traced yet, so the glass sphere is almost black.",
        f"* DEPTH 2 (mean {mean[2]:.1f}; {step[1][0]:.1f} % of the values change by more "
        f"than one step, at most by {step[1][1]}): reflections appear: highlights on the "
        "orange and cyan spheres (the light spheres, mirrored), the orange sphere in the "
        "cyan one, and the two light spheres as pale discs on the glass. The refracted "
        "rays only reach the far inside wall of the glass, which is dark, so the glass is "
        "not yet transparent.",
        f"* DEPTH 3 (mean {mean[3]:.1f}; {step[2][0]:.1f} % change, at most {step[2][1]}): "
        "the glass becomes transparent. A ray needs three calls to get through it (into "
        "the sphere, across, out into the scene), so only now do the orange and cyan "
        "spheres behind it show through it, upside down, as through a lens.",
        f"* DEPTH 4 (mean {mean[4]:.1f}; {step[3][0]:.1f} % change, at most {step[3][1]}, "
        f"{step[3][2]:.0f} % of them on the glass sphere) and DEPTH 5 (mean {mean[5]:.1f}; "
        f"{step[4][0]:.1f} % change, at most {step[4][1]}, {step[4][2]:.0f} % on the glass): "
        "ever smaller corrections, mostly light that was reflected once more inside the "
        "glass before leaving it, and what is seen through it after further bounces. Each "
        "extra bounce is weighted by another ks or kt (0.2 to 0.85), and rays that leave "
        "the scene bring back only the dim ambient colour, so the changes shrink with "
        "every level.",
    ]
    for a, b, pct, mx, inside in tail:
        lines.append(f"* DEPTH {a} to {b}: {pct:.2f} % of the values change by more than one "
                     f"step (at most by {mx})" + (f", {inside:.0f} % of them on the glass "
                                                  "sphere." if pct > 0 else "."))
    lines += [
        "",
        "So the picture converges: " + (converged + "." if converged else
                                         "the changes shrink with every DEPTH.") +
        " What DEPTH adds after 3 is mostly light that bounced around inside the glass "
        "sphere, seen directly or reflected in the other spheres.",
        "",
        "## Does the runtime deteriorate with DEPTH, and why",
        "",
        f"The tracer took {first.seconds:.3f} s at DEPTH {first.depth} and {last.seconds:.3f} s "
        f"at DEPTH {last.depth} (median of {res.repeat} warm renders each, on a shared "
        "machine: read the trend, not the digits). It traced "
        f"{first.rays_total:,} rays at DEPTH {first.depth}, {r5.rays_total:,} at DEPTH "
        f"{r5.depth} and {last.rays_total:,} at DEPTH {last.depth}: every extra DEPTH adds "
        f"about the same number of rays ({min(level):,} to {max(level):,} per level), so the "
        "runtime grows linearly with DEPTH; it does not deteriorate. The tracer follows a "
        "reflected or refracted ray only where its weight is not zero: the opaque spheres "
        "have kt = 0 and the light spheres neither ks nor kt, so most rays end after one or "
        "two bounces, and only rays caught inside the glass sphere keep bouncing.",
        "",
        "minray itself does deteriorate. It calls trace for the reflected ray at every hit "
        "and for the refracted ray wherever Snell's law has a solution, whatever ks and kt "
        "are, so rays refracted into the opaque spheres and the lights keep bouncing inside "
        f"them too. For the same image it traces {first.minray_total:,} rays at DEPTH "
        f"{first.depth}, {r5.minray_total:,} at DEPTH {r5.depth} and "
        f"{last.minray_total:,} at DEPTH {last.depth}, "
        f"{last.minray_total / last.rays_total:.0f} times the tracer's"
        + (f"; from level {len(c.trace) - 1} to {len(c.trace)} its rays per level grow by a "
           f"factor of {per_level[-1]:.2f}" if per_level else "")
        + ". That is exponential growth (a full binary tree of rays would double per level; "
        "rays that leave the scene stop), and minray's runtime follows its rays: raising "
        "DEPTH from 10 to 20 multiplies its work "
        + (f"by {by_depth[20].minray_total / by_depth[10].minray_total:.0f} "
           if 10 in by_depth and 20 in by_depth else "many times ")
        + "while the picture no longer changes.",
        "",
        "## Files",
        "",
        "`heckbert_depth1.png` ... `heckbert_depth5.png` and "
        f"`heckbert_depth{deepest}.png` (the PPM numbers, 255 x linear colour, saved as PNG "
        "unchanged), `heckbert_runtimes1.txt` and `heckbert_runtimes1.png` (runtime and rays "
        "against DEPTH, minray's rays beside the tracer's), `light_paths.png` (LE, LDE, LSE "
        "and LDSE on the DEPTH 5 picture; LDDE and LSDE dash-dotted: paths only a path "
        "tracer makes, and where Mitsuba's path tracer finds them).",
        "",
    ]
    path.write_text("\n".join(lines))
    return path
