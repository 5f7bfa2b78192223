"""``whitted assignment``: the first lecture's assignment (Heckbert's business-card
ray tracer) in one run."""

from __future__ import annotations

from whitted.reference.commands.common import output_folder, use_backend
from whitted.reference.commands.options import backend_opt, parse_positive
from whitted.reference.commands.status import EXIT_OK


def add_parser(sub) -> None:
    a = sub.add_parser("assignment", help="the first lecture's assignment, in one run",
                       description="Heckbert's business-card ray tracer assignment: "
                                   "heckbert_depth1.png ... heckbert_depth5.png and a DEPTH "
                                   "20+ image, heckbert_runtimes1.txt and .png (runtime and "
                                   "rays against DEPTH, with the rays minray traces), "
                                   "light_paths.png (LE, LDE, LSE, LDDE, LDSE, LSDE) and "
                                   "observations.md, rendered with the classic model that "
                                   "prints minray's numbers. About a minute at 256x256.")
    a.add_argument("-o", "--output", required=True, help="output folder")
    a.add_argument("--size", type=parse_positive, default=256,
                   help="image width and height in pixels (default 256)")
    a.add_argument("--depths", default="1-10,15,20",
                   help="DEPTHs of the runtime sweep; the deepest also gets a picture "
                        "(default 1-10,15,20)")
    a.add_argument("--repeat", type=int, default=3, help="timed renders per DEPTH (default 3)")
    a.add_argument("--no-mitsuba", action="store_true",
                   help="leave out the LDDE/LSDE panel rendered with Mitsuba's path tracer")
    backend_opt(a)
    a.set_defaults(func=run)


def run(args) -> int:
    from whitted.reference.teaching.depth_sweep import parse_depths
    from whitted.tracer.errors import UserError

    depths = tuple(parse_depths(args.depths))
    if max(depths) < 5:
        raise UserError(f"--depths: expected a DEPTH of 5 or more (the assignment asks for "
                        f"1 to 5 and 20+), got {args.depths!r}")
    if args.repeat < 1:
        raise UserError(f"--repeat: expected a positive number, got {args.repeat}")
    out = output_folder(args.output)
    use_backend(args)
    from whitted.reference.teaching.assignment import run as run_assignment

    print(f"whitted assignment: heckbert_minray at {args.size}x{args.size}, DEPTH "
          f"{', '.join(map(str, depths))} -> {out}/", flush=True)
    res = run_assignment(out, args.size, depths, args.repeat, mitsuba=not args.no_mitsuba,
                         log=lambda m: print(m, flush=True))
    print("wrote " + ", ".join(f.name for f in res.files) + f" in {res.seconds:.0f} s")
    return EXIT_OK

