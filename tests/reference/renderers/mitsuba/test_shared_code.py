"""Code that both sides of a comparison could read, checked against Mitsuba's own reading.

The Mitsuba side builds its placements from the scene file's own values (the steps of
each to_world, a sphere's centre and radius, a triangle's own vertices) with Mitsuba's
own transforms (reference/renderers/mitsuba/transforms.py), not from the matrices
tracer/transform.py composes: the first law below shows that with a bug switched into
the tracer's composition the tracer's model changes and the Mitsuba scene does not, so
the comparison sees it. The other laws compare the tracer's own code with what Mitsuba
computes from the same values: each step's matrix made by ``mi.ScalarTransform4f`` (its
rotation convention, not ours), steps composed here in the order the scene format states
(the first step is applied first), a mesh's normals transformed by Mitsuba's own ``obj``
plugin under the same ``to_world``.
"""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from conftest import ROOT, write_scene

from whitted.reference import mutants
from whitted.reference.renderers.mitsuba.scene import load
from whitted.tracer import faults, load_scene
from whitted.tracer.meshio import clear_cache

# Steps of every kind, non-uniform scales, rotations about each axis with both signs and
# about an oblique (unit) axis, several steps in an order that matters.
TO_WORLDS = [
    "[ { translate = [1.5, -2, 0.25] } ]",
    "[ { scale = [2.0, 0.5, 1.0] }, { translate = [-2.4, 0.25, -1.2] } ]",
    "[ { rotate = { axis = [1, 0, 0], angle = 30 } } ]",
    "[ { rotate = { axis = [0, 1, 0], angle = -75 } } ]",
    "[ { rotate = { axis = [0, 0, 1], angle = 120 } } ]",
    "[ { rotate = { axis = [0.6, 0.0, 0.8], angle = 47 } } ]",
    "[ { scale = [1.6, 0.6, 0.8] }, { rotate = { axis = [0, 0, 1], angle = 35 } }, "
    "{ translate = [0.4, 0.55, -2.0] } ]",
    "[ { translate = [0, 1, 0] }, { rotate = { axis = [1, 0, 0], angle = 90 } }, "
    "{ scale = [1, 2, 3] } ]",
    "[ { scale = 0.5 }, { matrix = [[0, -1, 0, 2], [1, 0, 0, 0], [0, 0, 1, 0], "
    "[0, 0, 0, 1]] } ]",
]

HEAD = """
[film]
width = 8
height = 6

[camera]
origin = [0, 0, 10]
target = [0, 0, 0]

[materials.white]
type = "diffuse"
reflectance = 0.5

[[lights]]
type = "point"
position = [0, 3, 3]
intensity = 10
"""


def _mitsuba_matrix(mi, steps: list[dict]) -> np.ndarray:
    """The to_world of ``steps`` with every step's matrix made by Mitsuba."""
    m = np.eye(4)
    for s in steps:
        (op, v), = s.items()
        if op == "translate":
            step = mi.ScalarTransform4f().translate(mi.ScalarVector3f(v))
        elif op == "scale":
            step = mi.ScalarTransform4f().scale(mi.ScalarVector3f(v if isinstance(v, list)
                                                                  else [v, v, v]))
        elif op == "rotate":
            step = mi.ScalarTransform4f().rotate(mi.ScalarVector3f(v["axis"]), v["angle"])
        else:
            step = mi.ScalarTransform4f(mi.ScalarMatrix4f(np.asarray(v, np.float64)))
        m = np.asarray(step.matrix, np.float64) @ m  # the first step is applied first
    return m


def test_to_world_steps_compose_as_mitsuba_builds_them(tmp_path, mi):
    text = HEAD + "\n[groups.ball]\n[[groups.ball.shapes]]\ntype = \"sphere\"\n" \
                  "center = [0, 0, 0]\nradius = 0.5\nmaterial = \"white\"\n"
    for tw in TO_WORLDS:
        text += f'\n[[shapes]]\ntype = "instance"\ngroup = "ball"\nto_world = {tw}\n'
    scene = load_scene(write_scene(tmp_path, text))
    steps = [s["to_world"] for s in tomllib.loads(text)["shapes"]]
    assert len(scene.shapes) == len(steps)
    for shape, st in zip(scene.shapes, steps, strict=True):
        ours = np.asarray(shape.to_world, np.float64)
        # Mitsuba's matrices are float32: agreement to float32 rounding of entries <= 3
        np.testing.assert_allclose(ours, _mitsuba_matrix(mi, st), rtol=0, atol=2e-6,
                                   err_msg=str(st))


def test_builtin_scenes_instances_compose_as_mitsuba_builds_them(mi):
    """The same law on the built-in scene that relies on it most."""
    path = ROOT / "scenes" / "instances_scaled.toml"
    data = tomllib.loads(path.read_text())
    scene = load_scene(path)
    instances = [s for s in scene.shapes if type(s).__name__ == "Instance"]
    tables = [s for s in data["shapes"] if s.get("type") == "instance"]
    assert len(instances) == len(tables) >= 8
    for shape, t in zip(instances, tables, strict=True):
        np.testing.assert_allclose(np.asarray(shape.to_world, np.float64),
                                   _mitsuba_matrix(mi, t["to_world"]), rtol=0, atol=2e-6)


