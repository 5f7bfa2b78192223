"""``whitted export``: write a scene as a Mitsuba 3 XML file."""

from __future__ import annotations

from whitted.reference.commands.common import load_with_options, shown
from whitted.reference.commands.options import scene_opts
from whitted.reference.commands.status import EXIT_OK


def add_parser(sub) -> None:
    e = sub.add_parser("export", help="write the scene as Mitsuba 3 XML",
                       description="Write SCENE as a Mitsuba 3 XML file that Mitsuba renders "
                                   "to the same picture as `whitted reference`.")
    scene_opts(e, "output .xml file (triangles go to meshes/NAME_*.obj beside it)", seed=False)
    e.add_argument("--integrator", choices=("whitted", "direct", "path"), default="whitted",
                   help="integrator written into the XML (whitted needs `import whitted.reference` "
                        "before loading; direct and path are stock Mitsuba)")
    e.set_defaults(func=run)


def run(args) -> int:
    from whitted.tracer.imageio import check_output_path

    out = check_output_path(args.output, (".xml",), "file type")
    scene = load_with_options(args)
    from whitted.tracer.limits import check_depth

    check_depth(scene.film.max_depth)  # Mitsuba reads it as a 32-bit integer
    from whitted.reference.renderers.mitsuba.scene import write_xml

    files = write_xml(scene, out, args.integrator)
    print("wrote " + ", ".join(shown(f) for f in files))
    return EXIT_OK

