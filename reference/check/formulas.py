"""``whitted formulas``: the catalog of formula bugs at the level of one function.

Another renderer's formulas are tested one at a time, away from any image:
the harness sends a formula's name and its inputs, the renderer answers with
its outputs, and the answers are compared with Mitsuba 3's own function
where Mitsuba has one (``mi.fresnel``, ``mi.reflect``, ``mi.refract``,
``mi.fresnel_conductor``, a sphere's and a triangle mesh's ray intersection)
and with the tracer's own formula otherwise (``tracer/fresnel.py``,
``phong.py``, ``lights.py``, ``camera.py``, ``shapes/``, ``geometry.py``).
A failing formula is matched against the catalog of bugs
(:mod:`reference.mutants`): the tracer's formula is evaluated with each
catalogued switch that it reaches turned on (:mod:`tracer.faults`), alone and
in pairs, and a bug whose outputs equal the given ones on every input is
named. The protocol, the formulas' inputs and outputs and the tolerances are
documented in ``docs/formulas.md``; :data:`FORMULAS` is the one source of all
three.

Tolerances are stated in units of float32's unit roundoff u = 2^-24 (about
6e-8): an output x passes against the expected e when
|x - e| <= K u (1 + |e|) for each component, K chosen per formula from the
number of roundings its float32 evaluation takes and how it amplifies them
(a power cos^p multiplies cos's relative error by p; a root near a tangent
divides by sqrt of the discriminant). An adapter computing in float32 or in
float64 passes; one ulp-exact agreement is not asked for.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import select
import shlex
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from whitted.tracer.errors import UserError

#: float32's unit roundoff, the unit of every tolerance
U = 2.0 ** -24


class AdapterError(UserError):
    """The adapter crashed, timed out or answered garbage (exit 2; the message is one line)."""


# ---------------------------------------------------------------------------- the formulas


@dataclass(frozen=True)
class Formula:
    """One formula of the protocol: its inputs, outputs, reference, tolerance and cases."""
    name: str
    summary: str
    #: input name -> kind: "number", "vec3", "matrix4" (4 rows of 4), "string"
    inputs: dict
    #: output name -> kind: "bool", "number", "vec3"
    outputs: dict
    #: output name -> (the bool output, the value it must have for this output to count)
    when: dict
    #: what the answers are compared with, in words
    reference: str
    #: the tolerance in units of U (module docstring), and why
    ulps: int
    why: str
    #: () -> [(label, inputs)]
    cases: Callable
    #: [inputs] -> [outputs] (the reference)
    expected: Callable
    #: [inputs] -> [outputs] (the tracer's formula, for naming a bug; faults switch it)
    tracer: Callable

    @property
    def tolerance(self) -> float:
        return self.ulps * U


def _f32(x):
    """x rounded to float32 and back to a Python float (what both sides read)."""
    return float(np.float32(x))


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return [_f32(c) for c in v / np.linalg.norm(v)]


def _vec(v):
    return [_f32(c) for c in v]


# -------- array helpers: lists of inputs <-> Dr.Jit arrays (the tracer's and Mitsuba's)

def _col(rows, key):
    return np.array([r[key] for r in rows], dtype=np.float32)


def _jf(rows, key):
    from whitted.tracer.backend import jit
    return jit.Float(_col(rows, key))


def _jv(rows, key):
    from whitted.tracer.backend import jit
    a = np.array([r[key] for r in rows], dtype=np.float32).reshape(-1, 3)
    return jit.Array3f(*(jit.Float(np.ascontiguousarray(a[:, i])) for i in range(3)))


def _mf(mi, rows, key):
    return mi.Float(_col(rows, key))


def _mv(mi, cls, rows, key):
    a = np.array([r[key] for r in rows], dtype=np.float32).reshape(-1, 3)
    return cls(*(mi.Float(np.ascontiguousarray(a[:, i])) for i in range(3)))


def _np(x, n):
    """A Dr.Jit Float (or a Python number) as n float64 values."""
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    return np.broadcast_to(a, (n,)) if a.size == 1 else a


def _npv(v, n):
    return np.stack([_np(v.x, n), _np(v.y, n), _np(v.z, n)], axis=1)


def _npb(x, n):
    a = np.asarray(x, dtype=bool).reshape(-1)
    return np.broadcast_to(a, (n,)) if a.size == 1 else a


def _mitsuba():
    from whitted.reference import mitsuba
    return mitsuba()


# -------- Fresnel, reflection, refraction

_FRESNEL_CASES = [(1.5, "glass"), (1.33, "water"), (2.42, "diamond"), (1 / 1.5, "eta < 1"),
                  (1.0, "equal indices")]


def _cos_label(c, eta):
    rel = eta if c >= 0 else 1 / eta
    side = "from outside" if c >= 0 else "from inside"
    s2 = (1 - c * c) / (rel * rel)
    what = ("total internal reflection" if s2 > 1 else "grazing" if abs(c) < 0.05
            else "normal incidence" if abs(c) == 1 else "oblique")
    return f"{side}, {what}"


def _fresnel_cases():
    out = []
    for eta, name in _FRESNEL_CASES:
        for c in (1.0, 0.9, 0.6, 0.3, 0.1, 0.02, -1.0, -0.95, -0.8, -0.6, -0.3, -0.02):
            out.append((f"{name} (eta {eta:.4g}), {_cos_label(c, eta)}",
                        {"cos_i": _f32(c), "eta": _f32(eta)}))
    return out


def _fresnel_exact_expected(rows):
    mi = _mitsuba()
    f, *_ = mi.fresnel(_mf(mi, rows, "cos_i"), _mf(mi, rows, "eta"))
    return [{"R": r} for r in _np(f, len(rows)).tolist()]


def _fresnel_exact_tracer(rows):
    from whitted.tracer import fresnel
    r = fresnel.fresnel_exact(_jf(rows, "cos_i"), _jf(rows, "eta"))
    return [{"R": x} for x in _np(r, len(rows)).tolist()]


def _fresnel_schlick_tracer(rows):
    from whitted.tracer import fresnel
    r = fresnel.fresnel_schlick(_jf(rows, "cos_i"), _jf(rows, "eta"))
    return [{"R": x} for x in _np(r, len(rows)).tolist()]


def _conductor_cases():
    out = []
    for eta, k, name in ((0.2, 3.0, "gold-like"), (1.5, 0.0, "k = 0 (a dielectric)"),
                         (0.0, 1.0, "perfect mirror (eta 0, k 1)"), (2.9, 3.0, "iron-like")):
        for c in (1.0, 0.7, 0.3, 0.05, 0.01):
            what = "grazing" if c < 0.06 else "normal incidence" if c == 1 else "oblique"
            out.append((f"{name}, {what}", {"cos_i": _f32(c), "eta": _f32(eta), "k": _f32(k)}))
    return out


def _conductor_expected(rows):
    import drjit as dr
    mi = _mitsuba()
    complex_t = getattr(dr, mi.variant().split("_")[0]).ad.Complex2f
    r = mi.fresnel_conductor(_mf(mi, rows, "cos_i"),
                             complex_t(_mf(mi, rows, "eta"), _mf(mi, rows, "k")))
    return [{"R": x} for x in _np(r, len(rows)).tolist()]


def _conductor_tracer(rows):
    from whitted.tracer import fresnel
    r = fresnel.fresnel_conductor(_jf(rows, "cos_i"), _jf(rows, "eta"), _jf(rows, "k"))
    return [{"R": x} for x in _np(r, len(rows)).tolist()]


def _reflect_cases():
    n = _unit((0.2, 1.0, -0.1))
    out = [("normal incidence", {"d": [-c for c in n], "n": n}),
           ("oblique, 45 degrees", {"d": _unit((1, -1, 0)), "n": [0.0, 1.0, 0.0]}),
           ("oblique, tilted normal", {"d": _unit((0.3, -1.0, 0.5)), "n": n}),
           ("grazing", {"d": _unit((1, -0.01, 0.2)), "n": [0.0, 1.0, 0.0]}),
           ("from the back side (d . n > 0)", {"d": _unit((0.5, 1.0, 0.2)), "n": n}),
           ("parallel to the surface", {"d": [1.0, 0.0, 0.0], "n": [0.0, 0.0, 1.0]})]
    return out


def _reflect_expected(rows):
    mi = _mitsuba()
    d = _mv(mi, mi.Vector3f, rows, "d")
    r = mi.reflect(-d, _mv(mi, mi.Vector3f, rows, "n"))
    return [{"r": list(v)} for v in _npv(r, len(rows)).tolist()]


def _reflect_tracer(rows):
    from whitted.tracer import fresnel
    r = fresnel.reflect(_jv(rows, "d"), _jv(rows, "n"))
    return [{"r": list(v)} for v in _npv(r, len(rows)).tolist()]


def _refract_cases():
    out = []
    n = _unit((0.1, 1.0, 0.2))
    for eta, name in ((1.5, "glass"), (1.33, "water"), (1 / 1.33, "eta < 1"),
                      (1.0, "equal indices")):
        for c in (1.0, 0.8, 0.3, 0.03):
            for side in (1, -1):
                # d at angle acos(c) to the normal on the chosen side, in the plane of n and t
                t = np.cross(n, (0.0, 0.0, 1.0))
                t /= np.linalg.norm(t)
                s = math.sqrt(max(0.0, 1 - c * c))
                d = -side * c * np.asarray(n) + s * t
                label = _cos_label(side * c, eta)
                out.append((f"{name} (eta {eta:.4g}), {label}",
                            {"d": _unit(d), "n": n, "eta": _f32(eta)}))
    return out


def _refract_expected(rows):
    import drjit as dr
    mi = _mitsuba()
    wi = -_mv(mi, mi.Vector3f, rows, "d")
    n = _mv(mi, mi.Vector3f, rows, "n")
    eta = _mf(mi, rows, "eta")
    f, cos_t, _, eta_ti = mi.fresnel(dr.dot(wi, n), eta)
    t = mi.refract(wi, n, cos_t, eta_ti)
    tir = (cos_t == 0) & (eta != 1)
    m = len(rows)
    return [{"tir": bool(b), "t": list(v)}
            for b, v in zip(_npb(tir, m).tolist(), _npv(t, m).tolist(), strict=True)]


def _refract_tracer(rows):
    from whitted.tracer import fresnel
    t, tir = fresnel.refract(_jv(rows, "d"), _jv(rows, "n"), _jf(rows, "eta"))
    m = len(rows)
    return [{"tir": bool(b), "t": list(v)}
            for b, v in zip(_npb(tir, m).tolist(), _npv(t, m).tolist(), strict=True)]


# -------- shading

def _lambert_cases():
    n = _unit((0.0, 1.0, 0.3))
    out = []
    for wi, what in (((0.0, 1.0, 0.3), "normal incidence"), ((1.0, 1.0, 0.0), "oblique"),
                     ((1.0, 0.02, -0.3), "grazing"), ((0.0, -1.0, 0.2), "light behind"),
                     ((1.0, 0.0, 0.0), "light in the tangent plane"),
                     ((0.3, -0.2, -1.0), "light behind, oblique")):
        for albedo in (0.5, 1.0):
            out.append((f"{what}, albedo {albedo}",
                        {"n": n, "wi": _unit(wi), "albedo": _f32(albedo)}))
    return out


def _lambert_reference(rows):
    """albedo / pi * max(n . wi, 0), from the tracer's diffuse BSDF and its cosine."""
    from whitted.tracer import lights
    from whitted.tracer.materials import diffuse

    kd = _jf(rows, "albedo")
    wi, n = _jv(rows, "wi"), _jv(rows, "n")
    value = diffuse.BSDF.eval(None, kd, None, wi) * lights.lambert_cosine(n, wi)
    return [{"value": x} for x in _np(value, len(rows)).tolist()]


