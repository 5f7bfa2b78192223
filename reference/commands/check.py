"""``whitted check``: judge another renderer's image of a scene against the reference."""

from __future__ import annotations

from pathlib import Path

from whitted.reference.commands.common import (
    film_summary,
    load_scene_arg,
    output_folder,
    shown,
    use_backend,
)
from whitted.reference.commands.options import (
    ENCODINGS,
    backend_opt,
    max_depth,
    parse_positive,
    parse_size,
    threshold_opts,
    thresholds,
)
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK


def add_parser(sub) -> None:
    ck = sub.add_parser(
        "check", help="judge another renderer's image against the reference",
        description="Judge IMAGE (OpenEXR, PFM, Radiance HDR, PNG or PPM P3/P6), made by any "
                    "renderer from SCENE, against whitted's reference for the scene: its "
                    "tracer's image (deterministic at the scene's strata; with --mitsuba also "
                    "Mitsuba's deterministic reference). Your image's noise comes from its "
                    "EXR variance layer, or from --spp N (the noise of N samples of Mitsuba's "
                    "path tracer), or is estimated from neighbouring pixels. Writes diff.png "
                    "(heat map), side_by_side.png, reference.exr, check.json and check.html "
                    "(a viewer: hover, flip, zoom). An image that fails gets its difference "
                    "split by light path and material, and the suspects: the three formula "
                    "bugs of the catalog (whitted mutants --list) whose image explains most "
                    "of it. Exit 0 when the image agrees, 1 when it "
                    "does not, 2 for bad input (an unreadable file, a size other than the "
                    "film's).")
    ck.add_argument("image", metavar="IMAGE", help="your renderer's image")
    ck.add_argument("--scene", required=True,
                    help="the scene it shows (.toml, built-in name, or Mitsuba 3 .xml: then "
                         "the import is also checked against Mitsuba's reading of the "
                         "original, a difference failing the check)")
    ck.add_argument("-o", "--output", default=None,
                    help="output folder (default: out/check/SCENE-IMAGE)")
    ck.add_argument("--encoding", choices=ENCODINGS, default=None,
                    help="how an 8-bit PNG or PPM encodes light: srgb (default), linear "
                         "(value / maxval, clipped at 1) or minray (255 x linear, no gamma, no "
                         "clamp: values above 255 allowed)")
    ck.add_argument("--spp", type=parse_positive, default=None,
                    help="your samples per pixel: judge your noise as that of N samples of "
                         "Mitsuba's path tracer (without it, and without a variance layer, "
                         "the noise is estimated from neighbouring pixels)")
    ck.add_argument("--size", type=parse_size, metavar="WxH",
                    help="the film size you rendered the scene at, e.g. 320x240")
    ck.add_argument("--max-depth", type=parse_positive, dest="max_depth",
                    help="the max_depth you rendered with (path segments)")
    ck.add_argument("--depth", type=parse_positive, dest="depth",
                    help="Heckbert's DEPTH you rendered with (= --max-depth DEPTH+1)")
    ck.add_argument("--mitsuba", action="store_true",
                    help="also judge the image against Mitsuba's deterministic reference, and "
                         "check the tracer's reference against it")
    ck.add_argument("--seed", type=int, default=0,
                    help="seed of the reference's light samples (scenes with area lights)")
    ck.add_argument("--no-suspects", action="store_true", dest="no_suspects",
                    help="for an image that fails, do not rank the catalog's formula bugs "
                         "by how much of the difference each explains (that renders the "
                         "scene once per bug it reaches, kept in ~/.cache/whitted/suspects or "
                         "WHITTED_SUSPECTS_CACHE)")
    backend_opt(ck)
    threshold_opts(ck)
    ck.set_defaults(func=run)


def run(args) -> int:
    from whitted.reference.check.images import read_user_image
    from whitted.reference.check.judge import check_image, format_run, write_outputs
    from whitted.tracer.errors import UserError
    from whitted.tracer.limits import check_render

    th = thresholds(args)
    user = read_user_image(args.image, args.encoding)   # bad input before any rendering
    # --spp is the image's samples, not the reference's: the film keeps the scene's strata.
    scene = load_scene_arg(args).with_overrides(
        max_depth=max_depth(args), size=args.size)
    w, h = scene.film.width, scene.film.height
    if user.size != (w, h):
        raise UserError(f"{shown(args.image)} is {user.size[0]}x{user.size[1]} pixels, the "
                        f"film of {scene.name} is {w}x{h} (render at {w}x{h}, or give --size "
                        f"{user.size[0]}x{user.size[1]} if you rendered the scene at that size)")
    check_render(scene, moments=True)
    if args.mitsuba or args.spp is not None:
        check_render(scene, mitsuba=True)
    if args.mitsuba:
        from whitted.reference.renderers.mitsuba.deterministic import shares_light_samples

        if not shares_light_samples(scene):
            raise UserError(f"--mitsuba: an emitter of {scene.name} has no shared light "
                            "samples (reference.renderers.mitsuba.deterministic.SAMPLE_MAPS), "
                            "so Mitsuba's "
                            "deterministic reference cannot render it")
    from whitted.reference.commands.common import resolve_scene
    from whitted.reference.renderers.mitsuba.original import check_and_print, is_xml

    # A scene given as XML: the reference renders its import, which the original judges.
    path = resolve_scene(args.scene)
    structure = check_and_print(path, getattr(args, "approximate", False)) \
        if is_xml(path) else None
    from whitted.reference.check.judge import (
        OPTIONAL_OUTPUT_NAMES,
        OUTPUT_NAMES,
        refuse_in_the_way,
    )
    from whitted.tracer.imageio import StagedFolder

    outdir = output_folder(args.output or Path("out") / "check" /
                           f"{scene.name}-{Path(args.image).stem}")
    refuse_in_the_way(outdir, OUTPUT_NAMES + OPTIONAL_OUTPUT_NAMES)
    # All five files or none: an error, a full disk or Ctrl-C leaves no partial output.
    with StagedFolder(outdir) as staged:
        use_backend(args)
        judged = check_image(user, scene, args.spp, th, mitsuba=args.mitsuba, seed=args.seed,
                             suspects=not args.no_suspects,
                             log=lambda m: print(m + " ...", flush=True))
        title = (f"{shown(args.image)} against {scene.name} ({film_summary(scene)}), read as "
                 f"{user.storage}")
        write_outputs(judged, staged.path, title, final=outdir)
        staged.commit()
    print(format_run(judged, title))
    print(f"wrote {shown(outdir)}/" + ", ".join(Path(f).name for f in judged.files.values()))
    original_passed = True
    if structure is not None:   # the tracer's reference against the original's own reading
        from whitted.reference.commands.common import check_lines
        from whitted.reference.renderers.mitsuba.original import (
            judge_against_original,
            original_lines,
        )

        verdict, _, why = judge_against_original(path, scene, None,
                                                 getattr(args, "approximate", False),
                                                 args.seed)
        print("\n".join(original_lines(verdict, why)))
        if verdict is not None:
            print("\n".join(check_lines(verdict.checks)))
            original_passed = verdict.passed
    if structure is not None and not structure.agrees:
        print(f"FAIL: the reference was rendered from the import, which differs from "
              f"Mitsuba's reading of the original ({len(structure.findings)} structural "
              "difference(s), printed above)")
        return EXIT_FAIL
    if not original_passed:
        print("FAIL: the reference (the tracer's render of the import) differs from Mitsuba's "
              "render of its own reading of the original (above)")
        return EXIT_FAIL
    return EXIT_OK if judged.passed else EXIT_FAIL

