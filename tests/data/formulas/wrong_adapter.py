"""docs/formulas/adapter.py with bugs put in: `python wrong_adapter.py BUG,BUG,...`.

Each bug is the catalog's (reference/mutants.py) as a student would write it, except
``schlick-exponent-4``, which the catalog does not have.
"""

import importlib.util
import math
import os
import sys

_spec = importlib.util.spec_from_file_location(
    "adapter", os.path.join(os.path.dirname(__file__), "..", "..", "..", "docs", "formulas",
                            "adapter.py"))
a = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(a)


def schlick(cos_i, eta, exponent=5, dense_side=False):
    c, rel, cos_t = a.snell(cos_i, eta)
    if cos_t is None:
        return {"R": 1.0}
    r0 = ((eta - 1) / (eta + 1)) ** 2
    cos = c if rel >= 1 or dense_side else cos_t
    return {"R": r0 + (1 - r0) * (1 - cos) ** exponent}


def refract_no_tir(d, n, eta):
    cos_i = -a.dot(d, n)
    rel = eta if cos_i >= 0 else 1 / eta
    c = abs(cos_i)
    cos_t = math.sqrt(abs(1 - (1 - c * c) / (rel * rel)))   # the "fix": no TIR
    nf = n if cos_i >= 0 else a.mul(n, -1)
    return {"tir": False, "t": a.add(a.mul(d, 1 / rel), a.mul(nf, c / rel - cos_t))}


def refract_eta_inverted(d, n, eta):
    return a.refract(d, n, 1 / eta)


def sphere_near_root(origin, direction, center, radius):
    f = a.sub(origin, center)
    b = a.dot(f, direction)
    disc = b * b - (a.dot(f, f) - radius * radius)
    if disc < 0:
        return {"hit": False}
    t0 = -b - math.sqrt(disc)                 # always the near root
    return {"hit": True, "t": t0} if t0 > 0 else {"hit": False}


def reflect_sign(d, n):
    return {"r": a.add(d, a.mul(n, 2 * a.dot(d, n)))}


def fresnel_average_amplitudes(cos_i, eta):
    c, rel, cos_t = a.snell(cos_i, eta)
    if rel == 1:
        return {"R": 0.0}
    if cos_t is None:
        return {"R": 1.0}
    rs = (c - rel * cos_t) / (c + rel * cos_t)
    rp = (rel * c - cos_t) / (rel * c + cos_t)
    return {"R": ((rs + rp) / 2) ** 2}


def lambert_abs(n, wi, albedo):
    return {"value": albedo / math.pi * abs(a.dot(n, wi))}


def blinn_unnormalized_half(n, wi, wo, exponent, kd, ks):
    p = exponent
    cos_h = max(a.dot(n, a.add(wi, wo)), 0.0)
    norm = (p + 2) * (p + 4) / (8 * math.pi * (2 ** (-p / 2) + p))
    return a._lobe(n, wi, wo, kd, ks, norm * cos_h ** p)


def phong_unnormalized(n, wi, wo, exponent, kd, ks):
    cos_a = max(a.dot(a.sub(a.mul(n, 2 * a.dot(n, wi)), wi), wo), 0.0)
    return a._lobe(n, wi, wo, kd, ks, cos_a ** exponent)


def triangle_swapped(**kw):
    out = a.triangle_intersect(**kw)
    if out["hit"]:
        out["u"], out["v"] = out["v"], out["u"]
    return out


def camera_y_up(**kw):
    kw["y"] = kw["height"] - kw["y"]
    return a.camera_ray(**kw)


def point_linear(p, position, intensity):
    out = a.point_light(p, position, intensity)
    out["irradiance"] = intensity / out["distance"]
    return out


def spot_linear_in_cos(cos_theta, cutoff_angle, beam_width):
    cc, cb = math.cos(math.radians(cutoff_angle)), math.cos(math.radians(beam_width))
    if cos_theta <= cc:
        return {"falloff": 0.0}
    if cos_theta >= cb:
        return {"falloff": 1.0}
    return {"falloff": (cos_theta - cc) / (cb - cc)}


def normal_by_matrix(matrix, n):
    return {"n": a.normalize([a.dot(row[:3], n) for row in matrix[:3]])}


BUGS = {
    "schlick-exponent-4": ("fresnel_schlick", lambda **k: schlick(**k, exponent=4)),
    "schlick-dense-side-cosine": ("fresnel_schlick", lambda **k: schlick(**k, dense_side=True)),
    "tir-ignored": ("refract", refract_no_tir),
    "snell-eta-inverted": ("refract", refract_eta_inverted),
    "sphere-near-root-from-inside": ("sphere_intersect", sphere_near_root),
    "reflect-sign": ("reflect", reflect_sign),
    "fresnel-average-amplitudes": ("fresnel_exact", fresnel_average_amplitudes),
    "lambert-abs-cosine": ("lambert", lambert_abs),
    "half-vector-unnormalized": ("blinn_phong", blinn_unnormalized_half),
    "phong-no-normalization": ("phong", phong_unnormalized),
    "barycentrics-swapped": ("triangle_intersect", triangle_swapped),
    "camera-y-not-flipped": ("camera_ray", camera_y_up),
    "point-light-linear-falloff": ("point_light", point_linear),
    "spot-linear-falloff": ("spot_falloff", spot_linear_in_cos),
    "instance-normal-by-matrix": ("instance_normal", normal_by_matrix),
}

if __name__ == "__main__":
    for bug in filter(None, (sys.argv[1] if len(sys.argv) > 1 else "").split(",")):
        name, func = BUGS[bug]
        a.FORMULAS[name] = func
    a.main()