def _phong_cases(model):
    n = [0.0, 0.0, 1.0]
    out = []
    wi = _unit((0.4, 0.1, 1.0))
    mirror = _unit((-0.4, -0.1, 1.0))
    for p in (0.0, 1.0, 10.0, 60.0):
        for wo, what in ((mirror, "at the mirror direction"), (_unit((-0.3, 0.0, 1.0)),
                                                                "near the mirror direction"),
                         (_unit((0.5, 0.5, 1.0)), "off the highlight"),
                         (_unit((-1.0, -0.2, 0.03)), "grazing view"),
                         (_unit((0.2, 0.3, -1.0)), "view below the surface"),
                         (n, "view along the normal")):
            out.append((f"exponent {p:g}, {what}",
                        {"n": n, "wi": wi, "wo": wo, "exponent": _f32(p), "kd": 0.25,
                         "ks": 0.5}))
        out.append((f"exponent {p:g}, light below the surface",
                    {"n": n, "wi": _unit((0.2, 0.0, -1.0)), "wo": mirror,
                     "exponent": _f32(p), "kd": 0.25, "ks": 0.5}))
    return out


def _phong_reference(model):
    def evaluate(rows):
        from whitted.tracer import phong

        f = phong.phong_brdf(_jv(rows, "n"), _jv(rows, "wi"), _jv(rows, "wo"), _jf(rows, "kd"),
                             _jf(rows, "ks"), _jf(rows, "exponent"), model)
        return [{"value": x} for x in _np(f, len(rows)).tolist()]
    return evaluate


