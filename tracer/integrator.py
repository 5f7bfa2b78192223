"""Whitted's recursive ray tracer, as a wavefront over recursion levels.

Recursion is unrolled into levels: level k holds every ray with k path
segments behind it (camera rays are level 1). Each level is traced in one go
for all its rays; its hits add

* the radiance of an area light hit on its front side (the LE, LS+E paths),
* at diffuse hits, the light of every light source, each through one shadow
  ray (Lambert's law, BRDF = reflectance / pi; lecture 1, "The illumination
  equation"; shadow rays are blocked by every surface, glass included),

and spawn the next level: at mirrors the reflected ray (weight = the
reflectance), at dielectrics both the reflected ray (weight R) and the
refracted ray (weight (1 - R) (n1 / n2)^2), with R from the exact Fresnel
equations or Schlick's approximation, and only reflection under total
internal reflection. Rays that miss, end on a diffuse surface or carry zero
weight spawn nothing, and the next level is compacted to the rays that
remain, so the cost follows the rays actually traced rather than 2^depth.

``max_depth`` counts path segments as Mitsuba does: 1 sees only emitters,
2 adds direct light at the first hit, each further unit one more specular
bounce. The recursion "illumination equation with recursion" of lecture 1 is
exactly this sum, written level by level.

Work is bounded: the image is rendered in chunks of whole pixels, and a level
that grows beyond the chunk size is split and processed depth-first.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from tracer import backend, fresnel, lights, phong, texture
from tracer.backend import jit
from tracer.camera import generate_rays
from tracer.geometry import (
    BLACK,
    DIELECTRIC,
    DIFFUSE,
    MIRROR,
    PHONG,
    Geometry,
    Hit,
    spawn_offset,
)
from tracer.sampling import mix32, pixel_samples, seed32, stratified_2d
from tracer.scene import (
    Checkerboard,
    Dielectric,
    DirectionalLight,
    Disk,
    Mirror,
    Phong,
    PointLight,
    Rectangle,
    Scene,
    Sphere,
    SpotLight,
)
from tracer.shapes import sphere as sphere_f

#: Shadow rays stop this fraction short of the light, so the light's own surface
#: (for area lights) never counts as an occluder.
SHADOW_EPSILON = 1e-3

#: A ray "still matters" in the statistics when its weight exceeds this: it can then
#: change its pixel by more than 0.1 % of the light it finds.
SIGNIFICANT_WEIGHT = 1e-3


@dataclass
class RenderResult:
    """An image (H x W x 3, float32, linear radiance) and what it cost."""
    image: np.ndarray
    spp: int
    seconds: float = 0.0
    rays_per_level: list[int] = field(default_factory=list)
    shadow_rays_per_level: list[int] = field(default_factory=list)
    #: rays per level whose weight (in any channel) exceeds SIGNIFICANT_WEIGHT
    significant_rays_per_level: list[int] = field(default_factory=list)
    #: with ``moments``: variance of each pixel mean, (E[x^2] - E[x]^2) / spp
    variance: np.ndarray | None = None

    @property
    def rays_total(self) -> int:
        return sum(self.rays_per_level) + sum(self.shadow_rays_per_level)


@dataclass
class _Batch:
    """Rays of one recursion level: state carried from level to level."""
    o: object
    d: object
    tmax: object
    weight: object
    pixel: object   # global pixel index
    s: object       # sample index within the pixel
    slot: object    # index of the sample in the chunk's radiance buffer
    state: object = None  # light-path-expression DFA state (only with an expression)

    FIELDS = ("o", "d", "tmax", "weight", "pixel", "s", "slot", "state")

    def size(self) -> int:
        return dr.width(self.slot)

    def gather(self, index) -> _Batch:
        return _Batch(*(None if getattr(self, f) is None else
                        dr.gather(type(getattr(self, f)), getattr(self, f), index)
                        for f in self.FIELDS))

    def split(self, cap: int) -> list[_Batch]:
        n = self.size()
        if n <= cap:
            return [self]
        return [self.gather(dr.arange(jit.UInt32, a, min(a + cap, n))) for a in range(0, n, cap)]


def _concat(parts: list[_Batch]) -> _Batch | None:
    parts = [p for p in parts if p is not None and p.size() > 0]
    if not parts:
        return None
    if len(parts) == 1:
        return parts[0]
    out = []
    for f in _Batch.FIELDS:
        vals = [getattr(p, f) for p in parts]
        t = type(vals[0])
        if vals[0] is None:
            out.append(None)
        elif dr.size_v(t) == 3:
            out.append(t(*(dr.concat([v[k] for v in vals]) for k in range(3))))
        else:
            out.append(dr.concat(vals))
    return _Batch(*out)


def _count(masks) -> int:
    return sum(int(dr.count(m)[0]) for m in masks)


class _Materials:
    """Material table: kind, colours, Phong parameters, eta, Schlick flag, checkerboards."""

    def __init__(self, scene: Scene):
        def blank(kind: int) -> dict:
            return {"kind": kind, "refl": (0, 0, 0), "ks": (0, 0, 0), "p": 1.0, "blinn": False,
                    "amb": (0, 0, 0), "eta": 1.0, "schlick": False, "checker": False,
                    "c0": (0, 0, 0), "c1": (0, 0, 0), "scale": (1, 1)}

        rows = []
        for m in scene.materials.values():
            row = blank(DIFFUSE)
            if isinstance(m, Dielectric):
                row.update(kind=DIELECTRIC, refl=(1, 1, 1), eta=m.eta,
                           schlick=m.fresnel == "schlick")
            elif isinstance(m, Mirror):
                row.update(kind=MIRROR, refl=m.reflectance)
            else:
                tex = m.diffuse if isinstance(m, Phong) else m.reflectance
                if isinstance(tex, Checkerboard):
                    row.update(checker=True, c0=tex.color0, c1=tex.color1, scale=tex.scale)
                else:
                    row.update(refl=tex)
                if isinstance(m, Phong):
                    row.update(kind=PHONG, ks=m.specular, p=m.exponent,
                               blinn=m.model == "blinn-phong", amb=m.ambient)
            rows.append(row)
        rows.append(blank(BLACK))  # pure emitters: material index len(materials), black

        def col(key):
            a = np.asarray([r[key] for r in rows], dtype=np.float32)
            return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])

        self.kind = jit.UInt32(np.asarray([r["kind"] for r in rows], dtype=np.uint32))
        self.reflectance = col("refl")
        self.ks = col("ks")
        self.ambient = col("amb")
        self.c0, self.c1 = col("c0"), col("c1")
        sc = np.asarray([r["scale"] for r in rows], dtype=np.float32)
        self.scale = jit.Array2f(sc[:, 0], sc[:, 1])
        self.exponent = jit.Float(np.asarray([r["p"] for r in rows], dtype=np.float32))
        self.blinn = jit.Bool(np.asarray([r["blinn"] for r in rows]))
        self.checker = jit.Bool(np.asarray([r["checker"] for r in rows]))
        self.eta = jit.Float(np.asarray([r["eta"] for r in rows], dtype=np.float32))
        self.schlick = jit.Bool(np.asarray([r["schlick"] for r in rows]))
        kinds = {r["kind"] for r in rows}
        self.has_specular = bool(kinds & {MIRROR, DIELECTRIC})
        self.has_phong = PHONG in kinds
        self.has_blinn = any(r["blinn"] for r in rows)
        self.has_checker = any(r["checker"] for r in rows)
        self.has_ambient = any(any(r["amb"]) for r in rows)

    def diffuse_color(self, mid, uv, active):
        """kd at the hit: the material's colour, or its checkerboard looked up at uv."""
        refl = dr.gather(jit.Array3f, self.reflectance, mid, active)
        if not self.has_checker:
            return refl
        checker = dr.gather(jit.Bool, self.checker, mid, active)
        scale = dr.gather(jit.Array2f, self.scale, mid, active)
        board = texture.checkerboard(uv, scale, dr.gather(jit.Array3f, self.c0, mid, active),
                                     dr.gather(jit.Array3f, self.c1, mid, active))
        return dr.select(checker, board, refl)


