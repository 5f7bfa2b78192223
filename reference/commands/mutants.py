"""``whitted mutants``: show that the comparison catches each formula bug of the
catalog (reference/mutants.py)."""

from __future__ import annotations

from pathlib import Path

from whitted.reference.commands.common import output_folder, shown, use_backend
from whitted.reference.commands.options import backend_opt
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK
from whitted.scenes import SCENES_DIR


def add_parser(sub) -> None:
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
    backend_opt(mu)
    mu.set_defaults(func=run)


def run(args) -> int:
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
    use_backend(args)
    size = "full" if args.full else "quick"
    print(f"whitted mutants: {len(chosen)} mutant(s) x {len(paths)} scene(s) and "
          f"{len(mutants.structure_sources(args.scenes))} Mitsuba XML file(s), {size} sizes",
          flush=True)
    result = mutants.sweep(paths, chosen, quick=not args.full,
                           log=lambda m: print(m, flush=True),
                           xml_sources=mutants.structure_sources(args.scenes))
    print(mutants.format_table(result))
    if out is not None:
        from whitted.reference.verdicts.compare import write_json

        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "mutants.json", result.to_json())
        (out / "mutants.md").write_text(mutants.markdown(result))
        print(f"wrote {shown(out)}/mutants.json, mutants.md")
    return EXIT_OK if result.passed else EXIT_FAIL

