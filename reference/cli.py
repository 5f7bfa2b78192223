"""The ``whitted`` command: render with the tracer, render on Mitsuba, compare, export.

Every subcommand is a thin layer over a Python function; exit status 0 on
success (for ``compare``: within the scene's tolerance), 1 when a comparison
fails, 2 on bad input (scene, options, output path, missing libLLVM, a job
beyond the limits of tracer/limits.py) or when the operating system refuses a
file or standard output, always with one line on stderr, never a traceback.
Bad input is refused before any rendering; a job that fails later writes
nothing. ``whitted render`` never imports Mitsuba.
"""

from __future__ import annotations

import argparse
import io
import os
import sys
import time
from pathlib import Path

from whitted import scenes
from whitted.scenes import SCENES_DIR, builtin_scenes  # noqa: F401  (re-exported)

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2


# ---------------------------------------------------------------- helpers


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = text.lower().split("x")
        size = int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 320x240, got {text!r}") \
            from None
    if size[0] < 1 or size[1] < 1:
        raise argparse.ArgumentTypeError(f"expected a positive size, got {text!r}")
    if max(size) > 2 ** 32 - 1:  # no image side beyond 32-bit indices; not echoed whole later
        raise argparse.ArgumentTypeError(f"expected sides of at most 4,294,967,295 pixels, "
                                         f"got {text!r}")
    return size