def _vec(v):
    return jit.Array3f(float(v[0]), float(v[1]), float(v[2]))


def _col(c):
    return jit.Array3f(float(c[0]), float(c[1]), float(c[2]))


class _DeltaLight:
    """A point, spot or directional light: one shadow ray per shading point, no sampling."""

    def __init__(self, light):
        self.light = light
        if isinstance(light, DirectionalLight):
            self.direction = _vec(light.direction)
            self.irradiance = _col(light.irradiance)
        else:
            self.position = _vec(light.position)
            self.intensity = _col(light.intensity)
            if isinstance(light, SpotLight):
                self.axis = _vec(light.axis)

    def incident(self, p, p_off):
        """(wi, shadow-ray tmax, incident factor) at shading points p, shadow rays from p_off."""
        L = self.light
        if isinstance(L, DirectionalLight):
            wi, dist, e = lights.directional(p, self.direction, self.irradiance)
            return wi, dist, e
        if isinstance(L, PointLight):
            wi, _, e = lights.point(p, self.position, self.intensity)
        else:
            wi, _, e = lights.spot(p, self.position, self.axis, self.intensity,
                                   L.cutoff_angle, L.beam_width)
        return wi, dr.norm(self.position - p_off) * (1 - SHADOW_EPSILON), e


class _AreaLight:
    """An emitting shape, sampled once per shading point (by solid angle for spheres)."""

    def __init__(self, shape, index: int):
        self.index = index
        self.radiance = _col(shape.emitter.radiance)
        self.kind = type(shape).__name__
        if isinstance(shape, Sphere):
            self.center, self.radius = _vec(shape.center), float(shape.radius)
        elif isinstance(shape, (Rectangle, Disk)):
            c, u, v = shape.corners()
            self.center, self.u, self.v = _vec(c), _vec(u), _vec(v)
            self.n = _vec(shape.normal())
            area = float(np.linalg.norm(np.cross(u, v)))
            self.area = (math.pi if isinstance(shape, Disk) else 4.0) * area
        else:
            p = np.asarray(shape.vertices)
            self.p0, self.e1, self.e2 = _vec(p[0]), _vec(p[1] - p[0]), _vec(p[2] - p[0])
            n = np.cross(p[1] - p[0], p[2] - p[0])
            self.n = _vec(n / np.linalg.norm(n))
            self.area = 0.5 * float(np.linalg.norm(n))

    def incident(self, p, p_off, sample):
        """(wi, shadow-ray tmax, L cos / r^2 / pdf) from one light sample per shading point."""
        if self.kind == "Sphere":
            to_c = self.center - p
            dc = dr.norm(to_c)
            outside = dc > self.radius
            sin2_max = dr.minimum((self.radius * self.radius) / (dc * dc), 1)
            cos_max = dr.sqrt(1 - sin2_max)
            # 1 - cos_max without cancellation, for small and distant spheres
            x, y, z, pdf = lights.sample_cone(sample, cos_max, sin2_max / (1 + cos_max))
            w = to_c / dc
            t1, t2 = lights.coordinate_system(w)
            wi = dr.normalize(x * t1 + y * t2 + z * w)
            t0, _, real = sphere_f.roots(p_off, wi, self.center, self.radius)
            # A grazing sample can miss by rounding: take the tangent distance then.
            dist = dr.select(real & (t0 > 0), t0, dr.dot(self.center - p_off, wi))
            value = dr.select(outside, self.radiance / pdf, 0)
            return wi, dist * (1 - SHADOW_EPSILON), value
        if self.kind == "Rectangle":
            y = lights.sample_parallelogram(sample, self.center, self.u, self.v)
        elif self.kind == "Disk":
            y = lights.sample_ellipse(sample, self.center, self.u, self.v)
        else:
            y = lights.sample_triangle(sample, self.p0, self.e1, self.e2)
        to_y = y - p
        dist = dr.norm(to_y)
        wi = to_y / dist
        cos_l = -dr.dot(self.n, wi)  # front side emits: the light's normal faces p
        value = dr.select(cos_l > 0, self.radiance * (cos_l * self.area / (dist * dist)), 0)
        return wi, dr.norm(y - p_off) * (1 - SHADOW_EPSILON), value


