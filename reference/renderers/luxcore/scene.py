"""Convert the scene model into LuxCore's scene description (LuxCoreRender 2.11, ``pyluxcore``).

LuxCore is a path tracer; what maps exactly onto a Whitted scene is below,
each with its formula. Anything else is refused in one line before LuxCore
starts (:class:`~tracer.errors.UserError`): kinds without a ``luxcore()``
conversion say "<kind>: no LuxCore equivalent".

=======================  ====================================================
scene                    LuxCore
=======================  ====================================================
perspective camera       ``perspective``, ``lookat``; ``fieldofview`` applies to
                         the longer image side, so for H > W it is
                         2 atan(tan(fov / 2) H / W); ``screenwindow`` set so
                         that film row y is image row y (see below)
orthographic camera      ``orthographic``, ``screenwindow`` = the view's half
                         width w / 2 by w H / (2 W) in world units
film                     filter ``NONE`` (raw pixel means), ``RGB`` output
                         (radiance, no tone mapping), ``imagepipeline`` NOP
                         (pixel positions below)
diffuse                  ``matte`` (kd / pi), lit from both sides
mirror                   ``mirror`` (kr)
dielectric               ``glass``, kr = kt = 1, ``interiorior`` / ``exteriorior``
point                    ``point``, gain 4 pi x colour I (intensity = gain x
                         colour / (4 pi) without power and efficiency)
spot                     ``spot``: same intensity; its falloff ring differs
                         (reference/emitters/spot.py)
directional              ``sharpdistant``, gain x colour = irradiance
emitter (area light)     the shape's mesh with a material emitting
                         ``emission`` = L from its front side
rectangle, triangle,     triangle meshes, exact
polygon, mesh
sphere, disk, cylinder,  tessellated meshes whose chords stay within
paraboloid               ``TESSELLATION`` x the shape's size (1e-4: positions
                         off by at most that, shading by ~(pi / N)^2 / 8 for N
                         segments through interpolated exact normals)
instance                 its group's meshes, transformed
max_depth M              ``path.pathdepth``: total = M - 1 + 1, diffuse 2,
                         glossy 2, specular M - 1 (see :func:`config_props`)
=======================  ====================================================

Pixel positions. Every LuxCore sampler jitters inside the pixel, so
LuxCore's pixel is the mean of radiance over the pixel's square (filter
``NONE``), while the tracer and Mitsuba put their samples at the centres of
an s x s grid of strata, a midpoint rule for the same mean. The comparison
(:mod:`reference.renderers.luxcore.vote`) renders those two sides with many strata
so that both estimate the same integral. ``subsamples`` k renders the film k
times larger on each side, k x k film pixels per image pixel
(:mod:`reference.renderers.luxcore.render` averages them).

The perspective and orthographic cameras map film row y to raster row
filmHeight - y - 1, one row off after the image is flipped: the screen
window is moved by one film row (towards -y) to put it back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from whitted.reference.emitters import area as area_conv
from whitted.reference.emitters import convert as convert_light
from whitted.reference.materials import convert as convert_material
from whitted.reference.shapes import luxcore_mesh

# Shapes convert in their own modules (reference/shapes/), through its registry; the
# tessellations that used to be here are re-exported ("X as X").
from whitted.reference.shapes.cylinder import cylinder_mesh as cylinder_mesh
from whitted.reference.shapes.disk import disk_mesh as disk_mesh
from whitted.reference.shapes.meshes import TESSELLATION as TESSELLATION
from whitted.reference.shapes.rectangle import rectangle_mesh as rectangle_mesh
from whitted.reference.shapes.sphere import sphere_mesh as sphere_mesh
from whitted.tracer import transform as tf
from whitted.tracer.errors import UserError
from whitted.tracer.scene import Instance, Scene


@dataclass
class Description:
    """A scene for LuxCore: property lines, meshes, and where the image's pixels lie."""
    props: dict = field(default_factory=dict)       # key -> value (scene.* keys)
    meshes: dict = field(default_factory=dict)      # name -> (vertices, faces, normals|None)
    width: int = 0                                  # the scene's image
    height: int = 0
    subsamples: int = 1                             # film pixels per image pixel side
    max_depth: int = 2

    @property
    def film_size(self) -> tuple[int, int]:
        return self.width * self.subsamples, self.height * self.subsamples

    def text(self) -> str:
        return props_text(self.props)