def _positive(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


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


def load(args):
    scene = load_scene_arg(args)
    return scene.with_overrides(spp=args.spp, max_depth=_max_depth(args), size=args.size)


def _max_depth(args) -> int | None:
    """``--max-depth``, or ``--depth`` in Heckbert's numbering: max_depth = DEPTH + 1."""
    depth = getattr(args, "depth", None)
    if depth is None:
        return args.max_depth
    if args.max_depth is not None:
        from whitted.tracer.errors import UserError

        raise UserError("give either --depth (Heckbert's DEPTH) or --max-depth "
                        "(= DEPTH + 1), not both")
    return depth + 1


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


def _note_spp(scene) -> None:
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


def _backend(args) -> str:
    from whitted.tracer import backend

    return backend.use(args.backend)


def _describe(scene) -> str:
    f = scene.film
    return (f"{f.width}x{f.height}, {f.strata ** 2} spp, max_depth {f.max_depth} "
            f"(DEPTH {f.depth})")


# ---------------------------------------------------------------- subcommands


def cmd_render(args) -> int:
    from whitted.tracer.imageio import check_output_path, write_image

    out = check_output_path(args.output)
    if args.lpe is not None:
        from whitted.tracer.lpe import compile_lpe

        compile_lpe(args.lpe)  # refuse a bad expression before anything renders
    scene = load(args)
    from whitted.tracer.limits import check_render

    check_render(scene)
    _note_spp(scene)
    name = _backend(args)
    from whitted.tracer.integrator import Integrator

    if not args.min_weight >= 0:
        from whitted.tracer.errors import UserError

        raise UserError(f"--min-weight: expected a number >= 0, got {args.min_weight}")
    result = Integrator(scene, seed=args.seed, lpe=args.lpe, min_weight=args.min_weight).render(
        Progress(f"render {scene.name}"))
    check_finite(result.image)
    write_image(out, result.image)
    rays = ", ".join(str(r) for r in result.rays_per_level)
    only = f", only paths {shown(args.lpe)}" if args.lpe else ""
    print(f"wrote {shown(out)} ({_describe(scene)}, {name}{only}) in {result.seconds:.3f} s; "
          f"rays per level: {rays}; shadow rays: {sum(result.shadow_rays_per_level)}")
    return EXIT_OK


def cmd_reference(args) -> int:
    from whitted.tracer.imageio import check_output_path, write_image

    out = check_output_path(args.output)
    if args.renderer == "luxcore":
        return _reference_luxcore(args, out)
    scene = load(args)
    from whitted.tracer.limits import check_render

    check_render(scene, mitsuba=True)
    _note_spp(scene)
    name = _backend(args)
    from whitted.reference.renderers.mitsuba.render import render_reference

    result = render_reference(scene, args.integrator, seed=args.seed)
    check_finite(result.image, "Mitsuba's render")
    write_image(out, result.image)
    print(f"wrote {shown(out)} (Mitsuba, {args.integrator} integrator, {_describe(scene)}, "
          f"{name}) in {result.seconds:.3f} s")
    return EXIT_OK


def _reference_luxcore(args, out) -> int:
    """``whitted reference --renderer luxcore``: LuxCore's image, spp jittered samples a pixel."""
    from whitted.reference.renderers.luxcore import render as luxcore
    from whitted.tracer.errors import UserError
    from whitted.tracer.imageio import write_image

    luxcore.require()
    if args.integrator != "whitted":
        raise UserError("--integrator: Mitsuba's integrators only; LuxCore renders with its "
                        "path tracer at Whitted's depths (reference/renderers/luxcore/scene.py)")
    scene = load(args)
    from whitted.reference.renderers.luxcore.scene import describe

    describe(scene)  # refuse in one line before the child starts
    _note_spp(scene)
    s = scene.film.strata
    result = luxcore.render(scene, passes=1, seed=args.seed, subsamples=s,
                            progress=Progress(f"luxcore {scene.name}"))
    check_finite(result.image, "LuxCore's render")
    write_image(out, result.image)
    print(f"wrote {shown(out)} (LuxCore {luxcore.VERSION}, path tracer at Whitted's depths, "
          f"{scene.film.width}x{scene.film.height}, {s * s} jittered spp, max_depth "
          f"{scene.film.max_depth}) in {result.seconds:.3f} s")
    return EXIT_OK


_CHECK_LABELS = {"median_rel": "median rel. difference", "frac_over_5pct": "pixels beyond 5 %",
                 "frac_over_01pct": "pixels beyond 0.1 %",
                 "mean_rel_diff": "image means differ by",
                 "z_fraction_passed": "z-test pixels passing",
                 "block_median_rel": "4x4 blocks: median rel.",
                 "block_frac_over_5pct": "4x4 blocks beyond 5 %",
                 "region_max_z": "regions: largest |Z|"}
_PCT_CHECKS = ("frac_over_5pct", "frac_over_01pct", "z_fraction_passed", "block_frac_over_5pct")


def _check_lines(checks: dict) -> list[str]:
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


def format_comparison(c) -> str:
    m = c.metrics
    lines = [f"scene {c.scene}: {c.size[0]}x{c.size[1]}, {c.spp} spp, backend {c.backend}, "
             f"reference {c.reference} (integrator {c.integrator}), test {c.test}"]
    lines += _check_lines(c.checks)
    flip = "n/a" if m["flip"] is None else f"{m['flip']:.4f}"
    lines.append(f"  RMSE {m['rmse']:.3e}   mean rel. {m['mean_rel']:.2e}   "
                 f"99.9th pct. rel. {m['p999_rel']:.2e}   max rel. {m['max_rel']:.2e}   "
                 f"FLIP {flip}")
    s = c.seconds
    ratio = s.get("ratio_mitsuba_over_tracer")
    lines.append(f"  seconds: tracer {s['tracer']:.3f}, Mitsuba {s['mitsuba']:.3f}"
                 + (f" (Mitsuba / tracer = {ratio:.2f})" if ratio else ""))
    if c.second_opinion:
        so = c.second_opinion
        lines.append(f"second opinion: reference {so['reference']} (integrator "
                     f"{so['integrator']}, {so['reference_passes']} passes; tracer mean of "
                     f"{so['tracer_seeds']} seeds), test {so['test']}: "
                     f"{'pass' if so['passed'] else 'FAIL'}")
        lines += _check_lines(so["checks"])
    if getattr(c, "tracer_only_model", None):
        tm = c.tracer_only_model
        lines.append(f"tracer-only parts against the harness's model ({', '.join(tm['models'])}"
                     f", reference {tm['reference']}), test {tm['test']}: "
                     f"{'pass' if tm['passed'] else 'FAIL'}")
        lines += _check_lines(tm["checks"])
    if c.expected_deviation:
        e = c.expected_deviation
        lines.append(f"  expected deviation of the full render (tracer-only: "
                     f"{', '.join(c.tracer_only)}): median rel. {e['median_rel']:.2e}, pixels "
                     f"beyond 5 % {100 * e['frac_over_5pct']:.2f} %, means differ by "
                     f"{100 * e['mean_rel_diff']:.3f} %")
    lines.append(("PASS" if c.passed else "FAIL") + f" ({c.reason})")
    return "\n".join(lines)


def format_three_way(t) -> str:
    """A scene's three-way verdict (reference.renderers.luxcore.vote.ThreeWay) as text."""
    lines = [f"three renderers at {t.size[0]}x{t.size[1]}: {t.verdict}"
             + (f" ({t.detail})" if t.detail else "")]
    for name, p in t.pairs.items():
        w = p.get("worst") or {}
        where = (f"; largest region difference {w['region']} {100 * w['relative']:+.3f} % "
                 f"(|Z| {abs(w['z']):.1f})" if w else "")
        src = f" ({p['from']})" if p.get("from") else ""
        lines.append(f"  {name:<16} {'pass' if p['passed'] else 'FAIL'}{src}{where}")
        lines += ["  " + line for line in _check_lines(
            {k: v for k, v in p["checks"].items() if v.get("judged", True)})[1:]]
    return "\n".join(lines)


def _compare_luxcore(args, scene, main=None) -> int:
    """The three-way comparison of ``whitted compare --renderer luxcore|all``."""
    from whitted.reference.renderers.luxcore import render as luxcore
    from whitted.reference.renderers.luxcore.vote import compare_three
    from whitted.reference.verdicts.compare import write_json
    from whitted.tracer.errors import UserError

    luxcore.require()
    [t] = compare_three([scene], progress=Progress(f"luxcore {scene.name}"),
                        main=None if main is None else [{"passed": main.passed,
                                                         "checks": main.checks}])
    if not t.compared:
        raise UserError(f"{scene.name}: not compared with LuxCore: {t.detail}")
    outdir = output_folder(args.output or Path("out") / "compare" / scene.name)
    outdir.mkdir(parents=True, exist_ok=True)
    write_json(outdir / "luxcore.json", t.to_json())
    print(format_three_way(t))
    print(f"wrote {shown(outdir)}/luxcore.json")
    if main is None:   # --renderer luxcore: the tracer against LuxCore
        return EXIT_OK if t.pairs["tracer-luxcore"]["passed"] else EXIT_FAIL
    return EXIT_OK if main.passed else EXIT_FAIL


def cmd_compare(args) -> int:
    from whitted.reference.verdicts.compare import choose_test, comparable, compare_scene
    from whitted.tracer.errors import UserError
    from whitted.tracer.limits import check_render

    if args.renderer != "mitsuba":
        from whitted.reference.renderers.luxcore import render as luxcore

        luxcore.require()   # before anything renders
    scene = load(args)
    if args.renderer == "luxcore":
        check_render(scene)
        return _compare_luxcore(args, scene)
    reference = _reference_option(args)
    if reference == "direct" and choose_test(comparable(scene), "direct") == "z-test":
        given = "--integrator" if args.integrator is not None else "--reference"
        raise UserError(f"{given} direct: {scene.name} has mirrors, glass or sampled "
                        "lights, whose comparison needs the per-pixel variance that Mitsuba's "
                        "direct integrator does not give; use --reference deterministic "
                        "(the default) or onelobe")
    check_render(scene)
    check_render(scene, moments=True, mitsuba=True)
    _note_spp(scene)
    if scene.film.filter != "box" or scene.film.jitter:
        print("note: compare judges both sides at the strata centres with the box filter "
              f"(the scene's {scene.film.filter} filter"
              f"{' and jitter' if scene.film.jitter else ''} weigh and place the same "
              "samples alike on both sides)", flush=True)
    outdir = output_folder(args.output or Path("out") / "compare" / scene.name)
    _backend(args)
    result, _, _ = compare_scene(scene, outdir, reference,
                                 progress=Progress(f"render {scene.name}"),
                                 second_opinion=False if args.no_second_opinion else None,
                                 seed=args.seed)
    print(format_comparison(result))
    print(f"wrote {shown(outdir)}/" + ", ".join(Path(f).name for f in result.files.values()))
    if args.renderer == "all":
        try:
            return _compare_luxcore(args, scene, result)
        except UserError as e:   # LuxCore failed or ran past its limits: the vote is optional
            from whitted.tracer.errors import one_line

            print(f"note: LuxCore (the third renderer's vote): not available: "
                  f"{one_line(str(e), 300)}", file=sys.stderr, flush=True)
    return EXIT_OK if result.passed else EXIT_FAIL


def _reference_option(args) -> str:
    """``--reference``, or the reference that the older ``--integrator`` option names."""
    from whitted.tracer.errors import UserError

    legacy = {"whitted": "onelobe", "direct": "direct"}
    if args.integrator is not None:
        named = legacy[args.integrator]
        if args.reference is not None and args.reference != named:
            raise UserError(f"--integrator {args.integrator} means --reference {named}; "
                            f"it contradicts --reference {args.reference}")
        return named
    return args.reference or "deterministic"


def cmd_export(args) -> int:
    from whitted.tracer.imageio import check_output_path

    out = check_output_path(args.output, (".xml",), "file type")
    scene = load(args)
    from whitted.tracer.limits import check_depth

    check_depth(scene.film.max_depth)  # Mitsuba reads it as a 32-bit integer
    from whitted.reference.renderers.mitsuba.scene import write_xml

    files = write_xml(scene, out, args.integrator)
    print("wrote " + ", ".join(shown(f) for f in files))
    return EXIT_OK


def cmd_import(args) -> int:
    from whitted.reference.renderers.mitsuba.importer import write_import
    from whitted.tracer.errors import UserError
    from whitted.tracer.imageio import check_output_path
    from whitted.tracer.mitsuba_xml import VALUE_SHOWN

    out = check_output_path(args.output, (".toml",), "file type")
    params = {}
    for item in args.param or []:
        name, sep, value = item.partition("=")
        shown_item = item if len(item) <= VALUE_SHOWN else item[:VALUE_SHOWN - 3] + "..."
        if not sep or not name or not value.strip():
            raise UserError(f"-D {shown_item!r}: expected NAME=VALUE with a value")
        params[name] = value
    scene, imp = write_import(args.xml, out, args.approximate, args.verify, **params)
    for line in imp.warnings:
        print(f"warning: {line}", flush=True)
    n = sum(len(v) for v in imp.notes.values())
    print(f"wrote {shown(out)} ({len(scene.shapes)} shapes, {len(scene.lights)} lights; "
          f"{n} notes as comments" + (", APPROXIMATE" if imp.approximate else "")
          + (", camera and film verified against Mitsuba" if args.verify else "") + ")")
    return EXIT_OK


def cmd_fresnel(args) -> int:
    from whitted.tracer.errors import UserError

    for ior in args.ior:
        if not (ior > 0 and ior < 1e6):
            raise UserError(f"--ior: expected positive numbers, got {ior:g}")
    if args.samples < 100:
        raise UserError(f"--samples: expected at least 100, got {args.samples}")
    if not 0 < args.step <= 45:
        raise UserError(f"--step: expected a number of degrees in (0, 45], got {args.step:g}")
    from whitted.tracer import limits

    # Per index and side, one table row per angle step, each sampled --samples times.
    per_table = (int(90 / args.step) + 2) * args.samples
    limits.check_samples(2 * len(args.ior) * per_table, "the Fresnel table")
    limits.check_memory(per_table * limits.FRESNEL_BYTES_PER_SAMPLE, "the Fresnel table")
    out = output_folder(args.output)
    _backend(args)
    from whitted.reference.teaching.fresnel_curves import fresnel_table, write_outputs

    table = fresnel_table(tuple(args.ior), args.step, args.samples, args.seed)
    files = write_outputs(table, out)
    print(format_fresnel(table))
    print("wrote " + ", ".join(shown(f) for f in files))
    return EXIT_OK if table.passed else EXIT_FAIL


def format_fresnel(table) -> str:
    lines = [f"{'ior':>5} {'side':<8} {'|exact-mi.fresnel|':>19} {'/tol':>6} "
             f"{'|plugin-exact|':>15} {'/CI':>6} {'|Schlick-exact|':>16} {'at':>6}  check"]
    for s in table.summary:
        ok = s["pass"]
        lines.append(
            f"{s['ior']:5g} {s['side']:<8} {s['max_abs_exact_minus_mitsuba']:19.2e} "
            f"{s['worst_exact_vs_mitsuba_over_tolerance']:6.2f} "
            f"{s['max_abs_plugin_minus_exact']:15.2e} "
            f"{s['worst_plugin_deviation_in_half_intervals']:6.2f} "
            f"{s['max_abs_schlick_minus_exact']:16.4f} {s['schlick_worst_theta_deg']:5.1f}d  "
            f"{'pass' if ok else 'FAIL'}")
    lines.append(f"{'conductor':>9} {'ch':<4} {'|ours-mi.fresnel_conductor|':>28} {'/tol':>6}"
                 f" {'|ours-float64|':>15}  check")
    for c in table.conductors:
        lines.append(f"{c['conductor']:>9} {c['channel']:<4} "
                     f"{c['max_abs_ours_minus_mitsuba']:28.2e} {c['worst_over_tolerance']:6.2f} "
                     f"{c['max_abs_ours_minus_float64']:15.2e}  "
                     f"{'pass' if c['pass'] else 'FAIL'}")
    lines.append(("PASS" if table.passed else "FAIL") +
                 " (exact vs mi.fresnel and conductors vs mi.fresnel_conductor within float32 "
                 "rounding; exact inside the plugin's binomial interval)")
    return "\n".join(lines)


def cmd_report(args) -> int:
    from whitted.reference.report.build import build_report, select_scenes
    from whitted.tracer.errors import UserError

    scenes_dir = Path(args.scenes_dir) if args.scenes_dir else SCENES_DIR
    if not scenes_dir.is_dir():
        raise UserError(f"{scenes_dir}: no such folder of scenes")
    paths = select_scenes(scenes_dir, args.scenes)
    if not paths:
        raise UserError(f"no scene in {scenes_dir} matches {args.scenes!r}")
    out = output_folder(args.output)
    from whitted.tracer import load_scene

    for p in paths:  # refuse a bad scene before any rendering
        load_scene(p)
    _backend(args)
    print(f"whitted report: {len(paths)} scene(s){' (quick)' if args.quick else ''} "
          f"+ Fresnel curves -> {out}/", flush=True)
    # The formula-bug sweep needs every scene of the folder: a bug no selected scene
    # reaches would count as missed.
    sweep = not args.no_mutants and args.scenes is None
    luxcore = _report_luxcore(args)
    report = build_report(out, paths, quick=args.quick, fresnel=not args.no_fresnel,
                          reference=args.reference,
                          second_opinion=False if args.no_second_opinion else None,
                          mutants=sweep, luxcore=luxcore,
                          imported=not args.no_imported and args.scenes is None)
    print(f"{'PASS' if report.passed else 'FAIL'} in {report.seconds:.0f} s: "
          f"{sum(s['pass'] for s in report.scenes)}/{len(report.scenes)} scenes pass"
          + ("" if not report.imported else
             f", imported {sum(r['passed'] for r in report.imported)}/{len(report.imported)}")
          + ("" if args.no_fresnel else
             f", Fresnel curves {'pass' if report.fresnel_passed else 'FAIL'}")
          + ("" if report.mutants is None else
             f", formula bugs {'pass' if report.mutants['pass'] else 'FAIL'}")
          + f"; wrote {out}/index.html, report.md, report.json")
    return EXIT_OK if report.passed else EXIT_FAIL


def _report_luxcore(args) -> bool:
    """Whether the report adds LuxCore's three-way verdicts: unless ``--no-luxcore``.

    LuxCore is optional: where it is missing, fails or runs past its time limits the
    report goes on without it and says so ("not available", reference.report.build), its
    exit status the tracer's against Mitsuba. WHITTED_REQUIRE_LUXCORE=1 (CI) makes
    LuxCore's tests fail without it (tests/test_luxcore.py), not the report.
    """
    return not args.no_luxcore


def cmd_mutants(args) -> int:
    from whitted.reference import mutants
    from whitted.reference.report.build import select_scenes
    from whitted.tracer.errors import UserError

    if args.list:
        print(mutants.catalog_table())
        return EXIT_OK
    chosen = mutants.get(args.only) if args.only else list(mutants.CATALOG)
    scenes_dir = Path(args.scenes_dir) if args.scenes_dir else SCENES_DIR
    if not scenes_dir.is_dir():
        raise UserError(f"{scenes_dir}: no such folder of scenes")
    paths = select_scenes(scenes_dir, args.scenes)
    if not paths:
        raise UserError(f"no scene in {scenes_dir} matches {args.scenes!r}")
    out = output_folder(args.output) if args.output else None
    from whitted.tracer import load_scene

    for p in paths:  # refuse a bad scene before any rendering
        load_scene(p)
    _backend(args)
    size = "full" if args.full else "quick"
    print(f"whitted mutants: {len(chosen)} mutant(s) x {len(paths)} scene(s), {size} sizes",
          flush=True)
    result = mutants.sweep(paths, chosen, quick=not args.full,
                           log=lambda m: print(m, flush=True))
    print(mutants.format_table(result))
    if out is not None:
        from whitted.reference.verdicts.compare import write_json

        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "mutants.json", result.to_json())
        (out / "mutants.md").write_text(mutants.markdown(result))
        print(f"wrote {shown(out)}/mutants.json, mutants.md")
    return EXIT_OK if result.passed else EXIT_FAIL


