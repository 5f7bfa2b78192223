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

from tracer.errors import UserError

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

    from tracer.backend import jit
    from tracer.camera import generate_rays
    from tracer.emitters import scene_emitters
    from tracer.geometry import Geometry, spawn_offset
    from tracer.integrator import SHADOW_EPSILON
    from tracer.materials.base import ShadingPoint
    from tracer.materials.dispatch import SceneMaterials

    geo = Geometry(scene)
    materials = SceneMaterials(list(scene.materials.values()))
    emitters = scene_emitters(scene.lights, geo.emitters)
    W, H = scene.film.width, scene.film.height

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
    emits = np.asarray(geo.radiance).T.max(axis=1) > 0
    for depth in range(1, scene.film.max_depth + 1):
        if not rays:
            break
        O = jit.Array3f(*np.array([r[0] for r in rays]).T.astype(np.float32))
        D = jit.Array3f(*np.array([r[1] for r in rays]).T.astype(np.float32))
        T = jit.Float(np.array([r[2] for r in rays], dtype=np.float32))
        hit = geo.closest_hit(O, D, T)
        surf = geo.surface(hit, O, D)
        valid = hit.valid
        # The hit as the integrator shades it (Integrator._level).
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
                continue
            p, ns = P[i], N[i]
            tree.segments.append(Segment(ro, p, kind, ti))
            if emits[int(prim[i])] and front_side[i]:
                tree.paths.append("L" + letters[::-1] + "E")
            if depth == scene.film.max_depth:
                continue
            if smooth[i]:
                origin = F[i]
                for wi_all, dist_all in shadow:
                    wi, dist = wi_all[i], float(dist_all[i])
                    if float(np.dot(ns, wi)) <= 0:
                        continue
                    blocked = bool(np.asarray(geo.occluded(
                        v3(origin), v3(wi), jit.Float(dist * (1 - SHADOW_EPSILON))))[0])
                    end = origin + wi * (dist if math.isfinite(dist) else scale)
                    tree.segments.append(Segment(origin, end, "blocked" if blocked else
                                                 "shadow", ti))
                    if not blocked:
                        tree.paths.append("LD" + letters[::-1] + "E")
            for dirs, ws, kinds, lobe_letters in slots:
                if ws[i].max() <= DRAW_MIN_WEIGHT:
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
    from tracer.camera import frame

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
    from tracer.camera import frame

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


def pick_pixels(scene, wanted=WANTED, seed: int = 0) -> dict[str, tuple[int, int] | None]:
    """A pixel whose light mostly travels along each wanted path, or None if no pixel does."""
    from tracer.integrator import Integrator

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
        y, x = np.unravel_index(int(np.argmax(score)), score.shape)
        out[expr] = (int(x), int(y))
    return out


COLORS = {"camera": "white", "reflect": "#00e5ff", "refract": "#ff4df0", "shadow": "#ffd400",
          "blocked": "#ff3b30", "escape": "#9a9a9a"}


def draw(scene, image: np.ndarray, trees: list[Tree], path: str, notes: list[str],
         extra_panel=None) -> None:
    """The image with the ray trees, and optionally the LDDE/LSDE panel beside it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from tracer.imageio import to_srgb8

    W, H = scene.film.width, scene.film.height
    ncols = 2 if extra_panel is not None else 1
    size = 6.0
    fig, axes = plt.subplots(1, ncols, figsize=(size * ncols * max(W / H, 0.6), size + 1.4),
                             dpi=110, squeeze=False)
    ax = axes[0, 0]
    ax.imshow(to_srgb8(image), extent=(0, W, H, 0), interpolation="nearest")
    for tree in trees:
        for seg in tree.segments:
            clipped = _clip_to_front(scene, seg.a, seg.b)
            if clipped is None:
                continue
            (xa, ya), (xb, yb) = project(scene, np.array(clipped))[0]
            ls = "--" if seg.kind == "blocked" else (":" if seg.kind == "escape" else "-")
            ax.plot([xa, xb], [ya, yb], ls, color=COLORS[seg.kind], lw=1.3, alpha=0.95)
        x, y = tree.pixel
        ax.plot([x + 0.5], [y + 0.5], "o", ms=6, mfc="none", mec="white", mew=1.5)
        labels = sorted(set(tree.paths), key=lambda s: (len(s), s)) or ["(no light)"]
        ax.annotate(", ".join(labels), (x + 0.5, y + 0.5), xytext=(6, -6),
                    textcoords="offset points", color="white", fontsize=8,
                    bbox={"boxstyle": "round,pad=0.2", "fc": "black", "alpha": 0.6})
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
    from reference.render import render_reference

    s = scene.with_overrides(max_depth=3, spp=spp)
    path = render_reference(s, "path", seed=seed, jitter=True).image
    whitted = render_reference(s, "whitted", seed=seed, jitter=True).image
    extra = np.maximum((path - whitted).mean(-1), 0)
    share = extra.sum() / max(path.mean(-1).sum(), 1e-30)
    title = (f"LDDE + LSDE: Mitsuba's path tracer (3 segments) minus Whitted;\n"
             f"{100 * share:.1f} % of the path-traced light, none of it in a Whitted tracer")
    vmax = np.quantile(extra, 0.995) if extra.max() > 0 else 1.0
    return np.clip(extra / max(vmax, 1e-30), 0, 1), title
