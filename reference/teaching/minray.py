"""Heckbert's minray as a yardstick: the rays it traces, and how our image agrees with its image.

minray (Paul Heckbert's business-card ray tracer, 1987) recurses on both
branches at every hit, whatever their weights: its trace routine calls
itself for the reflected ray always and for the refracted ray wherever
Snell's law has a solution, until DEPTH calls deep, and casts a shadow ray
towards each light sphere that faces the hit. Its cost therefore grows
exponentially with DEPTH wherever rays keep hitting spheres, while the
tracer drops branches of weight zero (a sphere with ks = 0 or kt = 0, a
light with neither). :func:`ray_count` counts minray's rays exactly for a
scene of the classic model (``scenes/heckbert_minray.toml``), so that
benchmarks and the assignment can put minray's work beside ours.

How: the ray trees of all pixels are followed in double precision with
numpy, level by level, with minray's rules and its arithmetic in its order
(the ray-sphere test with its 1e-7 threshold and origins on the surface,
its normal, its refraction), so that every decision on which the count
depends (a hit or a miss, total internal reflection, a light facing the
hit) comes out as minray's double precision makes it. Colours are not
computed. Checked against a build of minray with counters added
(``tests/data/minray/ray_counts.txt``, ``tests/reference/teaching/test_minray.py``).

:func:`agreement` states how two images' printed numbers agree, and
:func:`decision_margins` finds, per pixel, how close minray's own ray tree
comes to a discontinuity (a ray or a shadow ray passing a sphere's outline,
a refraction at the critical angle), which is what explains a value the
tracer prints differently.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: minray's threshold on the ray parameter t: hits nearer than this are ignored.
T_MIN = 1e-7


@dataclass
class RayCount:
    """Rays minray traces: per recursion level (1 = camera rays) and in total."""
    trace: list[int]     # calls of trace that intersect a ray with the scene, per level
    shadow: list[int]    # shadow rays cast from the hits of each level

    @property
    def total(self) -> int:
        return sum(self.trace) + sum(self.shadow)

    def at_depth(self, depth: int) -> RayCount:
        """The count at a smaller DEPTH: levels 1..depth (deeper levels never change them)."""
        return RayCount(self.trace[:depth], self.shadow[:depth])


@dataclass
class _Spheres:
    """The classic spheres of a scene, in minray's order, as float64 arrays."""
    c: np.ndarray       # (S, 3)
    r: np.ndarray       # (S,)
    kl: np.ndarray
    ks: np.ndarray
    kt: np.ndarray
    kd: np.ndarray
    ir: np.ndarray


def _spheres(scene) -> _Spheres:
    from whitted.tracer.materials.classic import Classic
    from whitted.tracer.scene import Sphere

    rows = []
    for s in scene.shapes:
        m = scene.material_of(s)
        if not isinstance(s, Sphere) or not isinstance(m, Classic):
            raise ValueError(f"{scene.name}: minray's rays are counted for scenes of classic "
                             "spheres only")
        rows.append((s.center, s.radius, m.kl, m.ks, m.kt, m.kd, m.ir))
    return _Spheres(np.array([r[0] for r in rows], np.float64),
                    *(np.array([r[k] for r in rows], np.float64) for k in range(1, 7)))


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _unit(a):
    inv = 1.0 / np.sqrt(_dot(a, a))
    return [inv * a[0], inv * a[1], inv * a[2]]


