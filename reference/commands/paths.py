"""``whitted paths``: draw chosen pixels' ray trees with their light paths."""

from __future__ import annotations

from whitted.reference.commands.common import check_finite, load_with_options, shown, use_backend
from whitted.reference.commands.options import scene_opts
from whitted.reference.commands.status import EXIT_OK


def add_parser(sub) -> None:
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
    pa.set_defaults(func=run)


def run(args) -> int:
    from whitted.tracer.imageio import check_output_path

    out = check_output_path(args.output, (".png",))
    scene = load_with_options(args)
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
    use_backend(args)
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

