"""``whitted reference``: render a scene on Mitsuba 3 (or, with ``--renderer luxcore``,
on LuxCoreRender) after converting it to that renderer's plugins."""

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
from whitted.reference.commands.status import EXIT_OK


def add_parser(sub) -> None:
    ref = sub.add_parser("reference", help="render a scene on Mitsuba 3",
                         description="Render SCENE on Mitsuba 3 after converting it to Mitsuba's "
                                     "plugins.")
    scene_opts(ref, "output image (.exr, .png or .ppm)")
    ref.add_argument("--integrator", choices=("whitted", "direct", "path", "deterministic"),
                     default="whitted",
                     help="Mitsuba integrator: whitted (ours, one lobe per sample, every light "
                          "once per sample; default), direct or path (Mitsuba's), or "
                          "deterministic (the harness's loop over Mitsuba's plugins: both lobes, "
                          "the tracer's light samples of --seed; what compare uses)")
    ref.add_argument("--renderer", choices=("mitsuba", "luxcore"), default="mitsuba",
                     help="mitsuba (default) or luxcore: LuxCoreRender's path tracer at "
                          "Whitted's depths, spp jittered samples per pixel, in a child "
                          "process (needs the extra: pip install 'whitted[luxcore]')")
    ref.set_defaults(func=run)


def run(args) -> int:
    from whitted.tracer.imageio import check_output_path, write_image

    out = check_output_path(args.output)
    if args.renderer == "luxcore":
        return _reference_luxcore(args, out)
    scene = load_with_options(args)
    from whitted.tracer.limits import check_render

    check_render(scene, mitsuba=True)
    note_spp(scene)
    name = use_backend(args)
    from whitted.reference.renderers.mitsuba.render import render_reference

    result = render_reference(scene, args.integrator, seed=args.seed)
    check_finite(result.image, "Mitsuba's render")
    write_image(out, result.image)
    print(f"wrote {shown(out)} (Mitsuba, {args.integrator} integrator, {film_summary(scene)}, "
          f"{name}) in {result.seconds:.3f} s")
    return EXIT_OK


def _reference_luxcore(args, out) -> int:
    """``whitted reference --renderer luxcore``: LuxCore's image, spp jittered samples a pixel."""
    from whitted.reference.renderers.luxcore import render as luxcore
    from whitted.tracer.errors import UserError
    from whitted.tracer.imageio import write_image

    luxcore.require()
    if args.integrator != "whitted":
        raise UserError("--integrator: Mitsuba's integrators only; LuxCore renders with its "
                        "path tracer at Whitted's depths (reference/renderers/luxcore/scene.py)")
    scene = load_with_options(args)
    from whitted.reference.renderers.luxcore.scene import describe

    describe(scene)  # refuse in one line before the child starts
    note_spp(scene)
    s = scene.film.strata
    result = luxcore.render(scene, passes=1, seed=args.seed, subsamples=s,
                            progress=Progress(f"luxcore {scene.name}"))
    check_finite(result.image, "LuxCore's render")
    write_image(out, result.image)
    print(f"wrote {shown(out)} (LuxCore {luxcore.VERSION}, path tracer at Whitted's depths, "
          f"{scene.film.width}x{scene.film.height}, {s * s} jittered spp, max_depth "
          f"{scene.film.max_depth}) in {result.seconds:.3f} s")
    return EXIT_OK