#: Most timed runs per depth of a depth sweep.
MAX_REPEAT = 100


def cmd_depth_sweep(args) -> int:
    from whitted.reference.teaching.depth_sweep import (
        depth_sweep,
        explain,
        parse_depths,
        write_outputs,
    )
    from whitted.tracer.errors import UserError

    depths = parse_depths(args.depths)
    if not 1 <= args.repeat <= MAX_REPEAT:
        raise UserError(f"--repeat: expected a number from 1 to {MAX_REPEAT}, got "
                        f"{args.repeat:,}")
    if not args.min_weight >= 0:
        raise UserError(f"--min-weight: expected a number >= 0, got {args.min_weight}")
    scene = load(args)
    from whitted.tracer.imageio import StagedFolder
    from whitted.tracer.limits import check_render

    deepest = scene.with_overrides(max_depth=max(depths) + 1)
    check_render(deepest)
    if not args.no_mitsuba:
        check_render(deepest, mitsuba=True)
    _note_spp(scene)
    # The images appear in the folder only when the sweep is complete: an interrupted
    # or failed sweep leaves nothing behind.
    with StagedFolder(args.output) as staged:
        _backend(args)
        print(f"depth sweep of {scene.name} ({_describe(scene).rsplit(',', 1)[0]}), DEPTH "
              f"{', '.join(map(str, depths))}, {args.repeat} timed run(s) each", flush=True)
        rows = depth_sweep(scene, depths, args.repeat, staged.path, mitsuba=not args.no_mitsuba,
                           log=lambda m: print(m, flush=True), min_weight=args.min_weight,
                           seed=args.seed)
        files = write_outputs(rows, staged.path, scene.name)
        staged.commit()
    print(explain(rows))
    print("wrote " + ", ".join(shown(staged.final(f)) for f in files) +
          f" and depth_*.png in {shown(staged.target)}")
    return EXIT_OK