# -------- intersections

def _sphere_cases():
    c, r = [0.5, -0.25, 2.0], 1.5
    out = []

    def ray(label, o, d, center=c, radius=r):
        out.append((label, {"origin": _vec(o), "direction": _unit(d), "center": _vec(center),
                            "radius": _f32(radius)}))

    ray("hit from outside, head on", (0.5, -0.25, -3.0), (0, 0, 1))
    ray("hit from outside, oblique", (-2.0, 1.0, -1.0), (2.5, -1.0, 3.0))
    ray("grazing hit (0.99 of the radius off the centre)", (0.5 + 0.99 * r, -0.25, -4.0),
        (0, 0, 1))
    ray("miss beside the sphere", (0.5 + 1.2 * r, -0.25, -4.0), (0, 0, 1))
    ray("miss: the sphere behind the ray", (0.5, -0.25, 5.0), (0, 0, 1))
    ray("miss: ray pointing away", (3.0, 3.0, 3.0), (1, 1, 0.5))
    ray("from inside, at the centre", c, (0.3, 0.2, -1.0))
    ray("from inside, off centre", (1.0, 0.0, 2.5), (-1.0, 0.5, 0.2))
    ray("from inside, towards the near side", (1.5, -0.25, 2.0), (1, 0, 0))
    ray("from inside, grazing out", (0.5, -0.25 + 0.99 * r, 2.0), (1, 0.0, 0.1))
    ray("large far sphere", (0.0, 0.0, 0.0), (0.01, 0.0, 1.0), center=(0.0, 0.0, 1000.0),
        radius=100.0)
    ray("small sphere", (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), center=(0.0, 5.0, 0.0), radius=0.01)
    return out


def _sphere_expected(rows):
    mi = _mitsuba()
    out = []
    for row in rows:   # one Mitsuba sphere a row: the shape's own ray_intersect
        s = mi.load_dict({"type": "sphere", "center": row["center"], "radius": row["radius"]})
        ray = mi.Ray3f(mi.Point3f(*row["origin"]), mi.Vector3f(*row["direction"]))
        pi = s.ray_intersect_preliminary(ray)
        hit = bool(_npb(pi.is_valid(), 1)[0])
        out.append({"hit": hit, "t": float(_np(pi.t, 1)[0])})
    return out


def _sphere_tracer(rows):
    import drjit as dr

    from whitted.tracer.shapes import sphere
    t, hit = sphere.intersect(_jv(rows, "origin"), _jv(rows, "direction"), _jv(rows, "center"),
                              _jf(rows, "radius"), dr.inf)
    m = len(rows)
    return [{"hit": bool(h), "t": x}
            for h, x in zip(_npb(hit, m).tolist(), _np(t, m).tolist(), strict=True)]


def _triangle_cases():
    p0, p1, p2 = [0.0, 0.0, 0.0], [2.0, 0.0, 0.5], [0.0, 1.5, 0.0]
    out = []

    def ray(label, o, d, tri=(p0, p1, p2)):
        out.append((label, {"origin": _vec(o), "direction": _unit(d), "p0": _vec(tri[0]),
                            "p1": _vec(tri[1]), "p2": _vec(tri[2])}))

    ray("hit inside", (0.5, 0.5, -3.0), (0, 0, 1))
    ray("hit near p1", (1.9, 0.05, -2.0), (0, 0, 1))
    ray("hit near p2", (0.05, 1.4, 2.0), (0, 0, -1))
    ray("hit near the edge p1-p2 (inside)", (0.99, 0.74, 3.0), (0, -0.01, -1))
    ray("hit from the back side", (0.4, 0.3, 4.0), (0.1, 0.05, -1))
    ray("oblique hit", (-1.0, -1.0, -1.0), (1.5, 1.4, 1.0))
    ray("grazing hit (5 degrees to the plane)", (-3.0, 0.4, -0.2), (1.0, 0.0, 0.1))
    ray("miss beyond the edge p1-p2", (1.2, 0.8, -2.0), (0, 0, 1))
    ray("miss: the triangle behind the ray", (0.5, 0.5, 2.0), (0, 0, 1))
    ray("miss: ray parallel to the plane", (-1.0, 0.5, 0.0), (1.0, 0.0, 0.0),
        tri=(p0, [2.0, 0.0, 0.0], p2))
    ray("degenerate triangle (collinear corners)", (0.5, 0.0, -1.0), (0, 0.01, 1),
        tri=(p0, [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]))
    return out


def _triangle_expected(rows):
    mi = _mitsuba()
    m = len(rows)
    mesh = mi.Mesh("formulas", 3 * m, m)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.array(
        [r[k] for r in rows for k in ("p0", "p1", "p2")], dtype=np.float32).reshape(-1))
    params["faces"] = mi.UInt32(np.arange(3 * m, dtype=np.uint32))
    params.update()
    ray = mi.Ray3f(_mv(mi, mi.Point3f, rows, "origin"), _mv(mi, mi.Vector3f, rows, "direction"))
    pi = mesh.ray_intersect_triangle(mi.UInt32(np.arange(m, dtype=np.uint32)), ray)
    hit, t = _npb(pi.is_valid(), m), _np(pi.t, m)
    u, v = _np(pi.prim_uv.x, m), _np(pi.prim_uv.y, m)
    return [{"hit": bool(h), "t": a, "u": b, "v": c}
            for h, a, b, c in zip(hit.tolist(), t.tolist(), u.tolist(), v.tolist(), strict=True)]