def _value(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace('"', "") + '"'
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, (tuple, list, np.ndarray)):
        return " ".join(_value(x) for x in v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


def props_text(props: dict) -> str:
    """LuxCore's property syntax: one ``key = value ...`` line each."""
    return "".join(f"{k} = {_value(v)}\n" for k, v in props.items())


# ------------------------------------------------------------------ shapes


def shape_mesh(shape):
    """(vertices, faces, normals or None) of a shape in world space: its kind's
    ``luxcore()`` (reference/shapes/)."""
    return luxcore_mesh(shape)


def _transformed(mesh, m: np.ndarray):
    v, f, n = mesh
    v2 = tf.apply_point(m, v)
    if n is not None:
        n = tf.apply_normal(m, n)
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
    if np.linalg.det(m[:3, :3]) < 0:
        f = f[:, [0, 2, 1]]
    return v2, f, n


# ------------------------------------------------------------------ camera, config


def camera_props(scene: Scene, film: tuple[int, int]) -> dict:
    cam = scene.camera
    if any(cam.pixel_offset):
        raise UserError("camera pixel_offset: no LuxCore equivalent")
    fw, fh = film
    p = {"scene.camera.lookat.orig": tuple(cam.origin),
         "scene.camera.lookat.target": tuple(cam.target),
         "scene.camera.up": tuple(cam.up),
         "scene.camera.cliphither": cam.near_clip, "scene.camera.clipyon": cam.far_clip}
    # Screen window in LuxCore's screen units: the longer side spans [-1, 1] (perspective)
    # or the view's half width is w / 2 world units (orthographic).
    if cam.type == "perspective":
        p["scene.camera.type"] = "perspective"
        t = math.tan(math.radians(cam.fov) / 2)
        if fw >= fh:
            fov = cam.fov
            half_x, half_y = 1.0, fh / fw
        else:
            fov = math.degrees(2 * math.atan(t * fh / fw))
            half_x, half_y = fw / fh, 1.0
        p["scene.camera.fieldofview"] = fov
    else:
        p["scene.camera.type"] = "orthographic"
        half_x, half_y = cam.width / 2, cam.width / 2 * fh / fw
    # One film row: the camera maps film row y to raster row fh - y - 1 (module docstring);
    # measured on sphere_point, the window moved by -1, 0, +1 rows: 0.23 %, 54 %, 55 % of
    # the pixel-channels beyond |z| = 4.5.
    row = 2 * half_y / fh
    p["scene.camera.screenwindow"] = (-half_x, half_x, -half_y - row, half_y - row)
    return p


def config_props(desc: Description, seed: int = 0, spp_per_pass: int = 1,
                 threads: int = 0) -> dict:
    """Render settings: PATHCPU, Whitted-like depths, raw RGB radiance.

    Depths: a Whitted path of ``max_depth`` M has up to M - 2 specular bounces
    before the diffuse vertex where the lights are sampled. LuxCore skips light
    sampling at the last vertex a depth allows, so diffuse = 2 (the second
    diffuse vertex, reached only by a diffuse bounce, never adds light from a
    point light; with area lights it is the BSDF-sampled half of direct
    lighting, MIS-weighted) and specular = M - 1, total = M. Glossy 2 (no
    glossy materials convert).
    """
    w, h = desc.film_size
    m = desc.max_depth
    p = {"renderengine.type": "PATHCPU", "sampler.type": "RANDOM",
         "renderengine.seed": int(seed) % 2147483647 + 1,
         "batch.haltspp": int(spp_per_pass), "batch.halttime": 0,
         "film.width": w, "film.height": h, "film.filter.type": "NONE",
         "film.outputs.0.type": "RGB", "film.outputs.0.filename": "rgb.exr",
         "film.imagepipelines.0.0.type": "NOP",
         "path.pathdepth.total": m, "path.pathdepth.diffuse": 2,
         "path.pathdepth.glossy": 2, "path.pathdepth.specular": max(m - 1, 1),
         "path.clamping.variance.maxvalue": 0.0, "path.russianroulette.depth": 1000,
         "lightstrategy.type": "UNIFORM"}
    if threads:
        p["native.threads.count"] = int(threads)
    return p


# ------------------------------------------------------------------ scene


def describe(scene: Scene, subsamples: int = 1) -> Description:
    """The scene in LuxCore's terms; one-line UserError for what does not map."""
    film = scene.film
    desc = Description(width=film.width, height=film.height, subsamples=subsamples,
                       max_depth=film.max_depth)
    if scene.tracer_only:
        from whitted.reference.verdicts.compare import comparable

        scene = comparable(scene)
    p = desc.props
    p.update(camera_props(scene, desc.film_size))
    for i, light in enumerate(scene.lights):
        for k, v in convert_light(light, "luxcore").items():
            p[f"scene.lights.light_{i}.{k}"] = v
    p["scene.materials.black.type"] = "matte"
    p["scene.materials.black.kd"] = (0.0, 0.0, 0.0)
    for name, mat in scene.materials.items():
        if mat in scene.used_materials():
            for k, v in convert_material(mat, "luxcore").items():
                p[f"scene.materials.m_{_safe(name)}.{k}"] = v
    count = 0
    for shape in scene.shapes:
        members = [(shape, np.eye(4))]
        if isinstance(shape, Instance):
            members = [(s, np.asarray(shape.to_world, dtype=np.float64))
                       for s in scene.groups[shape.group]]
        for s, m in members:
            material = scene.material_of(s)
            if material is not None and material.light_of(s) is not None:
                raise UserError(f"{type(material).__name__.lower()} light spheres: no LuxCore "
                                "equivalent")
            mesh = shape_mesh(s)
            if not np.allclose(m, np.eye(4)):
                mesh = _transformed(mesh, m)
            name = f"shape_{count}"
            count += 1
            desc.meshes[name] = mesh
            emitter = s.emitter if s.emitter is not None else getattr(shape, "emitter", None)
            mat_name = "black" if material is None else f"m_{_safe(material.name)}"
            if emitter is not None:
                # an emitting mesh needs a material of its own that carries the emission
                own = f"emit_{name}"
                for k, v in list(p.items()):
                    if k.startswith(f"scene.materials.{mat_name}."):
                        p[k.replace(f".{mat_name}.", f".{own}.", 1)] = v
                for k, v in area_conv.luxcore(emitter).items():
                    p[f"scene.materials.{own}.{k}"] = v
                mat_name = own
            p[f"scene.objects.{name}.shape"] = name
            p[f"scene.objects.{name}.material"] = mat_name
    if not scene.lights and not any(k.endswith(".emission") for k in p):
        raise UserError("a scene without lights LuxCore can convert: nothing to render")
    return desc


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in name)