def cmd_paths(args) -> int:
    from whitted.tracer.imageio import check_output_path

    out = check_output_path(args.output, (".png",))
    scene = load(args)
    from whitted.reference.teaching.paths import (
        MAX_PIXELS,
        WANTED,
        draw,
        ldde_lsde_panel,
        parse_pixel,
        pick_pixels,
        ray_trees,
    )
    from whitted.tracer.errors import UserError
    from whitted.tracer.limits import check_render

    if len(args.pixel or []) > MAX_PIXELS:
        raise UserError(f"--pixel: at most {MAX_PIXELS} pixels, got {len(args.pixel):,}")
    pixels = [parse_pixel(p, scene.film.width, scene.film.height) for p in args.pixel or []]
    check_render(scene)
    if not args.no_mitsuba:
        check_render(scene.with_overrides(max_depth=3, spp=64), mitsuba=True)
    _backend(args)
    from whitted.tracer.integrator import Integrator

    notes = []
    if not pixels:
        picked = pick_pixels(scene, seed=args.seed)
        for expr in WANTED:
            if picked[expr] is None:
                why = (" (a point, spot or directional light cannot be seen: only area "
                       "lights can)" if expr in ("LE", "LSE") else "")
                notes.append(f"{expr}: no pixel of this scene shows it{why}.")
            else:
                notes.append(f"{expr}: pixel {picked[expr][0]},{picked[expr][1]}.")
        pixels = sorted({p for p in picked.values() if p is not None})
        if not pixels:
            notes.append("No pixel of this scene shows a Whitted light path: no ray trees to "
                         "draw (give pixels with --pixel X,Y to draw theirs).")
    notes.append("LDDE and LSDE: a Whitted tracer makes no such paths (no indirect diffuse "
                 "light, no caustics)" + ("." if args.no_mitsuba else ": see the right panel."))
    image = Integrator(scene, seed=args.seed).render().image
    check_finite(image)
    trees = ray_trees(scene, pixels) if pixels else []
    panel = None if args.no_mitsuba else ldde_lsde_panel(scene, seed=args.seed)
    draw(scene, image, trees, str(out), notes, panel)
    for t in trees:
        print(f"pixel {t.pixel[0]},{t.pixel[1]}: " +
              (", ".join(sorted(set(t.paths), key=lambda s: (len(s), s))) or "no light"))
    for n in notes:
        print(n)
    print(f"wrote {shown(out)}")
    return EXIT_OK


def cmd_assignment(args) -> int:
    from whitted.reference.teaching.depth_sweep import parse_depths
    from whitted.tracer.errors import UserError

    depths = tuple(parse_depths(args.depths))
    if max(depths) < 5:
        raise UserError(f"--depths: expected a DEPTH of 5 or more (the assignment asks for "
                        f"1 to 5 and 20+), got {args.depths!r}")
    if args.repeat < 1:
        raise UserError(f"--repeat: expected a positive number, got {args.repeat}")
    out = output_folder(args.output)
    _backend(args)
    from whitted.reference.teaching.assignment import run

    print(f"whitted assignment: heckbert_minray at {args.size}x{args.size}, DEPTH "
          f"{', '.join(map(str, depths))} -> {out}/", flush=True)
    res = run(out, args.size, depths, args.repeat, mitsuba=not args.no_mitsuba,
              log=lambda m: print(m, flush=True))
    print("wrote " + ", ".join(f.name for f in res.files) + f" in {res.seconds:.0f} s")
    return EXIT_OK


def cmd_scenes(args) -> int:
    from whitted.tracer import load_scene

    for p in builtin_scenes():
        s = load_scene(p)
        print(f"{p.stem:<24} {_describe(s):<44} {s.description}")
    return EXIT_OK


def cmd_schema(args) -> int:
    from whitted.tracer.schema import schema_text

    if args.output is None:
        sys.stdout.write(schema_text())
        return EXIT_OK
    from whitted.tracer.imageio import check_output_path

    out = check_output_path(args.output, (".json",), "file type")
    out.write_text(schema_text())
    print("wrote " + shown(out))
    return EXIT_OK


def _thresholds(args):
    """OpenImageIO idiff's thresholds from the options (None where not given), checked."""
    from whitted.reference.check.judge import Thresholds
    from whitted.tracer.errors import UserError

    th = Thresholds(**{k: getattr(args, k, None) for k in
                       ("fail", "fail_percent", "hard_fail", "warn", "warn_percent", "hard_warn")})
    for k, v in vars(th).items():
        if v is None:
            continue
        opt = "--" + k.replace("_", "-")
        if not v >= 0:
            raise UserError(f"{opt}: expected a number >= 0, got {v}")
        if k.endswith("percent") and v > 100:
            raise UserError(f"{opt}: expected a percentage from 0 to 100, got {v}")
    return th


def cmd_check(args) -> int:
    from whitted.reference.check.images import read_user_image
    from whitted.reference.check.judge import check_image, format_run, write_outputs
    from whitted.tracer.errors import UserError
    from whitted.tracer.limits import check_render

    th = _thresholds(args)
    user = read_user_image(args.image, args.encoding)   # bad input before any rendering
    # --spp is the image's samples, not the reference's: the film keeps the scene's strata.
    scene = load_scene_arg(args).with_overrides(
        max_depth=_max_depth(args), size=args.size)
    w, h = scene.film.width, scene.film.height
    if user.size != (w, h):
        raise UserError(f"{shown(args.image)} is {user.size[0]}x{user.size[1]} pixels, the "
                        f"film of {scene.name} is {w}x{h} (render at {w}x{h}, or give --size "
                        f"{user.size[0]}x{user.size[1]} if you rendered the scene at that size)")
    check_render(scene, moments=True)
    if args.mitsuba or args.spp is not None:
        check_render(scene, mitsuba=True)
    if args.mitsuba:
        from whitted.reference.renderers.mitsuba.deterministic import shares_light_samples

        if not shares_light_samples(scene):
            raise UserError(f"--mitsuba: an emitter of {scene.name} has no shared light "
                            "samples (reference.renderers.mitsuba.deterministic.SAMPLE_MAPS), "
                            "so Mitsuba's "
                            "deterministic reference cannot render it")
    from whitted.reference.check.judge import OUTPUT_NAMES, refuse_in_the_way
    from whitted.tracer.imageio import StagedFolder

    outdir = output_folder(args.output or Path("out") / "check" /
                           f"{scene.name}-{Path(args.image).stem}")
    refuse_in_the_way(outdir, OUTPUT_NAMES)
    # All five files or none: an error, a full disk or Ctrl-C leaves no partial output.
    with StagedFolder(outdir) as staged:
        _backend(args)
        run = check_image(user, scene, args.spp, th, mitsuba=args.mitsuba, seed=args.seed,
                          suspects=not args.no_suspects,
                          log=lambda m: print(m + " ...", flush=True))
        title = (f"{shown(args.image)} against {scene.name} ({_describe(scene)}), read as "
                 f"{user.storage}")
        write_outputs(run, staged.path, title, final=outdir)
        staged.commit()
    print(format_run(run, title))
    print(f"wrote {shown(outdir)}/" + ", ".join(Path(f).name for f in run.files.values()))
    return EXIT_OK if run.passed else EXIT_FAIL


