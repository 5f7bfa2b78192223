"""Where an image's difference from the reference sits, and which formula bug explains it.

Three views of a failing image's difference D = image - reference, each a
weighted least-squares fit, weights 1 / Var (the per-pixel noise of
:func:`reference.check.judge_image`), so that a pixel counts by how sure its
difference is:

* by light path (:func:`light_path_fit`): the reference split into Heckbert's
  four paths of a Whitted tracer, LE, LDE, LS+E and LDS+E (lecture 1, "Light
  path notation"; Heckbert, "Adaptive radiosity textures for bidirectional ray
  tracing", SIGGRAPH 1990), whose images the tracer renders with ``--lpe`` and
  which sum to the reference. Each pixel's difference beyond its noise is
  shared among the paths by their light there ("the error sits in light seen
  through glass"), and D ~ sum_p a_p R_p gives each path's relative error
  ("that light is 4.8 % too bright");
* by material (:func:`material_split`): the signed sum of D over the pixels
  whose camera ray first hits each material (:func:`tracer.integrator.material_ids`),
  the background and the emitters, with its share of the difference beyond
  the noise and its relative bias;
* by suspect (:func:`rank_suspects`): candidates, each a formula bug with a
  function rendering the reference with that bug; D ~ k (M_c - R) for each
  candidate's image M_c, ranked by the share of D it explains. A render made
  with one of the bugs is explained by that bug with k near 1.

The share a suspect explains is its fit's explained sum of squares over
the part of sum w D^2 that noise does not account for (sum w D^2 minus the
number of values, its expectation under noise alone): "explains 95 % of the
difference beyond the noise", at most 100 %.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: Heckbert's expressions that partition a Whitted tracer's paths (as in the report).
PATHS = ("LE", "LDE", "LS+E", "LDS+E")
PATH_WORDS = {"LE": "light seen directly", "LDE": "direct light on diffuse surfaces",
              "LS+E": "light seen in mirrors or through glass",
              "LDS+E": "diffuse surfaces seen in mirrors or through glass"}


def _weights(var: np.ndarray, use: np.ndarray | None) -> np.ndarray:
    w = 1.0 / np.maximum(np.asarray(var, dtype=np.float64), 1e-300)
    if use is not None:
        w = w * np.asarray(use, dtype=bool)[..., None]
    return np.where(np.isfinite(w), w, 0.0)


def _excess(d: np.ndarray, w: np.ndarray) -> float:
    """sum w d^2 beyond its expectation under noise alone (the number of weighted values)."""
    return float((w * d * d).sum() - np.count_nonzero(w))


def _share(fitted_ss: float, total_excess: float) -> float:
    if fitted_ss <= 0:
        return 0.0
    return float(min(1.0, fitted_ss / max(total_excess, fitted_ss)))


def single_fit(d: np.ndarray, x: np.ndarray, w: np.ndarray) -> tuple[float, float, float]:
    """Weighted least squares d ~ k x: (k, its standard error, the explained sum of squares)."""
    sxx = float((w * x * x).sum())
    if sxx <= 0:
        return 0.0, math.inf, 0.0
    sxd = float((w * x * d).sum())
    k = sxd / sxx
    return k, 1 / math.sqrt(sxx), sxd * sxd / sxx


@dataclass
class PathFit:
    path: str
    words: str
    #: share of the reference's light on this path
    light_share: float
    #: relative error of that light, from the joint fit, and its standard error
    relative_error: float
    standard_error: float
    #: share of the difference beyond the noise that falls on this path's light
    share: float


def light_path_images(scene, seed: int = 0) -> dict[str, np.ndarray]:
    """The tracer's image of each path of :data:`PATHS` (paths without light left out)."""
    from tracer.integrator import Integrator

    out = {}
    for expr in PATHS:
        img = Integrator(scene, seed=seed, lpe=expr).render().image.astype(np.float64)
        if np.abs(img).sum() > 0:
            out[expr] = img
    return out


def beyond_noise(diff: np.ndarray, var: np.ndarray, use: np.ndarray | None = None) -> np.ndarray:
    """H x W: each pixel's difference beyond one standard deviation of its noise, summed."""
    e = np.maximum(np.abs(diff) - np.sqrt(np.maximum(var, 0)), 0).sum(-1)
    return e if use is None else np.where(use, e, 0.0)


def light_path_fit(diff: np.ndarray, var: np.ndarray, parts: dict[str, np.ndarray],
                   use: np.ndarray | None = None) -> list[PathFit]:
    """The difference by light path, largest share first.

    ``share``: each pixel's difference beyond its noise is shared among the
    paths in proportion to their light in that pixel (a Fresnel error, which
    moves light between reflection and refraction by amounts that change with
    the angle, lands on the paths through glass). ``relative_error``: the joint
    weighted least-squares fit D ~ sum_p a_p R_p (a light that is a few per cent
    too bright everywhere comes out as that a_p).
    """
    w = _weights(var, use)
    d = np.where(w > 0, diff, 0.0)
    names = list(parts)
    if not names:
        return []
    xs = [np.where(w > 0, parts[p], 0.0) for p in names]
    a = np.array([[float((w * xi * xj).sum()) for xj in xs] for xi in xs])
    b = np.array([float((w * xi * d).sum()) for xi in xs])
    coef = np.linalg.lstsq(a, b, rcond=None)[0]
    cov = np.linalg.pinv(a)
    light = {p: np.abs(parts[p]).sum(-1) for p in names}
    per_pixel = sum(light.values())
    e = beyond_noise(diff, var, use)
    total_e = float(e.sum()) or 1.0
    total = sum(float(v.sum()) for v in light.values()) or 1.0
    fits = []
    for i, p in enumerate(names):
        frac = np.divide(light[p], per_pixel, out=np.zeros_like(per_pixel),
                         where=per_pixel > 0)
        fits.append(PathFit(p, PATH_WORDS.get(p, p), float(light[p].sum()) / total,
                            float(coef[i]), float(math.sqrt(max(cov[i, i], 0))),
                            float((e * frac).sum()) / total_e))
    return sorted(fits, key=lambda f: -f.share)