def _camera_rays(scene, pixels: np.ndarray):
    """Unit directions of minray's camera rays for the given pixel indices (3 arrays)."""
    from whitted.tracer.camera import frame

    cam, film = scene.camera, scene.film
    if cam.type != "perspective":
        raise ValueError("minray's camera is a perspective one")
    w, h = film.width, film.height
    x = pixels % w + 0.5 + cam.pixel_offset[0] - w / 2      # minray: x - SIZE/2
    z = h / 2 - (pixels // w + 0.5 + cam.pixel_offset[1])   # minray: SIZE/2 - y
    dist = (w / 2) / math.tan(math.radians(cam.fov) / 2)
    r, up, f = frame(cam)
    u = [x * r[k] + dist * f[k] + z * up[k] for k in range(3)]
    return _unit(u)


def _closest(sph: _Spheres, P, D):
    """(index or -1, t) of the nearest sphere along each ray, by minray's test."""
    n = len(P[0])
    tmin = np.full(n, 1e30)
    best = np.full(n, -1, np.int64)
    for i in reversed(range(len(sph.r))):     # minray tests its spheres last to first
        U = [sph.c[i, k] - P[k] for k in range(3)]
        b = _dot(D, U)
        u = b * b - _dot(U, U) + sph.r[i] * sph.r[i]
        u = np.where(u > 0, np.sqrt(np.maximum(u, 0)), 1e31)
        t = np.where(b - u > T_MIN, b - u, b + u)
        hit = (t >= T_MIN) & (t < tmin)
        tmin = np.where(hit, t, tmin)
        best = np.where(hit, i, best)
    return best, tmin


def _outline_margin(sph: _Spheres, P, D, t_end, skip=None):
    """How far each ray (P, D) passes from the outline of the nearest sphere it passes
    in front of before t_end: |distance of the centre from the ray - r| (inf if none)."""
    margin = np.full(len(P[0]), np.inf)
    for i in range(len(sph.r)):
        U = [sph.c[i, k] - P[k] for k in range(3)]
        b = _dot(D, U)
        d2 = np.maximum(_dot(U, U) - b * b, 0)
        m = np.abs(np.sqrt(d2) - sph.r[i])
        ahead = (b > 0) & (b - sph.r[i] < t_end)
        if skip is not None:
            ahead &= skip != i
        margin = np.where(ahead, np.minimum(margin, m), margin)
    return margin


@dataclass
class _Level:
    P: list
    D: list
    pixel: np.ndarray
    weight: np.ndarray   # product of the ks and kt along the ray's way (for margins)


def _follow(scene, depth: int, chunk: int, margins: bool):
    """Walk minray's ray trees; yield (level, rays, hits data) chunk by chunk."""
    sph = _spheres(scene)
    lights = [i for i in reversed(range(len(sph.r))) if sph.kl[i] > 0]
    total = scene.film.width * scene.film.height
    for first in range(0, total, chunk):
        pixels = np.arange(first, min(first + chunk, total))
        level = _Level([np.zeros(len(pixels))] * 3, _camera_rays(scene, pixels), pixels,
                       np.ones(len(pixels)))
        for k in range(1, depth + 1):
            if len(level.pixel) == 0:
                break
            P, D = level.P, level.D
            best, t = _closest(sph, P, D)
            hit = best >= 0
            out = {"rays": len(best), "pixel": level.pixel, "weight": level.weight}
            if margins:
                out["outline"] = _outline_margin(sph, P, D, np.where(hit, t, np.inf))
            idx = best[hit]
            P = [P[j][hit] + t[hit] * D[j][hit] for j in range(3)]
            D = [D[j][hit] for j in range(3)]
            c = sph.c[idx]
            N = _unit([c[:, j] - P[j] for j in range(3)])       # minray's normal: inwards
            d = -_dot(D, N)
            flip = d < 0                                        # arriving from outside
            N = [np.where(flip, -N[j], N[j]) for j in range(3)]
            eta = np.where(flip, 1.0 / sph.ir[idx], sph.ir[idx])
            d = np.where(flip, -d, d)
            shadow = 0
            shadow_margin = np.full(len(idx), np.inf)
            for li in lights:
                U = _unit([sph.c[li, j] - P[j] for j in range(3)])
                facing = sph.kl[li] * _dot(N, U) > 0
                shadow += int(np.count_nonzero(facing))
                if margins:
                    to_light = np.sqrt(_dot([sph.c[li, j] - P[j] for j in range(3)],
                                            [sph.c[li, j] - P[j] for j in range(3)]))
                    m = _outline_margin(sph, P, U, to_light - sph.r[li], skip=li)
                    shadow_margin = np.where(facing & (sph.kd[idx] > 0),
                                             np.minimum(shadow_margin, m), shadow_margin)
            out["shadow"] = shadow
            e = 1 - eta * eta * (1 - d * d)
            refr = e > 0
            if margins:
                out["hit_pixel"] = level.pixel[hit]
                out["hit_weight"] = level.weight[hit]
                out["shadow_margin"] = shadow_margin
                out["tir_margin"] = np.where(sph.kt[idx] > 0, np.abs(e), np.inf)
            yield first, k, out
            if k == depth:
                break
            R = [D[j] + (2 * d) * N[j] for j in range(3)]
            kk = eta * d - np.sqrt(np.where(refr, e, 0))
            T = [(kk * N[j] + eta * D[j])[refr] for j in range(3)]
            w = level.weight[hit]
            level = _Level([np.concatenate([P[j], P[j][refr]]) for j in range(3)],
                           [np.concatenate([R[j], T[j]]) for j in range(3)],
                           np.concatenate([level.pixel[hit], level.pixel[hit][refr]]),
                           np.concatenate([w * sph.ks[idx], (w * sph.kt[idx])[refr]]))


def ray_count(scene, depth: int, chunk: int = 8192) -> RayCount:
    """Exactly the rays minray traces for ``scene`` (classic spheres) at this DEPTH and size.

    ``scene``'s film gives the size (``with_overrides(size=...)``), its
    camera minray's view (perspective, ``pixel_offset`` (-0.5, -0.5) for its
    corner rays). Per level: the rays its trace routine intersects with the
    scene (a call with no depth left traces nothing) and the shadow rays
    cast from that level's hits (one per light sphere whose kl (N . L) is
    positive, blocked or not). Memory stays bounded by following ``chunk``
    pixels at a time.
    """
    trace = [0] * depth
    shadow = [0] * depth
    for _, k, out in _follow(scene, depth, chunk, margins=False):
        trace[k - 1] += out["rays"]
        shadow[k - 1] += out["shadow"]
    while trace and trace[-1] == 0:
        trace.pop()
        shadow.pop()
    return RayCount(trace, shadow)


@dataclass
class Margins:
    """Per pixel (H x W), the closest minray's own ray tree comes to a discontinuity.

    ``outline``: how far a camera, reflected or refracted ray passes from a
    sphere's outline (a silhouette, seen directly or in reflections and
    refractions); ``shadow``: how far a shadow ray passes from the outline of
    a sphere between the hit and the light (a shadow edge); ``tir``: |1 -
    (n1/n2)^2 sin^2| at a refraction (0 at the critical angle). Only branches
    that weigh at least ``min_weight`` count; distances are in scene units.
    """
    outline: np.ndarray
    shadow: np.ndarray
    tir: np.ndarray
    min_weight: float = field(default=0.5 / 255)


def decision_margins(scene, depth: int, min_weight: float = 0.5 / 255,
                     chunk: int = 8192) -> Margins:
    """Where minray's ray trees come close to a discontinuity (see :class:`Margins`)."""
    n = scene.film.width * scene.film.height
    outline, shadow, tir = (np.full(n, np.inf) for _ in range(3))
    for _, _, out in _follow(scene, depth, chunk, margins=True):
        keep = out["weight"] >= min_weight
        np.minimum.at(outline, out["pixel"][keep], out["outline"][keep])
        keep = out["hit_weight"] >= min_weight
        np.minimum.at(shadow, out["hit_pixel"][keep], out["shadow_margin"][keep])
        np.minimum.at(tir, out["hit_pixel"][keep], out["tir_margin"][keep])
    shape = (scene.film.height, scene.film.width)
    return Margins(outline.reshape(shape), shadow.reshape(shape), tir.reshape(shape),
                   min_weight)


# --------------------------------------------------------------------------- agreement


@dataclass
class Agreement:
    """How two images' printed numbers (PPM values) agree."""
    values: int
    equal: float            # fraction of values equal
    within_one: float       # fraction equal or one step of 255 apart
    max_difference: int
    beyond_one: int         # values more than one step apart

    def line(self) -> str:
        return (f"{100 * self.equal:.3f} % equal, {100 * self.within_one:.3f} % within one "
                f"step, max difference {self.max_difference}, {self.beyond_one} of "
                f"{self.values} values beyond one step")


def agreement(ours: np.ndarray, theirs: np.ndarray) -> Agreement:
    """Compare integer images of the same shape (e.g. from :func:`tracer.imageio.read_ppm`)."""
    if ours.shape != theirs.shape:
        raise ValueError(f"image shapes differ: {ours.shape} and {theirs.shape}")
    d = np.abs(ours.astype(np.int64) - theirs.astype(np.int64))
    return Agreement(int(d.size), float((d == 0).mean()), float((d <= 1).mean()),
                     int(d.max()) if d.size else 0, int((d > 1).sum()))


# --------------------------------------------------------------------------- explanation

#: Ray-origin offsets tried to explain a value (see :func:`explain`), in float32 ulps of
#: 1 + max |p_i| as the tracer's own (tracer.geometry.RAY_EPSILON_ULPS, Mitsuba's 1500):
#: 16 and 2. At one ulp float32 rays begin to hit their own sphere again (5 or 6 values
#: at 256 x 256 DEPTH 2-20), at half an ulp a third of the image.
TIGHT_OFFSET_ULPS = (16, 2)

KINDS = {"outline": "silhouette", "shadow": "shadow edge", "tir": "critical angle"}

#: float32 ulps within which a discontinuity cannot be placed without double precision: a
#: hit point, a normal and a shadow ray's direction each take a few roundings of 2^-24
#: relative to the scene's largest coordinate, and 16 ulps cover their sum.
FLOAT_ULPS = 16


def float_margin(scene) -> float:
    """16 float32 ulps of the scene's extent (the largest |centre| + radius of its spheres)."""
    sph = _spheres(scene)
    extent = float(np.max(np.linalg.norm(sph.c, axis=1) + sph.r))
    return FLOAT_ULPS * 2.0 ** -24 * (1 + extent)


@dataclass
class Difference:
    """One printed value more than one step from minray's, and why."""
    x: int
    y: int
    channel: int
    ours: int
    theirs: int
    kind: str          # the nearest discontinuity in minray's ray tree: silhouette, ...
    margin: float      # how near it passes (scene units; for a critical angle |1 - ...|)
    cause: str | None  # "ray offset", "float precision", or None: unexplained


def explain(scene, depth: int, theirs: np.ndarray, ours: np.ndarray | None = None
            ) -> list[Difference]:
    """Every value of ours more than one step from minray's ``theirs``, with its cause.

    The tracer starts every reflected, refracted and shadow ray 1500 float32
    ulps of 1 + max |p_i| off the surface (:func:`tracer.geometry.spawn_offset`,
    Mitsuba's own ``RayEpsilon``, so that the deterministic Mitsuba reference
    traces the same ray tree: about 8e-4 around this scene's spheres), where
    minray starts on the surface and ignores hits nearer than 1e-7, in double
    precision. The offset moves the next hit by about its own size, and
    reflections off curved surfaces and refractions magnify the shift at every
    bounce; where minray's ray tree passes a silhouette, a shadow edge or a
    critical angle within that reach, the two trees part. (At 32 x 32, DEPTH
    10 and 20, pixel (8, 3) prints 25 40 43 where minray prints 33 43 45:
    after six bounces, two passes through the glass among them, the hit on
    the orange sphere has moved far enough that its shadow ray towards a
    light meets the glass's rim; with 1024, 16 or 2 ulps the tracer prints 33
    43 45.) A value is explained as "ray offset" when the tracer, rendering
    with the offset made :data:`TIGHT_OFFSET_ULPS` (16 or 2) ulps
    (``Integrator(offset_scale=...)``), prints minray's number within one step;
    ``kind`` names the discontinuity minray's tree passes nearest
    (:func:`decision_margins`): a ray passing a sphere's outline (silhouette),
    a shadow ray passing one (shadow edge), or a refraction at the critical
    angle. A value that even the smaller offsets do not bring to minray's is
    explained as "float precision" when that discontinuity lies within
    :func:`float_margin` (16 float32 ulps of the scene's extent; for a critical
    angle 16 ulps of 1): float32 cannot tell on which side it lies.
    """
    from whitted.tracer.geometry import RAY_EPSILON_ULPS
    from whitted.tracer.imageio import ppm_values
    from whitted.tracer.integrator import Integrator

    if ours is None:
        ours = ppm_values(Integrator(scene).render().image)
    beyond = np.argwhere(np.abs(ours.astype(np.int64) - theirs) > 1)
    if len(beyond) == 0:
        return []
    tight = [ppm_values(Integrator(scene, offset_scale=ulps / RAY_EPSILON_ULPS).render().image)
             for ulps in TIGHT_OFFSET_ULPS]
    m = decision_margins(scene, depth)
    limits = {"outline": float_margin(scene), "shadow": float_margin(scene),
              "tir": FLOAT_ULPS * 2.0 ** -24}
    out = []
    for y, x, c in beyond:
        margins = {"outline": m.outline[y, x], "shadow": m.shadow[y, x], "tir": m.tir[y, x]}
        nearest = min(margins, key=margins.get)
        reproduced = any(abs(int(t[y, x, c]) - int(theirs[y, x, c])) <= 1 for t in tight)
        cause = ("ray offset" if reproduced else "float precision"
                 if any(margins[k] <= limits[k] for k in margins) else None)
        out.append(Difference(int(x), int(y), int(c), int(ours[y, x, c]),
                              int(theirs[y, x, c]), KINDS[nearest], float(margins[nearest]),
                              cause))
    return out


def summary(differences: list[Difference]) -> str:
    """One line: how many values beyond one step, by cause and kind of discontinuity."""
    if not differences:
        return "no value beyond one step"
    counts: dict[str, int] = {}
    for d in differences:
        key = f"{d.cause or 'UNEXPLAINED'} at a {d.kind}"
        counts[key] = counts.get(key, 0) + 1
    return ", ".join(f"{n} {k}" for k, n in sorted(counts.items(), key=lambda kv: -kv[1]))


# --------------------------------------------------------------------------- table

def main(argv: list[str] | None = None) -> int:
    """``python -m reference.teaching.minray``: the stored minray images against the tracer's.

    For every image in ``tests/data/minray/`` (SIZE 32 and 256, DEPTH 1-5, 10,
    20), render ``heckbert_minray`` at that size and DEPTH, and print how the
    numbers agree and why the values more than one step apart differ.
    """
    import argparse
    import re
    from pathlib import Path

    from whitted.scenes import SCENES_DIR
    from whitted.tracer import load_scene
    from whitted.tracer.imageio import ppm_values, read_ppm
    from whitted.tracer.integrator import Integrator

    data = Path(__file__).resolve().parents[2] / "tests" / "data" / "minray"
    ap = argparse.ArgumentParser(prog="python -m whitted.reference.teaching.minray",
                                 description=main.__doc__)
    ap.add_argument("--data", type=Path, default=data, help="folder of minray_SIZE_depthD.ppm[.gz]")
    args = ap.parse_args(argv)
    files = sorted(args.data.glob("minray_*_depth*.ppm*"),
                   key=lambda p: tuple(int(x) for x in re.findall(r"\d+", p.name)[:2]))
    base = load_scene(SCENES_DIR / "heckbert_minray.toml")
    print(f"{'size':>5} {'DEPTH':>5} {'equal':>9} {'<=1 step':>9} {'max':>4} {'>1':>4}  why")
    for f in files:
        size, depth = (int(x) for x in re.findall(r"\d+", f.name)[:2])
        s = base.with_overrides(size=(size, size), max_depth=depth + 1)
        ours = ppm_values(Integrator(s).render().image)
        theirs = read_ppm(f)
        a = agreement(ours, theirs)
        why = summary(explain(s, depth, theirs, ours))
        print(f"{size:>5} {depth:>5} {100 * a.equal:>8.3f}% {100 * a.within_one:>8.3f}% "
              f"{a.max_difference:>4} {a.beyond_one:>4}  {why}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
