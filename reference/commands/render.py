"""``whitted render``: render a scene with whitted's own tracer (never imports Mitsuba)."""

from __future__ import annotations

from whitted.reference.commands.common import (
    Progress,
    check_finite,
    film_summary,
    load_with_options,
    note_spp,
    shown,
    use_backend,
)
from whitted.reference.commands.options import scene_opts
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK


def add_parser(sub) -> None:
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
    r.add_argument("--verify", action="store_true",
                   help="for a Mitsuba XML scene: before rendering, load the original with "
                        "Mitsuba and check that its reading of the import agrees object by "
                        "object (camera, shapes, BSDFs, emitters); exit 1 with the "
                        "differences if not (without it, render never loads Mitsuba)")
    r.set_defaults(func=run)


def run(args) -> int:
    from whitted.tracer.imageio import check_output_path, write_image

    out = check_output_path(args.output)
    if args.lpe is not None:
        from whitted.tracer.lpe import compile_lpe

        compile_lpe(args.lpe)  # refuse a bad expression before anything renders
    scene = load_with_options(args)
    from whitted.reference.commands.common import resolve_scene

    path = resolve_scene(args.scene)
    xml = str(path).lower().endswith(".xml")
    if args.verify:
        from whitted.tracer.errors import UserError

        if not xml:
            raise UserError("--verify: checks a Mitsuba XML scene's import against Mitsuba's "
                            f"reading of the original; {shown(args.scene)} is not .xml")
        from whitted.reference.renderers.mitsuba.original import check_and_print

        if not check_and_print(path, getattr(args, "approximate", False)).agrees:
            return EXIT_FAIL
    elif xml:
        print("note: the import's structure is not checked against Mitsuba's reading of the "
              "original (--verify checks it; render never loads Mitsuba without it)", flush=True)
    from whitted.tracer.limits import check_render

    check_render(scene)
    note_spp(scene)
    name = use_backend(args)
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
    print(f"wrote {shown(out)} ({film_summary(scene)}, {name}{only}) in {result.seconds:.3f} s; "
          f"rays per level: {rays}; shadow rays: {sum(result.shadow_rays_per_level)}")
    return EXIT_OK