@dataclass
class MaterialPart:
    name: str
    pixels: int
    #: share of sum |D| (R + G + B) over the image
    share: float
    #: sum D / sum reference over the region
    bias: float | None


def material_split(diff: np.ndarray, var: np.ndarray, reference: np.ndarray,
                   material_ids: np.ndarray, material_names: list[str],
                   use: np.ndarray | None = None) -> list[MaterialPart]:
    """The difference beyond noise over each first-hit material, the background, the emitters."""
    from reference.compare import regions_of

    d = np.asarray(diff, dtype=np.float64).sum(-1)
    r = np.abs(np.asarray(reference, dtype=np.float64)).sum(-1)
    ok = np.ones(d.shape, dtype=bool) if use is None else use
    e = beyond_noise(diff, var, ok)
    total = float(e.sum()) or 1.0
    out = []
    for name, mask in regions_of(material_ids, material_names, tiles=0).items():
        if name == "image":
            continue
        m = mask & ok
        level = float(r[m].sum())
        out.append(MaterialPart(name, int(m.sum()), float(e[m].sum()) / total,
                                float(d[m].sum()) / level if level > 0 else None))
    return sorted(out, key=lambda p: -p.share)


def format_decomposition(paths: list[PathFit], materials: list[MaterialPart]) -> str:
    lines = ["where the difference sits:"]
    for f in paths:
        lines.append(f"  light path {f.path:<6} ({f.words}; {100 * f.light_share:.0f} % of the "
                     f"light): {100 * f.share:.0f} % of the difference; fitted as "
                     f"{100 * f.relative_error:+.2f} % +- {100 * f.standard_error:.2f} % of it")
    for m in materials[:4]:
        bias = "" if m.bias is None else f", bias {100 * m.bias:+.2f} % of its light"
        lines.append(f"  {m.name} ({m.pixels:,} pixels): {100 * m.share:.0f} % of the "
                     f"difference{bias}")
    return "\n".join(lines)


# ---------------------------------------------------------------- suspects


@dataclass(frozen=True)
class Suspect:
    """A formula bug: what it is, where it is taught, and the reference rendered with it.

    ``render(scene)`` returns the H x W x 3 linear image the tracer makes of
    the scene with this bug switched on (at the reference's strata and seed).
    """
    id: str
    formula: str
    topic: str
    render: Callable[[object], np.ndarray]


@dataclass
class SuspectFit:
    id: str
    formula: str
    topic: str
    #: share of the difference beyond noise that k (M - R) explains
    explains: float
    #: the fitted strength k (1: exactly this bug)
    scale: float
    scale_error: float


def rank_suspects(user_image: np.ndarray, scene, candidates: list[Suspect],
                  reference: np.ndarray | None = None, variance: np.ndarray | None = None,
                  use: np.ndarray | None = None) -> list[SuspectFit]:
    """Rank formula bugs by how well each one's image explains ``user_image``.

    ``reference`` defaults to the tracer's image of the scene, ``variance``
    (the weights' inverse) to :func:`reference.check.judge_image`'s noise
    estimate for the user's image. For each candidate, D = image - reference
    is fitted by k (M - reference), M the candidate's render; candidates are
    ranked by the share of D they explain (best first).
    """
    u = np.asarray(user_image, dtype=np.float64)
    if reference is None or variance is None:
        from reference.check import judge_image, tracer_reference
        from reference.user_image import UserImage

        ref = tracer_reference(scene)
        if reference is None:
            reference = ref.image
        else:
            ref.image = np.asarray(reference, dtype=np.float64)
        if variance is None:
            result = judge_image(UserImage("<image>", "array", "float32", u), ref)
            variance, use = result.arrays["var"], result.arrays["valid"]
    r = np.asarray(reference, dtype=np.float64)
    w = _weights(variance, use)
    d = np.where(w > 0, u - r, 0.0)
    excess = _excess(d, w)
    fits = []
    for c in candidates:
        x = np.where(w > 0, np.asarray(c.render(scene), dtype=np.float64) - r, 0.0)
        k, se, ss = single_fit(d, x, w)
        fits.append(SuspectFit(c.id, c.formula, c.topic, _share(ss, excess), k, se))
    return sorted(fits, key=lambda f: -f.explains)


def format_suspects(fits: list[SuspectFit], top: int = 3) -> str:
    lines = ["suspects (formula bugs whose image explains the difference best):"]
    for i, f in enumerate(fits[:top], 1):
        lines.append(f"  {i}. {f.id}: {f.formula} (lecture: {f.topic}) explains "
                     f"{100 * f.explains:.0f} % of the difference, at strength {f.scale:.2f}")
    return "\n".join(lines)
