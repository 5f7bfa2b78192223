"""``whitted report``: compare every scene of a folder and write the accuracy report."""

from __future__ import annotations

from pathlib import Path

from whitted.reference.commands.common import output_folder, use_backend
from whitted.reference.commands.options import backend_opt
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK
from whitted.scenes import SCENES_DIR


def add_parser(sub) -> None:
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
    backend_opt(rp)
    rp.set_defaults(func=run)


def run(args) -> int:
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
    use_backend(args)
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
    LuxCore's tests fail without it (tests/reference/renderers/luxcore/test_luxcore.py),
    not the report.
    """
    return not args.no_luxcore

