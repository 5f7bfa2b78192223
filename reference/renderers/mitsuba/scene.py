"""Convert the scene model into Mitsuba 3 plugins (a ``load_dict`` dictionary or XML).

Each key of the scene format maps onto Mitsuba's plugins with the same
meaning, and Mitsuba's defaults that differ from a Whitted set-up are
overridden explicitly:

========================  ===================================================
scene                     Mitsuba
========================  ===================================================
perspective camera        ``perspective``, ``fov_axis = "x"``, same clip planes
orthographic camera       ``orthographic``, ``to_world`` = look_at x scale(w/2)
film                      ``hdrfilm``, ``box``, ``gaussian`` or ``tent`` filter, rgb float32
spp                       ``stratified`` sampler, ``jitter`` as the film's
camera to_world           ``to_world`` as given (``fov_axis`` and principal
                          point offsets as given)
cube                      ``cube`` with ``to_world``
diffuse                   ``twosided`` ``diffuse``
mirror                    ``twosided`` ``conductor`` (``material = "none"``)
dielectric                ``dielectric`` with ``int_ior`` and ``ext_ior`` set
point / spot              ``point`` / ``spot`` (``to_world`` = look_at)
directional               ``directional`` with ``direction``
sphere / rectangle        ``sphere`` / ``rectangle`` with ``to_world``
triangle                  a one-face mesh (``obj`` file in XML)
disk / cylinder           ``disk`` / ``cylinder`` with ``to_world``
polygon                   a mesh by ear clipping, uvs = the plane's coordinates
paraboloid                a smooth mesh (exact normals at the vertices), fine
                          enough that its chords stay within 1e-4 of its size
mesh                      ``obj`` / ``ply`` with ``face_normals = !smooth``
instance + groups         ``shapegroup`` + ``instance``
phong                     ``twosided`` ``whitted_phong`` (reference/materials/phong.py)
checkerboard              ``checkerboard`` with ``to_uv`` a scale
emitter                   ``area`` with ``radiance``
classic                   ``whitted_classic`` (reference/materials/classic.py)
classic with kl > 0       + ``whitted_heckbert`` on the sphere (reference/emitters/heckbert.py)
background                ``whitted_background`` (reference/emitters/background.py)
camera pixel_offset       ``principal_point_offset_x/y`` (perspective; orthographic: a shift)
integrator                ``whitted`` (reference/renderers/mitsuba/onelobe.py)
========================  ===================================================

Materials, lights and shapes are converted by their kinds' modules in
``reference/materials/``, ``reference/emitters/`` and ``reference/shapes/`` (each
beside its ``tracer/`` module), through their registries; the sensor and the
integrator are converted here.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

# Materials and lights convert in their own modules (reference/materials/,
# reference/emitters/), through their registries; their entry points are
# re-exported here ("X as X").
from whitted.reference.emitters import area_tree
from whitted.reference.emitters import emitter_tree as emitter_tree
from whitted.reference.materials import bsdf_tree as bsdf_tree
from whitted.reference.materials import plugin_names
from whitted.reference.materials.textures import texture_tree as texture_tree
from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.shapes import mitsuba_tree

# Shapes convert in their own modules (reference/shapes/), through its registry; the
# tessellations that used to be here are re-exported ("X as X").
from whitted.reference.shapes.paraboloid import PARABOLOID_DEVIATION as PARABOLOID_DEVIATION
from whitted.reference.shapes.paraboloid import paraboloid_mesh as paraboloid_mesh
from whitted.reference.shapes.polygon import polygon_mesh as polygon_mesh
from whitted.tracer.scene import Instance, Scene


def camera_steps(cam) -> tuple:
    """The camera's ``to_world`` as steps for Mitsuba to compose: the file's own steps, or a
    look_at of its origin, target and up (Mitsuba's ``look_at``); a camera made in code
    with a matrix and no steps gives that matrix as one step."""
    if cam.steps is not None:
        return tuple(cam.steps)
    if cam.matrix is not None:
        return transforms.matrix_step(cam.matrix)
    return transforms.lookat_step(cam.origin, cam.target, cam.up)


def sensor_tree(scene: Scene, jitter: bool = False) -> dict:
    """Sensor, film and sampler; ``jitter`` places samples at random inside their strata."""
    cam, film = scene.camera, scene.film
    look = camera_steps(cam)
    sensor = {"near_clip": ("float", cam.near_clip), "far_clip": ("float", cam.far_clip)}
    dx, dy = cam.pixel_offset
    if cam.type == "perspective":
        sensor.update(type="perspective", fov=("float", cam.fov),
                      fov_axis=("string", cam.fov_axis), to_world=transforms.tree(look))
        ppx = dx / film.width + cam.principal_point[0]
        ppy = dy / film.height + cam.principal_point[1]
        if ppx or ppy:  # moving the samples by (dx, dy) pixels = moving the principal point
            sensor["principal_point_offset_x"] = ("float", ppx)
            sensor["principal_point_offset_y"] = ("float", ppy)
    elif cam.matrix is not None:  # to_world given: it scales the [-1, 1]^2 view itself
        shift = ("translate", (-2 * dx / film.width, -2 * dy / film.width, 0.0))
        sensor.update(type="orthographic", to_world=transforms.tree((shift, *look)))
    else:
        half = cam.width / 2
        # Mitsuba's camera space has +x to the image's left and +y to its top: moving
        # the samples (dx, dy) pixels right and down moves the view by -2 dx / W, -2 dy / W
        # of half its width there.
        shift = ("translate", (-2 * dx / film.width * half, -2 * dy / film.width * half, 0.0))
        sensor.update(type="orthographic", to_world=transforms.tree(
            (("scale", (half, half, 1.0)), shift, *look)))
    sensor["film"] = {"type": "hdrfilm", "width": ("integer", film.width),
                      "height": ("integer", film.height), "rfilter": rfilter_tree(film),
                      "pixel_format": ("string", "rgb"),
                      "component_format": ("string", "float32"),
                      "sample_border": ("boolean", False)}
    sensor["sampler"] = {"type": "stratified", "sample_count": ("integer", film.strata ** 2),
                         "jitter": ("boolean", jitter or film.jitter)}
    return sensor


def rfilter_tree(film) -> dict:
    """Mitsuba's reconstruction filter of the film: ``box``, ``gaussian`` with its stddev,
    or ``tent`` with its radius."""
    if film.filter == "gaussian":
        return {"type": "gaussian", "stddev": ("float", film.stddev)}
    if film.filter == "tent":
        return {"type": "tent", "radius": ("float", film.radius)}
    return {"type": "box"}


def shape_tree(scene: Scene, shape, index: int, prefix: str = "shape",
               models: bool = False) -> dict:
    """Plugin tree of a shape; in-memory meshes are ``{"type": "mesh", ...}`` nodes.

    ``models``: tracer-only parts as the harness models them (see
    :func:`reference.materials.bsdf_tree`)."""
    t = mitsuba_tree(shape, f"{prefix}_{index}")
    if not shape.takes_material:  # an instance: its group's shapes carry their own
        return t
    material = scene.material_of(shape)
    t["bsdf"] = bsdf_tree(material, models)
    if shape.emitter is not None:
        t["emitter"] = area_tree(shape.emitter)
    elif material is not None and (light := material.light_of(shape)) is not None:
        t["emitter"] = emitter_tree(light)   # a light the material makes of its shape
    return t


def integrator_tree(scene: Scene, integrator: str = "whitted", moments: bool = False) -> dict:
    t = {"type": integrator, "max_depth": ("integer", scene.film.max_depth)}
    if integrator == "whitted" and moments:
        t["moments"] = ("boolean", True)
    if integrator in ("direct",):
        # `direct` has no max_depth: it is direct illumination (max_depth 2) by definition.
        del t["max_depth"]
    return t


def scene_tree(scene: Scene, integrator: str = "whitted", moments: bool = False,
               jitter: bool = False, models: bool = False) -> dict:
    tree = {"type": "scene", "sensor": sensor_tree(scene, jitter),
            "integrator": integrator_tree(scene, integrator, moments)}
    for i, light in enumerate(scene.lights):
        tree[f"light_{i}"] = emitter_tree(light)
    used = {s.group for s in scene.shapes if isinstance(s, Instance)}
    for gname, members in scene.groups.items():
        if gname in used:
            group = {"type": "shapegroup"}
            for i, shape in enumerate(members):
                group[f"shape_{i}"] = shape_tree(scene, shape, i, f"group_{gname}", models)
            tree[f"group_{gname}"] = group
    for i, shape in enumerate(scene.shapes):
        tree[f"shape_{i}"] = shape_tree(scene, shape, i, models=models)
    return tree


# ------------------------------------------------------------------ load_dict


def to_dict(tree: dict, mi) -> dict:
    """A plugin tree as a dictionary for ``mi.load_dict`` (meshes built in memory)."""
    import drjit as dr

    if tree.get("type") == "mesh":
        props = mi.Properties()
        props["bsdf"] = mi.load_dict(to_dict(tree["bsdf"], mi))
        if "emitter" in tree:
            props["emitter"] = mi.load_dict(to_dict(tree["emitter"], mi))
        v, f = tree["vertices"], tree["faces"]
        normals, uvs = tree["normals"], tree["uvs"]
        if tree.get("to_world"):   # moved by Mitsuba's composition of the file's steps
            v = transforms.move_points(mi, tree["to_world"], v)
            if normals is not None:
                normals = transforms.move_normals(mi, tree["to_world"], normals)
        if normals is None:
            props["face_normals"] = True
        mesh = mi.Mesh(tree["name"], len(v), len(f), props,
                       has_vertex_normals=normals is not None,
                       has_vertex_texcoords=uvs is not None)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(np.asarray(v, dtype=np.float32).ravel())
        params["faces"] = mi.UInt32(np.asarray(f, dtype=np.uint32).ravel())
        if normals is not None:
            params["vertex_normals"] = mi.Float(np.asarray(normals, dtype=np.float32).ravel())
        if uvs is not None:
            params["vertex_texcoords"] = mi.Float(np.asarray(uvs, dtype=np.float32).ravel())
        params.update()
        dr.eval()
        return mesh
    out = {}
    for k, v in tree.items():
        if isinstance(v, dict):
            out[k] = to_dict(v, mi)
        elif isinstance(v, tuple) and len(v) == 2 and isinstance(v[0], str):
            kind, val = v
            if kind == "steps":
                out[k] = transforms.compose(mi, val)
            elif kind == "uvscale":
                out[k] = mi.ScalarTransform3f().scale(mi.ScalarPoint2f(*val))
            elif kind == "uvmatrix":
                out[k] = mi.ScalarTransform3f(np.asarray(val, dtype=np.float64).tolist())
            elif kind in ("point", "vector"):
                out[k] = mi.ScalarPoint3f(*val) if kind == "point" else mi.ScalarVector3f(*val)
            elif kind == "rgb":
                out[k] = mi.ScalarColor3f(*val) if k == "value" else list(val)
            else:
                out[k] = val
        else:
            out[k] = v
    return out


def load(scene: Scene, mi, integrator: str = "whitted", moments: bool = False,
         jitter: bool = False, models: bool = False):
    """The scene as a Mitsuba ``Scene`` object (the variant must already be set).

    ``models``: tracer-only parts as the harness models them, where it has a model
    (:func:`reference.materials.tracer_only_model`)."""
    tree = to_dict(scene_tree(scene, integrator, moments, jitter, models), mi)
    with loading_threads():
        return mi.load_dict(tree)


@contextmanager
def loading_threads():
    """At least two Dr.Jit threads while Mitsuba loads a scene: Mitsuba 3.9.1's parser
    never returns from reading an EXR file (scenes/envmap.toml's map) on a pool of one
    thread, which renderers.luxcore.render.SharedCores leaves during the report's sweep
    (and a one-core machine by default). The pool is restored after."""
    import drjit as dr

    threads = dr.thread_count()
    if threads < 2:
        dr.set_thread_count(2)
    try:
        yield
    finally:
        if threads < 2:
            dr.set_thread_count(threads)


# ------------------------------------------------------------------ XML


def _fmt(x: float) -> str:
    return f"{float(x):.9g}"


_CHILD_TAGS = {"film": "film", "sampler": "sampler", "rfilter": "rfilter", "bsdf": "bsdf",
               "material": "bsdf", "emitter": "emitter"}


def _xml(tree: dict, tag: str, indent: int, meshes: list, obj_id: str | None = None,
         name: str | None = None, mesh_prefix: str = "") -> list[str]:
    pad = "    " * indent
    id_attr = f" id={quoteattr(obj_id)}" if obj_id else ""
    name_attr = f" name={quoteattr(name)}" if name else ""
    if tree["type"] == "ref":
        return [f'{pad}<ref id={quoteattr(tree["id"][1])}/>']
    if tree["type"] == "mesh":
        meshes.append(tree)
        filename = quoteattr(f"meshes/{mesh_prefix}{tree['name']}.obj")
        lines = [f'{pad}<shape type="obj"{id_attr}>',
                 f'{pad}    <string name="filename" value={filename}/>',
                 f'{pad}    <boolean name="face_normals" value="'
                 f'{"true" if tree["normals"] is None else "false"}"/>']
        if tree.get("to_world"):   # the file keeps the shape's own points; Mitsuba moves them
            lines += transforms.xml_lines("to_world", tree["to_world"], pad + "    ", _fmt)
        lines += _xml(tree["bsdf"], "bsdf", indent + 1, meshes, mesh_prefix=mesh_prefix)
        if "emitter" in tree:
            lines += _xml(tree["emitter"], "emitter", indent + 1, meshes, mesh_prefix=mesh_prefix)
        return lines + [f"{pad}</shape>"]
    lines = [f'{pad}<{tag} type="{tree["type"]}"{id_attr}{name_attr}>']
    for k, v in tree.items():
        if k == "type":
            continue
        if isinstance(v, dict) and v.get("type") == "rgb":
            lines.append(f'{pad}    <rgb name="{k}" value="'
                         f'{", ".join(_fmt(x) for x in v["value"][1])}"/>')
            continue
        if isinstance(v, dict):
            if k.startswith("shape_"):
                lines += _xml(v, "shape", indent + 1, meshes, mesh_prefix=mesh_prefix)
            elif k in _CHILD_TAGS:
                lines += _xml(v, _CHILD_TAGS[k], indent + 1, meshes, mesh_prefix=mesh_prefix)
            elif k.startswith(("bsdf_", "brdf_")):   # nested BSDFs: blendbsdf's two, ...
                lines += _xml(v, "bsdf", indent + 1, meshes, name=k, mesh_prefix=mesh_prefix)
            else:  # a texture given for a parameter, e.g. reflectance
                lines += _xml(v, "texture", indent + 1, meshes, name=k,
                              mesh_prefix=mesh_prefix)
            continue
        kind, val = v
        if kind == "steps":
            if val:
                lines += transforms.xml_lines(k, val, pad + "    ", _fmt)
        elif kind == "uvscale":
            lines += [f'{pad}    <transform name="{k}">',
                      f'{pad}        <scale x="{_fmt(val[0])}" y="{_fmt(val[1])}"/>',
                      f"{pad}    </transform>"]
        elif kind == "uvmatrix":
            # Written as a 4x4 with the 2D translation in the last column: Mitsuba 3.9.1
            # reads a 3x3 <matrix> into the upper-left of a 4x4 and then takes to_uv's
            # translation from the last column, so a 3x3's translation would be lost.
            (a, b, c), (d, e, f) = val[0], val[1]
            m4 = ((a, b, 0.0, c), (d, e, 0.0, f), (0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0))
            flat = " ".join(_fmt(x) for row in m4 for x in row)
            lines += [f'{pad}    <transform name="{k}">', f'{pad}        <matrix value="{flat}"/>',
                      f"{pad}    </transform>"]
        elif kind in ("point", "vector"):
            lines.append(f'{pad}    <{kind} name="{k}" value="{", ".join(_fmt(x) for x in val)}"/>')
        elif kind == "boolean":
            lines.append(f'{pad}    <boolean name="{k}" value="{"true" if val else "false"}"/>')
        elif kind == "float":
            lines.append(f'{pad}    <float name="{k}" value="{_fmt(val)}"/>')
        else:
            lines.append(f'{pad}    <{kind} name="{k}" value={quoteattr(str(val))}/>')
    return lines + [f"{pad}</{tag}>"]


def _write_obj(path: Path, node: dict) -> None:
    v, f = node["vertices"], node["faces"]
    lines = [f"v {_fmt(a)} {_fmt(b)} {_fmt(c)}\n" for a, b, c in np.asarray(v, dtype=np.float32)]
    if node["uvs"] is not None:  # v written as 1 - v: Mitsuba's obj (and whitted's) flips it
        lines += [f"vt {_fmt(a)} {_fmt(1 - b)}\n"
                  for a, b in np.asarray(node["uvs"], np.float32)]
    if node["normals"] is not None:
        lines += [f"vn {_fmt(a)} {_fmt(b)} {_fmt(c)}\n"
                  for a, b, c in np.asarray(node["normals"], dtype=np.float32)]
    has_t, has_n = node["uvs"] is not None, node["normals"] is not None
    for tri in np.asarray(f) + 1:
        corners = []
        for i in tri:
            corners.append(f"{i}/{i if has_t else ''}/{i}" if has_n else
                           (f"{i}/{i}" if has_t else f"{i}"))
        lines.append("f " + " ".join(corners) + "\n")
    path.write_text("".join(lines))


def _relative_mesh_files(tree: dict, folder: Path) -> None:
    """Mesh files named relative to the XML's folder, where Mitsuba looks for them."""
    import os

    for v in tree.values():
        if isinstance(v, dict):
            if v.get("type") in ("obj", "ply") and "filename" in v:
                name = os.path.abspath(v["filename"][1])
                try:
                    name = os.path.relpath(name, folder)
                except ValueError:  # another drive: keep it absolute
                    pass
                v["filename"] = ("string", name)
            _relative_mesh_files(v, folder)


def _comment(text: str) -> str:
    """Text safe inside an XML comment (no "--", printable)."""
    from whitted.tracer.errors import one_line

    return one_line(text, 200).replace("--", "- -")


def write_xml(scene: Scene, path: str | Path, integrator: str = "whitted",
              jitter: bool = False) -> list[Path]:
    """Write the scene as Mitsuba 3 XML (plus ``meshes/*.obj`` for triangles); return the files.

    ``jitter`` places the samples at random inside their strata (Mitsuba's
    ``stratified`` sampler with ``jitter``); the default puts them at the
    strata centres, the tracer's positions.

    Mesh files are named after the XML file (``meshes/NAME_shape_2.obj`` for
    ``NAME.xml``), so that scenes exported into one folder keep their own.
    """
    path = Path(path)
    mesh_prefix = path.stem + "_"
    tree = scene_tree(scene, integrator, jitter=jitter)
    _relative_mesh_files(tree, path.resolve().parent)
    meshes: list[dict] = []
    body = []
    for key, value in tree.items():
        if key == "type":
            continue
        tag = {"sensor": "sensor", "integrator": "integrator"}.get(key)
        if tag is None:
            tag = "emitter" if key.startswith("light_") else "shape"
        body += _xml(value, tag, 1, meshes, key if tag in ("shape", "emitter") else None,
                     mesh_prefix=mesh_prefix)
    from whitted.reference.emitters import plugin_names as emitter_plugin_names

    plugins = [name for name in plugin_names() + emitter_plugin_names()
               if any(f'type="{name}"' in line for line in body)]
    note = ("Rendered by Mitsuba 3 after `import whitted.reference` (which registers the "
            "`whitted` integrator), e.g. python -c \"import whitted.reference, mitsuba as mi; "
            "...\"; or export with "
            "the integrator option set to direct for a stock integrator (an XML comment may not "
            "hold two dashes in a row).") if integrator == "whitted" else ""
    if plugins:
        note += (" It uses plugins written on Mitsuba's API (" +
                 ", ".join(f"`{name}`" for name in plugins) + "), registered by "
                 "reference.mitsuba().")
    header = [
        '<?xml version="1.0" encoding="utf-8"?>',
        f"<!-- Exported by whitted from {_comment(scene.path)}. {note} -->",
        '<scene version="3.0.0">',
    ]
    files = []
    if meshes:
        (path.parent / "meshes").mkdir(parents=True, exist_ok=True)
    for m in meshes:
        obj = path.parent / "meshes" / f"{mesh_prefix}{m['name']}.obj"
        _write_obj(obj, m)
        files.append(obj)
    path.write_text("\n".join(header + body + ["</scene>", ""]))
    return [path] + files
