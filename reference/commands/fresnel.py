"""``whitted fresnel``: tabulate the Fresnel curves against Mitsuba's and print the table."""

from __future__ import annotations

from whitted.reference.commands.common import output_folder, shown, use_backend
from whitted.reference.commands.options import backend_opt
from whitted.reference.commands.status import EXIT_FAIL, EXIT_OK


def add_parser(sub) -> None:
    f = sub.add_parser("fresnel", help="compare Fresnel curves with Mitsuba's",
                       description="Tabulate our exact Fresnel reflectance and Schlick's "
                                   "approximation over 0..90 degrees from both sides of the "
                                   "boundary, against mi.fresnel and the reflection probability "
                                   "of Mitsuba's dielectric plugin (measured by sampling). "
                                   "Writes fresnel.csv, fresnel.png and fresnel.json; exits 1 "
                                   "when exact and mi.fresnel differ beyond float32 rounding or "
                                   "the plugin disagrees beyond its binomial interval.")
    f.add_argument("-o", "--output", required=True, help="output folder")
    f.add_argument("--ior", type=float, nargs="+", default=[1.0, 1.33, 1.5, 2.42],
                   help="indices of refraction against ext_ior = 1 (default: 1.0 1.33 1.5 2.42)")
    f.add_argument("--step", type=float, default=0.5, help="angle step in degrees (default 0.5)")
    f.add_argument("--samples", type=int, default=100_000,
                   help="plugin samples per angle (default 100000)")
    f.add_argument("--seed", type=int, default=0,
                   help="seed of the plugin's sample numbers (any integer)")
    backend_opt(f)
    f.set_defaults(func=run)


def run(args) -> int:
    from whitted.tracer.errors import UserError

    for ior in args.ior:
        if not (ior > 0 and ior < 1e6):
            raise UserError(f"--ior: expected positive numbers, got {ior:g}")
    if args.samples < 100:
        raise UserError(f"--samples: expected at least 100, got {args.samples}")
    if not 0 < args.step <= 45:
        raise UserError(f"--step: expected a number of degrees in (0, 45], got {args.step:g}")
    from whitted.tracer import limits

    # Per index and side, one table row per angle step, each sampled --samples times.
    per_table = (int(90 / args.step) + 2) * args.samples
    limits.check_samples(2 * len(args.ior) * per_table, "the Fresnel table")
    limits.check_memory(per_table * limits.FRESNEL_BYTES_PER_SAMPLE, "the Fresnel table")
    out = output_folder(args.output)
    use_backend(args)
    from whitted.reference.teaching.fresnel_curves import fresnel_table, write_outputs

    table = fresnel_table(tuple(args.ior), args.step, args.samples, args.seed)
    files = write_outputs(table, out)
    print(format_fresnel(table))
    print("wrote " + ", ".join(shown(f) for f in files))
    return EXIT_OK if table.passed else EXIT_FAIL


def format_fresnel(table) -> str:
    lines = [f"{'ior':>5} {'side':<8} {'|exact-mi.fresnel|':>19} {'/tol':>6} "
             f"{'|plugin-exact|':>15} {'/CI':>6} {'|Schlick-exact|':>16} {'at':>6}  check"]
    for s in table.summary:
        ok = s["pass"]
        lines.append(
            f"{s['ior']:5g} {s['side']:<8} {s['max_abs_exact_minus_mitsuba']:19.2e} "
            f"{s['worst_exact_vs_mitsuba_over_tolerance']:6.2f} "
            f"{s['max_abs_plugin_minus_exact']:15.2e} "
            f"{s['worst_plugin_deviation_in_half_intervals']:6.2f} "
            f"{s['max_abs_schlick_minus_exact']:16.4f} {s['schlick_worst_theta_deg']:5.1f}d  "
            f"{'pass' if ok else 'FAIL'}")
    lines.append(f"{'conductor':>9} {'ch':<4} {'|ours-mi.fresnel_conductor|':>28} {'/tol':>6}"
                 f" {'|ours-float64|':>15}  check")
    for c in table.conductors:
        lines.append(f"{c['conductor']:>9} {c['channel']:<4} "
                     f"{c['max_abs_ours_minus_mitsuba']:28.2e} {c['worst_over_tolerance']:6.2f} "
                     f"{c['max_abs_ours_minus_float64']:15.2e}  "
                     f"{'pass' if c['pass'] else 'FAIL'}")
    lines.append(("PASS" if table.passed else "FAIL") +
                 " (exact vs mi.fresnel and conductors vs mi.fresnel_conductor within float32 "
                 "rounding; exact inside the plugin's binomial interval)")
    return "\n".join(lines)

