"""``whitted schema``: print the JSON Schema of the TOML scene format."""

from __future__ import annotations

import sys

from whitted.reference.commands.common import shown
from whitted.reference.commands.status import EXIT_OK


def add_parser(sub) -> None:
    sc = sub.add_parser(
        "schema", help="print the JSON Schema of the TOML scene format",
        description="Print the JSON Schema (draft 2020-12) of the TOML scene format, derived "
                    "from the scene loader's own parsers, for editors: a `#:schema` line at "
                    "the top of a scene points TOML language servers (Taplo, Even Better TOML) "
                    "at it for completion and inline errors (docs/scene-format.md).")
    sc.add_argument("-o", "--output", metavar="FILE",
                    help="write the schema to FILE (.json) instead of standard output")
    sc.set_defaults(func=run)


def run(args) -> int:
    from whitted.tracer.schema import schema_text

    if args.output is None:
        sys.stdout.write(schema_text())
        return EXIT_OK
    from whitted.tracer.imageio import check_output_path

    out = check_output_path(args.output, (".json",), "file type")
    out.write_text(schema_text())
    print("wrote " + shown(out))
    return EXIT_OK

