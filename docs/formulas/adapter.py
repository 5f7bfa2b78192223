"""An example adapter for `whitted formulas`, in plain Python (no dependencies).

Two ways to use it (docs/formulas.md):

    whitted formulas --program "python3 docs/formulas/adapter.py"   # JSON lines
    whitted formulas --python docs/formulas/adapter.py:formula      # a callable

Replace a function's body by a call into your own renderer to test its formula.
"""

import json
import math
import sys


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def add(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def mul(a, s):
    return [a[0] * s, a[1] * s, a[2] * s]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def normalize(a):
    return mul(a, 1 / math.sqrt(dot(a, a)))


def sphere_intersect(origin, direction, center, radius):
    f = sub(origin, center)
    b = dot(f, direction)                      # half b, |direction| = 1
    c = dot(f, f) - radius * radius
    disc = b * b - c
    if disc < 0:
        return {"hit": False}
    t0, t1 = -b - math.sqrt(disc), -b + math.sqrt(disc)
    t = t0 if t0 > 0 else t1                   # the far root from inside
    return {"hit": True, "t": t} if t > 0 else {"hit": False}


def triangle_intersect(origin, direction, p0, p1, p2):
    e1, e2 = sub(p1, p0), sub(p2, p0)          # Moeller-Trumbore
    pv = cross(direction, e2)
    det = dot(e1, pv)
    if abs(det) < 1e-12:
        return {"hit": False}
    tv = sub(origin, p0)
    u = dot(tv, pv) / det
    qv = cross(tv, e1)
    v = dot(direction, qv) / det
    t = dot(e2, qv) / det
    if u < 0 or v < 0 or u + v > 1 or t <= 0:
        return {"hit": False}
    return {"hit": True, "t": t, "u": u, "v": v}


def reflect(d, n):
    return {"r": sub(d, mul(n, 2 * dot(d, n)))}


def snell(cos_i, eta):
    """(|cos_i|, n_t / n_i, cos_t or None under total internal reflection)."""
    rel = eta if cos_i >= 0 else 1 / eta
    c = abs(cos_i)
    sin2_t = (1 - c * c) / (rel * rel)
    return c, rel, (None if sin2_t > 1 else math.sqrt(1 - sin2_t))


def refract(d, n, eta):
    c, rel, cos_t = snell(-dot(d, n), eta)
    if cos_t is None:
        return {"tir": True}
    nf = n if -dot(d, n) >= 0 else mul(n, -1)  # the normal on the side the ray comes from
    return {"tir": False, "t": add(mul(d, 1 / rel), mul(nf, c / rel - cos_t))}


def fresnel_exact(cos_i, eta):
    c, rel, cos_t = snell(cos_i, eta)
    if rel == 1:
        return {"R": 0.0}
    if cos_t is None:
        return {"R": 1.0}
    rs = (c - rel * cos_t) / (c + rel * cos_t)
    rp = (rel * c - cos_t) / (rel * c + cos_t)
    return {"R": (rs * rs + rp * rp) / 2}


def fresnel_schlick(cos_i, eta):
    c, rel, cos_t = snell(cos_i, eta)
    if cos_t is None:
        return {"R": 1.0}
    r0 = ((eta - 1) / (eta + 1)) ** 2
    cos = c if rel >= 1 else cos_t             # the angle on the less dense side
    return {"R": r0 + (1 - r0) * (1 - cos) ** 5}


def fresnel_conductor(cos_i, eta, k):
    c = min(abs(cos_i), 1.0)
    n = complex(eta, k)
    cos_t = (1 - (1 - c * c) / (n * n)) ** 0.5
    rs = (c - n * cos_t) / (c + n * cos_t)
    rp = (n * c - cos_t) / (n * c + cos_t)
    return {"R": (abs(rs) ** 2 + abs(rp) ** 2) / 2}


def lambert(n, wi, albedo):
    return {"value": albedo / math.pi * max(dot(n, wi), 0.0)}


def _lobe(n, wi, wo, kd, ks, value):
    if dot(n, wi) <= 0 or dot(n, wo) <= 0:
        return {"value": 0.0}
    return {"value": kd / math.pi + ks * value}


def phong(n, wi, wo, exponent, kd, ks):
    cos_a = max(dot(sub(mul(n, 2 * dot(n, wi)), wi), wo), 0.0)
    return _lobe(n, wi, wo, kd, ks, (exponent + 2) / (2 * math.pi) * cos_a ** exponent)


def blinn_phong(n, wi, wo, exponent, kd, ks):
    p = exponent
    cos_h = max(dot(n, normalize(add(wi, wo))), 0.0)
    norm = (p + 2) * (p + 4) / (8 * math.pi * (2 ** (-p / 2) + p))
    return _lobe(n, wi, wo, kd, ks, norm * cos_h ** p)


def camera_ray(type, origin, target, up, fov, ortho_width, width, height, x, y):
    f = normalize(sub(target, origin))
    r = normalize(cross(f, up))
    u = cross(r, f)
    sx, sy = 2 * x / width - 1, 1 - 2 * y / height     # row 0 at the top
    aspect = width / height
    if type == "orthographic":
        half = ortho_width / 2
        return {"origin": add(origin, add(mul(r, sx * half), mul(u, sy * half / aspect))),
                "direction": f}
    t = math.tan(math.radians(fov) / 2)                 # fov is horizontal
    d = add(f, add(mul(r, sx * t), mul(u, sy * t / aspect)))
    return {"origin": origin, "direction": normalize(d)}


def point_light(p, position, intensity):
    to = sub(position, p)
    r = math.sqrt(dot(to, to))
    return {"direction": mul(to, 1 / r), "distance": r, "irradiance": intensity / (r * r)}


def spot_falloff(cos_theta, cutoff_angle, beam_width):
    theta = math.degrees(math.acos(max(-1.0, min(1.0, cos_theta))))
    if theta >= cutoff_angle:
        return {"falloff": 0.0}
    if theta <= beam_width:
        return {"falloff": 1.0}
    return {"falloff": (cutoff_angle - theta) / (cutoff_angle - beam_width)}


def instance_normal(matrix, n):
    (a, b, c), (d, e, f), (g, h, i) = (row[:3] for row in matrix[:3])
    # (M^-1)^T is the cofactor matrix over the determinant; the determinant's sign
    # only flips the result, so keep it and normalise.
    cof = [[e * i - f * h, f * g - d * i, d * h - e * g],
           [c * h - b * i, a * i - c * g, b * g - a * h],
           [b * f - c * e, c * d - a * f, a * e - b * d]]
    det = a * cof[0][0] + b * cof[0][1] + c * cof[0][2]
    m = [dot(row, n) / det for row in cof]
    return {"n": normalize(m)}


FORMULAS = {f.__name__: f for f in (
    sphere_intersect, triangle_intersect, reflect, refract, fresnel_exact, fresnel_schlick,
    fresnel_conductor, lambert, phong, blinn_phong, camera_ray, point_light, spot_falloff,
    instance_normal)}


def formula(name, inputs):
    """The callable of `--python`: a formula's outputs for its inputs."""
    if name not in FORMULAS:
        raise NotImplementedError(f"no formula {name}")
    return FORMULAS[name](**inputs)


def main():
    """The program of `--program`: one JSON request a line in, one answer a line out."""
    for line in sys.stdin:
        request = json.loads(line)
        try:
            answer = {"id": request["id"],
                      "outputs": formula(request["formula"], request["inputs"])}
        except NotImplementedError as e:
            answer = {"id": request["id"], "error": str(e)}
        print(json.dumps(answer), flush=True)


if __name__ == "__main__":
    main()