def cmd_suite(args) -> int:
    from whitted.reference.check import suite
    from whitted.tracer.errors import UserError

    given = {"--suite": args.suite, "--update": args.update or None,
             "--encoding": args.encoding, "--spp": args.spp}
    if args.action == "export":
        wrong = [k for k, v in given.items() if v is not None]
        if wrong:
            raise UserError(f"{', '.join(wrong)}: options of `whitted suite check`, not export")
        paths = suite.select(builtin_scenes(), args.scenes)
        if not paths:
            raise UserError(f"no built-in scene matches {args.scenes!r}")
        from whitted.tracer import load_scene
        from whitted.tracer.imageio import StagedFolder
        from whitted.tracer.limits import check_render

        for p in paths:   # refuse a bad scene before any rendering
            check_render(load_scene(p), moments=True)
        with StagedFolder(args.dir) as staged:
            _backend(args)
            print(f"whitted suite export: {len(paths)} scene(s) -> {shown(staged.target)}/",
                  flush=True)
            suite.export(staged.path, paths, log=lambda m: print(m, flush=True))
            staged.commit()
        print(f"wrote {shown(staged.target)}/manifest.json, README.md, scenes/, mitsuba/, "
              "references/")
        return EXIT_OK
    th = _thresholds(args)
    images = Path(args.dir)
    if not images.is_dir():
        raise UserError(f"{shown(images)}: no such folder of images")
    suite_dir = Path(args.suite) if args.suite else None
    if args.update and suite_dir is None:
        raise UserError("--update rewrites a suite's stored references: give --suite DIR")
    if suite_dir is not None and not suite_dir.is_dir():
        raise UserError(f"{shown(suite_dir)}: no such suite folder")
    if args.encoding is not None:
        from whitted.reference.check.images import ENCODINGS

        if args.encoding not in ENCODINGS:
            raise UserError(f"--encoding: expected one of {', '.join(ENCODINGS)}")
    from whitted.reference.check.judge import refuse_in_the_way
    from whitted.tracer.imageio import StagedFolder

    # Everything read and checked before any rendering: the manifest, its paths, and
    # that every file the command will write can be written.
    chosen = suite.load_suite(suite_dir, args.scenes)
    out = output_folder(args.output or images / "whitted-check")
    refuse_in_the_way(out, suite.OUTPUT_NAMES)
    if args.update:
        suite.check_update_targets(chosen)
    # All outputs or none: the report and the new references are written beside their
    # places and moved there only when all are complete.
    with StagedFolder(out) as staged, suite.PendingFiles() as pending:
        _backend(args)
        result = suite.grade(images, chosen, args.scenes, args.encoding, args.spp, th,
                             log=lambda m: print(m, flush=True))
        suite.write_outputs(result, staged.path)
        files = []
        if args.update and result.passed:
            files = suite.stage_references(result, chosen, pending)
        pending.commit()
        staged.commit()
    print(suite.format_suite(result))
    print(f"wrote {shown(out)}/index.html, suite.json")
    if args.update:
        if not result.passed:
            print("references not updated: the run fails (fix the failing scenes first)")
            return EXIT_FAIL
        print(f"updated {len(files)} reference(s) in {shown(suite_dir)}/references/")
    return EXIT_OK if result.passed else EXIT_FAIL


# ---------------------------------------------------------------- parser


#: The longest value an option error echoes whole (a 5000-digit --seed is cut).
ECHO_LIMIT = 60


def shorten(text: str, limit: int = ECHO_LIMIT) -> str:
    """``text`` cut to about ``limit`` characters, its start and end kept and its length
    said: ``'99999...99999' (5,002 characters)``."""
    if len(text) <= limit:
        return text
    keep = max(limit - 3, 2)
    return f"{text[:keep - keep // 3]}...{text[-(keep // 3):]} ({len(text):,} characters)"