def _triangle_tracer(rows):
    import drjit as dr

    from whitted.tracer.backend import jit
    from whitted.tracer.shapes import triangle
    t, hit, beta, gamma = triangle.intersect(_jv(rows, "origin"), _jv(rows, "direction"),
                                             _jv(rows, "p0"), _jv(rows, "p1"), _jv(rows, "p2"),
                                             dr.inf)
    # The barycentrics as the tracer weighs a vertex attribute with them (the weights of
    # p1 and p2), so that a swap there shows here.
    uv = triangle.interpolate(beta, gamma, jit.Array2f(0, 0), jit.Array2f(1, 0),
                              jit.Array2f(0, 1))
    m = len(rows)
    return [{"hit": bool(h), "t": a, "u": b, "v": c}
            for h, a, b, c in zip(_npb(hit, m).tolist(), _np(t, m).tolist(),
                                  _np(uv.x, m).tolist(), _np(uv.y, m).tolist(), strict=True)]


# -------- the camera

def _camera_cases():
    out = []
    cams = [("perspective 60 degrees, 4:3", {"type": "perspective", "origin": [1.0, 2.0, 5.0],
                                              "target": [0.0, 0.5, 0.0], "up": [0.0, 1.0, 0.0],
                                              "fov": 60.0, "ortho_width": 0.0,
                                              "width": 160, "height": 120}),
            ("perspective 90 degrees, 1:2", {"type": "perspective", "origin": [0.0, 0.0, 0.0],
                                              "target": [0.0, 0.0, -1.0], "up": [0.0, 1.0, 0.0],
                                              "fov": 90.0, "ortho_width": 0.0,
                                              "width": 50, "height": 100}),
            ("perspective 20 degrees, tilted up vector",
             {"type": "perspective", "origin": [-3.0, 1.0, 2.0], "target": [1.0, 0.0, 0.0],
              "up": [0.3, 1.0, 0.0], "fov": 20.0, "ortho_width": 0.0, "width": 64,
              "height": 48}),
            ("orthographic, 4 wide, 2:1", {"type": "orthographic", "origin": [0.0, 3.0, 3.0],
                                            "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                                            "fov": 0.0, "ortho_width": 4.0,
                                            "width": 200, "height": 100})]
    for label, cam in cams:
        w, h = cam["width"], cam["height"]
        for (x, y), where in (((w / 2, h / 2), "image centre"), ((0, 0), "top-left corner"),
                              ((w, h), "bottom-right corner"), ((w, 0), "top-right corner"),
                              ((10.5, 3.5), "a pixel centre near the top left")):
            out.append((f"{label}, {where}", {**cam, "x": _f32(x), "y": _f32(y)}))
    return out


def _camera_tracer(rows):
    from whitted.tracer import camera as cam_mod
    from whitted.tracer.backend import jit
    from whitted.tracer.scene import Camera

    out = []
    for r in rows:   # one camera a row
        cam = Camera(type=r["type"], origin=tuple(r["origin"]), target=tuple(r["target"]),
                     up=tuple(r["up"]), fov=r["fov"] or 45.0, width=r["ortho_width"] or 2.0,
                     near_clip=0.0)
        o, d, _ = cam_mod.generate_rays(cam, int(r["width"]), int(r["height"]),
                                        jit.Float(r["x"]), jit.Float(r["y"]))
        out.append({"origin": _npv(o, 1)[0].tolist(), "direction": _npv(d, 1)[0].tolist()})
    return out


# -------- lights

def _point_cases():
    out = []
    for p, pos, i, what in (((0, 0, 0), (0, 1, 0), 10.0, "1 away, straight above"),
                            ((1, 0, 2), (3, 4, -1), 50.0, "oblique, r about 5.4"),
                            ((0, 0, 0), (0.3, 0.4, 0.0), 2.0, "close, r = 0.5"),
                            ((5, 5, 5), (5, 5, 105), 1000.0, "far, r = 100"),
                            ((0, 1, 0), (0, -1, 0), 4.0, "below the point")):
        out.append((what, {"p": _vec(p), "position": _vec(pos), "intensity": _f32(i)}))
    return out


def _point_tracer(rows):
    from whitted.tracer import lights
    wi, dist, e = lights.point(_jv(rows, "p"), _jv(rows, "position"), _jf(rows, "intensity"))
    m = len(rows)
    return [{"direction": list(a), "distance": b, "irradiance": c}
            for a, b, c in zip(_npv(wi, m).tolist(), _np(dist, m).tolist(),
                               _np(e, m).tolist(), strict=True)]


def _spot_cases():
    out = []
    for cutoff, beam in ((30.0, 20.0), (45.0, 10.0), (20.0, 20.0)):
        for theta, what in ((0.0, "on the axis"), (5.0, "inside the beam"),
                            ((cutoff + beam) / 2 + 0.37, "in the ramp"),
                            (cutoff - 1.0, "just inside the cutoff"),
                            (cutoff + 2.0, "just outside the cutoff"), (100.0, "behind the spot")):
            out.append((f"cutoff {cutoff:g}, beam {beam:g}: {what}",
                        {"cos_theta": _f32(math.cos(math.radians(theta))),
                         "cutoff_angle": cutoff, "beam_width": beam}))
    return out


def _spot_tracer(rows):
    from whitted.tracer import lights
    from whitted.tracer.backend import jit

    out = []
    for r in rows:   # the angles are Python floats in the tracer's function
        f = lights.spot_falloff(jit.Float([r["cos_theta"]]), r["cutoff_angle"], r["beam_width"])
        out.append({"falloff": float(_np(f, 1)[0])})
    return out


# -------- transforms