class Integrator:
    """Renders one validated scene; construct once, render any number of times."""

    def __init__(self, scene: Scene, seed: int = 0, chunk_samples: int | None = None,
                 lpe: str | None = None, min_weight: float = 0.0):
        backend.use()
        from tracer.limits import check_render

        check_render(scene, moments=False)
        self.scene = scene
        #: any integer; the streams use its 32-bit form (tracer.sampling.seed32)
        self.seed = seed32(seed)
        #: Branches whose weight is at most this are dropped. 0 (exact Whitted) drops only
        #: zero-weight branches; a positive value is a biased speed-up.
        self.min_weight = float(min_weight)
        self.dfa = None
        if lpe is not None:
            from tracer.lpe import ALPHABET, compile_lpe

            self.dfa = compile_lpe(lpe)
            self.dfa_trans = jit.UInt32([t for row in self.dfa.transitions for t in row])
            self.dfa_accept = jit.Bool(list(self.dfa.accepting))
            self._letter = {c: i for i, c in enumerate(ALPHABET)}
        self.geo = Geometry(scene)
        self.mat = _Materials(scene)
        self.delta_lights = [_DeltaLight(light) for light in scene.lights]
        self.area_lights = [_AreaLight(s, i) for i, s in enumerate(self.geo.emitters)]
        if chunk_samples is None:
            chunk_samples = (1 << 24) if backend.name() == "cuda" else (1 << 21)
        self.chunk_samples = chunk_samples

    # ------------------------------------------------------------------ one level

    def _level(self, b: _Batch, depth: int, L) -> tuple[_Batch | None, int]:
        """Trace one level; add its light to L; return the next level and the shadow-ray count."""
        scene, geo, mat = self.scene, self.geo, self.mat
        max_depth = scene.film.max_depth
        hit: Hit = geo.closest_hit(b.o, b.d, b.tmax)
        valid = hit.valid
        surf = geo.surface(hit, b.o, b.d)
        p, n, n_sh = surf.p, surf.n, surf.ns
        cos_o = -dr.dot(n, b.d)              # > 0: the ray arrives on the front side
        contrib = dr.zeros(jit.Array3f, b.size())

        if self.area_lights:
            le = dr.gather(jit.Array3f, geo.radiance, hit.prim, valid)
            seen = valid & (cos_o > 0)
            if self.dfa is not None:  # the light is the path's L: ... E + L
                seen &= self._accepts(self._step(b.state, "L"))
            contrib += dr.select(seen, b.weight * le, 0)

        children = None
        shadow_masks = []
        if depth < max_depth:
            mid = dr.gather(jit.UInt32, geo.material_id, hit.prim, valid)
            kind = dr.gather(jit.UInt32, mat.kind, mid, valid)
            refl = dr.gather(jit.Array3f, mat.reflectance, mid, valid)
            # Two-sided: shading happens on the side the ray arrives from (judged, as
            # Mitsuba's twosided BSDF does, by the shading normal); ray origins move off
            # the surface along the geometric normal.
            cos_sh = -dr.dot(n_sh, b.d)
            nl = dr.select(cos_sh >= 0, n_sh, -n_sh)
            ng = dr.select(cos_o >= 0, n, -n)
            off = spawn_offset(p)
            p_front = dr.fma(ng, off, p)
            lit = valid & ((kind == DIFFUSE) | (kind == PHONG))
            if self.dfa is not None:  # light at a diffuse vertex: ... E + D + L
                lit &= self._accepts(self._step(self._step(b.state, "D"), "L"))
            kd = mat.diffuse_color(mid, surf.uv, lit)
            wo = -b.d
            if mat.has_phong:
                is_phong = kind == PHONG
                ks = dr.gather(jit.Array3f, mat.ks, mid, lit & is_phong)
                exponent = dr.gather(jit.Float, mat.exponent, mid, lit & is_phong)
                blinn = dr.gather(jit.Bool, mat.blinn, mid, lit & is_phong)
                if mat.has_ambient:  # tracer-only: the lecture's "cheapest of all hacks"
                    amb = dr.gather(jit.Array3f, mat.ambient, mid, lit & is_phong)
                    contrib += dr.select(lit & is_phong, b.weight * amb, 0)
            sources = [(light, None) for light in self.delta_lights]
            sources += [(light, stratified_2d(b.pixel, b.s, scene.film.strata,
                                              mix32(self.seed, depth, light.index)))
                        for light in self.area_lights]
            for light, u in sources:
                if u is None:
                    wi, tmax, e = light.incident(p, p_front)
                else:
                    wi, tmax, e = light.incident(p, p_front, u)
                cos = lights.lambert_cosine(nl, wi)
                f = kd * (1 / math.pi)
                if mat.has_phong:
                    fp = phong.phong_brdf(nl, wi, wo, kd, ks, exponent, "phong")
                    if mat.has_blinn:
                        fb = phong.phong_brdf(nl, wi, wo, kd, ks, exponent, "blinn-phong")
                        fp = dr.select(blinn, fb, fp)
                    f = dr.select(is_phong, fp, f)
                active = lit & (cos > 0) & (dr.max(e) > 0)
                # Leave the surface on the side the shadow ray goes to (as Mitsuba's
                # spawn_ray_to does): with interpolated normals a lit direction can lie
                # behind the geometric surface near a shadow terminator.
                origin = dr.fma(dr.select(dr.dot(n, wi) >= 0, n, -n), off, p)
                blocked = geo.occluded(origin, wi, tmax, active)
                contrib += dr.select(active & ~blocked, b.weight * f * e * cos, 0)
                shadow_masks.append(active)
            if mat.has_specular:
                children = self._specular(b, valid, kind, refl, mid, n_sh, ng, p, off, cos_sh)

        dr.scatter_reduce(dr.ReduceOp.Add, L, contrib, b.slot)
        if children is None:
            dr.eval(L, *shadow_masks)      # one kernel: intersection, shading, shadow rays
            return None, _count(shadow_masks)
        refl_b, refr_b, keep_r, keep_t = children
        extra = () if refl_b.state is None else (refl_b.state,)
        dr.eval(L, *shadow_masks, refl_b.o, refl_b.d, refl_b.weight,
                refr_b.o, refr_b.d, refr_b.weight, keep_r, keep_t, *extra)
        nxt = _concat([refl_b.gather(dr.compress(keep_r)), refr_b.gather(dr.compress(keep_t))])
        return nxt, _count(shadow_masks)

    def _specular(self, b, valid, kind, refl, mid, n, ns, p, off, cos_o):
        mat = self.mat
        mirror = valid & (kind == MIRROR)
        glass = valid & (kind == DIELECTRIC)
        eta = dr.gather(jit.Float, mat.eta, mid, glass)
        schlick = dr.gather(jit.Bool, mat.schlick, mid, glass)
        eta = dr.select(glass, eta, 1.0)
        r = dr.select(schlick, fresnel.fresnel_schlick(cos_o, eta),
                      fresnel.fresnel_exact(cos_o, eta))
        t_dir, tir = fresnel.refract(b.d, n, eta)
        # Radiance crossing from n_i into n_t is scaled by (n_i / n_t)^2.
        n_ratio = dr.select(cos_o >= 0, dr.rcp(eta), eta)
        w_refl = dr.select(mirror, b.weight * refl, dr.select(glass, b.weight * r, 0))
        w_refr = dr.select(glass & ~tir, b.weight * ((1 - r) * n_ratio * n_ratio), 0)
        r_dir = fresnel.reflect(b.d, n)
        far = dr.full(jit.Float, dr.inf, b.size())
        # Origins leave the surface on the side each new direction goes to.
        ng = dr.select(dr.dot(ns, r_dir) >= 0, ns, -ns)
        state = None
        if self.dfa is not None:  # a specular vertex: ... + S; dead states carry nothing
            state = self._step(b.state, "S")
            alive = state != 0
            w_refl = dr.select(alive, w_refl, 0)
            w_refr = dr.select(alive, w_refr, 0)
        refl_b = _Batch(dr.fma(ng, off, p), r_dir, far, w_refl, b.pixel, b.s, b.slot, state)
        refr_b = _Batch(dr.fma(dr.select(dr.dot(ns, t_dir) >= 0, ns, -ns), off, p), t_dir, far,
                        w_refr, b.pixel, b.s, b.slot, state)
        return (refl_b, refr_b, dr.max(w_refl) > self.min_weight,
                dr.max(w_refr) > self.min_weight)

    def _step(self, state, letter: str):
        return dr.gather(jit.UInt32, self.dfa_trans, state * len(self._letter) +
                         self._letter[letter])

    def _accepts(self, state):
        return dr.gather(jit.Bool, self.dfa_accept, state)

    # ------------------------------------------------------------------ the image

    def render(self, progress: Callable[[int, int], None] | None = None,
               moments: bool = False) -> RenderResult:
        """Render the image; ``moments`` also estimates each pixel's variance."""
        scene = self.scene
        W, H = scene.film.width, scene.film.height
        n = scene.film.strata
        spp = n * n
        max_depth = scene.film.max_depth
        total = W * H
        per_chunk = max(1, self.chunk_samples // spp)
        image = np.zeros((total, 3), dtype=np.float32)
        second = np.zeros((total, 3), dtype=np.float32) if moments else None
        rays = [0] * max_depth
        shadow = [0] * max_depth
        significant = [0] * max_depth
        start = time.perf_counter()
        for first in range(0, total, per_chunk):
            count = min(per_chunk, total - first)
            pixel, s, fx, fy = pixel_samples(W, n, first, count)
            o, d, tmax = generate_rays(scene.camera, W, H, fx, fy)
            L = dr.zeros(jit.Array3f, count * spp)
            slot = dr.arange(jit.UInt32, count * spp)
            ones = dr.full(jit.Array3f, 1.0, count * spp)
            state = None
            if self.dfa is not None:  # every path ends at the eye: read E first
                state = dr.full(jit.UInt32, self.dfa.step(self.dfa.start, "E"), count * spp)
            stack = [(1, _Batch(o, d, tmax, ones, pixel, s, slot, state))]
            while stack:
                depth, batch = stack.pop()
                rays[depth - 1] += batch.size()
                significant[depth - 1] += int(dr.count(dr.max(batch.weight) >
                                                       SIGNIFICANT_WEIGHT)[0])
                nxt, n_shadow = self._level(batch, depth, L)
                shadow[depth - 1] += n_shadow
                if nxt is not None and depth < max_depth:
                    for part in reversed(nxt.split(self.chunk_samples)):
                        stack.append((depth + 1, part))
            px = dr.block_sum(L, spp) * (1.0 / spp)
            image[first:first + count] = px.numpy().T
            if second is not None:
                second[first:first + count] = (dr.block_sum(L * L, spp) * (1.0 / spp)).numpy().T
            if progress is not None:
                progress(first + count, total)
        seconds = time.perf_counter() - start
        while rays and rays[-1] == 0:
            rays.pop()
        variance = None
        if second is not None:
            variance = (np.maximum(second - image.astype(np.float64) ** 2, 0) / spp)
            variance = variance.astype(np.float32).reshape(H, W, 3)
        return RenderResult(image.reshape(H, W, 3), spp, seconds, rays,
                            shadow[:len(rays)] if rays else [], significant[:len(rays)],
                            variance)


def render(scene: Scene, progress: Callable[[int, int], None] | None = None,
           seed: int = 0, lpe: str | None = None) -> RenderResult:
    """Render a validated scene with the tracer (two lines from Python: load, render).

    ``lpe``: only the light on paths matching this light-path expression
    (see :mod:`tracer.lpe`), e.g. ``"LDS+E"``.
    """
    return Integrator(scene, seed=seed, lpe=lpe).render(progress)
