"""Affine transforms as 4x4 float64 matrices (numpy), built from ``to_world`` steps.

Conventions are Mitsuba 3's: column vectors, ``p' = M p``; a list of steps is
applied first step first, so ``[a, b, c]`` gives ``M = C @ B @ A``; rotations
are right-handed about the axis (counter-clockwise looking down the axis),
angles in degrees.
"""

from __future__ import annotations

import math

import numpy as np

from whitted.tracer import faults


def translate(v) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = v
    return m


def scale(v) -> np.ndarray:
    v = np.broadcast_to(np.asarray(v, dtype=np.float64), (3,))
    return np.diag([v[0], v[1], v[2], 1.0])


def rotate(axis, angle_deg: float) -> np.ndarray:
    """Rodrigues' rotation formula: R = cos I + sin [k]x + (1 - cos) k k^T."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    a = math.radians(angle_deg)
    if faults.on("rotation-sign-flipped"):
        a = -a
    c, s = math.cos(a), math.sin(a)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    m = np.eye(4)
    m[:3, :3] = c * np.eye(3) + s * kx + (1 - c) * np.outer(k, k)
    return m


def look_at(origin, target, up) -> np.ndarray:
    """Camera-to-world matrix: local +z looks at ``target``, +y is ``up``, +x is left.

    The same frame as Mitsuba's ``Transform4f.look_at``: the columns are
    (left, up', forward, origin) with left = normalize(up x forward).
    """
    o = np.asarray(origin, dtype=np.float64)
    f = np.asarray(target, dtype=np.float64) - o
    f /= np.linalg.norm(f)
    left = np.cross(np.asarray(up, dtype=np.float64), f)
    left /= np.linalg.norm(left)
    new_up = np.cross(f, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, f, o
    return m


def step_matrix(step: tuple) -> np.ndarray:
    """The matrix of one ``to_world`` step as the reader gives it
    (:data:`tracer.settings.Step`)."""
    op = step[0]
    if op == "translate":
        return translate(step[1])
    if op == "scale":
        return scale(step[1])
    if op == "rotate":
        return rotate(step[1], step[2])
    assert op == "matrix", op   # the reader gives no other step (tracer.settings.STEPS)
    return np.asarray(step[1], dtype=np.float64)


def compose(steps: list[np.ndarray]) -> np.ndarray:
    """Matrix of steps applied in the order given (first step first)."""
    # (the switch is asked only where the order can matter: two steps or more)
    reverse = len(steps) > 1 and faults.on("steps-composed-in-reverse")
    m = np.eye(4)
    for s in steps:
        m = m @ s if reverse else s @ m
    return m


def apply_point(m: np.ndarray, p) -> np.ndarray:
    p = np.asarray(p, dtype=np.float64)
    return p @ m[:3, :3].T + m[:3, 3]


def apply_vector(m: np.ndarray, v) -> np.ndarray:
    return np.asarray(v, dtype=np.float64) @ m[:3, :3].T


def apply_normal(m: np.ndarray, n) -> np.ndarray:
    """Normals transform by the inverse transpose of the linear part."""
    return np.asarray(n, dtype=np.float64) @ np.linalg.inv(m[:3, :3])


def is_similarity(m: np.ndarray, rtol: float = 1e-6) -> bool:
    """True when the linear part is a rotation (or reflection) times a uniform scale."""
    a = m[:3, :3]
    g = a.T @ a
    s = g[0, 0]
    return bool(s > 0 and np.allclose(g, s * np.eye(3), rtol=rtol, atol=rtol * s))
