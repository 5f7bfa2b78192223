"""Placements built by Mitsuba from the scene file's own steps, not from the tracer's matrices.

The Mitsuba side must not borrow the tracer's reading of a scene: the tracer composes
a ``to_world`` into one float64 matrix (:mod:`tracer.transform`), and a bug there (a
rotation's sign, steps applied in reverse, normals moved by M instead of its inverse
transpose, a sphere's radius that ignores the scale) would otherwise move both images
alike. So the conversion hands Mitsuba the *steps* as the file wrote them (the reader's
:data:`tracer.settings.Step` tuples, kept on each model: a shape's
:class:`tracer.shapes.base.Placement`, the camera's and an environment map's
``steps``), and Mitsuba composes them: ``mi.ScalarTransform4d``'s ``translate``,
``scale``, ``rotate``, ``look_at`` and a ``matrix`` step, first step first (the XML
writer puts the same steps into a ``<transform>``, which Mitsuba's parser composes
alike). Points and normals of in-memory meshes are moved by ``mi.Transform4f``
(normals by its inverse transpose, Mitsuba's ``Normal3f`` rule) and normalised by
Dr.Jit.

A step is a tuple: ``("translate", (x, y, z))``, ``("scale", (sx, sy, sz))``,
``("rotate", (ax, ay, az), degrees)``, ``("matrix", 4 rows)`` or ``("lookat", origin,
target, up)``. The scene format's rotation axis is a direction (docs/scene-format.md,
"to_world steps": "the axis is normalised"), while Mitsuba 3.9.1's ``rotate`` uses the
axis as given (Rodrigues' formula with the raw vector), so a rotation's axis is
normalised by Dr.Jit before Mitsuba sees it.

What stays shared is the reader of the values (:func:`tracer.settings.read_steps`), a
model made in code without a file (its matrix stands in as one ``matrix`` step,
:func:`of`), and the tessellations and uvs of the shapes Mitsuba lacks
(docs/verdicts.md, "What both sides share").
"""

from __future__ import annotations

import numpy as np

Step = tuple
Steps = tuple


def of(model) -> Steps:
    """A shape's or a light's ``to_world`` as steps: a shape's
    :class:`~tracer.shapes.base.Placement`'s, a light's ``steps``, or, for a model made in
    code (neither), its composed matrix as one step."""
    placement = getattr(model, "placement", None)
    steps = placement.steps if placement is not None else getattr(model, "steps", None)
    if steps is not None:
        return tuple(steps)
    return matrix_step(model.to_world)


def matrix_step(m) -> Steps:
    """One ``matrix`` step of a 4 x 4 matrix (for a scene made in code, without file data)."""
    return (("matrix", tuple(tuple(float(x) for x in row) for row in np.asarray(m))),)


def lookat_step(origin, target, up) -> Steps:
    return (("lookat", tuple(map(float, origin)), tuple(map(float, target)),
             tuple(map(float, up))),)


def tree(steps: Steps) -> tuple:
    """The plugin-tree value of a transform given as steps
    (:mod:`reference.renderers.mitsuba.tree`); no steps: the identity."""
    return ("steps", tuple(steps))


def compose(mi, steps: Steps):
    """The steps composed by Mitsuba, first step first: a ``mi.ScalarTransform4f``.

    Each step is made and composed by Mitsuba's double-precision transform
    (``mi.ScalarTransform4d``: its own ``translate``, ``scale``, ``rotate``, ``look_at``),
    and the result rounded once to the float32 transform Mitsuba's plugins take, as the
    tracer rounds its float64 composition once (composing in float32 would add one
    rounding a step, about 1e-7 each, that a mesh's computed normals can magnify)."""
    import drjit as dr

    T = mi.ScalarTransform4d()
    for step in steps:
        op = step[0]
        if op == "translate":
            S = mi.ScalarTransform4d().translate(mi.ScalarVector3d(*step[1]))
        elif op == "scale":
            S = mi.ScalarTransform4d().scale(mi.ScalarVector3d(*step[1]))
        elif op == "rotate":
            axis = dr.normalize(mi.ScalarVector3d(*step[1]))
            S = mi.ScalarTransform4d().rotate(axis, step[2])
        elif op == "matrix":
            S = mi.ScalarTransform4d(mi.ScalarMatrix4d([list(r) for r in step[1]]))
        elif op == "lookat":
            S = mi.ScalarTransform4d().look_at(origin=mi.ScalarPoint3d(*step[1]),
                                               target=mi.ScalarPoint3d(*step[2]),
                                               up=mi.ScalarVector3d(*step[3]))
        else:
            raise ValueError(f"unknown step {op!r}")
        T = S @ T
    return mi.ScalarTransform4f(np.asarray(T.matrix, dtype=np.float64).tolist())


def _unit(v) -> tuple:
    a = np.asarray(v, dtype=np.float64)
    return tuple(float(x) for x in a / np.linalg.norm(a))


def xml_lines(name: str, steps: Steps, pad: str, fmt) -> list[str]:
    """``<transform name=...>`` with one child per step (Mitsuba's parser composes them in
    the order written, first step first); ``fmt`` formats a number."""
    def xyz(v):
        return f'x="{fmt(v[0])}" y="{fmt(v[1])}" z="{fmt(v[2])}"'

    def triple(v):
        return ", ".join(fmt(x) for x in v)

    lines = [f'{pad}<transform name="{name}">']
    inner = pad + "    "
    for step in steps:
        op = step[0]
        if op in ("translate", "scale"):
            lines.append(f"{inner}<{op} {xyz(step[1])}/>")
        elif op == "rotate":   # the format's axis is a direction; Mitsuba takes it as given
            lines.append(f'{inner}<rotate {xyz(_unit(step[1]))} angle="{fmt(step[2])}"/>')
        elif op == "matrix":
            flat = " ".join(fmt(x) for row in step[1] for x in row)
            lines.append(f'{inner}<matrix value="{flat}"/>')
        else:
            lines.append(f'{inner}<lookat origin="{triple(step[1])}" target="{triple(step[2])}" '
                         f'up="{triple(step[3])}"/>')
    return lines + [f"{pad}</transform>"]


def move_points(mi, steps: Steps, points: np.ndarray) -> np.ndarray:
    """N x 3 points moved by Mitsuba's composition of ``steps`` (float32, as Mitsuba holds
    them), as a float64 array."""
    p = np.asarray(points, dtype=np.float32)
    T = mi.Transform4f(compose(mi, steps))
    q = T @ mi.Point3f(mi.Float(p[:, 0]), mi.Float(p[:, 1]), mi.Float(p[:, 2]))
    return np.asarray(q, dtype=np.float64).T   # Dr.Jit gives 3 x N


def move_normals(mi, steps: Steps, normals: np.ndarray) -> np.ndarray:
    """N x 3 normals moved by the inverse transpose of Mitsuba's composition (its
    ``Normal3f`` rule) and normalised, as a float64 array."""
    import drjit as dr

    n = np.asarray(normals, dtype=np.float32)
    T = mi.Transform4f(compose(mi, steps))
    q = dr.normalize(T @ mi.Normal3f(mi.Float(n[:, 0]), mi.Float(n[:, 1]), mi.Float(n[:, 2])))
    return np.asarray(q, dtype=np.float64).T
