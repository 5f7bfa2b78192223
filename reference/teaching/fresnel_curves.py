"""Fresnel curves: our exact and Schlick formulas against Mitsuba's, over 0..90 degrees.

For each index of refraction and each side of the boundary (``outside``: the
ray arrives from the ext_ior = 1 side; ``inside``: from the ior side, through
total internal reflection), four reflectances are tabulated per angle:

* ``exact``: :func:`tracer.fresnel.fresnel_exact`, in float32;
* ``schlick``: :func:`tracer.fresnel.fresnel_schlick`, in float32;
* ``mitsuba``: ``mi.fresnel``, Mitsuba's implementation, in float32;
* ``plugin``: the probability with which Mitsuba's ``dielectric`` plugin
  chooses reflection in ``BSDF.sample``, measured as the fraction of
  reflections among N samples drawn with independent uniform numbers.

Two checks decide the exit status:

* exact vs ``mi.fresnel``: both evaluate the same formula in float32, so they
  may differ only as much as rounding allows. The allowance at each angle is
  the change of R (computed in float64) when cos(theta) moves by 16 ulp, plus
  16 ulp of R: near the critical angle, where dR/dcos is unbounded, rounding
  legitimately moves R by far more than an ulp;
* exact vs plugin: k reflections in N independent trials are binomial; the
  exact R must lie in the Wilson score interval of k / N at confidence
  1 - 0.01 / M for M angles in all (Bonferroni), so that a correct plugin
  fails the whole table with probability below 1 %.

Schlick's approximation is not required to agree; its largest error is reported.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

DEFAULT_IORS = (1.0, 1.33, 1.5, 2.42)
#: Named conductors whose curves are checked (``tracer.ior.CONDUCTORS``).
DEFAULT_CONDUCTORS = ("Au", "Cu", "Al", "none")
ULP = 2.0 ** -24
ALPHA = 0.01


def exact64(cos_i: np.ndarray, eta: float) -> np.ndarray:
    """The exact Fresnel reflectance in float64 (numpy), the yardstick for rounding."""
    c = np.abs(cos_i)
    rel = np.where(cos_i >= 0, eta, 1 / eta)
    sin2_t = (1 - c * c) / (rel * rel)
    tir = sin2_t > 1
    ct = np.sqrt(np.maximum(1 - sin2_t, 0))
    with np.errstate(invalid="ignore", divide="ignore"):
        rs = (c - rel * ct) / (c + rel * ct)
        rp = (rel * c - ct) / (rel * c + ct)
        r = 0.5 * (rs * rs + rp * rp)
    r = np.where(tir, 1.0, r)
    return np.where(rel == 1, 0.0, np.where(c == 0, 1.0, r))


def float32_tolerance(cos_i: np.ndarray, eta: float, ulps: int = 16) -> np.ndarray:
    """How far two float32 evaluations of R may differ at cos_i (see module doc)."""
    d = ulps * ULP * np.maximum(np.abs(cos_i), ULP)
    r = exact64(cos_i, eta)
    up = np.abs(exact64(np.clip(cos_i + d, -1, 1), eta) - r)
    down = np.abs(exact64(np.clip(cos_i - d, -1, 1), eta) - r)
    # Do not step across zero: the side of the boundary is not a rounding matter.
    up = np.where(np.sign(cos_i + d) != np.sign(cos_i), 0, up)
    down = np.where(np.sign(cos_i - d) != np.sign(cos_i), 0, down)
    return np.maximum(up, down) + ulps * ULP * np.maximum(r, ULP)


def conductor64(cos_i: np.ndarray, eta: float, k: float) -> np.ndarray:
    """A conductor's Fresnel reflectance in float64 from pbrt-v4's complex form (``FrComplex``,
    section 9.3): the dielectric equations with n_t = eta + i k, for the rounding yardstick."""
    c = np.minimum(np.abs(cos_i), 1).astype(np.complex128)
    n = complex(eta, k)
    cos_t = np.sqrt(1 - (1 - c * c) / (n * n))
    r_par = (n * c - cos_t) / (n * c + cos_t)
    r_perp = (c - n * cos_t) / (c + n * cos_t)
    return 0.5 * (np.abs(r_par) ** 2 + np.abs(r_perp) ** 2)


def conductor_tolerance(cos_i: np.ndarray, eta: float, k: float, ulps: int = 16) -> np.ndarray:
    """How far two float32 evaluations of a conductor's R may differ (as for glass above)."""
    d = ulps * ULP * np.maximum(np.abs(cos_i), ULP)
    r = conductor64(cos_i, eta, k)
    up = np.abs(conductor64(np.clip(cos_i + d, 0, 1), eta, k) - r)
    down = np.abs(conductor64(np.clip(cos_i - d, 0, 1), eta, k) - r)
    return np.maximum(up, down) + ulps * ULP * np.maximum(r, ULP)


