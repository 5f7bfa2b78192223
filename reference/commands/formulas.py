"""``whitted formulas``: test another renderer's formulas one function at a time, against
Mitsuba's functions or the tracer's, and name the catalog's bug a wrong one matches."""

from __future__ import annotations

from whitted.reference.commands.common import shown, use_backend
from whitted.reference.commands.options import backend_opt
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK


def _seconds(text: str) -> float:
    import argparse

    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not 0 < v <= 3600:
        raise argparse.ArgumentTypeError(f"expected seconds in (0, 3600], got {text!r}")
    return v


def add_parser(sub) -> None:
    f = sub.add_parser(
        "formulas", help="test a renderer's formulas one function at a time",
        description="Send each formula's inputs (ray-sphere and ray-triangle intersection, "
                    "reflect, refract, Fresnel exact, Schlick and conductor, Lambert, Phong, "
                    "Blinn-Phong, the camera's ray, a point light, the spot's falloff, an "
                    "instance's normal; grazing, from inside, total internal reflection, misses) "
                    "to an adapter: a program answering JSON lines on stdin and stdout "
                    "(--program), or a Python callable (--python). Each answer is compared with "
                    "Mitsuba's function where it has one, else with the tracer's, within a "
                    "stated float32 tolerance; a failing formula prints its first failing "
                    "input, the expected and the given output, and the catalog bug whose "
                    "outputs equal the given ones. Exit 0 all pass, 1 any fails, 2 a bad "
                    "adapter (it crashed, timed out or answered garbage). Protocol: "
                    "docs/formulas.md.")
    how = f.add_mutually_exclusive_group()
    how.add_argument("--program", metavar="COMMAND",
                     help="the adapter program and its arguments, e.g. "
                          "'python3 docs/formulas/adapter.py' (split as a shell would, not "
                          "run by one)")
    how.add_argument("--python", metavar="MODULE:FUNCTION",
                     help="a Python callable f(name, inputs) -> outputs, as module:function "
                          "or path/to/file.py:function")
    how.add_argument("--list", action="store_true",
                     help="print every formula's inputs, outputs, reference and tolerance")
    f.add_argument("--formulas", metavar="NAMES", action="append", default=None,
                   help="only these formulas (comma-separated names or globs, e.g. "
                        "'fresnel_*,reflect'); default all")
    f.add_argument("--timeout", type=_seconds, default=10.0, metavar="SECONDS",
                   help="the most one answer may take (default 10)")
    f.add_argument("--json", metavar="FILE", default=None,
                   help="also write the results as JSON to FILE")
    backend_opt(f)
    f.set_defaults(func=run)


def run(args) -> int:
    from whitted.reference.check import formulas as lib
    from whitted.tracer.errors import UserError

    if args.list:
        print(lib.describe())
        return EXIT_OK
    if not (args.program or args.python):
        raise UserError("give the adapter: --program COMMAND or --python MODULE:FUNCTION "
                        "(docs/formulas.md)")
    chosen = lib.select_formulas(args.formulas)
    json_path = None
    if args.json:
        from pathlib import Path

        json_path = Path(args.json)
        if json_path.is_dir():
            raise UserError(f"--json: {shown(json_path)} is a folder")
        if not json_path.parent.is_dir():
            raise UserError(f"--json: {shown(json_path.parent)}: no such folder")
    use_backend(args)
    if args.program:
        adapter, label = lib.ProgramAdapter(args.program, args.timeout), args.program
    else:
        adapter, label = lib.PythonAdapter(args.python, args.timeout), args.python
    print(f"{'formula':<20} {'cases':>5}  result", flush=True)
    result = lib.run(chosen, adapter, label,
                     log=lambda r: print(lib.format_result(r), flush=True))
    print(lib.format_summary(result))
    if json_path is not None:
        from whitted.reference.verdicts.compare import write_json

        write_json(json_path, result.to_json())
        print(f"wrote {shown(json_path)}")
    return EXIT_OK if result.passed else EXIT_FAIL
