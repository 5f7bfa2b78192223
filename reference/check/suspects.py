"""Where an image's difference from the reference sits, and which formula bug explains it.

Three views of a failing image's difference D = image - reference, each a
weighted least-squares fit, weights 1 / Var (the per-pixel noise of
:func:`reference.check.judge.judge_image`), so that a pixel counts by how sure its
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
* by suspect (:func:`rank_difference`, :func:`rank_catalog`, and for a user's image
  :func:`reference.check.judge.rank_suspects`): candidates, each
  a formula bug with the reference rendered with that bug; D ~ k (M_c - R)
  for each candidate's image M_c, ranked by the share of D it explains. A
  render made with one of the bugs is explained by that bug with k near 1.
  ``whitted check`` takes the candidates from the catalog of formula bugs
  (:mod:`reference.mutants`): those whose switch the scene's render reaches
  (:func:`reached_faults`), each rendered once and kept on disk
  (:func:`mutated_image`).

The share a suspect explains is R^2 of its fit, the explained sum of squares
sum w (k x)^2 over sum w D^2 (equivalently: the candidate that leaves the
smallest weighted residual ranks first); ``beyond_noise`` divides the same by
the part of sum w D^2 that noise does not account for (sum w D^2 minus the
number of values, its expectation under noise alone), at most 100 %. k <= 0
(the image is off the other way from the bug) explains nothing. Two bugs
whose images are the same on the pixels judged are ties: no image of that
scene can tell them apart. What the ranking cannot do: name a bug the
catalog lacks (it then names the bugs whose images look most alike, each
explaining a part), or two bugs at once (each is fitted alone).

Naming a cause (:func:`name_cause`): the bugs at strength 1, the conventions of
:mod:`reference.check.conventions` and a fitted monotone curve, each judged by
the check's own rules on what it leaves; one is named only when it leaves
noise alone and scores best, otherwise "cannot name a cause" (``docs/check.md``).
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import pickle
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

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
    from whitted.tracer.integrator import Integrator

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
    from whitted.reference.verdicts.compare import regions_of

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

#: Suspects printed (and put in check.json with their fits; every ranked one in ``ranked``).
TOP = 3
#: Two bugs' differences M - R whose weighted cosine squared is at least this are the same
#: pattern up to a factor (within 0.1 % of its weighted energy): a fit explains the image
#: with either as well, up to the noise, and only the strength k tells them apart (a bug at
#: k = 1 is the image as it is; the other needs scaling). Measured: the catalog's two
#: refraction scalings (no (n1/n2)^2, and its inverse) on a light inside glass, whose
#: differences are 1.25 and 1.81 times one pattern.
ALIKE = 0.999


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
    #: the formula as it should be
    correct: str = ""


@dataclass
class SuspectFit:
    id: str
    formula: str
    topic: str
    #: R^2: the share of sum w D^2 that k (M - R) explains (0 where k <= 0: the image is
    #: off the other way); the ranking's key (the largest leaves the smallest residual)
    explains: float
    #: the fitted strength k (1: exactly this bug)
    scale: float
    scale_error: float
    correct: str = ""
    #: the same explained sum of squares over the part of sum w D^2 beyond its expectation
    #: under noise alone, at most 1
    beyond_noise: float = 0.0
    #: "formula bug" (the catalog, :mod:`reference.mutants`) or "convention" (how the
    #: image was written, :mod:`reference.check.conventions`)
    kind: str = "formula bug"
    #: where the right formula comes from (a convention's standard)
    source: str = ""
    #: what is left once this suspect is put into the reference passes the check's own rules
    #: (the residual is at the noise: :func:`name_cause`)
    at_noise: bool = False
    #: sum of the residual's squares over the noise's variance (common to all suspects),
    #: plus twice the fitted parameters; the lowest at the noise is the cause
    score: float | None = None
    #: a convention's class ("transfer curve", "channel order", ...), its fitted parameters
    family: str = ""
    params: dict = field(default_factory=dict)
    #: other suspects this image cannot tell from this one: their image with their bug is
    #: the same bit for bit on the pixels judged, or the same pattern (:data:`ALIKE`) at a
    #: strength that agrees with this one's within 3 standard errors
    ties: list[str] = field(default_factory=list)
    #: other suspects whose image differs from the reference in the same pattern up to a
    #: factor (:data:`ALIKE`): told apart only by the strength (ranked nearest 1 first)
    alike: list[str] = field(default_factory=list)


def rank_difference(diff: np.ndarray, var: np.ndarray, use: np.ndarray | None,
                    candidates: list[Suspect], images: list[np.ndarray],
                    base: np.ndarray) -> list[SuspectFit]:
    """Rank ``candidates`` by the share of ``diff`` that k (image - base) explains.

    ``images`` are the candidates' renders, ``base`` the image rendered the
    same way without a bug (the reference itself where it is deterministic;
    for a sampled reference the render at the same seed, so that the
    difference M - base carries the bug and not the light samples' noise).
    Candidates whose image equals ``base`` on the judged pixels are left out
    (the scene does not show them); candidates with the same image are ties.
    """
    w = _weights(var, use)
    d = np.where(w > 0, diff, 0.0)
    excess = _excess(d, w)
    total = float((w * d * d).sum())
    b = np.asarray(base, dtype=np.float64)
    xs, kept = [], []
    for c, m in zip(candidates, images, strict=True):
        x = np.where(w > 0, np.asarray(m, dtype=np.float64) - b, 0.0)
        x = np.where(np.isfinite(x), x, 0.0)
        if not x.any():
            continue
        xs.append(x)
        kept.append(c)
    fits = []
    for c, x in zip(kept, xs, strict=True):
        k, se, ss = single_fit(d, x, w)
        ss = ss if k > 0 else 0.0
        fits.append(SuspectFit(c.id, c.formula, c.topic, min(1.0, ss / total) if total > 0 else 0.0,
                               k, se, c.correct, _share(ss, excess)))
    for i, x in enumerate(xs):
        fits[i].ties = [kept[j].id for j, y in enumerate(xs) if j != i and np.array_equal(x, y)]
    norms = [float((w * x * x).sum()) for x in xs]
    for i, x in enumerate(xs):
        for j in range(i + 1, len(xs)):
            if kept[j].id in fits[i].ties:
                continue
            c = float((w * x * xs[j]).sum())
            if c > 0 and c * c >= ALIKE * norms[i] * norms[j]:
                a, b = fits[i], fits[j]
                same = abs(a.scale - b.scale) <= 3 * math.hypot(a.scale_error, b.scale_error)
                (a.ties if same else a.alike).append(b.id)
                (b.ties if same else b.alike).append(a.id)
    return _order(fits)


def _order(fits: list[SuspectFit]) -> list[SuspectFit]:
    """By R^2, best first; a group of alike suspects at its best one's place, by |log k|."""
    by_id = {f.id: f for f in fits}
    out, placed = [], set()
    for f in sorted(fits, key=lambda f: -f.explains):
        if f.id in placed:
            continue
        group = [f] + [by_id[a] for a in f.alike if a not in placed]
        group.sort(key=lambda g: abs(math.log(g.scale)) if g.scale > 0 else math.inf)
        out += group
        placed.update(g.id for g in group)
    return out


# ------------------------------------------------------- the catalog's bugs as suspects


def reached_faults(scene) -> frozenset[str]:
    """The catalog switches the tracer asks about while it renders ``scene``.

    Decided in Python while Dr.Jit traces (:func:`tracer.faults.recording`),
    so a tiny film at the scene's strata asks the same questions as the full
    one; a switch never asked about cannot change the image.
    """
    from whitted.tracer import faults
    from whitted.tracer.integrator import Integrator

    small = scene.with_overrides(size=(min(8, scene.film.width), min(6, scene.film.height)))
    with faults.recording() as asked:
        Integrator(small).render()
    return frozenset(asked)


def cache_dir() -> Path:
    """Where the scenes' images with a bug are kept: ``WHITTED_SUSPECTS_CACHE``, else
    ``$XDG_CACHE_HOME/whitted/suspects`` (``~/.cache/whitted/suspects``); used only as
    :mod:`tracer.cache` allows (this user's, 0700, no one else may write)."""
    from whitted.tracer import cache

    if os.environ.get("WHITTED_SUSPECTS_CACHE"):
        return Path(os.environ["WHITTED_SUSPECTS_CACHE"])
    return cache.home() / "suspects"


_TRACER_DIGEST: str | None = None


def _tracer_digest() -> str:
    """A hash of the tracer's sources: a cached image is never reused by another tracer."""
    global _TRACER_DIGEST
    if _TRACER_DIGEST is None:
        from whitted import tracer

        h = hashlib.blake2b(digest_size=16)
        root = Path(tracer.__file__).parent
        for f in sorted(root.rglob("*.py")):
            h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
        _TRACER_DIGEST = h.hexdigest()
    return _TRACER_DIGEST


def _scene_key(scene, seed: int) -> str:
    """A hash of everything that makes the scene's image (not its file's path), and the seed."""
    from dataclasses import replace

    h = hashlib.blake2b(digest_size=16)
    h.update(pickle.dumps(replace(scene, path=scene.name), protocol=4))
    h.update(f"\0{seed}\0{_tracer_digest()}".encode())
    return h.hexdigest()


def mutated_image(scene, fault_id: str | None, seed: int = 0, cache: Path | None = None
                  ) -> tuple[np.ndarray, bool]:
    """(the tracer's image of ``scene`` with the bug ``fault_id`` on, whether it was cached).

    ``fault_id`` None: the tracer as written, rendered the same way (one
    render at ``seed``). Kept as .npy under ``cache`` (:func:`cache_dir` by
    default), keyed by the scene's content, the seed, the bug and the tracer's
    sources, in folders and files :mod:`tracer.cache` makes and checks. A
    stored image is used only when it is float32 of the film's shape and
    finite everywhere (:func:`_cached_image`); anything else is rendered again
    and overwritten.
    """
    from whitted.reference import mutants  # noqa: F401  (declares the catalog's ids)
    from whitted.tracer import cache as tcache
    from whitted.tracer import faults
    from whitted.tracer.integrator import Integrator

    top = cache or cache_dir()
    folder = top / _scene_key(scene, seed)
    path = folder / f"{fault_id or 'as-written'}.npy"
    shape = (scene.film.height, scene.film.width, 3)
    img = _cached_image(path, shape) if tcache.folder(folder, top, create=False) else None
    if img is not None:
        return img, True
    with faults.active(*([fault_id] if fault_id else []), shared_kernel=True):
        img = np.asarray(Integrator(scene, seed=seed).render().image, dtype=np.float32)
    # An image that is not finite everywhere would be refused when read again.
    if img.shape == shape and np.isfinite(img).all() and tcache.folder(folder, top):
        buf = io.BytesIO()
        np.save(buf, img, allow_pickle=False)
        tcache.write_bytes(path, buf.getvalue())   # not written: it only costs time
    return img, False


def _cached_image(path: Path, shape: tuple[int, int, int]) -> np.ndarray | None:
    """The float32 image of ``shape`` kept as .npy at ``path``, or None for anything else.

    The header is read and checked before any data (a header may claim any
    size); then exactly the data the shape needs, which must be finite. A
    pickled object, another dtype or shape, an .npz or a short file is a miss.
    """
    from numpy.lib import format as npy

    from whitted.tracer import cache as tcache

    f = tcache.open_entry(path)
    if f is None:
        return None
    with f:
        try:
            version = npy.read_magic(f)
            if version == (1, 0):
                header = npy.read_array_header_1_0(f)
            elif version == (2, 0):
                header = npy.read_array_header_2_0(f)
            else:
                return None
            got_shape, fortran, dtype = header
            if tuple(got_shape) != shape or fortran or dtype != np.dtype(np.float32):
                return None
            n = math.prod(shape)
            data = f.read(4 * n)
        except (OSError, ValueError, SyntaxError, TypeError, EOFError):
            return None
    if len(data) != 4 * n:
        return None
    img = np.frombuffer(data, dtype=np.float32).reshape(shape).copy()
    return img if np.isfinite(img).all() else None


def catalog_suspects(scene, seed: int = 0, ids: list[str] | None = None) -> list[Suspect]:
    """The catalog's bugs (:mod:`reference.mutants`) that the scene reaches, as suspects."""
    from whitted.reference import mutants

    reached = reached_faults(scene)
    entries = mutants.CATALOG if ids is None else mutants.get(ids)
    return [Suspect(m.id, m.wrong, m.topic,
                    lambda s, i=m.id: mutated_image(s, i, seed)[0], m.correct)
            for m in entries if m.id in reached]


@dataclass
class SuspectRanking:
    """The catalog ranked for one failing image (``check.json``'s ``suspects``)."""
    #: bugs of the catalog the scene reaches, and how many of their images were cached
    candidates: int
    cached: int
    #: bugs the scene reaches whose image is the reference's (the scene does not show them)
    no_effect: list[str]
    #: every bug that changes the image, best first
    ranked: list[SuspectFit]
    seconds: float
    #: id -> the bug's image, and the tracer as written at the same seed (not in JSON)
    images: dict = field(default_factory=dict, repr=False)
    base: np.ndarray | None = field(default=None, repr=False)

    @property
    def top(self) -> list[SuspectFit]:
        return self.ranked[:TOP]

    def to_json(self) -> dict:
        return {"candidates": self.candidates, "cached": self.cached,
                "no_effect": self.no_effect, "top": [asdict(f) for f in self.top],
                "ranked": [asdict(f) for f in self.ranked], "seconds": self.seconds}


def rank_catalog(scene, diff: np.ndarray, var: np.ndarray, use: np.ndarray | None,
                 seed: int = 0, ids: list[str] | None = None,
                 cache: Path | None = None, log: Callable[[str], None] | None = None
                 ) -> SuspectRanking:
    """Rank the catalog's bugs that reach ``scene`` for a difference ``diff`` (check's arrays).

    Each bug's image is rendered once per scene, seed and tracer and kept on
    disk (:func:`mutated_image`); ``log`` gets a progress line per bug. The
    fit takes M - R from one render with and one without the bug at the same
    seed: where the tracer samples lights (its reference a mean of seeds) the
    light samples' noise cancels, and a bug the scene does not show gives
    exactly zero.
    """
    import time

    from whitted.reference import mutants

    start = time.perf_counter()
    reached = reached_faults(scene)
    entries = [m for m in (mutants.CATALOG if ids is None else mutants.get(ids))
               if m.id in reached]
    cands, images, cached = [], [], 0
    base, hit = mutated_image(scene, None, seed, cache)
    cached += hit
    for i, m in enumerate(entries, 1):
        try:
            img, hit = mutated_image(scene, m.id, seed, cache)
        except Exception as e:   # a bug that crashes the tracer cannot be a suspect here
            if log:
                log(f"suspects [{i}/{len(entries)}] {m.id}: not rendered ({type(e).__name__})")
            continue
        cached += hit
        if log:
            log(f"suspects [{i}/{len(entries)}] {m.id}" + (" (cached)" if hit else ""))
        cands.append(Suspect(m.id, m.wrong, m.topic, lambda s: None, m.correct))
        images.append(img)
    ranked = rank_difference(diff, var, use, cands, images, base)
    ranked_ids = {f.id for f in ranked}
    return SuspectRanking(len(entries), cached, [c.id for c in cands if c.id not in ranked_ids],
                          ranked, time.perf_counter() - start,
                          {c.id: m for c, m in zip(cands, images, strict=True)
                           if c.id in ranked_ids}, base)


def format_suspects(fits: list[SuspectFit], top: int = TOP) -> str:
    lines = ["suspects (formula bugs whose image explains the difference best):"]
    for i, f in enumerate(fits[:top], 1):
        ties = f"; not told apart from {', '.join(f.ties)}" if f.ties else ""
        if f.alike:
            ties += f"; the same pattern, other strength, as {', '.join(f.alike)}"
        lines.append(f"  {i}. {f.id} (lecture: {f.topic}): explains {100 * f.explains:.1f} % "
                     f"of the difference ({100 * f.beyond_noise:.0f} % of what noise leaves), "
                     f"at strength {f.scale:.2f}{ties}")
        lines.append(f"       formula: {f.formula}")
        if f.correct:
            lines.append(f"       right:   {f.correct}")
    if not fits:
        lines.append("  none: no bug of the catalog that the scene reaches changes its image")
    return "\n".join(lines)


# ------------------------------------------------- naming a cause, or saying there is none

#: Suspects judged with the check's own rules after a first, cheap ranking (by the residual's
#: squares over the failing check's noise); the monotone curve is always judged.
JUDGED = 8
#: Two suspects at the noise whose predictions differ by less than this sum of squares over
#: the noise's variance are ties: a 6-sigma difference in all, so that the image picks the
#: wrong one of two by chance with probability Phi(-3) = 0.13 % (their scores' difference
#: has mean S and standard deviation 2 sqrt(S) under the right one).
TIE_SCORE = 36.0


@dataclass
class _Hypothesis:
    fit: SuspectFit
    image: np.ndarray
    reference: object             # judge.Reference: the prediction with its noise terms
    unknown: np.ndarray | None = None
    parameters: int = 0
    prediction: object = None     # conventions.Prediction


def _difference_beyond_noise(x: np.ndarray, sd: np.ndarray, use: np.ndarray) -> float:
    """sum of |x| - sd where positive, over the judged values (the light beyond the noise)."""
    return float(np.where(use[..., None], np.maximum(np.abs(x) - sd, 0), 0).sum())


def name_cause(user, ref, result, material_ids=None, material_names=None,
               ranking: SuspectRanking | None = None, fine: Callable | None = None,
               log: Callable[[str], None] | None = None, *, judge_image: Callable,
               reference_type: type) -> dict:
    """Name what makes a failing image differ, or say that nothing known does.

    The hypotheses: each convention of :mod:`reference.check.conventions`
    (the image right, written wrongly), each formula bug of ``ranking`` (its
    image at strength 1: the reference plus the bug's M - R), and any monotone
    curve per channel (:func:`~reference.check.conventions.monotone_fit`). Each
    predicts the image a renderer makes under it; the residual image -
    prediction is judged by the check's own rules (:func:`~reference.check.judge.
    judge_image`, the noise estimated again from the residual; the
    :data:`JUDGED` most likely after a cheap first ranking). A suspect is named
    only when its residual passes (it explains the difference down to the
    noise) and it has the lowest score of those that pass (the residual's
    squares over the noise, the smallest variance any judgement found per
    value, plus twice its fitted parameters), which makes it beat every
    convention, every other bug and a generic curve; suspects at the noise
    whose predictions differ by less than :data:`TIE_SCORE` are ties.
    Otherwise no cause is named. ``explains`` is a share of the whole
    difference: 1 - B(image - prediction) / B(image - reference), with B the
    light beyond one standard deviation of noise summed over every value (so
    no region dominates by its brightness squared).
    """
    from whitted.reference.check import conventions as cv

    # The check's own rules are handed in by reference.check.judge, which calls this:
    # judging sits above naming, and this module never imports it.
    Reference = reference_type

    a = result.arrays
    u, r = a["image"], a["reference"]
    valid = a["valid"]
    var0 = a["var"]
    w0 = np.where(valid[..., None], 1 / np.maximum(var0, 1e-300), 0.0)
    enc = cv.file_encoding(user)
    hyps: list[_Hypothesis] = []
    for c in cv.CONVENTIONS:
        p = cv.predict(c, enc, ref, u, w0, valid, fine, getattr(user, "alpha", None))
        if p is None:
            continue
        fit = SuspectFit(c.id, p.formula, c.kind, 0.0, float(p.params.get("s", 1.0)), 0.0,
                         p.correct, kind="convention", source=c.source, family=c.kind,
                         params=p.params)
        hyps.append(_Hypothesis(fit, p.image, Reference(p.image, p.variance, ref.name,
                                                        ref.seeds, p.spread, p.quadrature),
                                p.unknown, c.parameters, p))
    mono_img, mono = cv.monotone_fit(u, r, w0, valid)
    if user.clip is not None:
        mono_img = np.minimum(mono_img, user.clip)
    m = cv.MONOTONE
    mfit = SuspectFit(m.id, m.formula(enc), m.kind, 0.0, 1.0, 0.0, m.correct(enc),
                      kind="convention", source=m.source, family=m.kind)
    mono_h = _Hypothesis(mfit, mono_img, Reference(mono_img, ref.variance, ref.name, ref.seeds,
                                                   ref.spread, ref.quadrature),
                         None, mono.pieces)
    hyps.append(mono_h)
    if ranking is not None and ranking.base is not None:
        base = np.asarray(ranking.base, dtype=np.float64)
        for f in ranking.ranked:
            img = r + np.where(np.isfinite(ranking.images[f.id]),
                               ranking.images[f.id] - base, 0.0)
            if user.clip is not None:
                img = np.minimum(img, user.clip)
            hyps.append(_Hypothesis(f, img, Reference(img, ref.variance, ref.name, ref.seeds,
                                                      ref.spread, ref.quadrature)))

    def known(h):
        return valid if h.unknown is None else valid & ~h.unknown

    def cheap(h):
        k = known(h)
        n = max(int(k.sum()), 1)
        return float(np.where(k[..., None], w0 * (u - h.image) ** 2, 0).sum()) / n

    order = sorted((h for h in hyps if h is not mono_h), key=cheap)
    judged = order[:JUDGED] + [mono_h]
    variances = [var0]
    for h in judged:
        conv = h.prediction.convention if h.prediction is not None else None
        if conv is not None and conv.unmove is not None:
            # judged in the image's own frame: the noise's level then varies slowly again
            back, unknown = _moved_back(user, conv.unmove)
            res = judge_image(back, ref, material_ids, material_names, ignore=unknown,
                              metrics=False)
            var_h = conv.move(res.arrays["var"])[0]
        else:
            res = judge_image(user, h.reference, material_ids, material_names,
                              ignore=h.unknown, metrics=False)
            var_h = res.arrays["var"]
        h.fit.at_noise = bool(res.passed)
        variances.append(np.where(known(h)[..., None], var_h, np.inf))
        if log:
            log(f"suspect {h.fit.id}: " + ("at the noise" if res.passed else "beyond"))
    v = np.min(variances, axis=0)
    v = np.maximum(np.where(np.isfinite(v), v, var0), 1e-300)
    sd = np.sqrt(v)
    total = _difference_beyond_noise(u - r, sd, valid)
    for h in hyps:
        k = known(h)
        resid = np.where(k[..., None], u - h.image, 0.0)
        chi = float(np.where(k[..., None], resid ** 2 / v, 0).sum())
        chi += 3 * float((valid & ~k).sum())       # what it cannot predict counts as noise
        h.fit.score = chi + 2 * h.parameters
        left = _difference_beyond_noise(resid, sd, k)
        h.fit.explains = max(0.0, 1 - left / total) if total > 0 else 0.0
    passing = sorted((h for h in hyps if h.fit.at_noise), key=lambda h: h.fit.score)
    named_ones = [h for h in passing if h is not mono_h]
    # The generic curve is first only when no named suspect is at the noise: a named one
    # that is says more (the curve also fits what noise does to a steep curve's dark end).
    first = named_ones[0] if named_ones else (mono_h if mono_h.fit.at_noise else None)

    def same(h, g):
        for a, b in ((h, g), (g, h)):
            if a.prediction is not None and b.fit.id in a.prediction.convention.same_as:
                return True
        return False
    if first is not None and first is not mono_h:
        for h in named_ones:
            if h is first:
                continue
            k = known(h) & known(first)
            s = float(np.where(k[..., None], (h.image - first.image) ** 2 / v, 0).sum())
            if (s < TIE_SCORE or same(h, first)) and h.fit.id not in first.fit.ties:
                first.fit.ties.append(h.fit.id)
                if first.fit.id not in h.fit.ties:
                    h.fit.ties.append(first.fit.id)
    if first is not None and first.prediction is not None:
        # a bug that makes this very image (by construction) is a tie, at the noise or not
        # (its own render differs from the moved reference only by light samples' noise)
        for h in hyps:
            if h.fit.id in first.prediction.convention.same_as and \
                    h.fit.id not in first.fit.ties:
                first.fit.ties.append(h.fit.id)
                h.fit.ties.append(first.fit.id)
    if first is not None and first.fit.kind == "formula bug":
        # "conventions first": of suspects the image cannot tell apart, the way of writing
        # a right image is the simpler story, and a bug that flips the image is the same
        tied = [h for h in named_ones if h.fit.id in first.fit.ties and
                h.fit.kind == "convention"]
        if tied:
            first = tied[0]
    rest = sorted((h for h in hyps if h is not first and not h.fit.at_noise),
                  key=lambda h: -h.fit.explains)
    ranked = ([first] if first else []) + [h for h in passing if h is not first] + rest
    fits = [h.fit for h in ranked]
    agrees = mono_h.fit.at_noise
    curve = {"x": [x.tolist() for x in mono.x], "y": [y.tolist() for y in mono.y],
             "pieces": mono.pieces, "encoding": enc.name, "maxval": enc.maxval,
             "clip": enc.clip, "at_noise": agrees}
    return {"named": first is not None, "cause": _cause_words(first, agrees),
            "transport_agrees": agrees, "judged": [h.fit.id for h in judged],
            "top": [asdict(f) for f in fits[:TOP]], "ranked": [asdict(f) for f in fits],
            "curve": curve}


def _moved_back(user, unmove):
    """The user's image (and its per-pixel fields) moved back by ``unmove``."""
    from dataclasses import replace

    def back(a):
        return None if a is None else unmove(np.asarray(a))[0]

    image, unknown = unmove(np.asarray(user.image))
    return replace(user, image=image, step=back(user.step), variance=back(user.variance),
                   saturated=back(user.saturated)), unknown


def _cause_words(first: _Hypothesis | None, agrees: bool) -> str:
    if first is None:
        return ("cannot name a cause: no formula bug of the catalog and no way of writing a "
                "right image explains the difference down to the noise"
                + ("" if agrees else "; no monotone curve does either, so the light "
                   "transport differs") + " (where it sits: above)")
    f = first.fit
    if f.kind == "formula bug":
        return f"a formula bug of the catalog explains the difference down to the noise: {f.id}"
    summary = first.prediction.convention.summary if first.prediction else \
        "an output curve none of the named ones (fitted: see curve.png)"
    what = "output encoding" if f.family in ("transfer curve", "quantisation") else \
        "way of writing the image (" + f.family + ")"
    if f.params.get("s") is not None and f.id == "exposure-scale":
        summary += f" (x {f.params['s']:.3g})"
    return f"your light transport agrees; your {what} differs: it looks like {summary}"


def format_cause(sp: dict, top: int = TOP) -> str:
    """The suspects as ``whitted check`` prints them (``sp``: check.json's ``suspects``)."""
    fits = [SuspectFit(**f) for f in sp["top"]]
    lines = [("cause: " if sp.get("named") else "") + sp.get("cause", "")]
    if sp.get("named"):
        lines.append("suspects (the first explains the difference down to the noise):")
    else:
        lines.append("closest suspects (none leaves only noise: not a diagnosis):")
    for i, f in enumerate(fits[:top], 1):
        ties = f"; not told apart from {', '.join(f.ties)}" if f.ties else ""
        if f.alike:
            ties += f"; the same pattern, other strength, as {', '.join(f.alike)}"
        noise = "down to the noise" if f.at_noise else "leaving a difference beyond the noise"
        if f.kind == "formula bug":
            lines.append(f"  {i}. {f.id} (lecture: {f.topic}): explains {100 * f.explains:.1f} % "
                         f"of the difference, {noise}; fitted strength {f.scale:.2f}{ties}")
        else:
            lines.append(f"  {i}. {f.id} (convention: {f.family}): explains "
                         f"{100 * f.explains:.1f} % of the difference, {noise}{ties}")
        lines.append(f"       formula: {f.formula}")
        if f.correct:
            lines.append(f"       right:   {f.correct}")
        if f.source:
            lines.append(f"       source:  {f.source}")
    if not fits:
        lines.append("  none: no bug of the catalog that the scene reaches changes its image")
    return "\n".join(lines)