def conductor_curves(mi, names=DEFAULT_CONDUCTORS, step: float = 0.5) -> list[dict]:
    """Per named conductor and RGB channel: :func:`tracer.fresnel.fresnel_conductor` against
    ``mi.fresnel_conductor`` in float32, within :func:`conductor_tolerance`, and both against
    the float64 complex form."""

    from whitted.tracer import fresnel
    from whitted.tracer.backend import jit
    from whitted.tracer.ior import CONDUCTORS

    theta = np.arange(0, 90 + 1e-9, step)
    cos32 = np.cos(np.radians(theta)).astype(np.float32)
    cos64 = cos32.astype(np.float64)
    out = []
    for name in names:
        eta, k = CONDUCTORS[name]
        for ch, channel in enumerate("rgb"):
            ours = np.asarray(fresnel.fresnel_conductor(
                jit.Float(cos32), jit.Float(np.float32(eta[ch])), jit.Float(np.float32(k[ch]))),
                dtype=np.float64)
            theirs = np.asarray(mi.fresnel_conductor(
                mi.Float(cos32), mi.Complex2f(float(eta[ch]), float(k[ch]))), dtype=np.float64)
            tol = conductor_tolerance(cos64, eta[ch], k[ch])
            exact = conductor64(cos64, eta[ch], k[ch])
            d = np.abs(ours - theirs)
            ok = bool(np.all(d <= tol))
            out.append({"conductor": name, "channel": channel, "eta": eta[ch], "k": k[ch],
                        "max_abs_ours_minus_mitsuba": float(d.max()),
                        "worst_over_tolerance": float(np.max(d / tol)),
                        "max_abs_ours_minus_float64": float(np.abs(ours - exact).max()),
                        "pass": ok})
    return out


