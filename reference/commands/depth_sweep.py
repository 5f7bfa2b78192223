"""``whitted depth-sweep``: runtime and rays of a scene against recursion depth."""

from __future__ import annotations

from whitted.reference.commands.common import (
    film_summary,
    load_with_options,
    note_spp,
    shown,
    use_backend,
)
from whitted.reference.commands.options import scene_opts
from whitted.reference.commands.status import EXIT_OK


def add_parser(sub) -> None:
    ds = sub.add_parser("depth-sweep", help="runtime and rays against recursion depth",
                        description="Render SCENE at each DEPTH (Heckbert's numbering: "
                                    "max_depth = DEPTH + 1), timing the tracer (median of "
                                    "--repeat runs after a warm-up) and Mitsuba's reference; "
                                    "write depth_NN.png, runtimes.txt and runtimes.png.")
    scene_opts(ds, "output folder")
    ds.add_argument("--depths", default="1-5,10,20,25",
                    help="DEPTH values: numbers and ranges (default: 1-5,10,20,25)")
    ds.add_argument("--repeat", type=int, default=3, help="timed runs per depth (default 3)")
    ds.add_argument("--no-mitsuba", action="store_true", help="do not time Mitsuba alongside")
    ds.add_argument("--min-weight", type=float, default=0.0,
                    help="drop branches whose weight falls to this or below (biased; default "
                         "0: exact Whitted, only zero-weight branches are dropped)")
    ds.set_defaults(func=run)


#: Most timed runs per depth of a depth sweep.
MAX_REPEAT = 100


def run(args) -> int:
    from whitted.reference.teaching.depth_sweep import (
        depth_sweep,
        explain,
        parse_depths,
        write_outputs,
    )
    from whitted.tracer.errors import UserError

    depths = parse_depths(args.depths)
    if not 1 <= args.repeat <= MAX_REPEAT:
        raise UserError(f"--repeat: expected a number from 1 to {MAX_REPEAT}, got "
                        f"{args.repeat:,}")
    if not args.min_weight >= 0:
        raise UserError(f"--min-weight: expected a number >= 0, got {args.min_weight}")
    scene = load_with_options(args)
    from whitted.tracer.imageio import StagedFolder
    from whitted.tracer.limits import check_render

    deepest = scene.with_overrides(max_depth=max(depths) + 1)
    check_render(deepest)
    if not args.no_mitsuba:
        check_render(deepest, mitsuba=True)
    note_spp(scene)
    # The images appear in the folder only when the sweep is complete: an interrupted
    # or failed sweep leaves nothing behind.
    with StagedFolder(args.output) as staged:
        use_backend(args)
        print(f"depth sweep of {scene.name} ({film_summary(scene).rsplit(',', 1)[0]}), DEPTH "
              f"{', '.join(map(str, depths))}, {args.repeat} timed run(s) each", flush=True)
        rows = depth_sweep(scene, depths, args.repeat, staged.path, mitsuba=not args.no_mitsuba,
                           log=lambda m: print(m, flush=True), min_weight=args.min_weight,
                           seed=args.seed)
        files = write_outputs(rows, staged.path, scene.name)
        staged.commit()
    print(explain(rows))
    print("wrote " + ", ".join(shown(staged.final(f)) for f in files) +
          f" and depth_*.png in {shown(staged.target)}")
    return EXIT_OK