def _instance_cases():
    from whitted.tracer import transform as tf

    out = []
    mats = (("identity", np.eye(4)),
            ("rotation", tf.rotate((1, 2, 3), 40)),
            ("uniform scale and translation", tf.translate((1, -2, 3)) @ tf.scale(2.5)),
            ("non-uniform scale", tf.scale((3.0, 1.0, 0.5))),
            ("rotation after non-uniform scale",
             tf.rotate((0, 1, 0), 30) @ tf.scale((1.0, 4.0, 1.0))),
            ("shear", np.array([[1, 0.8, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])),
            ("mirror (negative determinant)", tf.scale((-1.0, 2.0, 1.0))))
    for label, m in mats:
        for n in ((0.0, 1.0, 0.0), (1.0, 1.0, 1.0)):
            out.append((f"{label}, n = {n}",
                        {"matrix": [[_f32(x) for x in row] for row in m], "n": _unit(n)}))
    return out


def _instance_tracer(rows):
    from whitted.tracer.geometry import instance_normal_matrix

    out = []
    for r in rows:
        a = instance_normal_matrix(np.array(r["matrix"], dtype=np.float64))
        n = a @ np.array(r["n"], dtype=np.float64)
        out.append({"n": (n / np.linalg.norm(n)).tolist()})
    return out


V3, NUM, BOOL = "vec3", "number", "bool"

FORMULAS: tuple[Formula, ...] = (
    Formula("sphere_intersect",
            "ray-sphere intersection: the nearest root t > 0 of |o + t d - c|^2 = r^2",
            {"origin": V3, "direction": V3 + " (unit)", "center": V3, "radius": NUM},
            {"hit": BOOL, "t": NUM}, {"t": ("hit", True)},
            "Mitsuba: the sphere shape's ray_intersect_preliminary", 1024,
            "t from a quadratic: a few roundings, divided by sqrt(disc) / r (at least 0.14 "
            "for the grazing case)",
            _sphere_cases, _sphere_expected, _sphere_tracer),
    Formula("triangle_intersect",
            "ray-triangle intersection: t > 0 and the barycentrics u, v of p1 and p2 "
            "(p = (1 - u - v) p0 + u p1 + v p2), hit from either side",
            {"origin": V3, "direction": V3 + " (unit)", "p0": V3, "p1": V3, "p2": V3},
            {"hit": BOOL, "t": NUM, "u": NUM, "v": NUM},
            {"t": ("hit", True), "u": ("hit", True), "v": ("hit", True)},
            "Mitsuba: a triangle mesh's ray_intersect_triangle (its prim_uv)", 1024,
            "cross products and a division; the grazing case divides by sin(5 degrees)",
            _triangle_cases, _triangle_expected, _triangle_tracer),
    Formula("reflect", "mirror direction r = d - 2 (d . n) n of d (towards the surface)",
            {"d": V3 + " (unit)", "n": V3 + " (unit)"}, {"r": V3}, {},
            "Mitsuba: mi.reflect(-d, n)", 32, "a dot product and a multiply-add",
            _reflect_cases, _reflect_expected, _reflect_tracer),
    Formula("refract",
            "refracted direction by Snell's law, n outward, eta = n_inside / n_outside; "
            "tir true (and t not compared) beyond the critical angle",
            {"d": V3 + " (unit, towards the surface)", "n": V3 + " (unit, outward)",
             "eta": NUM},
            {"tir": BOOL, "t": V3}, {"t": ("tir", False)},
            "Mitsuba: mi.fresnel's cos_theta_t and eta_ti, then mi.refract(-d, n, ...)", 256,
            "a square root of 1 - sin^2 and a few products",
            _refract_cases, _refract_expected, _refract_tracer),
    Formula("fresnel_exact",
            "unpolarised Fresnel reflectance R = (r_s^2 + r_p^2) / 2 of a dielectric, R = 1 "
            "under total internal reflection; cos_i > 0 from outside, < 0 from inside",
            {"cos_i": NUM, "eta": NUM}, {"R": NUM}, {},
            "Mitsuba: mi.fresnel", 256, "Snell's cosine and two quotients",
            _fresnel_cases, _fresnel_exact_expected, _fresnel_exact_tracer),
    Formula("fresnel_schlick",
            "Schlick's R0 + (1 - R0)(1 - cos)^5 with cos on the less dense side, R = 1 under "
            "total internal reflection",
            {"cos_i": NUM, "eta": NUM}, {"R": NUM}, {},
            "the tracer: tracer/fresnel.py fresnel_schlick (Mitsuba has no Schlick)", 256,
            "a fifth power of a number in [0, 1]: 5 times its rounding",
            _fresnel_cases, _fresnel_schlick_tracer, _fresnel_schlick_tracer),
    Formula("fresnel_conductor",
            "Fresnel reflectance of a conductor with complex index eta + i k (|cos_i| used)",
            {"cos_i": NUM, "eta": NUM, "k": NUM}, {"R": NUM}, {},
            "Mitsuba: mi.fresnel_conductor", 256, "square roots of sums of squares",
            _conductor_cases, _conductor_expected, _conductor_tracer),
    Formula("lambert",
            "Lambert's reflected light per unit irradiance: albedo / pi * max(n . wi, 0)",
            {"n": V3 + " (unit)", "wi": V3 + " (unit, towards the light)", "albedo": NUM},
            {"value": NUM}, {},
            "the tracer: tracer/materials/diffuse.py BSDF.eval times tracer/lights.py "
            "lambert_cosine", 32, "a dot product and a product",
            _lambert_cases, _lambert_reference, _lambert_reference),
    Formula("phong",
            "modified Phong BRDF kd / pi + ks (p + 2) / (2 pi) max(r . wo, 0)^p, r the mirror "
            "of wi; 0 when wi or wo is below the surface",
            {"n": V3 + " (unit)", "wi": V3 + " (unit)", "wo": V3 + " (unit)", "exponent": NUM,
             "kd": NUM, "ks": NUM}, {"value": NUM}, {},
            "the tracer: tracer/phong.py phong_brdf", 4096,
            "cos^p multiplies the cosine's relative error by p (up to 60)",
            lambda: _phong_cases("phong"), _phong_reference("phong"), _phong_reference("phong")),
    Formula("blinn_phong",
            "Blinn-Phong BRDF kd / pi + ks (p + 2)(p + 4) / (8 pi (2^(-p/2) + p)) "
            "max(n . h, 0)^p, h = normalize(wi + wo); 0 below the surface",
            {"n": V3 + " (unit)", "wi": V3 + " (unit)", "wo": V3 + " (unit)", "exponent": NUM,
             "kd": NUM, "ks": NUM}, {"value": NUM}, {},
            "the tracer: tracer/phong.py phong_brdf (model blinn-phong)", 4096,
            "cos^p multiplies the cosine's relative error by p (up to 60)",
            lambda: _phong_cases("blinn-phong"), _phong_reference("blinn-phong"),
            _phong_reference("blinn-phong")),
    Formula("camera_ray",
            "the primary ray through film position (x, y) in pixels, (0, 0) the top-left "
            "corner; perspective: horizontal field of view fov (degrees), origin the eye; "
            "orthographic: ortho_width wide",
            {"type": '"perspective" or "orthographic"', "origin": V3, "target": V3, "up": V3,
             "fov": NUM, "ortho_width": NUM, "width": NUM, "height": NUM, "x": NUM, "y": NUM},
            {"origin": V3, "direction": V3 + " (unit)"}, {},
            "the tracer: tracer/camera.py generate_rays (near_clip 0)", 64,
            "a frame of cross products and a tangent",
            _camera_cases, _camera_tracer, _camera_tracer),
    Formula("point_light",
            "a point light seen from p: the unit direction to it, its distance, and the "
            "irradiance I / r^2 normal to that direction",
            {"p": V3, "position": V3, "intensity": NUM},
            {"direction": V3, "distance": NUM, "irradiance": NUM}, {},
            "the tracer: tracer/lights.py point", 64, "a norm and a quotient",
            _point_cases, _point_tracer, _point_tracer),
    Formula("spot_falloff",
            "Mitsuba's spot profile: 1 within beam_width, linear in the angle down to 0 at "
            "cutoff_angle (degrees), 0 beyond",
            {"cos_theta": NUM, "cutoff_angle": NUM, "beam_width": NUM}, {"falloff": NUM}, {},
            "the tracer: tracer/lights.py spot_falloff", 256,
            "acos, whose error grows as 1 / sin(theta) (theta >= 5 degrees in the ramp)",
            _spot_cases, _spot_tracer, _spot_tracer),
    Formula("instance_normal",
            "an instance's normal in world space: normalize((M^-1)^T n), M the 4x4 to_world "
            "matrix (rows)",
            {"matrix": "4 rows of 4 numbers", "n": V3 + " (unit)"}, {"n": V3 + " (unit)"}, {},
            "the tracer: tracer/geometry.py instance_normal_matrix", 256,
            "a 3x3 inverse of matrices of condition number at most 8",
            _instance_cases, _instance_tracer, _instance_tracer),
)

BY_NAME: dict[str, Formula] = {f.name: f for f in FORMULAS}


def select_formulas(names: list[str] | None) -> list[Formula]:
    """The formulas named (comma lists and globs allowed), in catalog order; all if None."""
    import fnmatch

    if not names:
        return list(FORMULAS)
    wanted = [p.strip() for n in names for p in n.split(",") if p.strip()]
    chosen = set()
    for w in wanted:
        hit = [f.name for f in FORMULAS if fnmatch.fnmatchcase(f.name, w)]
        if not hit:
            raise UserError(f"--formulas: no formula matches {w!r} (known: "
                            f"{', '.join(BY_NAME)})")
        chosen.update(hit)
    return [f for f in FORMULAS if f.name in chosen]


# ---------------------------------------------------------------------------- comparing

def _kind(spec: str) -> str:
    return spec.split(" ")[0]


def compare(formula: Formula, given: dict, expected: dict) -> str | None:
    """None when ``given`` matches ``expected`` within the tolerance, else why not."""
    tol = formula.tolerance
    for key, spec in formula.outputs.items():
        cond = formula.when.get(key)
        if cond is not None and expected.get(cond[0]) != cond[1]:
            continue
        e, g = expected[key], given.get(key)
        kind = _kind(spec)
        if kind == "bool":
            if g is not e:
                return f"{key}: {g} instead of {e}"
            continue
        ev = np.atleast_1d(np.asarray(e, dtype=np.float64))
        gv = np.atleast_1d(np.asarray(g if g is not None else math.nan, dtype=np.float64))
        err = np.abs(gv - ev)
        if not np.all(err <= tol * (1 + np.abs(ev))):   # NaN fails
            return f"{key} differs by {np.nanmax(err) if np.any(np.isfinite(err)) else 'NaN'}"
    return None


# ---------------------------------------------------------------------------- adapters

def _check_outputs(formula: Formula, out, rid: int) -> dict:
    """The outputs of an answer, their shapes checked (AdapterError: garbage)."""
    def bad(why):
        raise AdapterError(f"the adapter answered garbage to request {rid} ({formula.name}): "
                           f"{why}")

    if not isinstance(out, dict):
        bad(f"outputs is not an object: {json.dumps(out)[:80]}")
    checked = {}
    for key, spec in formula.outputs.items():
        v = out.get(key)
        cond = formula.when.get(key)
        optional = cond is not None and out.get(cond[0]) is not cond[1]
        if v is None:
            if optional:
                continue
            bad(f"no output {key!r} ({spec})")
        kind = _kind(spec)
        if kind == "bool":
            if not isinstance(v, bool):
                bad(f"{key} should be true or false, got {json.dumps(v)[:60]}")
        elif kind == "number":
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                bad(f"{key} should be a number, got {json.dumps(v)[:60]}")
            v = float(v)
        else:
            if (not isinstance(v, list) or len(v) != 3 or
                    any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
                bad(f"{key} should be a list of 3 numbers, got {json.dumps(v)[:60]}")
            v = [float(x) for x in v]
        checked[key] = v
    return checked


class NotImplementedByAdapter(Exception):
    """The adapter declined a formula (``{"error": ...}``, or NotImplementedError)."""


class ProgramAdapter:
    """A program answering JSON lines on stdin and stdout, one request at a time."""

    def __init__(self, command: str, timeout: float):
        argv = shlex.split(command)
        if not argv:
            raise UserError("--program: empty command")
        self.timeout = timeout
        self.what = argv[0]
        try:
            self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                         stderr=subprocess.PIPE, bufsize=0)
        except OSError as e:
            raise UserError(f"--program: cannot start {argv[0]}: {e.strerror or e}") from None
        self.buffer = b""
        self.err = b""
        self.next_id = 0

    def _stderr_tail(self) -> str:
        try:
            while select.select([self.proc.stderr], [], [], 0)[0]:
                chunk = os.read(self.proc.stderr.fileno(), 65536)
                if not chunk:
                    break
                self.err = (self.err + chunk)[-4000:]
        except (OSError, ValueError):
            pass
        lines = [ln for ln in self.err.decode("utf-8", "replace").splitlines() if ln.strip()]
        return f"; its stderr: {lines[-1].strip()[:200]}" if lines else ""

    def _read_line(self, rid: int, name: str) -> bytes:
        deadline = time.monotonic() + self.timeout
        fd = self.proc.stdout.fileno()
        while b"\n" not in self.buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AdapterError(f"the adapter timed out: no answer to request {rid} ({name}) "
                                   f"in {self.timeout:g} s")
            ready = select.select([fd, self.proc.stderr.fileno()], [], [], left)[0]
            if self.proc.stderr.fileno() in ready:
                chunk = os.read(self.proc.stderr.fileno(), 65536)
                self.err = (self.err + chunk)[-4000:]
            if fd in ready:
                chunk = os.read(fd, 65536)
                if not chunk:
                    try:
                        rc = self.proc.wait(timeout=1)
                    except subprocess.TimeoutExpired:
                        rc = None
                    raise AdapterError(
                        f"the adapter crashed: it closed its output"
                        f"{'' if rc is None else f' and exited with status {rc}'} before "
                        f"answering request {rid} ({name}){self._stderr_tail()}")
                self.buffer += chunk
                if len(self.buffer) > 1 << 20:
                    raise AdapterError(f"the adapter answered garbage to request {rid} ({name}): "
                                       "a line of over 1 MiB")
        line, self.buffer = self.buffer.split(b"\n", 1)
        return line

    def __call__(self, formula: Formula, inputs: dict) -> dict:
        self.next_id += 1
        rid = self.next_id
        request = json.dumps({"id": rid, "formula": formula.name, "inputs": inputs})
        try:
            self.proc.stdin.write(request.encode() + b"\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError):
            try:
                rc = self.proc.wait(timeout=1)
            except subprocess.TimeoutExpired:
                rc = None
            raise AdapterError(f"the adapter crashed: it "
                               f"{'closed its input' if rc is None else f'exited with status {rc}'}"
                               f" before reading request {rid} ({formula.name})"
                               f"{self._stderr_tail()}") from None
        line = self._read_line(rid, formula.name)
        try:
            answer = json.loads(line)
        except (ValueError, RecursionError):
            text = line.decode("utf-8", "replace").strip()
            raise AdapterError(f"the adapter answered garbage to request {rid} ({formula.name}): "
                               f"not JSON: {text[:80]!r}") from None
        if not isinstance(answer, dict) or answer.get("id") != rid:
            raise AdapterError(f"the adapter answered garbage to request {rid} ({formula.name}): "
                               f"expected an object with \"id\": {rid}, got "
                               f"{json.dumps(answer)[:80]}")
        if "error" in answer:
            raise NotImplementedByAdapter(str(answer["error"])[:200])
        return _check_outputs(formula, answer.get("outputs"), rid)

    def close(self) -> None:
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout=self.timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for s in (self.proc.stdout, self.proc.stderr):
            s.close()


class PythonAdapter:
    """A Python callable ``module:function`` (or ``path/to/file.py:function``) called with
    the formula's name and its inputs, returning the outputs as a dict."""

    def __init__(self, spec: str, timeout: float):
        import importlib
        import importlib.util

        mod_name, sep, func = spec.rpartition(":")
        if not sep or not mod_name or not func:
            raise UserError(f"--python: expected MODULE:FUNCTION or FILE.py:FUNCTION, got "
                            f"{spec!r}")
        try:
            if mod_name.endswith(".py"):
                if not os.path.isfile(mod_name):
                    raise UserError(f"--python: {mod_name}: no such file")
                s = importlib.util.spec_from_file_location("whitted_formulas_adapter", mod_name)
                module = importlib.util.module_from_spec(s)
                s.loader.exec_module(module)
            else:
                module = importlib.import_module(mod_name)
        except UserError:
            raise
        except Exception as e:   # the adapter's own import failed: a bad adapter
            raise AdapterError(f"the adapter crashed while imported: {type(e).__name__}: "
                               f"{e}") from None
        self.func = getattr(module, func, None)
        if not callable(self.func):
            raise UserError(f"--python: {mod_name} has no function {func!r}")
        self.timeout = timeout
        self.next_id = 0

    def __call__(self, formula: Formula, inputs: dict) -> dict:
        self.next_id += 1
        rid = self.next_id
        box: dict = {}

        def call():
            try:
                box["out"] = self.func(formula.name, json.loads(json.dumps(inputs)))
            except BaseException as e:   # reported below, in the caller's thread
                box["exc"] = e

        worker = threading.Thread(target=call, daemon=True)
        worker.start()
        worker.join(self.timeout)
        if worker.is_alive():
            raise AdapterError(f"the adapter timed out: no answer to request {rid} "
                               f"({formula.name}) in {self.timeout:g} s")
        exc = box.get("exc")
        if isinstance(exc, NotImplementedError):
            raise NotImplementedByAdapter(str(exc)[:200] or "not implemented")
        if exc is not None:
            raise AdapterError(f"the adapter crashed on request {rid} ({formula.name}): "
                               f"{type(exc).__name__}: {exc}")
        out = box.get("out")
        try:   # what JSON would carry: numpy numbers and tuples become plain values
            out = json.loads(json.dumps(out, default=lambda o: o.tolist()
                                        if hasattr(o, "tolist") else str(o)))
        except (TypeError, ValueError):
            pass
        return _check_outputs(formula, out, rid)

    def close(self) -> None:
        pass


# ---------------------------------------------------------------------------- the run

@dataclass
class FormulaResult:
    formula: Formula
    status: str                      # "pass", "FAIL", "not implemented"
    cases: int = 0
    failed: int = 0
    first: dict | None = None        # label, inputs, expected, given, why
    bugs: list = field(default_factory=list)   # catalog ids that explain the answers
    reached: list = field(default_factory=list)
    message: str = ""

    def to_json(self) -> dict:
        return {"formula": self.formula.name, "status": self.status, "cases": self.cases,
                "failed": self.failed, "first_failure": self.first, "bugs": self.bugs,
                "catalog_bugs_reached": self.reached, "message": self.message,
                "reference": self.formula.reference,
                "tolerance": {"ulps": self.formula.ulps, "value": self.formula.tolerance}}


def _faulted(formula: Formula, rows: list[dict], ids: tuple[str, ...]) -> list[dict]:
    from whitted.tracer import faults
    with faults.active(*ids):
        return formula.tracer(rows)


def name_bugs(formula: Formula, rows: list[dict], given: list[dict],
              reached: list[str]) -> list[str]:
    """The catalog bugs (one, or two together) whose switched tracer formula gives
    ``given`` on every input; the first combination that does, in catalog order."""
    combos = [(i,) for i in reached] + list(itertools.combinations(reached, 2))
    for ids in combos:
        try:
            outs = _faulted(formula, rows, ids)
        except Exception:   # a switched formula that cannot run on these inputs
            continue
        if all(compare(formula, g, o) is None for g, o in zip(given, outs, strict=True)):
            return list(ids)
    return []


def run_formula(formula: Formula, adapter) -> FormulaResult:
    """Ask the adapter every case of ``formula`` and judge its answers."""
    from whitted.reference import mutants  # noqa: F401  (declares the catalog's switches)
    from whitted.tracer import faults

    cases = formula.cases()
    rows = [inputs for _, inputs in cases]
    expected = formula.expected(rows)
    given = []
    for _, inputs in cases:
        try:
            given.append(adapter(formula, inputs))
        except NotImplementedByAdapter as e:
            return FormulaResult(formula, "not implemented", len(cases), message=str(e))
    res = FormulaResult(formula, "pass", len(cases))
    for (label, inputs), e, g in zip(cases, expected, given, strict=True):
        why = compare(formula, g, e)
        if why is not None:
            res.failed += 1
            if res.first is None:
                res.first = {"case": label, "inputs": inputs,
                             "expected": _counted(formula, e),
                             "given": _counted(formula, g), "why": why}
    if res.failed:
        res.status = "FAIL"
        with faults.recording() as asked:
            formula.tracer(rows)
        from whitted.reference.mutants import CATALOG
        res.reached = [m.id for m in CATALOG if m.id in asked]
        res.bugs = name_bugs(formula, rows, given, res.reached)
    return res


@dataclass
class FormulasRun:
    results: list
    adapter: str

    @property
    def passed(self) -> bool:
        return all(r.status == "pass" for r in self.results)

    def to_json(self) -> dict:
        return {"pass": self.passed, "adapter": self.adapter,
                "formulas": [r.to_json() for r in self.results]}


def run(formulas: list[Formula], adapter, label: str = "", log=None) -> FormulasRun:
    """Judge every formula; the adapter is closed at the end (or on an error)."""
    results = []
    try:
        for f in formulas:
            r = run_formula(f, adapter)
            results.append(r)
            if log is not None:
                log(r)
    finally:
        adapter.close()
    return FormulasRun(results, label)


def _counted(formula: Formula, outputs: dict) -> dict:
    """The outputs that count (those whose condition, e.g. hit or tir, holds)."""
    return {k: v for k, v in outputs.items()
            if k not in formula.when or outputs.get(formula.when[k][0]) is formula.when[k][1]}


def _short(v) -> str:
    def fmt(x):
        if isinstance(x, float):
            return f"{x:.9g}"
        if isinstance(x, list):
            return "[" + ", ".join(fmt(y) for y in x) + "]"
        if isinstance(x, dict):
            return "{" + ", ".join(f"{k}: {fmt(y)}" for k, y in x.items()) + "}"
        return json.dumps(x)
    return fmt(v)


def format_result(r: FormulaResult) -> str:
    f = r.formula
    head = f"{f.name:<20} {r.cases:>5}  "
    if r.status == "pass":
        return head + "pass"
    if r.status == "not implemented":
        return head + f"FAIL: not implemented by the adapter ({r.message})"
    from whitted.reference.mutants import BY_ID

    lines = [head + f"FAIL ({r.failed} of {r.cases} inputs)",
             f"  first failing input ({r.first['case']}): {_short(r.first['inputs'])}",
             f"  expected: {_short(r.first['expected'])}   ({f.reference})",
             f"  given:    {_short(r.first['given'])}   ({r.first['why']}; tolerance "
             f"{f.ulps} u = {f.tolerance:.2g} (1 + |expected|))"]
    if r.bugs:
        for i in r.bugs:
            m = BY_ID[i]
            lines.append(f"  catalog bug: {i} ({m.topic}): {m.summary}")
            lines.append(f"       formula: {m.wrong}")
            lines.append(f"       right:   {m.correct}")
        if len(r.bugs) > 1:
            lines.append("  (the answers equal the tracer's with these bugs together)")
    else:
        lines.append("  catalog bug: none matches (tried "
                     + (", ".join(r.reached) if r.reached else "no bug of the catalog reaches "
                        "this formula") + ")")
    return "\n".join(lines)


def format_summary(run_: FormulasRun) -> str:
    bad = [r for r in run_.results if r.status != "pass"]
    n = len(run_.results)
    if not bad:
        return f"PASS: all {n} formulas within their tolerances"
    return f"FAIL: {len(bad)} of {n} formulas fail: {', '.join(r.formula.name for r in bad)}"


def describe() -> str:
    """The formulas as ``whitted formulas --list`` prints them."""
    lines = []
    for f in FORMULAS:
        lines.append(f"{f.name}: {f.summary}")
        lines.append("  inputs:  " + ", ".join(f"{k} ({v})" for k, v in f.inputs.items()))
        outs = []
        for k, v in f.outputs.items():
            c = f.when.get(k)
            outs.append(f"{k} ({v}" + (f", when {c[0]} is {str(c[1]).lower()}" if c else "")
                        + ")")
        lines.append("  outputs: " + ", ".join(outs))
        lines.append(f"  against: {f.reference}; tolerance {f.ulps} u = {f.tolerance:.2g} "
                     f"(1 + |expected|): {f.why}")
        lines.append(f"  cases:   {len(f.cases())}")
    return "\n".join(lines)