def wilson_interval(k: np.ndarray, n: int, z: float) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval for a binomial proportion k / n."""
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return np.maximum(centre - half, 0), np.minimum(centre + half, 1)


def normal_quantile(p: float) -> float:
    """z with P(Z > z) = p for a standard normal Z (bisection on erfc)."""
    lo, hi = 0.0, 40.0
    for _ in range(200):
        mid = (lo + hi) / 2
        if 0.5 * math.erfc(mid / math.sqrt(2)) > p:
            lo = mid
        else:
            hi = mid
    return (lo + hi) / 2


@dataclass
class FresnelTable:
    rows: list[dict]
    summary: list[dict]
    passed: bool
    samples: int
    #: conductor curves: per named conductor and channel, ours against mi.fresnel_conductor
    conductors: list[dict] = field(default_factory=list)


def _ours(cos_i: np.ndarray, eta: float):
    from whitted.tracer import fresnel
    from whitted.tracer.backend import jit

    c = jit.Float(cos_i.astype(np.float32))
    e = jit.Float(np.float32(eta))
    return (np.asarray(fresnel.fresnel_exact(c, e), dtype=np.float64),
            np.asarray(fresnel.fresnel_schlick(c, e), dtype=np.float64))


def _plugin_reflect_fraction(mi, ior: float, cos_i: np.ndarray, samples: int, seed: int):
    """Reflections counted in ``samples`` calls of the dielectric plugin's sample() per angle.

    One Dr.Jit kernel draws, samples and counts (``samples`` consecutive lanes per angle,
    summed by a block reduction): 18 million calls an ior and side at the full table.
    """
    import drjit as dr

    bsdf = mi.load_dict({"type": "dielectric", "int_ior": float(ior), "ext_ior": 1.0})
    m = len(cos_i)
    n = m * samples
    idx = dr.arange(mi.UInt32, n) // samples
    c = dr.gather(mi.Float, mi.Float(cos_i.astype(np.float32)), idx)
    sin_i = np.sqrt(np.maximum(1 - cos_i.astype(np.float64) ** 2, 0)).astype(np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(dr.gather(mi.Float, mi.Float(sin_i), idx), 0.0, c)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    # Independent uniform numbers, one PCG32 stream a lane (O'Neill 2014), as odd multiples
    # of 2^-24: inside (0, 1), since the plugin reflects when u <= R and u = 0 would
    # reflect even where R = 0 (equal indices); 24-bit values are exact in float32.
    rng = mi.PCG32(n, dr.opaque(mi.UInt64, 0x853C49E6748FEA9B + seed),
                   dr.arange(mi.UInt64, n))
    u1 = mi.Float((rng.next_uint32() >> 8) | 1) * (1.0 / (1 << 24))
    bs, weight = bsdf.sample(mi.BSDFContext(), si, u1, mi.Point2f(0.5, 0.5))
    reflected = mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaReflection)
    valid = (dr.max(weight) > 0) | reflected
    k = dr.block_sum(dr.select(reflected & valid, mi.UInt32(1), mi.UInt32(0)), samples)
    return np.asarray(k, dtype=np.float64)


def fresnel_table(iors=DEFAULT_IORS, step: float = 0.5, samples: int = 100_000,
                  seed: int = 0) -> FresnelTable:
    """Tabulate and check the curves for every ior and both sides (see module doc)."""
    from whitted.reference import mitsuba

    mi = mitsuba()
    theta = np.arange(0, 90 + 1e-9, step)
    grazing = theta >= 90 - 1e-9       # the plugin has no direction to sample at 90 degrees
    tests = len(iors) * 2 * int((~grazing).sum())
    z = normal_quantile(ALPHA / tests / 2)
    rows, summary = [], []
    passed = True
    for ior in iors:
        for side, sign in (("outside", 1.0), ("inside", -1.0)):
            cos_i = sign * np.cos(np.radians(theta))
            cos_i = np.where(grazing, 0.0, cos_i) if sign > 0 else np.where(grazing, -0.0, cos_i)
            cos32 = cos_i.astype(np.float32).astype(np.float64)
            exact, schlick = _ours(cos32, ior)
            r_mi, _, _, _ = mi.fresnel(mi.Float(cos32.astype(np.float32)), mi.Float(ior))
            r_mi = np.asarray(r_mi, dtype=np.float64)
            k = _plugin_reflect_fraction(mi, ior, cos32[~grazing], samples, seed)
            plugin = np.full(len(theta), np.nan)
            plugin[~grazing] = k / samples
            lo, hi = wilson_interval(k, samples, z)
            tol = float32_tolerance(cos32, ior)
            d_mi = np.abs(exact - r_mi)
            d_plugin_ok = (exact[~grazing] >= lo - 1e-12) & (exact[~grazing] <= hi + 1e-12)
            d_s = np.abs(schlick - exact)
            ok_mi = bool(np.all(d_mi <= tol))
            ok_plugin = bool(np.all(d_plugin_ok))
            passed &= ok_mi and ok_plugin
            crit = math.degrees(math.asin(1 / ior)) if side == "inside" and ior > 1 else None
            worst_plugin = np.abs(exact[~grazing] - plugin[~grazing]) / np.maximum(
                (hi - lo) / 2, 1e-12)
            summary.append({
                "ior": ior, "side": side, "critical_angle_deg": crit,
                "max_abs_exact_minus_mitsuba": float(d_mi.max()),
                "at_theta_deg": float(theta[int(np.argmax(d_mi))]),
                "exact_vs_mitsuba_within_float32": ok_mi,
                "worst_exact_vs_mitsuba_over_tolerance": float(np.max(d_mi / tol)),
                "max_abs_schlick_minus_exact": float(d_s.max()),
                "schlick_worst_theta_deg": float(theta[int(np.argmax(d_s))]),
                "max_abs_plugin_minus_exact": float(np.nanmax(np.abs(plugin - exact))),
                "worst_plugin_deviation_in_half_intervals": float(worst_plugin.max()),
                "exact_within_plugin_interval": ok_plugin,
                "pass": ok_mi and ok_plugin,
                "plugin_samples_per_angle": samples,
                "interval_z": z,
            })
            for i, t in enumerate(theta):
                rows.append({"ior": ior, "side": side, "theta_deg": float(t),
                             "exact": float(exact[i]), "schlick": float(schlick[i]),
                             "mitsuba": float(r_mi[i]),
                             "plugin": None if np.isnan(plugin[i]) else float(plugin[i])})
    conductors = conductor_curves(mi, step=step)
    passed &= all(c["pass"] for c in conductors)
    return FresnelTable(rows, summary, passed, samples, conductors)


def write_outputs(table: FresnelTable, outdir: str | Path) -> list[Path]:
    """fresnel.csv, fresnel.json and fresnel.png in ``outdir``."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "fresnel.csv"
    with csv_path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["ior", "side", "theta_deg", "exact", "schlick", "mitsuba", "plugin"])
        for r in table.rows:
            w.writerow([f"{r['ior']:g}", r["side"], f"{r['theta_deg']:g}", f"{r['exact']:.9g}",
                        f"{r['schlick']:.9g}", f"{r['mitsuba']:.9g}",
                        "" if r["plugin"] is None else f"{r['plugin']:.9g}"])
    json_path = out / "fresnel.json"
    json_path.write_text(json.dumps({"pass": table.passed, "samples_per_angle": table.samples,
                                     "curves": table.summary,
                                     "conductors": table.conductors}, indent=2) + "\n")
    png_path = out / "fresnel.png"
    plot(table, png_path)
    return [csv_path, json_path, png_path]


