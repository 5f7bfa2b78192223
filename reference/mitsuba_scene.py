"""Convert the scene model into Mitsuba 3 plugins (a ``load_dict`` dictionary or XML).

Each key of the scene format maps onto Mitsuba's plugins with the same
meaning, and Mitsuba's defaults that differ from a Whitted set-up are
overridden explicitly:

========================  ===================================================
scene                     Mitsuba
========================  ===================================================
perspective camera        ``perspective``, ``fov_axis = "x"``, same clip planes
orthographic camera       ``orthographic``, ``to_world`` = look_at x scale(w/2)
film                      ``hdrfilm``, ``box`` filter, rgb float32
spp                       ``stratified`` sampler, ``jitter = false``
diffuse                   ``twosided`` ``diffuse``
mirror                    ``twosided`` ``conductor`` (``material = "none"``)
dielectric                ``dielectric`` with ``int_ior`` and ``ext_ior`` set
point / spot              ``point`` / ``spot`` (``to_world`` = look_at)
directional               ``directional`` with ``direction``
sphere / rectangle        ``sphere`` / ``rectangle`` with ``to_world``
triangle                  a one-face mesh (``obj`` file in XML)
emitter                   ``area`` with ``radiance``
integrator                ``whitted`` (reference/integrators.py)
========================  ===================================================
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from tracer import transform as tf
from tracer.scene import (
    Dielectric,
    Diffuse,
    DirectionalLight,
    Mirror,
    PointLight,
    Rectangle,
    Scene,
    Sphere,
    SpotLight,
    Triangle,
)

# Plugin description as a plain tree: {"type": ..., key: value | nested dict}.
# Values are tagged tuples so that one tree serves both load_dict and XML:
#   ("rgb", (r, g, b)), ("point", (x, y, z)), ("vector", ...), ("matrix", 4x4),
#   ("float", x), ("integer", n), ("boolean", b), ("string", s).


def _rgb(c) -> dict:
    return {"type": "rgb", "value": ("rgb", tuple(float(x) for x in c))}


def _matrix(m) -> tuple:
    return ("matrix", tuple(tuple(float(x) for x in row) for row in np.asarray(m)))


def bsdf_tree(material) -> dict:
    if material is None:  # a pure emitter reflects nothing
        return {"type": "twosided", "material": {"type": "diffuse", "reflectance": _rgb((0, 0, 0))}}
    if isinstance(material, Diffuse):
        return {"type": "twosided",
                "material": {"type": "diffuse", "reflectance": _rgb(material.reflectance)}}
    if isinstance(material, Mirror):
        return {"type": "twosided",
                "material": {"type": "conductor", "material": ("string", "none"),
                             "specular_reflectance": _rgb(material.reflectance)}}
    if isinstance(material, Dielectric):
        return {"type": "dielectric", "int_ior": ("float", material.ior),
                "ext_ior": ("float", material.ext_ior)}
    raise TypeError(f"no Mitsuba conversion for {type(material).__name__}")


def sensor_tree(scene: Scene, jitter: bool = False) -> dict:
    """Sensor, film and sampler; ``jitter`` places samples at random inside their strata."""
    cam, film = scene.camera, scene.film
    look = tf.look_at(cam.origin, cam.target, cam.up)
    sensor = {"near_clip": ("float", cam.near_clip), "far_clip": ("float", cam.far_clip)}
    if cam.type == "perspective":
        sensor.update(type="perspective", fov=("float", cam.fov), fov_axis=("string", "x"),
                      to_world=_matrix(look))
    else:
        sensor.update(type="orthographic",
                      to_world=_matrix(look @ tf.scale([cam.width / 2, cam.width / 2, 1])))
    sensor["film"] = {"type": "hdrfilm", "width": ("integer", film.width),
                      "height": ("integer", film.height), "rfilter": {"type": "box"},
                      "pixel_format": ("string", "rgb"),
                      "component_format": ("string", "float32"),
                      "sample_border": ("boolean", False)}
    sensor["sampler"] = {"type": "stratified", "sample_count": ("integer", film.strata ** 2),
                         "jitter": ("boolean", jitter)}
    return sensor


def _any_up(axis) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64)
    up = np.array([0.0, 1.0, 0.0]) if abs(a[1]) < 0.9 * np.linalg.norm(a) else np.array([1.0, 0, 0])
    return up


def emitter_tree(light) -> dict:
    if isinstance(light, PointLight):
        return {"type": "point", "position": ("point", light.position),
                "intensity": _rgb(light.intensity)}
    if isinstance(light, DirectionalLight):
        return {"type": "directional", "direction": ("vector", light.direction),
                "irradiance": _rgb(light.irradiance)}
    if isinstance(light, SpotLight):
        return {"type": "spot",
                "to_world": _matrix(tf.look_at(light.position, light.target,
                                               _any_up(light.axis))),
                "intensity": _rgb(light.intensity),
                "cutoff_angle": ("float", light.cutoff_angle),
                "beam_width": ("float", light.beam_width)}
    raise TypeError(f"no Mitsuba conversion for {type(light).__name__}")


def shape_tree(scene: Scene, shape, index: int) -> dict:
    """Plugin tree of a shape; a triangle is ``{"type": "mesh", "vertices": 3x3}``."""
    if isinstance(shape, Sphere):
        t = {"type": "sphere", "center": ("point", shape.center),
             "radius": ("float", shape.radius)}
    elif isinstance(shape, Rectangle):
        t = {"type": "rectangle", "to_world": _matrix(shape.to_world)}
    elif isinstance(shape, Triangle):
        t = {"type": "mesh", "vertices": shape.vertices, "name": f"triangle_{index}"}
    else:
        raise TypeError(f"no Mitsuba conversion for {type(shape).__name__}")
    t["bsdf"] = bsdf_tree(scene.material_of(shape))
    if shape.emitter is not None:
        t["emitter"] = {"type": "area", "radiance": _rgb(shape.emitter.radiance)}
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
               jitter: bool = False) -> dict:
    tree = {"type": "scene", "sensor": sensor_tree(scene, jitter),
            "integrator": integrator_tree(scene, integrator, moments)}
    for i, light in enumerate(scene.lights):
        tree[f"light_{i}"] = emitter_tree(light)
    for i, shape in enumerate(scene.shapes):
        tree[f"shape_{i}"] = shape_tree(scene, shape, i)
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
        mesh = mi.Mesh(tree["name"], 3, 1, props)
        params = mi.traverse(mesh)
        params["vertex_positions"] = dr.ravel(mi.Point3f(
            *[mi.Float(np.asarray(tree["vertices"], dtype=np.float32)[:, k]) for k in range(3)]))
        params["faces"] = mi.UInt32([0, 1, 2])
        params.update()
        return mesh
    out = {}
    for k, v in tree.items():
        if isinstance(v, dict):
            out[k] = to_dict(v, mi)
        elif isinstance(v, tuple) and len(v) == 2 and isinstance(v[0], str):
            kind, val = v
            if kind == "matrix":
                out[k] = mi.ScalarTransform4f(np.asarray(val, dtype=np.float64).tolist())
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
         jitter: bool = False):
    """The scene as a Mitsuba ``Scene`` object (the variant must already be set)."""
    return mi.load_dict(to_dict(scene_tree(scene, integrator, moments, jitter), mi))


# ------------------------------------------------------------------ XML


def _fmt(x: float) -> str:
    return f"{float(x):.9g}"


_CHILD_TAGS = {"film": "film", "sampler": "sampler", "rfilter": "rfilter", "bsdf": "bsdf",
               "material": "bsdf", "emitter": "emitter"}


def _xml(tree: dict, tag: str, indent: int, meshes: list, obj_id: str | None = None) -> list[str]:
    pad = "    " * indent
    id_attr = f" id={quoteattr(obj_id)}" if obj_id else ""
    if tree["type"] == "mesh":
        meshes.append(tree)
        lines = [f'{pad}<shape type="obj"{id_attr}>',
                 f'{pad}    <string name="filename" value="meshes/{tree["name"]}.obj"/>',
                 f'{pad}    <boolean name="face_normals" value="true"/>']
        lines += _xml(tree["bsdf"], "bsdf", indent + 1, meshes)
        if "emitter" in tree:
            lines += _xml(tree["emitter"], "emitter", indent + 1, meshes)
        return lines + [f"{pad}</shape>"]
    lines = [f'{pad}<{tag} type="{tree["type"]}"{id_attr}>']
    for k, v in tree.items():
        if k == "type":
            continue
        if isinstance(v, dict) and v.get("type") == "rgb":
            lines.append(f'{pad}    <rgb name="{k}" value="'
                         f'{", ".join(_fmt(x) for x in v["value"][1])}"/>')
            continue
        if isinstance(v, dict):
            lines += _xml(v, _CHILD_TAGS[k], indent + 1, meshes)
            continue
        kind, val = v
        if kind == "matrix":
            flat = " ".join(_fmt(x) for row in val for x in row)
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


def write_xml(scene: Scene, path: str | Path, integrator: str = "whitted") -> list[Path]:
    """Write the scene as Mitsuba 3 XML (plus ``meshes/*.obj`` for triangles); return the files."""
    path = Path(path)
    tree = scene_tree(scene, integrator)
    meshes: list[dict] = []
    body = []
    for key, value in tree.items():
        if key == "type":
            continue
        tag = {"sensor": "sensor", "integrator": "integrator"}.get(key)
        if tag is None:
            tag = "emitter" if key.startswith("light_") else "shape"
        body += _xml(value, tag, 1, meshes, key if tag in ("shape", "emitter") else None)
    note = ("Rendered by Mitsuba 3 after `import reference` (which registers the `whitted` "
            "integrator), e.g. python -c \"import reference, mitsuba as mi; ...\"; or export with "
            "--integrator direct for a stock integrator.") if integrator == "whitted" else ""
    header = [
        '<?xml version="1.0" encoding="utf-8"?>',
        f"<!-- Exported by whitted from {scene.path}. {note} -->",
        '<scene version="3.0.0">',
    ]
    files = []
    if meshes:
        (path.parent / "meshes").mkdir(parents=True, exist_ok=True)
    for m in meshes:
        obj = path.parent / "meshes" / f"{m['name']}.obj"
        v = np.asarray(m["vertices"], dtype=np.float32)
        obj.write_text("".join(f"v {_fmt(a)} {_fmt(b)} {_fmt(c)}\n" for a, b, c in v) + "f 1 2 3\n")
        files.append(obj)
    path.write_text("\n".join(header + body + ["</scene>", ""]))
    return [path] + files