class Parser(argparse.ArgumentParser):
    """argparse, with its errors in one line that points to --help (not usage + error);
    each word of the message longer than ECHO_LIMIT (a value echoed back) is shortened."""

    def error(self, message: str):
        import re

        from whitted.tracer.errors import one_line

        message = re.sub(rf"\S{{{ECHO_LIMIT + 1},}}", lambda m: shorten(m.group()),
                         one_line(message, 1 << 20))
        self.exit(EXIT_USAGE, f"{self.prog}: error: {one_line(message)} "
                              f"(see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = Parser(
        prog="whitted",
        description="A Whitted ray tracer on Dr.Jit that proves itself against Mitsuba 3. "
                    "SCENE is a TOML scene file or the name of a built-in scene "
                    "(see `whitted scenes`).",
        epilog="Exit status: 0 success, 1 comparison outside tolerance, 2 bad input or a "
               "file that cannot be written (one line on stderr). Limits on work and memory: "
               "WHITTED_MAX_SAMPLES, WHITTED_MAX_MEMORY, WHITTED_MAX_DEPTH, "
               "WHITTED_MAX_PRIMITIVES, WHITTED_MAX_SCENE_BYTES, WHITTED_LPE_MAX_STATES.")
    p.add_argument("--version", action=_VersionAction)
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def scene_opts(sp, output_help=None, output_required=True, seed=True):
        sp.add_argument("scene", metavar="SCENE",
                        help="scene file (.toml), built-in name, or Mitsuba 3 scene (.xml)")
        sp.add_argument("--approximate", action="store_true",
                        help="Mitsuba XML: replace what lies outside the Whitted subset (rough "
                             "BSDFs, ...) by its nearest equivalent, warning once per kind")
        if output_help:
            sp.add_argument("-o", "--output", required=output_required, help=output_help)
        sp.add_argument("--spp", type=_positive, help="samples per pixel (rounded up to a square)")
        sp.add_argument("--max-depth", type=_positive, dest="max_depth",
                        help="path segments, as Mitsuba counts them (2 = direct light)")
        sp.add_argument("--depth", type=_positive, dest="depth",
                        help="Heckbert's DEPTH: trace calls (1 = the camera rays' hits "
                             "shaded); the same as --max-depth DEPTH+1")
        sp.add_argument("--size", type=_size, metavar="WxH", help="image size, e.g. 320x240")
        sp.add_argument("--backend", choices=("auto", "llvm", "cuda"), default=None,
                        help="Dr.Jit backend (default: WHITTED_BACKEND or auto: CUDA if "
                             "there is a GPU, else LLVM)")
        if seed:
            sp.add_argument("--seed", type=int, default=0,
                            help="seed of the random numbers (area-light samples, the "
                                 "reference's lobe choices): any integer, hashed to 32 bits "
                                 "beyond 0..2^32-1")

    r = sub.add_parser("render", help="render a scene with the tracer (no Mitsuba involved)",
                       description="Render SCENE with whitted's own tracer.")
    scene_opts(r, "output image: .exr (linear float32), .png (sRGB 8-bit) or .ppm "
                  "(plain text, as Heckbert's minray prints it)")
    r.add_argument("--lpe", metavar="EXPR", default=None,
                   help="render only light on paths matching this light-path expression in "
                        "Heckbert's notation, written from the light to the eye: L light, "
                        "D diffuse, S specular, E eye; e.g. LDE, 'LDS+E', 'LS*E', 'L(D|S)*E'")
    r.add_argument("--min-weight", type=float, default=0.0,
                   help="drop specular branches whose weight falls to this or below (a biased "
                        "speed-up; default 0: exact Whitted)")
    r.set_defaults(func=cmd_render)

    ref = sub.add_parser("reference", help="render a scene on Mitsuba 3",
                         description="Render SCENE on Mitsuba 3 after converting it to Mitsuba's "
                                     "plugins.")
    scene_opts(ref, "output image (.exr, .png or .ppm)")
    ref.add_argument("--integrator", choices=("whitted", "direct", "path", "deterministic"),
                     default="whitted",
                     help="Mitsuba integrator: whitted (ours, one lobe per sample, every light "
                          "once per sample; default), direct or path (Mitsuba's), or "
                          "deterministic (the harness's loop over Mitsuba's plugins: both lobes, "
                          "the tracer's light samples of --seed; what compare uses)")
    ref.add_argument("--renderer", choices=("mitsuba", "luxcore"), default="mitsuba",
                     help="mitsuba (default) or luxcore: LuxCoreRender's path tracer at "
                          "Whitted's depths, spp jittered samples per pixel, in a child "
                          "process (needs the extra: pip install 'whitted[luxcore]')")
    ref.set_defaults(func=cmd_reference)

    c = sub.add_parser("compare", help="render with both and compare",
                       description="Render SCENE with the tracer and with Mitsuba, write "
                                   "tracer.exr, mitsuba.exr, diff.png and metrics.json into DIR, "
                                   "print the metrics, and exit 0 within the scene's tolerance, "
                                   "1 outside it.")
    scene_opts(c, "output folder (default: out/compare/SCENE_NAME)", output_required=False)
    c.add_argument("--reference", choices=("deterministic", "onelobe", "direct"),
                   default=None,
                   help="Mitsuba's side: deterministic (default: both lobes of every mirror "
                        "and glass, area lights at the tracer's light samples, judged at "
                        "float precision), onelobe (the whitted integrator: one lobe per "
                        "sample, judged by the statistical z-test), or direct (Mitsuba's, "
                        "scenes without mirrors, glass or area lights)")
    c.add_argument("--integrator", choices=("whitted", "direct"), default=None,
                   help="older name of --reference: whitted = onelobe, direct = direct")
    c.add_argument("--no-second-opinion", action="store_true",
                   help="skip the one-lobe reference's z-test that the deterministic reference "
                        "adds for scenes with area lights")
    c.add_argument("--renderer", choices=("mitsuba", "luxcore", "all"), default="mitsuba",
                   help="mitsuba (default): the comparison above; luxcore: the tracer, "
                        "Mitsuba and LuxCore at a small size, exit status the tracer's "
                        "against LuxCore; all: both, with the three-way verdict (exit "
                        "status the tracer's against Mitsuba). LuxCore needs the extra: "
                        "pip install 'whitted[luxcore]'")
    c.set_defaults(func=cmd_compare)

    e = sub.add_parser("export", help="write the scene as Mitsuba 3 XML",
                       description="Write SCENE as a Mitsuba 3 XML file that Mitsuba renders "
                                   "to the same picture as `whitted reference`.")
    scene_opts(e, "output .xml file (triangles go to meshes/NAME_*.obj beside it)", seed=False)
    e.add_argument("--integrator", choices=("whitted", "direct", "path"), default="whitted",
                   help="integrator written into the XML (whitted needs `import whitted.reference` "
                        "before loading; direct and path are stock Mitsuba)")
    e.set_defaults(func=cmd_export)

    im = sub.add_parser("import", help="write a Mitsuba 3 XML scene as a TOML scene",
                        description="Read a Mitsuba 3 XML scene (default/$param, include, "
                                    "ref, path, nested transforms; rgb and one-valued spectra "
                                    "as RGB; named IORs) and write it as a TOML scene, meshes "
                                    "referenced, with a comment wherever something was "
                                    "approximated. Elements outside the Whitted subset exit 2 "
                                    "naming the element and its line.")
    im.add_argument("xml", metavar="SCENE.xml", help="Mitsuba 3 scene file")
    im.add_argument("-o", "--output", required=True, help="output .toml file")
    im.add_argument("--approximate", action="store_true",
                    help="replace what lies outside the Whitted subset (rough conductor -> "
                         "conductor, ...) by its nearest equivalent, warning once per kind")
    im.add_argument("-D", dest="param", action="append", metavar="NAME=VALUE",
                    help="value of a $NAME parameter of the file (overrides its <default>)")
    im.add_argument("--verify", action="store_true",
                    help="also load the file with Mitsuba and check that the camera and film "
                         "agree with Mitsuba's")
    im.set_defaults(func=cmd_import)

    f = sub.add_parser("fresnel", help="compare Fresnel curves with Mitsuba's",
                       description="Tabulate our exact Fresnel reflectance and Schlick's "
                                   "approximation over 0..90 degrees from both sides of the "
                                   "boundary, against mi.fresnel and the reflection probability "
                                   "of Mitsuba's dielectric plugin (measured by sampling). "
                                   "Writes fresnel.csv, fresnel.png and fresnel.json; exits 1 "
                                   "when exact and mi.fresnel differ beyond float32 rounding or "
                                   "the plugin disagrees beyond its binomial interval.")
    f.add_argument("-o", "--output", required=True, help="output folder")
    f.add_argument("--ior", type=float, nargs="+", default=[1.0, 1.33, 1.5, 2.42],
                   help="indices of refraction against ext_ior = 1 (default: 1.0 1.33 1.5 2.42)")
    f.add_argument("--step", type=float, default=0.5, help="angle step in degrees (default 0.5)")
    f.add_argument("--samples", type=int, default=100_000,
                   help="plugin samples per angle (default 100000)")
    f.add_argument("--seed", type=int, default=0,
                   help="seed of the plugin's sample numbers (any integer)")
    f.add_argument("--backend", choices=("auto", "llvm", "cuda"), default=None,
                   help="Dr.Jit backend")
    f.set_defaults(func=cmd_fresnel)

    rp = sub.add_parser("report", help="compare every scene and write an accuracy report",
                        description="Compare every scene in the scenes folder with Mitsuba and "
                                    "check the Fresnel curves; write index.html (for people), "
                                    "report.md (for CI logs) and report.json (for machines). "
                                    "Exit 1 when a scene or curve fails.")
    rp.add_argument("-o", "--output", default="reports",
                    help="output folder (default: reports/)")
    rp.add_argument("--scenes", metavar="GLOB", default=None,
                    help="only scenes whose file name matches GLOB, e.g. 'glass*'")
    rp.add_argument("--scenes-dir", default=None,
                    help="folder of scenes (default: the built-in scenes/)")
    rp.add_argument("--quick", action="store_true",
                    help="smaller images (<= 96 px wide), <= 16 spp, fewer reference passes "
                         "and a coarser Fresnel table: minutes instead of tens of minutes")
    rp.add_argument("--no-fresnel", action="store_true", help="skip the Fresnel curves")
    rp.add_argument("--no-mutants", action="store_true",
                    help="skip the formula-bug sweep (whitted mutants), which otherwise runs "
                         "over the same scenes unless --scenes picks some of them")
    rp.add_argument("--no-imported", action="store_true",
                    help="skip the imported group: Mitsuba scenes (its data repository's, "
                         "mi.cornell_box()) imported and compared with Mitsuba's render of "
                         "the originals; it runs unless --scenes picks scenes")
    rp.add_argument("--reference", choices=("deterministic", "onelobe"), default="deterministic",
                    help="Mitsuba's side of every scene (see whitted compare --help; default "
                         "deterministic)")
    rp.add_argument("--no-second-opinion", action="store_true",
                    help="skip the one-lobe z-test beside the deterministic reference on "
                         "scenes with area lights")
    rp.add_argument("--no-luxcore", action="store_true",
                    help="skip the LuxCore column (three-way verdicts of tracer, Mitsuba and "
                         "LuxCore), which is on where the extra whitted[luxcore] is installed")
    rp.add_argument("--backend", choices=("auto", "llvm", "cuda"), default=None,
                    help="Dr.Jit backend")
    rp.set_defaults(func=cmd_report)

    mu = sub.add_parser("mutants", help="check that the comparison catches known formula bugs",
                        description="Render every scene with the tracer as written and with "
                                    "each bug of the catalog (reference/mutants.py) switched "
                                    "on, judge each image as `whitted compare` does, and print "
                                    "which scenes' verdicts fail for each bug and by how much "
                                    "(margin: how many times the most violated check exceeds "
                                    "its limit). Exit 0 when the tracer as written passes "
                                    "every scene and every bug is caught by at least one, "
                                    "1 otherwise.")
    mu.add_argument("--list", action="store_true",
                    help="print the catalog (id, lecture topic, formula wrong and right) and exit")
    mu.add_argument("--only", nargs="+", metavar="ID", default=None,
                    help="only these bugs (ids from --list)")
    mu.add_argument("--scenes", metavar="GLOB", default=None,
                    help="only scenes whose file name matches GLOB (bugs that no chosen scene "
                         "catches then fail the run)")
    mu.add_argument("--scenes-dir", default=None,
                    help="folder of scenes (default: the built-in scenes/)")
    mu.add_argument("--full", action="store_true",
                    help="the scenes' own sizes, as whitted compare renders them (default: "
                         "quick sizes, at most 64 pixels wide and 16 spp)")
    mu.add_argument("-o", "--output", default=None,
                    help="also write mutants.json and mutants.md into this folder")
    mu.add_argument("--backend", choices=("auto", "llvm", "cuda"), default=None,
                    help="Dr.Jit backend")
    mu.set_defaults(func=cmd_mutants)

    ds = sub.add_parser("depth-sweep", help="runtime and rays against recursion depth",
                        description="Render SCENE at each DEPTH (Heckbert's numbering: "
                                    "max_depth = DEPTH + 1), timing the tracer (median of "
                                    "--repeat runs after a warm-up) and Mitsuba's reference; "
                                    "write depth_NN.png, runtimes.txt and runtimes.png.")
    scene_opts(ds, "output folder")
    ds.add_argument("--depths", default="1-5,10,20,25",
                    help="DEPTH values: numbers and ranges (default: 1-5,10,20,25)")
    ds.add_argument("--repeat", type=int, default=3, help="timed runs per depth (default 3)")
    ds.add_argument("--no-mitsuba", action="store_true", help="do not time Mitsuba alongside")
    ds.add_argument("--min-weight", type=float, default=0.0,
                    help="drop branches whose weight falls to this or below (biased; default "
                         "0: exact Whitted, only zero-weight branches are dropped)")
    ds.set_defaults(func=cmd_depth_sweep)

    pa = sub.add_parser("paths", help="draw pixels' ray trees with their light paths",
                        description="Draw, over the rendered image, the ray trees of chosen "
                                    "pixels (camera ray, reflections, refractions, shadow rays "
                                    "to each light), each light path labelled in Heckbert's "
                                    "notation. Without --pixel, pixels that show LE, LDE, LSE "
                                    "and LDSE are picked. Beside it, where Mitsuba's path "
                                    "tracer finds LDDE and LSDE paths, which a Whitted tracer "
                                    "cannot make.")
    scene_opts(pa, "output .png")
    pa.add_argument("--pixel", action="extend", nargs="+", metavar="X,Y",
                    help="pixels to draw: --pixel 1,2 3,4 (or repeated); default: picked "
                         "automatically")
    pa.add_argument("--no-mitsuba", action="store_true",
                    help="leave out the LDDE/LSDE panel rendered on Mitsuba")
    pa.set_defaults(func=cmd_paths)

    a = sub.add_parser("assignment", help="the first lecture's assignment, in one run",
                       description="Heckbert's business-card ray tracer assignment: "
                                   "heckbert_depth1.png ... heckbert_depth5.png and a DEPTH "
                                   "20+ image, heckbert_runtimes1.txt and .png (runtime and "
                                   "rays against DEPTH, with the rays minray traces), "
                                   "light_paths.png (LE, LDE, LSE, LDDE, LDSE, LSDE) and "
                                   "observations.md, rendered with the classic model that "
                                   "prints minray's numbers. About a minute at 256x256.")
    a.add_argument("-o", "--output", required=True, help="output folder")
    a.add_argument("--size", type=_positive, default=256,
                   help="image width and height in pixels (default 256)")
    a.add_argument("--depths", default="1-10,15,20",
                   help="DEPTHs of the runtime sweep; the deepest also gets a picture "
                        "(default 1-10,15,20)")
    a.add_argument("--repeat", type=int, default=3, help="timed renders per DEPTH (default 3)")
    a.add_argument("--no-mitsuba", action="store_true",
                   help="leave out the LDDE/LSDE panel rendered with Mitsuba's path tracer")
    a.add_argument("--backend", choices=("auto", "llvm", "cuda"), default=None,
                   help="Dr.Jit backend")
    a.set_defaults(func=cmd_assignment)

    def threshold_opts(sp):
        g = sp.add_argument_group(
            "thresholds (OpenImageIO idiff's meanings)",
            "A pixel fails when the difference of any channel exceeds the fail threshold; the "
            "image fails when more than --fail-percent of its pixels fail, or when any pixel's "
            "difference exceeds --hard-fail. By default the threshold is statistical (the "
            "Sidak level, about 5 sigma of each pixel's noise) and 0.25 %% of the pixels may "
            "exceed it; --fail replaces it by an absolute difference. Either way the image "
            "must also pass the region sums, which see a small bias over many pixels and "
            "which these options leave as they are. --warn, --warn-percent and --hard-warn "
            "do the same for a warning (exit status 0).")
        for name, what in (("fail", "absolute difference beyond which a pixel fails "
                                    "(default: the statistical threshold)"),
                           ("fail-percent", "percentage of pixels allowed to fail (default "
                                            "0.25)"),
                           ("hard-fail", "fail if any pixel's difference exceeds this "
                                         "(default: none)"),
                           ("warn", "absolute difference beyond which a pixel warns (default: "
                                    "the statistical threshold)"),
                           ("warn-percent", "percentage of pixels allowed to warn (default 0 "
                                            "once a --warn option is given)"),
                           ("hard-warn", "warn if any pixel's difference exceeds this")):
            g.add_argument(f"--{name}", type=float, default=None, metavar="X", help=what)

    encodings = ("srgb", "linear", "minray")
    ck = sub.add_parser(
        "check", help="judge another renderer's image against the reference",
        description="Judge IMAGE (OpenEXR, PFM, Radiance HDR, PNG or PPM P3/P6), made by any "
                    "renderer from SCENE, against whitted's reference for the scene: its "
                    "tracer's image (deterministic at the scene's strata; with --mitsuba also "
                    "Mitsuba's deterministic reference). Your image's noise comes from its "
                    "EXR variance layer, or from --spp N (the noise of N samples of Mitsuba's "
                    "path tracer), or is estimated from neighbouring pixels. Writes diff.png "
                    "(heat map), side_by_side.png, reference.exr, check.json and check.html "
                    "(a viewer: hover, flip, zoom). An image that fails gets its difference "
                    "split by light path and material, and the suspects: the three formula "
                    "bugs of the catalog (whitted mutants --list) whose image explains most "
                    "of it. Exit 0 when the image agrees, 1 when it "
                    "does not, 2 for bad input (an unreadable file, a size other than the "
                    "film's).")
    ck.add_argument("image", metavar="IMAGE", help="your renderer's image")
    ck.add_argument("--scene", required=True, help="the scene it shows (.toml or built-in name)")
    ck.add_argument("-o", "--output", default=None,
                    help="output folder (default: out/check/SCENE-IMAGE)")
    ck.add_argument("--encoding", choices=encodings, default=None,
                    help="how an 8-bit PNG or PPM encodes light: srgb (default), linear "
                         "(value / maxval, clipped at 1) or minray (255 x linear, no gamma, no "
                         "clamp: values above 255 allowed)")
    ck.add_argument("--spp", type=_positive, default=None,
                    help="your samples per pixel: judge your noise as that of N samples of "
                         "Mitsuba's path tracer (without it, and without a variance layer, "
                         "the noise is estimated from neighbouring pixels)")
    ck.add_argument("--size", type=_size, metavar="WxH",
                    help="the film size you rendered the scene at, e.g. 320x240")
    ck.add_argument("--max-depth", type=_positive, dest="max_depth",
                    help="the max_depth you rendered with (path segments)")
    ck.add_argument("--depth", type=_positive, dest="depth",
                    help="Heckbert's DEPTH you rendered with (= --max-depth DEPTH+1)")
    ck.add_argument("--mitsuba", action="store_true",
                    help="also judge the image against Mitsuba's deterministic reference, and "
                         "check the tracer's reference against it")
    ck.add_argument("--seed", type=int, default=0,
                    help="seed of the reference's light samples (scenes with area lights)")
    ck.add_argument("--no-suspects", action="store_true", dest="no_suspects",
                    help="for an image that fails, do not rank the catalog's formula bugs "
                         "by how much of the difference each explains (that renders the "
                         "scene once per bug it reaches, kept in ~/.cache/whitted/suspects or "
                         "WHITTED_SUSPECTS_CACHE)")
    ck.add_argument("--backend", choices=("auto", "llvm", "cuda"), default=None,
                    help="Dr.Jit backend")
    threshold_opts(ck)
    ck.set_defaults(func=cmd_check)

    su = sub.add_parser(
        "suite", help="hand out every built-in scene, or grade a folder of images",
        description="export DIR: write every built-in scene (or those matching --scenes) into "
                    "DIR as TOML and Mitsuba 3 XML, with its reference (EXR with variance "
                    "layers, and PNG) and a manifest (manifest.json, README.md: size, what "
                    "each scene tests, which formulas). check DIR: grade a folder of images "
                    "named after the scenes (NAME.exr, .pfm, .hdr, .png or .ppm) against the "
                    "references of --suite SUITE (or references rendered now), as `whitted "
                    "check` does; write index.html and suite.json; exit 1 if any scene fails "
                    "or has no image. --update then stores the images as the suite's "
                    "references, unless the run fails.")
    su.add_argument("action", choices=("export", "check"), metavar="export|check",
                    help="export a suite, or check a folder of images")
    su.add_argument("dir", metavar="DIR",
                    help="export: the folder to write; check: the folder of images")
    su.add_argument("--scenes", metavar="GLOB", default=None,
                    help="only scenes whose name matches GLOB, e.g. 'glass*'")
    su.add_argument("--suite", metavar="SUITE", default=None,
                    help="check: an exported suite folder whose stored references to use")
    su.add_argument("-o", "--output", default=None,
                    help="check: folder for index.html and suite.json (default: "
                         "DIR/whitted-check)")
    su.add_argument("--encoding", choices=encodings, default=None,
                    help="check: how 8-bit images encode light (as in `whitted check`)")
    su.add_argument("--spp", type=_positive, default=None,
                    help="check: your samples per pixel (as in `whitted check`)")
    su.add_argument("--update", action="store_true",
                    help="check: store the images as the suite's references (your golden "
                         "images), refused when the run fails")
    su.add_argument("--backend", choices=("auto", "llvm", "cuda"), default=None,
                    help="Dr.Jit backend")
    threshold_opts(su)
    su.set_defaults(func=cmd_suite)

    s = sub.add_parser("scenes", help="list the built-in scenes")
    s.set_defaults(func=cmd_scenes)

    sc = sub.add_parser(
        "schema", help="print the JSON Schema of the TOML scene format",
        description="Print the JSON Schema (draft 2020-12) of the TOML scene format, derived "
                    "from the scene loader's own parsers, for editors: a `#:schema` line at "
                    "the top of a scene points TOML language servers (Taplo, Even Better TOML) "
                    "at it for completion and inline errors (docs/scene-format.md).")
    sc.add_argument("-o", "--output", metavar="FILE",
                    help="write the schema to FILE (.json) instead of standard output")
    sc.set_defaults(func=cmd_schema)
    return p


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked for.

    Reading the package metadata costs about 25 ms (importlib.metadata), which
    every other command would pay for nothing when building the parser.
    """

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show the version and exit"):
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(_version())
        parser.exit()


def _version() -> str:
    from importlib import metadata

    try:
        return f"whitted {metadata.version('whitted')}"
    except metadata.PackageNotFoundError:
        return "whitted (not installed)"


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's last flush cannot fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        pass


class StdoutError(Exception):
    """Standard output cannot be written (a full device, a closed terminal)."""


class _Stdout:
    """sys.stdout, with its OS errors told apart from those of output files."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text):
        try:
            return self.stream.write(text)
        except BrokenPipeError:
            raise
        except OSError as e:
            raise StdoutError(e.strerror or str(e)) from None

    def flush(self):
        try:
            self.stream.flush()
        except BrokenPipeError:
            raise
        except OSError as e:
            raise StdoutError(e.strerror or str(e)) from None

    def __getattr__(self, name):
        return getattr(self.stream, name)


