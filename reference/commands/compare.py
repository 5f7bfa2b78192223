"""``whitted compare``: render a scene with the tracer and with Mitsuba (and LuxCore)
and judge the two images; the verdict as the command prints it."""

from __future__ import annotations

import sys
from pathlib import Path

from whitted.reference.commands.common import (
    Progress,
    check_lines,
    load_with_options,
    note_spp,
    output_folder,
    shown,
    use_backend,
)
from whitted.reference.commands.options import scene_opts
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK


def add_parser(sub) -> None:
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
    c.set_defaults(func=run)


def format_comparison(c) -> str:
    m = c.metrics
    lines = [f"scene {c.scene}: {c.size[0]}x{c.size[1]}, {c.spp} spp, backend {c.backend}, "
             f"reference {c.reference} (integrator {c.integrator}), test {c.test}"]
    lines += check_lines(c.checks)
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
        lines += check_lines(so["checks"])
    if getattr(c, "tracer_only_model", None):
        tm = c.tracer_only_model
        lines.append(f"tracer-only parts against the harness's model ({', '.join(tm['models'])}"
                     f", reference {tm['reference']}), test {tm['test']}: "
                     f"{'pass' if tm['passed'] else 'FAIL'}")
        lines += check_lines(tm["checks"])
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
        lines += ["  " + line for line in check_lines(
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


def run(args) -> int:
    from whitted.reference.verdicts.compare import choose_test, comparable, compare_scene
    from whitted.tracer.errors import UserError
    from whitted.tracer.limits import check_render

    if args.renderer != "mitsuba":
        from whitted.reference.renderers.luxcore import render as luxcore

        luxcore.require()   # before anything renders
    scene = load_with_options(args)
    structure = _structure(args)
    if args.renderer == "luxcore":
        check_render(scene)
        status = _compare_luxcore(args, scene)
        return status if structure is None or structure.agrees else EXIT_FAIL
    reference = _reference_option(args)
    if reference == "direct" and choose_test(comparable(scene), "direct") == "z-test":
        given = "--integrator" if args.integrator is not None else "--reference"
        raise UserError(f"{given} direct: {scene.name} has mirrors, glass or sampled "
                        "lights, whose comparison needs the per-pixel variance that Mitsuba's "
                        "direct integrator does not give; use --reference deterministic "
                        "(the default) or onelobe")
    check_render(scene)
    check_render(scene, moments=True, mitsuba=True)
    note_spp(scene)
    if scene.film.filter != "box" or scene.film.jitter:
        print("note: compare judges both sides at the strata centres with the box filter "
              f"(the scene's {scene.film.filter} filter"
              f"{' and jitter' if scene.film.jitter else ''} weigh and place the same "
              "samples alike on both sides)", flush=True)
    outdir = output_folder(args.output or Path("out") / "compare" / scene.name)
    use_backend(args)
    result, tracer_image, _ = compare_scene(
        scene, outdir, reference, progress=Progress(f"render {scene.name}"),
        second_opinion=False if args.no_second_opinion else None, seed=args.seed)
    print(format_comparison(result))
    print(f"wrote {shown(outdir)}/" + ", ".join(Path(f).name for f in result.files.values()))
    original_passed = True
    if structure is not None and reference == "deterministic":
        original_passed = _against_original(args, scene, tracer_image, outdir)
    if structure is not None and not structure.agrees:
        print(f"FAIL: the images were rendered from the import, which differs from "
              f"Mitsuba's reading of the original ({len(structure.findings)} structural "
              "difference(s), printed above)")
        return EXIT_FAIL
    if not original_passed:
        print("FAIL: the tracer's image differs from Mitsuba's render of its own reading of "
              "the original (above)")
        return EXIT_FAIL
    if args.renderer == "all":
        try:
            return _compare_luxcore(args, scene, result)
        except UserError as e:   # LuxCore failed or ran past its limits: the vote is optional
            from whitted.tracer.errors import one_line

            print(f"note: LuxCore (the third renderer's vote): not available: "
                  f"{one_line(str(e), 300)}", file=sys.stderr, flush=True)
    return EXIT_OK if result.passed else EXIT_FAIL


def _against_original(args, scene, tracer_image, outdir) -> bool:
    """For a scene given as Mitsuba XML: the tracer's image judged against the
    deterministic reference evaluated on Mitsuba's own reading of the original file
    (:func:`reference.renderers.mitsuba.original.original_reference`), printed, the image
    written as ``mitsuba_original.exr``; True where it passes or cannot be made (said so)."""
    from whitted.reference.commands.common import resolve_scene
    from whitted.reference.renderers.mitsuba.deterministic import shares_light_samples
    from whitted.reference.renderers.mitsuba.original import (
        judge_against_original,
        original_lines,
    )
    from whitted.tracer.imageio import write_exr

    approximate = getattr(args, "approximate", False) or scene.approximate
    if not approximate and not shares_light_samples(scene) and args.size is None:
        return _against_original_render(args, scene)
    verdict, image, why = judge_against_original(resolve_scene(args.scene), scene,
                                                 tracer_image, approximate, args.seed)
    print("\n".join(original_lines(verdict, why)), flush=True)
    if verdict is None:
        return True
    write_exr(outdir / "mitsuba_original.exr", image)
    print("\n".join(check_lines(verdict.checks)))
    print(f"wrote {shown(outdir)}/mitsuba_original.exr", flush=True)
    return verdict.passed


def _against_original_render(args, scene) -> bool:
    """Where the deterministic reference cannot take the tracer's light samples (the
    one-lobe reference's scenes): Mitsuba's own render of the original file at max_depth 2
    against the tracer's render of the import at max_depth 2, at the file's film, filter
    and sampler, within the noise of both (importer.validate_case, the report's imported
    group); printed; True where it passes."""
    from whitted.reference.commands.common import resolve_scene
    from whitted.reference.renderers.mitsuba.importer import ImportedCase, validate_case

    path = resolve_scene(args.scene)
    print("original: Mitsuba's render of the original file (path, max_depth 2) against the "
          "tracer's of the import (max_depth 2), within the noise of both ...", flush=True)
    out = validate_case(ImportedCase(scene.name, "path", 16, 4, xml=path),
                        Path(args.output or Path("out") / "compare" / scene.name))
    print(f"original: z-test pixels passing {100 * out['z_fraction_passed']:.3f} %, image "
          f"means {100 * out['mean_rel_diff']:+.3f} % apart (z {out['mean_z']:+.2f}): "
          f"{'pass' if out['images_passed'] else 'FAIL'}", flush=True)
    return bool(out["images_passed"])


def _structure(args):
    """For a scene given as Mitsuba XML, its import judged by the original
    (:func:`reference.renderers.mitsuba.original.compare_structure`), printed; else None.
    Both sides render the import, so this is what sees an importer's mistake."""
    from whitted.reference.commands.common import resolve_scene
    from whitted.reference.renderers.mitsuba.original import check_and_print, is_xml

    path = resolve_scene(args.scene)
    if not is_xml(path):
        return None
    return check_and_print(path, getattr(args, "approximate", False))


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

