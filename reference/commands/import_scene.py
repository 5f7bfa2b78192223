"""``whitted import``: write a Mitsuba 3 XML scene as a TOML scene."""

from __future__ import annotations

from whitted.reference.commands.common import shown
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK


def add_parser(sub) -> None:
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
                    help="also load the file with Mitsuba and check that Mitsuba's reading of "
                         "the import agrees with its reading of the original, object by "
                         "object (camera, film, shapes, BSDFs, emitters); exit 1 with the "
                         "differences, nothing written, if not")
    im.set_defaults(func=run)


def run(args) -> int:
    from whitted.reference.renderers.mitsuba.importer import check_output, write_import
    from whitted.tracer.errors import UserError
    from whitted.tracer.mitsuba_xml import shown_value

    out = check_output(args.output)  # its folder is made once the import has been checked
    params = {}
    for item in args.param or []:
        name, sep, value = item.partition("=")
        shown_item = shown_value(item)
        if not sep or not name or not value.strip():
            raise UserError(f"-D {shown_item!r}: expected NAME=VALUE with a value")
        params[name] = value
    from whitted.reference.renderers.mitsuba.original import StructureMismatch

    try:
        scene, imp = write_import(args.xml, out, args.approximate, args.verify, **params)
    except StructureMismatch as e:
        print("\n".join(e.structure.lines()), flush=True)
        print(f"nothing written: {shown(out)}", flush=True)
        return EXIT_FAIL
    for line in imp.warnings + imp.cautions:
        print(f"warning: {line}", flush=True)
    if args.verify:
        print(imp.structure.summary(), flush=True)
    n = sum(len(v) for v in imp.notes.values())
    print(f"wrote {shown(out)} ({len(scene.shapes)} shapes, {len(scene.lights)} lights; "
          f"{n} notes as comments" + (", APPROXIMATE" if imp.approximate else "")
          + (", verified against Mitsuba's reading of the original" if args.verify else "")
          + ")")
    return EXIT_OK

