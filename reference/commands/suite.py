"""``whitted suite``: hand out every built-in scene with its reference, or grade a
folder of images against such a suite."""

from __future__ import annotations

from pathlib import Path

from whitted.reference.commands.common import output_folder, shown, use_backend
from whitted.reference.commands.options import (
    ENCODINGS,
    backend_opt,
    parse_positive,
    threshold_opts,
    thresholds,
)
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK
from whitted.scenes import builtin_scenes


def add_parser(sub) -> None:
    su = sub.add_parser(
        "suite", help="hand out every built-in scene, or grade a folder of images",
        description="export DIR: write every built-in scene (or those matching --scenes) into "
                    "DIR as TOML and Mitsuba 3 XML, with its reference (EXR with variance "
                    "layers, and PNG) and a manifest (manifest.json, README.md: size, what "
                    "each scene tests, which formulas). check DIR: grade a folder of images "
                    "named after the scenes (NAME.exr, .pfm, .hdr, .png or .ppm) against the "
                    "references of --suite SUITE (or references rendered now), as `whitted "
                    "check` does; write index.html, suite.json, a Gradescope autograder "
                    "results.json and a JUnit junit.xml; exit 1 if any scene fails "
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
                    help="check: folder for index.html, suite.json, results.json and "
                         "junit.xml (default: DIR/whitted-check)")
    su.add_argument("--encoding", choices=ENCODINGS, default=None,
                    help="check: how 8-bit images encode light (as in `whitted check`)")
    su.add_argument("--spp", type=parse_positive, default=None,
                    help="check: your samples per pixel (as in `whitted check`)")
    su.add_argument("--update", action="store_true",
                    help="check: store the images as the suite's references (your golden "
                         "images), refused when the run fails")
    backend_opt(su)
    threshold_opts(su)
    su.set_defaults(func=run)


def run(args) -> int:
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
            use_backend(args)
            print(f"whitted suite export: {len(paths)} scene(s) -> {shown(staged.target)}/",
                  flush=True)
            suite.export(staged.path, paths, log=lambda m: print(m, flush=True))
            staged.commit()
        print(f"wrote {shown(staged.target)}/manifest.json, README.md, scenes/, mitsuba/, "
              "references/")
        return EXIT_OK
    th = thresholds(args)
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
        use_backend(args)
        result = suite.grade(images, chosen, args.scenes, args.encoding, args.spp, th,
                             log=lambda m: print(m, flush=True))
        suite.write_outputs(result, staged.path)
        files = []
        if args.update and result.passed:
            files = suite.stage_references(result, chosen, pending)
        pending.commit()
        staged.commit()
    print(suite.format_suite(result))
    print(f"wrote {shown(out)}/{', '.join(suite.OUTPUT_NAMES)}")
    if args.update:
        if not result.passed:
            print("references not updated: the run fails (fix the failing scenes first)")
            return EXIT_FAIL
        print(f"updated {len(files)} reference(s) in {shown(suite_dir)}/references/")
    return EXIT_OK if result.passed else EXIT_FAIL

