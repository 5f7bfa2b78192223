"""Draw the ray trees of chosen pixels over the image, each light path in Heckbert's notation.

For every chosen pixel the ray through its centre is followed as the tracer
follows it: at a mirror one reflected ray, at glass a reflected and (unless
totally reflected) a refracted ray, at a diffuse surface one shadow ray to
each light. Segments are projected into the image with the camera's own
projection. A path that brings light to the eye is labelled from the light
to the eye (``LDE``, ``LDSE``, ...). Branches whose weight falls below 1e-3
are not drawn (they cannot change the pixel visibly).

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


def _light_points(scene):
    """(position or None for directional, direction, label) of every light to draw rays to."""
    from tracer.scene import DirectionalLight, Sphere, _Planar

    out = []
    for light in scene.lights:
        if isinstance(light, DirectionalLight):
            out.append((None, -np.asarray(light.direction), None))
        else:
            out.append((np.asarray(light.position, dtype=np.float64), None, None))
    for shape in scene.shapes:
        if shape.emitter is None:
            continue
        if isinstance(shape, Sphere):
            out.append((np.asarray(shape.center, dtype=np.float64), None, shape))
        elif isinstance(shape, _Planar):  # rectangles and disks: aim at the centre
            out.append((shape.corners()[0], None, shape))
        else:
            out.append((np.mean(np.asarray(shape.vertices), axis=0), None, shape))
    return out


def ray_trees(scene, pixels: list[tuple[int, int]]) -> list[Tree]:
    """Follow the centre ray of each pixel through the scene (see module doc)."""
    import drjit as dr

    from tracer.backend import jit
    from tracer.camera import generate_rays
    from tracer.fresnel import fresnel_exact, fresnel_schlick, reflect, refract
    from tracer.geometry import Geometry, spawn_offset
    from tracer.scene import Dielectric, Diffuse, Mirror, Phong, Sphere

    geo = Geometry(scene)
    W, H = scene.film.width, scene.film.height

    def v3(a):
        return jit.Array3f(*(float(x) for x in a))

    trees = [Tree(p) for p in pixels]
    fx = np.array([p[0] + 0.5 for p in pixels], dtype=np.float32)
    fy = np.array([p[1] + 0.5 for p in pixels], dtype=np.float32)
    o, d, tmax = generate_rays(scene.camera, W, H, jit.Float(fx), jit.Float(fy))
    # One entry per live ray: origin, direction, weight, eye-side letters, tree index, kind.
    rays = [(np.asarray(o)[:, i].astype(np.float64), np.asarray(d)[:, i].astype(np.float64),
             float(np.asarray(tmax)[i]), 1.0, "", i, "camera") for i in range(len(pixels))]
    lights = _light_points(scene)
    scale = _scene_scale(scene)
    names = list(scene.materials)
    mat_of = np.asarray(geo.material_id)
    emits = np.asarray(geo.radiance).T.max(axis=1) > 0
    for depth in range(1, scene.film.max_depth + 1):
        if not rays:
            break
        O = jit.Array3f(*np.array([r[0] for r in rays]).T.astype(np.float32))
        D = jit.Array3f(*np.array([r[1] for r in rays]).T.astype(np.float32))
        T = jit.Float(np.array([r[2] for r in rays], dtype=np.float32))
        hit = geo.closest_hit(O, D, T)
        surf = geo.surface(hit, O, D)
        prim = np.asarray(hit.prim)
        P = np.asarray(surf.p).T.astype(np.float64)
        N = np.asarray(surf.n).T.astype(np.float64)
        nxt = []
        for i, (ro, rd, _, w, letters, ti, kind) in enumerate(rays):
            tree = trees[ti]
            if prim[i] == 0xFFFFFFFF:
                tree.segments.append(Segment(ro, ro + rd * scale, "escape" if kind != "camera"
                                             else "camera", ti))
                continue
            p, n = P[i], N[i]
            tree.segments.append(Segment(ro, p, kind, ti))
            k = int(prim[i])
            cos_o = -float(np.dot(n, rd))
            if emits[k] and cos_o > 0:
                tree.paths.append("L" + letters[::-1] + "E")
            if depth == scene.film.max_depth:
                continue
            mid = int(mat_of[k])
            mat = scene.materials[names[mid]] if mid < len(names) else None
            ns = n if cos_o >= 0 else -n
            off = float(np.asarray(spawn_offset(v3(p)))[0])
            if isinstance(mat, (Diffuse, Phong)) and depth < scene.film.max_depth:
                origin = p + ns * off
                for pos, direction, lshape in lights:
                    if pos is None:
                        wi, dist = direction / np.linalg.norm(direction), math.inf
                    else:
                        if isinstance(lshape, Sphere):  # aim at the sphere's near side
                            to_c = pos - p
                            pos = pos - to_c / np.linalg.norm(to_c) * lshape.radius
                        wi = pos - origin
                        dist = float(np.linalg.norm(wi))
                        wi = wi / dist
                    if float(np.dot(ns, wi)) <= 0:
                        continue
                    blocked = bool(np.asarray(geo.occluded(
                        v3(origin), v3(wi), jit.Float(float(dist * (1 - 2e-3)))))[0])
                    end = origin + wi * (dist if math.isfinite(dist) else scale)
                    tree.segments.append(Segment(origin, end, "blocked" if blocked else
                                                 "shadow", ti))
                    if not blocked:
                        tree.paths.append("LD" + letters[::-1] + "E")
            elif isinstance(mat, Mirror):
                r = np.asarray(reflect(v3(rd), v3(n))).ravel().astype(np.float64)
                wr = w * max(mat.reflectance)
                if wr > DRAW_MIN_WEIGHT:
                    nxt.append((p + ns * off, r, math.inf, wr, letters + "S", ti, "reflect"))
            elif isinstance(mat, Dielectric):
                c = jit.Float(float(cos_o))
                e = jit.Float(float(mat.eta))
                fr = fresnel_schlick if mat.fresnel == "schlick" else fresnel_exact
                R = float(np.asarray(fr(c, e))[0])
                r = np.asarray(reflect(v3(rd), v3(n))).ravel().astype(np.float64)
                t, tir = refract(v3(rd), v3(n), e)
                if w * R > DRAW_MIN_WEIGHT:
                    nxt.append((p + ns * off, r, math.inf, w * R, letters + "S", ti, "reflect"))
                if not bool(np.asarray(tir)[0]) and w * (1 - R) > DRAW_MIN_WEIGHT:
                    nxt.append((p - ns * off, np.asarray(t).ravel().astype(np.float64),
                                math.inf, w * (1 - R), letters + "S", ti, "refract"))
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