OBJ = """v 0 0 0
v 1 0 0
v 0 1 0
v 1 1 0.5
vn 0.3 0.2 0.93
vn -0.4 0.1 0.91
vn 0.5 -0.5 0.707
vn 0 0.6 0.8
f 1//1 2//2 3//3
f 2//2 4//4 3//3
"""


@pytest.mark.parametrize("to_world", [
    "[ { scale = [3.0, 0.25, 1.0] } ]",
    "[ { scale = [0.5, 2.0, 4.0] }, { rotate = { axis = [0, 1, 0], angle = 30 } } ]"])
def test_mesh_normals_under_a_non_uniform_scale_are_mitsubas(tmp_path, mi, to_world):
    """Normals go by the inverse transpose of to_world (lecture 2, "Instancing"); Mitsuba's
    obj plugin transforms the file's normals itself. Under a non-uniform scale, M in
    place of (M^-1)^T turns them by up to tens of degrees."""
    (tmp_path / "quad.obj").write_text(OBJ)
    text = HEAD + f'\n[[shapes]]\ntype = "mesh"\nfile = "quad.obj"\nmaterial = "white"\n' \
                  f"to_world = {to_world}\n"
    clear_cache()
    scene = load_scene(write_scene(tmp_path, text))
    (mesh,) = scene.shapes
    ours = np.asarray(mesh.normals, np.float64).reshape(-1, 3)
    m = _mitsuba_matrix(mi, tomllib.loads(text)["shapes"][0]["to_world"])
    shape = mi.load_dict({"type": "obj", "filename": str(tmp_path / "quad.obj"),
                          "face_normals": False,
                          "to_world": mi.ScalarTransform4f(mi.ScalarMatrix4f(m))})
    params = mi.traverse(shape)
    theirs = np.asarray(params["vertex_normals"], np.float64).reshape(-1, 3)
    verts = np.asarray(params["vertex_positions"], np.float64).reshape(-1, 3)
    ours_v = np.asarray(mesh.vertices, np.float64).reshape(-1, 3)
    # Mitsuba may reorder or merge vertices: match them by position
    order = [int(np.argmin(np.linalg.norm(ours_v - v, axis=1))) for v in verts]
    np.testing.assert_allclose(ours_v[order], verts, atol=1e-5)
    # unit normals in float32 on both sides: 1e-5 is ~20 float32 steps
    np.testing.assert_allclose(ours[order], theirs, atol=1e-5)


PARSE_BUGS = [m.id for m in mutants.CATALOG if m.stage == "parse"]


def _tracer_model(scene) -> list[np.ndarray]:
    """What the tracer made of the scene's placements: matrices, centres, radii, points,
    normals, as arrays."""
    out = []
    for shape in scene.all_shapes():
        for attr in ("to_world", "center", "radius", "vertices", "normals"):
            v = getattr(shape, attr, None)
            if callable(v) or v is None:
                continue
            out.append(np.asarray(v, dtype=np.float64))
    return out


def _mitsuba_geometry(mi, scene) -> list[tuple[str, np.ndarray]]:
    """What Mitsuba made of the converted scene: every shape's bounding box, and a mesh's
    world-space positions and normals, shape by shape in the order of their boxes (Mitsuba
    keeps no fixed order of its shapes from one load to the next)."""
    loaded = load(scene, mi, integrator="direct")
    shapes = []
    for shape in loaded.shapes():
        b = shape.bbox()
        box = np.array([list(b.min), list(b.max)], dtype=np.float64)
        parts = [("bbox", box)]
        if shape.is_mesh():
            p = mi.traverse(shape)
            for key in ("vertex_positions", "vertex_normals"):
                if key in p.keys():
                    parts.append((key, np.asarray(p[key], dtype=np.float64)))
        shapes.append((tuple(box.ravel()), parts))
    shapes.sort(key=lambda s: s[0])
    return [part for _, parts in shapes for part in parts]


@pytest.mark.parametrize("bug", PARSE_BUGS)
def test_a_bug_in_the_tracers_reading_of_placements_changes_its_model_not_mitsubas(mi, bug):
    """With the bug on, the tracer's own model of at least one built-in scene changes
    (else the law would say nothing), while the Mitsuba scene built from the same file is
    the same to the bit: Mitsuba composes the file's values itself."""
    changed = 0
    for name in ("ortho_transforms", "mesh_scaled_normals", "instances_scaled"):
        clear_cache()
        clean = load_scene(name)
        with faults.active(bug):
            clear_cache()
            buggy = load_scene(name)
        ours = _tracer_model(clean), _tracer_model(buggy)
        changed += any(a.shape != b.shape or not np.array_equal(a, b)
                       for a, b in zip(*ours, strict=True))
        theirs = _mitsuba_geometry(mi, clean), _mitsuba_geometry(mi, buggy)
        assert [k for k, _ in theirs[0]] == [k for k, _ in theirs[1]]
        for (key, a), (_, b) in zip(*theirs, strict=True):
            # Normals Mitsuba computes from the faces are summed in parallel, in an order
            # that varies from load to load: the same scene loaded twice differs by up to
            # one float32 step (1.2e-7 seen), so 1e-6 (8 steps) for them; all else exact.
            atol = 1e-6 if key == "vertex_normals" else 0.0
            np.testing.assert_allclose(a, b, rtol=0, atol=atol, err_msg=f"{name}: {bug}")
    assert changed, f"{bug} changes no tracer model of these scenes"
