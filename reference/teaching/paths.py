"""Draw the ray trees of chosen pixels over the image, each light path in Heckbert's notation.

For every chosen pixel the ray through its centre is followed as the tracer
follows it: at a mirror one reflected ray, at glass a reflected and (unless
totally reflected) a refracted ray, at a diffuse surface one shadow ray to
each light. Segments are projected into the image with the camera's own
projection. A path that brings light to the eye is labelled from the light
to the eye (``LDE``, ``LDSE``, ...). Branches whose weight, as the tracer
carries it (the product of the lobe weights so far, refraction's (n1/n2)^2
included), falls below 1e-3 are not drawn (they cannot change the pixel
visibly).

A Whitted tracer makes no LDDE (diffuse light reflected by another diffuse
surface) and no LSDE (light focused by a mirror or glass onto a diffuse
surface: a caustic) paths. The right-hand panel shows where they would carry
light: Mitsuba's path tracer with three segments minus the Whitted reference
with three segments leaves exactly LDDE + LSDE.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from whitted.tracer.errors import UserError

DRAW_MIN_WEIGHT = 1e-3
WANTED = ("LE", "LDE", "LSE", "LDSE")
#: Most pixels one picture draws the ray trees of.
MAX_PIXELS = 64


@dataclass
class Segment:
    a: np.ndarray
    b: np.ndarray
    kind: str          # "camera", "reflect", "refract", "shadow", "blocked", "escape"
    pixel: int


@dataclass
class Tree:
    pixel: tuple[int, int]
    segments: list[Segment] = field(default_factory=list)
    paths: list[str] = field(default_factory=list)     # light paths that reach the eye


def parse_pixel(text: str, width: int, height: int) -> tuple[int, int]:
    shown = text if len(text) <= 40 else text[:40] + "..."
    try:
        x, y = (int(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--pixel: expected X,Y such as 12,20, got {shown!r}") from None
    if not (0 <= x < width and 0 <= y < height):
        raise UserError(f"--pixel {shown}: outside the {width}x{height} image")
    return x, y


def ray_trees(scene, pixels: list[tuple[int, int]]) -> list[Tree]:
    """Follow the centre ray of each pixel through the scene (see module doc).

    What happens at a hit is decided by the tracer's own interfaces, as in
    the integrator: where the material has a smooth part, one shadow ray goes
    to each light, aimed at the light's middle sample (``Emitter.aim``); each
    delta lobe spawns a ray with its weight (:mod:`tracer.materials.dispatch`).
    """
    import drjit as dr

    from whitted.tracer.backend import jit
    from whitted.tracer.camera import generate_rays
    from whitted.tracer.emitters import scene_emitters
    from whitted.tracer.geometry import Geometry, spawn_offset
    from whitted.tracer.integrator import SHADOW_EPSILON
    from whitted.tracer.materials.base import ShadingPoint
    from whitted.tracer.materials.dispatch import SceneMaterials

    geo = Geometry(scene)
    materials = SceneMaterials(list(scene.materials.values()))
    every = scene_emitters(scene.lights, geo.emitters, scene.shape_lights())
    emitters = [e for e in every if e.illuminates]
    backgrounds = [e for e in every if e.infinite]
    W, H = scene.film.width, scene.film.height
    # As the integrator: rays of the last segment only where they can see a light.
    last_level_sees = bool(geo.emitters) or any(not b.hit_term for b in backgrounds)

    def v3(a):
        return jit.Array3f(*(float(x) for x in a))

    def rows(x) -> np.ndarray:
        return np.asarray(x).T.astype(np.float64)

    trees = [Tree(p) for p in pixels]
    fx = np.array([p[0] + 0.5 for p in pixels], dtype=np.float32)
    fy = np.array([p[1] + 0.5 for p in pixels], dtype=np.float32)
    o, d, tmax = generate_rays(scene.camera, W, H, jit.Float(fx), jit.Float(fy))
    # One entry per live ray: origin, direction, tmax, RGB weight, eye-side letters,
    # tree index, segment kind.
    rays = [(np.asarray(o)[:, i].astype(np.float64), np.asarray(d)[:, i].astype(np.float64),
             float(np.asarray(tmax)[i]), np.ones(3), "", i, "camera") for i in range(len(pixels))]
    scale = _scene_scale(scene)
    emits = geo.emitting()
    for depth in range(1, scene.film.max_depth + 1):
        if not rays:
            break
        O = jit.Array3f(*np.array([r[0] for r in rays]).T.astype(np.float32))
        D = jit.Array3f(*np.array([r[1] for r in rays]).T.astype(np.float32))
        T = jit.Float(np.array([r[2] for r in rays], dtype=np.float32))
        hit = geo.closest_hit(O, D, T)
        surf = geo.surface(hit, O, D)
        valid = hit.valid
        # The hit as the integrator shades it (Integrator._shade).
        cos_o = -dr.dot(surf.n, D)
        cos_sh = -dr.dot(surf.ns, D)
        ng = dr.select(cos_o >= 0, surf.n, -surf.n)
        si = ShadingPoint(surf.p, surf.n, surf.ns, surf.uv, D,
                          dr.select(cos_sh >= 0, surf.ns, -surf.ns), ng, cos_sh)
        closure = materials.at(dr.gather(jit.UInt32, geo.material_id, hit.prim, valid), si, valid)
        weights = jit.Array3f(*np.array([r[3] for r in rays]).T.astype(np.float32))
        slots = [(rows(s.d), rows(s.weight), {k: np.asarray(m) for k, m in s.kinds.items()},
                  {k: np.asarray(m) for k, m in s.letters.items()})
                 for s in closure.delta_lobes(weights)]
        off = spawn_offset(surf.p)
        front = dr.fma(ng, off, surf.p)
        # Radiance added at the hit (an ambient term, a light sphere's glow), with the
        # letters of its light path read from the hit towards the light.
        glows = [(np.asarray(mask), rows(value).max(axis=1) > 0, letters)
                 for mask, value, letters in closure.emission()]
        shadow = []
        for light in emitters:
            u = jit.Array2f(*(np.full(len(rays), a, np.float32) for a in light.aim))
            wi, dist, _ = light.sample(surf.p, front, u)
            shadow.append((rows(wi), np.asarray(dist).astype(np.float64)))
        smooth = np.asarray(closure.smooth)
        prim, front_side = np.asarray(hit.prim), np.asarray(cos_o) > 0
        P, N, F = rows(surf.p), rows(ng), rows(front)
        offs = np.asarray(off).astype(np.float64)
        nxt = []
        for i, (ro, rd, _, _, letters, ti, kind) in enumerate(rays):
            tree = trees[ti]
            if prim[i] == 0xFFFFFFFF:
                tree.segments.append(Segment(ro, ro + rd * scale, "escape" if kind != "camera"
                                             else "camera", ti))
                if any(not b.hit_term or depth < scene.film.max_depth for b in backgrounds):
                    tree.paths.append("L" + letters[::-1] + "E")   # the background
                continue
            p, ns = P[i], N[i]
            tree.segments.append(Segment(ro, p, kind, ti))
            if emits[int(prim[i])] and front_side[i]:
                tree.paths.append("L" + letters[::-1] + "E")
            if depth == scene.film.max_depth:
                continue
            for mask, positive, glow_letters in glows:
                if mask[i] and positive[i]:
                    tree.paths.append(glow_letters[::-1] + letters[::-1] + "E")
            if smooth[i]:
                origin = F[i]
                for light, (wi_all, dist_all) in zip(emitters, shadow, strict=True):
                    wi, dist = wi_all[i], float(dist_all[i])
                    if float(np.dot(ns, wi)) <= 0:
                        continue
                    d_s, length = light.shadow_ray(v3(P[i]), v3(origin), v3(wi),
                                                   jit.Float(dist))
                    d_s, length = np.asarray(d_s).ravel().astype(np.float64), float(
                        np.asarray(length).ravel()[0])
                    blocked = bool(np.asarray(geo.occluded(
                        v3(origin), v3(d_s), jit.Float(length * (1 - SHADOW_EPSILON))))[0])
                    end = origin + d_s * (length if math.isfinite(length) else scale)
                    tree.segments.append(Segment(origin, end, "blocked" if blocked else
                                                 "shadow", ti))
                    if not blocked:
                        tree.paths.append("LD" + letters[::-1] + "E")
            for dirs, ws, kinds, lobe_letters in slots:
                if ws[i].max() <= DRAW_MIN_WEIGHT or (depth + 1 == scene.film.max_depth and
                                                       not last_level_sees):
                    continue
                r = dirs[i]
                side = ns if float(np.dot(ns, r)) >= 0 else -ns
                seg = "refract" if "transmit" in kinds and kinds["transmit"][i] else "reflect"
                letter = next(k for k, m in lobe_letters.items() if m[i])
                nxt.append((p + side * offs[i], r, math.inf, ws[i], letters + letter, ti, seg))
        rays = nxt
        dr.eval()
    return trees


def _scene_scale(scene) -> float:
    pts = [np.asarray(scene.camera.origin), np.asarray(scene.camera.target)]
    for s in scene.shapes:
        if hasattr(s, "center"):
            pts.append(np.asarray(s.center))
        elif hasattr(s, "corners"):
            pts.append(s.corners()[0])
        elif hasattr(s, "vertices"):
            pts.append(np.asarray(s.vertices[0]))
        elif hasattr(s, "to_world"):
            pts.append(np.asarray(s.to_world)[:3, 3])
    a = np.array(pts, dtype=np.float64)
    return 2.0 * float(np.linalg.norm(a.max(axis=0) - a.min(axis=0))) + 1.0


def project(scene, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image coordinates (pixels, y down) of world points, and a mask of points in front."""
    from whitted.tracer.camera import frame

    cam = scene.camera
    r, up, f = frame(cam)
    W, H = scene.film.width, scene.film.height
    aspect = W / H
    v = points - np.asarray(cam.origin)
    z = v @ f
    if cam.type == "perspective":
        tan = math.tan(math.radians(cam.fov) / 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            sx = (v @ r) / (z * tan)
            sy = (v @ up) / (z * tan / aspect)
        front = z > cam.near_clip
    else:
        half = cam.width / 2
        sx = (v @ r) / half
        sy = (v @ up) / (half / aspect)
        front = np.ones(len(points), bool)
    return np.stack([(sx + 1) / 2 * W, (1 - sy) / 2 * H], axis=1), front


def _clip_to_front(scene, a: np.ndarray, b: np.ndarray):
    """The part of segment a-b in front of the camera's near plane (perspective), or None."""
    from whitted.tracer.camera import frame

    cam = scene.camera
    if cam.type != "perspective":
        return a, b
    _, _, f = frame(cam)
    near = cam.near_clip * 1.01
    za, zb = (a - cam.origin) @ f, (b - cam.origin) @ f
    if za < near and zb < near:
        return None
    if za < near:
        a = a + (b - a) * (near - za) / (zb - za)
    elif zb < near:
        b = b + (a - b) * (near - zb) / (za - zb)
    return a, b


def pick_pixels(scene, wanted=WANTED, spread: int = 0, seed: int = 0
                ) -> dict[str, tuple[int, int] | None]:
    """A pixel whose light mostly travels along each wanted path, or None if no pixel does.

    ``spread``: where possible, keep each pick at least that many pixels away from
    the earlier ones (so that their drawings do not overlap).
    """
    from whitted.tracer.integrator import Integrator

    quick = scene.with_overrides(spp=1)
    full = Integrator(quick, seed=seed).render().image.sum(-1)
    out = {}
    for expr in wanted:
        part = Integrator(quick, seed=seed, lpe=expr).render().image.sum(-1)
        share = np.where(full > 0, part / np.maximum(full, 1e-30), 0)
        score = np.where(share > 0.5, part, 0)
        if score.max() <= 0:
            out[expr] = None
            continue
        if spread > 0:
            yy, xx = np.mgrid[:score.shape[0], :score.shape[1]]
            far = np.ones(score.shape, bool)
            for p in out.values():
                if p is not None:
                    far &= (xx - p[0]) ** 2 + (yy - p[1]) ** 2 >= spread * spread
            if (score * far).max() > 0:
                score = score * far
        y, x = np.unravel_index(int(np.argmax(score)), score.shape)
        out[expr] = (int(x), int(y))
    return out


COLORS = {"camera": "white", "reflect": "#00e5ff", "refract": "#ff4df0", "shadow": "#ffd400",
          "blocked": "#ff3b30", "escape": "#9a9a9a", "indirect": "#7CFC00"}


def draw(scene, image: np.ndarray, trees: list[Tree], path: str, notes: list[str],
         extra_panel=None, missing: list[Tree] = (), shown: np.ndarray | None = None) -> None:
    """The image with the ray trees, and optionally the LDDE/LSDE panel beside it.

    ``missing``: example paths a Whitted tracer cannot make (:func:`example_paths`),
    drawn dash-dotted and marked so. ``shown``: the 8-bit picture to draw on
    (default: ``image`` in sRGB), e.g. minray's linear numbers.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from whitted.tracer.imageio import to_srgb8

    W, H = scene.film.width, scene.film.height
    ncols = 2 if extra_panel is not None else 1
    size = 6.0
    fig, axes = plt.subplots(1, ncols, figsize=(size * ncols * max(W / H, 0.6), size + 1.4),
                             dpi=110, squeeze=False)
    ax = axes[0, 0]
    ax.imshow(to_srgb8(image) if shown is None else shown, extent=(0, W, H, 0),
              interpolation="nearest")
    for tree in [*trees, *missing]:
        for seg in tree.segments:
            clipped = _clip_to_front(scene, seg.a, seg.b)
            if clipped is None:
                continue
            (xa, ya), (xb, yb) = project(scene, np.array(clipped))[0]
            ls = {"blocked": "--", "escape": ":", "indirect": "-."}.get(seg.kind, "-")
            ax.plot([xa, xb], [ya, yb], ls, color=COLORS[seg.kind], lw=1.3, alpha=0.95)
        x, y = tree.pixel
        ax.plot([x + 0.5], [y + 0.5], "o", ms=6, mfc="none", mec="white", mew=1.5)
        labels = sorted(set(tree.paths), key=lambda s: (len(s), s)) or ["(no light)"]
        text = ", ".join(labels)
        extra = any(tree is m for m in missing)
        if extra:
            text += ": no Whitted tracer makes it"
        ax.annotate(text, (x + 0.5, y + 0.5), xytext=(6, -6),
                    textcoords="offset points", color="white", fontsize=8,
                    bbox={"boxstyle": "round,pad=0.2",
                          "fc": "#335500" if extra else "black", "alpha": 0.7})
    ax.set_xlim(0, W)
    ax.set_ylim(H, 0)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"{scene.name}: ray trees of chosen pixels (light paths from light to eye)",
                 fontsize=9)
    handles = [Line2D([], [], color=COLORS[k], ls="--" if k == "blocked" else
                      (":" if k == "escape" else "-"), label=lab)
               for k, lab in (("reflect", "reflected"), ("refract", "refracted"),
                              ("shadow", "shadow ray, light reaches"),
                              ("blocked", "shadow ray, blocked"), ("escape", "leaves the scene"))]
    if missing:
        handles.append(Line2D([], [], color=COLORS["indirect"], ls="-.",
                              label="a path only a path tracer makes"))
    ax.legend(handles=handles, fontsize=7, loc="lower left", framealpha=0.7)
    if extra_panel is not None:
        ax2 = axes[0, 1]
        img, title = extra_panel
        ax2.imshow(img, extent=(0, W, H, 0), cmap="magma", interpolation="nearest")
        ax2.set_xticks([])
        ax2.set_yticks([])
        ax2.set_title(title, fontsize=9)
    fig.text(0.01, 0.01, "\n".join(notes), fontsize=8, va="bottom", ha="left", wrap=True)
    fig.tight_layout(rect=(0, 0.02 + 0.025 * len(notes), 1, 0.97))
    fig.savefig(path)
    plt.close(fig)


def ldde_lsde_panel(scene, spp: int = 64, seed: int = 0):
    """(luminance image, title): Mitsuba path (3 segments) minus Whitted (3 segments)."""
    from whitted.reference.renderers.mitsuba.render import render_reference

    s = scene.with_overrides(max_depth=3, spp=spp)
    path = render_reference(s, "path", seed=seed, jitter=True).image
    whitted = render_reference(s, "whitted", seed=seed, jitter=True).image
    extra = np.maximum((path - whitted).mean(-1), 0)
    share = extra.sum() / max(path.mean(-1).sum(), 1e-30)
    title = (f"LDDE + LSDE: Mitsuba's path tracer (3 segments) minus Whitted;\n"
             f"{100 * share:.1f} % of the path-traced light, none of it in a Whitted tracer")
    vmax = np.quantile(extra, 0.995) if extra.max() > 0 else 1.0
    return np.clip(extra / max(vmax, 1e-30), 0, 1), title


# ------------------------------------------------------------- paths a Whitted tracer lacks


class _Hits:
    """A batch of rays traced through the tracer's geometry and shaded through its interfaces."""

    def __init__(self, geo, materials, o: np.ndarray, d: np.ndarray):
        import drjit as dr

        from whitted.tracer.backend import jit
        from whitted.tracer.geometry import spawn_offset
        from whitted.tracer.materials.base import ShadingPoint

        O = jit.Array3f(*o.T.astype(np.float32))
        D = jit.Array3f(*d.T.astype(np.float32))
        hit = geo.closest_hit(O, D, jit.Float(np.full(len(o), np.inf, np.float32)))
        surf = geo.surface(hit, O, D)
        self.valid = np.asarray(hit.valid)
        self.prim = np.asarray(hit.prim)
        cos_o = -dr.dot(surf.n, D)
        cos_sh = -dr.dot(surf.ns, D)
        ng = dr.select(cos_o >= 0, surf.n, -surf.n)
        nl = dr.select(cos_sh >= 0, surf.ns, -surf.ns)
        self.si = ShadingPoint(surf.p, surf.n, surf.ns, surf.uv, D, nl, ng, cos_sh)
        self.closure = materials.at(dr.gather(jit.UInt32, geo.material_id, hit.prim,
                                              hit.valid), self.si, hit.valid)
        self.off = spawn_offset(surf.p)
        self.front = dr.fma(ng, self.off, surf.p)
        self.p = np.asarray(surf.p).T.astype(np.float64)
        self.ng = np.asarray(ng).T.astype(np.float64)
        self.nl = np.asarray(nl).T.astype(np.float64)
        self.smooth = np.asarray(self.closure.smooth) & self.valid
        self.front_side = np.asarray(cos_o) > 0

    def f(self, wi: np.ndarray) -> np.ndarray:
        """RGB f(wo, wi) of the smooth part, for directions wi (rows)."""
        from whitted.tracer.backend import jit

        return np.asarray(self.closure.eval(jit.Array3f(*wi.T.astype(np.float32)))).T

    def light(self, emits: np.ndarray) -> np.ndarray:
        """RGB radiance the hit shows as a light: an area light's front, or a glow (``L``)."""
        out = np.zeros((len(self.valid), 3))
        area = self.valid & emits[np.where(self.valid, self.prim, 0)] & self.front_side
        out[area] = 1.0
        for mask, value, letters in self.closure.emission():
            if letters == "L":
                v = np.asarray(value).T
                out = np.where(np.asarray(mask)[:, None], np.maximum(out, v), out)
        return out

    def lobes(self):
        """(direction, RGB weight) of each delta lobe, as rows."""
        from whitted.tracer.backend import jit

        ones = jit.Array3f(*np.ones((3, len(self.valid)), np.float32))
        return [(np.asarray(s.d).T.astype(np.float64), np.asarray(s.weight).T)
                for s in self.closure.delta_lobes(ones)]


def example_paths(scene, exprs=("LDDE", "LSDE"), candidates: int = 400,
                  directions: int = 128, seed: int = 7) -> dict[str, Tree | None]:
    """One light path of each kind a Whitted tracer cannot make, found in ``scene``.

    From points x on smooth (diffuse) surfaces seen through pixel centres,
    directions are drawn with a cosine-weighted distribution around the normal
    and traced with the tracer's own geometry and materials. An LDDE path
    continues at a second smooth surface y that a light reaches by an
    unblocked shadow ray (light -> y -> x -> eye: indirect diffuse light); an
    LSDE path follows, from a surface with delta lobes, its strongest lobe
    (at most four specular bounces) until it reaches a light (light -> mirror
    or glass -> x -> eye: a caustic). Of the paths found, the one carrying
    the most light to the eye (the product of f cos along it) is returned,
    as a :class:`Tree` of segments of kind ``"indirect"``; None where the
    scene has none.
    """
    import drjit as dr

    from whitted.tracer.backend import jit
    from whitted.tracer.camera import generate_rays
    from whitted.tracer.emitters import scene_emitters
    from whitted.tracer.geometry import Geometry
    from whitted.tracer.integrator import SHADOW_EPSILON
    from whitted.tracer.materials.dispatch import SceneMaterials

    geo = Geometry(scene)
    materials = SceneMaterials(list(scene.materials.values()))
    lights = [e for e in scene_emitters(scene.lights, geo.emitters, scene.shape_lights())
              if e.illuminates]
    emits = geo.emitting()
    W, H = scene.film.width, scene.film.height
    step = max(1, int(math.sqrt(W * H / candidates)))
    px = np.array([(x, y) for y in range(step // 2, H, step) for x in range(step // 2, W, step)])
    o, d, _ = generate_rays(scene.camera, W, H, jit.Float(px[:, 0] + 0.5),
                            jit.Float(px[:, 1] + 0.5))
    eye = _Hits(geo, materials, np.asarray(o).T.astype(np.float64),
                np.asarray(d).T.astype(np.float64))
    x_ok = eye.smooth
    px, eye_o = px[x_ok], np.asarray(o).T[x_ok].astype(np.float64)
    xp, xn, xfront = eye.p[x_ok], eye.nl[x_ok], np.asarray(eye.front).T[x_ok]
    if len(px) == 0:
        return {e: None for e in exprs}
    # Cosine-weighted directions around each x's normal (Malley's method).
    rng = np.random.default_rng(seed)
    n = len(px) * directions
    idx = np.repeat(np.arange(len(px)), directions)
    u1, u2 = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)], axis=1)
    nrm = xn[idx]
    a = np.where(np.abs(nrm[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t1 = np.cross(nrm, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nrm, t1)
    wd = local[:, :1] * t1 + local[:, 1:2] * t2 + local[:, 2:] * nrm
    # f(x) for each direction: the eye's closure evaluated per candidate, repeated.
    fx = _eval_at(eye, x_ok, wd, idx)
    cos_x = np.einsum("ij,ij->i", wd, nrm)
    hits = _Hits(geo, materials, xfront[idx], wd)
    out: dict[str, Tree | None] = {}

    def tree(i, points, expr):
        t = Tree((int(px[i][0]), int(px[i][1])))
        t.segments.append(Segment(eye_o[i], xp[i], "camera", 0))
        for a_, b_ in zip(points, points[1:], strict=False):
            t.segments.append(Segment(a_, b_, "indirect", 0))
        t.paths.append(expr)
        return t

    for expr in exprs:
        best, best_score = None, 0.0
        if expr == "LDDE":
            ok = hits.valid & hits.smooth
            for light in lights:
                u = jit.Array2f(*(np.full(n, v, np.float32) for v in light.aim))
                wi, dist, value = light.sample(hits.si.p, hits.front, u)
                wi_np = np.asarray(wi).T.astype(np.float64)
                dist_np = np.asarray(dist).astype(np.float64)
                cos_y = np.einsum("ij,ij->i", wi_np, hits.nl)
                lit = ok & (cos_y > 0) & (np.asarray(value).T.max(axis=1) > 0)
                d_s, length = light.shadow_ray(hits.si.p, hits.front, wi, dist)
                blocked = np.asarray(geo.occluded(hits.front, d_s,
                                                  length * (1 - SHADOW_EPSILON), jit.Bool(lit)))
                lit &= ~blocked
                fy = hits.f(wi_np)
                score = (fx * fy * np.asarray(value).T).sum(axis=1) * cos_x * cos_y
                score = np.where(lit, score, 0)
                k = int(np.argmax(score))
                if score[k] > best_score:
                    end = hits.p[k] + wi_np[k] * (dist_np[k] if math.isfinite(dist_np[k])
                                                  else _scene_scale(scene))
                    best_score, best = score[k], tree(idx[k], [xp[idx[k]], hits.p[k], end],
                                                      expr)
        elif expr == "LSDE":
            # Light focused by one specular bounce (LSDE); only if there is none, by more
            # (LS+DE), labelled with as many S as it has.
            weight = np.ones((n, 3))
            chain = [xp[idx], hits.p.copy()]
            cur = hits
            alive = hits.valid.copy()   # a specular vertex: any surface with a delta lobe
            for bounce in range(4):
                if bounce > 0 and best is not None:
                    break
                lobes = cur.lobes()
                if not lobes:
                    break
                strongest = np.argmax(np.stack([w.max(axis=1) for _, w in lobes]), axis=0)
                dnext = np.stack([lobes[j][0][i] for i, j in enumerate(strongest)])
                wnext = np.stack([lobes[j][1][i] for i, j in enumerate(strongest)])
                alive &= wnext.max(axis=1) > 0
                weight = weight * wnext
                side = np.where(np.einsum("ij,ij->i", dnext, cur.ng)[:, None] >= 0,
                                cur.ng, -cur.ng)
                with np.errstate(invalid="ignore"):
                    origin = np.where(alive[:, None],
                                      cur.p + side * np.asarray(cur.off)[:, None], 0)
                dnext = np.where(alive[:, None], dnext, [[0.0, 0.0, 1.0]])
                cur = _Hits(geo, materials, origin, dnext)
                chain.append(cur.p.copy())
                le = cur.light(emits)
                found = alive & cur.valid & (le.max(axis=1) > 0)
                score = np.where(found, (fx * weight * le).sum(axis=1) * cos_x, 0)
                k = int(np.argmax(score))
                if score[k] > best_score:
                    best_score = score[k]
                    best = tree(idx[k], [c[k] for c in chain], "L" + "S" * (bounce + 1) + "DE")
                alive &= cur.valid & ~found
                if not alive.any():
                    break
        out[expr] = best
        dr.eval()
    return out


def _eval_at(eye: _Hits, keep: np.ndarray, wd: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """f(x) (RGB rows) of the eye hits ``keep`` for directions ``wd`` (one per row, x = idx)."""
    import drjit as dr

    from whitted.tracer.backend import jit
    from whitted.tracer.materials.base import ShadingPoint

    lanes = np.nonzero(keep)[0][idx]
    take = jit.UInt32(lanes.astype(np.uint32))
    si = eye.si
    sub = ShadingPoint(*(dr.gather(type(v), v, take) for v in (si.p, si.n, si.ns, si.uv, si.d,
                                                                 si.nl, si.ng, si.cos_i)))
    parts = [(bsdf, dr.gather(type(mask), mask, take),
              None if prm is None else _gather_tree(prm, take))
             for bsdf, mask, prm in eye.closure.parts]
    from whitted.tracer.materials.dispatch import Closure

    closure = Closure(parts, sub, dr.gather(jit.Bool, jit.Bool(eye.valid), take))
    return np.asarray(closure.eval(jit.Array3f(*wd.T.astype(np.float32)))).T


def _gather_tree(prm, take):
    """A kind's parameters (arrays, tuples of arrays or None) gathered at lanes ``take``."""
    import drjit as dr

    if prm is None:
        return None
    if isinstance(prm, tuple):
        return tuple(_gather_tree(p, take) for p in prm)
    return dr.gather(type(prm), prm, take)