def plot(table: FresnelTable, path: str | Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    iors = sorted({r["ior"] for r in table.rows})
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), dpi=100)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for col, side in enumerate(("outside", "inside")):
        ax, ex = axes[0, col], axes[1, col]
        for i, ior in enumerate(iors):
            rs = [r for r in table.rows if r["ior"] == ior and r["side"] == side]
            th = np.array([r["theta_deg"] for r in rs])
            e = np.array([r["exact"] for r in rs])
            s = np.array([r["schlick"] for r in rs])
            m = np.array([r["mitsuba"] for r in rs])
            p = np.array([np.nan if r["plugin"] is None else r["plugin"] for r in rs])
            c = colors[i % len(colors)]
            ax.plot(th, e, color=c, lw=1.6, label=f"n = {ior:g} exact")
            ax.plot(th, s, color=c, lw=1, ls="--", label=f"n = {ior:g} Schlick")
            ax.plot(th[::6], p[::6], "o", color=c, ms=3, mfc="none")
            ex.semilogy(th, np.maximum(np.abs(s - e), 1e-12), color=c, ls="--", lw=1)
            ex.semilogy(th, np.maximum(np.abs(e - m), 1e-12), color=c, lw=1)
            ex.semilogy(th, np.maximum(np.abs(p - e), 1e-12), ".", color=c, ms=2)
        ax.set_title(f"reflectance, ray from {side}" +
                     (" (1 -> n)" if side == "outside" else " (n -> 1)"), fontsize=10)
        ax.set_xlabel("angle of incidence (degrees)")
        ax.set_ylabel("R")
        ax.set_xlim(0, 90)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ex.set_title("errors: |Schlick - exact| (dashed), |exact - mi.fresnel| (solid), "
                     "|plugin - exact| (dots)", fontsize=8)
        ex.set_xlabel("angle of incidence (degrees)")
        ex.set_ylabel("absolute difference")
        ex.set_xlim(0, 90)
        ex.set_ylim(1e-10, 1.5)
        ex.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=2, loc="upper left")
    axes[0, 1].text(2, 0.9, "o: Mitsuba dielectric plugin,\nfraction of sampled reflections",
                    fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