def _caused_by(e: BaseException, kind: type) -> bool:
    """Whether ``e``, or an exception it was raised from or while handling, is a ``kind``."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, kind):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def main(argv: list[str] | None = None) -> int:
    from whitted.tracer.errors import one_line

    # A name that is not UTF-8 reaches Python as surrogates: print them escaped.
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")

    def fail(message: str) -> int:
        print(f"whitted: error: {one_line(message)}", file=sys.stderr)
        return EXIT_USAGE

    stdout = sys.stdout
    sys.stdout = _Stdout(stdout)
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help, --version, or a one-line parser error
            return e.code if isinstance(e.code, int) else EXIT_USAGE
        from whitted.tracer import backend, llvm
        from whitted.tracer.errors import UserError

        try:
            rc = args.func(args)
            sys.stdout.flush()
            return rc
        except (UserError, llvm.LLVMUnavailable, backend.BackendUnavailable) as e:
            return fail(str(e))
    except KeyboardInterrupt:
        print("whitted: interrupted", file=sys.stderr)
        return 130
    except RuntimeError as e:
        # Ctrl-C while Dr.Jit traces a symbolic loop or branch (Python called back from
        # C++): Dr.Jit re-raises what the callback raised as a RuntimeError caused by it.
        if not _caused_by(e, KeyboardInterrupt):
            raise
        print("whitted: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `whitted scenes | head`: the reader has all it wants
        _silence_stdout()
        return EXIT_OK
    except StdoutError as e:
        sys.stdout = stdout
        _silence_stdout()
        return fail(f"cannot write to standard output: {e}")
    except OSError as e:
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        return fail(f"{where}{e.strerror or e}")
    except RecursionError:
        return fail("input nested too deeply to process")
    except MemoryError:
        return fail("out of memory (lower the limits: WHITTED_MAX_MEMORY)")
    finally:
        sys.stdout = stdout


def entrypoint() -> None:
    """The ``whitted`` console script: :func:`main`, then a quick exit.

    When main returns, every file is written and closed and everything worth
    printing is printed. What the interpreter would still do (free each module,
    then Dr.Jit's arrays, thread pool and caches) only delays the shell: about
    35 ms of a 0.5 s `whitted render` (measured from a script that times its own
    steps against /usr/bin/time). So the streams are flushed and the process
    leaves with os._exit; should a flush fail, Python's own exit reports it.
    """
    from whitted.reference.malloc import keep_freed_memory

    keep_freed_memory()
    rc = main()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        sys.exit(rc)
    os._exit(rc)


if __name__ == "__main__":
    entrypoint()
