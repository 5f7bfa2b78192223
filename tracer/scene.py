"""The scene model: TOML files validated into immutable dataclasses.

The format and its radiometric conventions are the public contract written in
``README.md`` (section "Scene format"), which follows Mitsuba 3's conventions
so that the same file means the same picture to the tracer and to the
reference. Any input the contract calls bad is refused by :func:`load_scene`
with a :class:`~tracer.errors.SceneError` naming the file, the key and what was
expected, before anything renders.

Each material, light and shape kind is parsed by its own module
(``tracer/materials/``, ``tracer/emitters/``, ``tracer/shapes/``), found through
their registries by the ``type`` key; this module reads the rest (film, camera,
groups, ``[compare]``, and what every shape has: ``type``, ``material``,
``emitter``).

Two lines load and render a scene::

    >>> from tracer import load_scene, render            # doctest: +SKIP
    >>> image = render(load_scene("scenes/sphere_point.toml"))  # doctest: +SKIP
"""

from __future__ import annotations

import functools
import math
import operator
import os
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from whitted.scenes import resolve as resolve_scene

# The kinds that used to be defined here are re-exported ("X as X"), so that
# ``from tracer.scene import Diffuse`` keeps working.
from whitted.tracer import emitters as _emitters
from whitted.tracer import fov as _fov
from whitted.tracer import materials as _materials
from whitted.tracer import settings_schema
from whitted.tracer import shapes as _shapes
from whitted.tracer import transform as tf
from whitted.tracer.emitters import area as _area
from whitted.tracer.emitters.area import AreaEmitter as AreaEmitter
from whitted.tracer.emitters.base import LightModel
from whitted.tracer.emitters.directional import DirectionalLight as DirectionalLight
from whitted.tracer.emitters.point import PointLight as PointLight
from whitted.tracer.emitters.spot import SpotLight as SpotLight
from whitted.tracer.errors import SceneError, UserError
from whitted.tracer.materials.base import MaterialModel
from whitted.tracer.materials.dielectric import Dielectric as Dielectric
from whitted.tracer.materials.diffuse import Diffuse as Diffuse
from whitted.tracer.materials.mirror import Mirror as Mirror
from whitted.tracer.materials.phong import Phong as Phong
from whitted.tracer.materials.textures import Checkerboard as Checkerboard
from whitted.tracer.materials.textures import Texture as Texture
from whitted.tracer.materials.textures import parse_texture, scalar_texture
from whitted.tracer.materials.textures import texture_max as texture_max
from whitted.tracer.settings import (
    Matrix,
    Table,
    Vec3,
    as_tuple,
    check_distinct,
    norm,
    read_steps,
    show,
)
from whitted.tracer.shapes.base import Context as _ShapeContext
from whitted.tracer.shapes.cube import Cube as Cube
from whitted.tracer.shapes.cube import cube_mesh as cube_mesh
from whitted.tracer.shapes.cylinder import Cylinder as Cylinder
from whitted.tracer.shapes.cylinder import _mitsuba_frame as _mitsuba_frame
from whitted.tracer.shapes.disk import Disk as Disk
from whitted.tracer.shapes.instance import Instance as Instance
from whitted.tracer.shapes.mesh import Mesh as Mesh
from whitted.tracer.shapes.paraboloid import Paraboloid as Paraboloid
from whitted.tracer.shapes.polygon import Polygon as Polygon
from whitted.tracer.shapes.rectangle import Rectangle as Rectangle
from whitted.tracer.shapes.sphere import Sphere as Sphere
from whitted.tracer.shapes.triangle import Triangle as Triangle

# ---------------------------------------------------------------------------
# The model
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Film:
    width: int = 320
    height: int = 240
    spp: int = 16
    max_depth: int = 6
    #: pixel filter: "box" (each sample counts for its own pixel) or "gaussian" (Mitsuba's
    #: ``gaussian`` rfilter: weights exp(-d^2 / 2 stddev^2) - exp(-r^2 / 2 stddev^2) within
    #: the radius r = 4 stddev, normalised over the weights a pixel receives) or "tent"
    #: (Mitsuba's ``tent``: weights 1 - |d| / radius per axis, normalised the same way)
    filter: str = "box"
    stddev: float = 0.5
    radius: float = 1.0   # the tent's
    #: samples at random inside their strata (Mitsuba's ``stratified`` with ``jitter``)
    #: instead of at the strata centres
    jitter: bool = False

    @property
    def filter_radius(self) -> float:
        """Radius of the pixel filter in pixels: 0.5 for the box, 4 stddev for the gaussian,
        ``radius`` for the tent."""
        return {"box": 0.5, "tent": self.radius}.get(self.filter, 4 * self.stddev)

    @property
    def depth(self) -> int:
        """Heckbert's DEPTH (trace calls): max_depth - 1 (docs/scene-format.md)."""
        return self.max_depth - 1

    @property
    def strata(self) -> int:
        """Strata per pixel side: spp is rounded up to a square, as Mitsuba's sampler does."""
        n = math.isqrt(self.spp)
        return n if n * n == self.spp else n + 1


@dataclass(frozen=True)
class Camera:
    type: str  # "perspective" | "orthographic"
    origin: Vec3
    target: Vec3
    up: Vec3 = (0.0, 1.0, 0.0)
    fov: float = 45.0           # perspective: horizontal field of view, degrees
    width: float = 2.0          # orthographic: world-space width of the view
    near_clip: float = 1e-2     # Mitsuba's defaults, so both sides clip alike
    far_clip: float = 1e4
    #: where each pixel's grid of samples sits, in pixels from its usual place: (-0.5, -0.5)
    #: puts a single sample on the pixel's upper-left corner, as Heckbert's minray does
    pixel_offset: tuple[float, float] = (0.0, 0.0)
    #: which extent of the film ``fov`` spans (Mitsuba's ``fov_axis``): "x" (horizontal,
    #: the default), "y", "diagonal", "smaller" or "larger"
    fov_axis: str = "x"
    #: Mitsuba's ``principal_point_offset_x/y``: the optical axis moved by these fractions
    #: of the film's width and height (perspective)
    principal_point: tuple[float, float] = (0.0, 0.0)
    #: the camera-to-world matrix when ``to_world`` was given instead of origin/target/up
    #: (origin, target and up are then read from it)
    matrix: Matrix | None = None
    #: that ``to_world``'s steps as the file gives them (:data:`tracer.settings.Step`),
    #: from which the Mitsuba side builds its own (None: origin/target/up, or made in code)
    steps: tuple | None = field(default=None, compare=False, repr=False)

    def to_world(self) -> np.ndarray:
        if self.matrix is not None:
            return np.asarray(self.matrix, dtype=np.float64)
        return tf.look_at(self.origin, self.target, self.up)

    def fov_x(self, aspect: float) -> float:
        """The horizontal field of view in degrees for a film of this aspect (width / height):
        ``fov`` along ``fov_axis``, converted as Mitsuba's ``parse_fov`` does
        (:func:`tracer.fov.horizontal`)."""
        return _fov.horizontal(self.fov, self.fov_axis, aspect)


# Materials and lights: one module per kind (tracer/materials/, tracer/emitters/), found
# through their registries; the kinds that were defined here are re-exported.
Material = MaterialModel
Light = LightModel


# Shapes: one module per kind (tracer/shapes/), found through its registry; the kinds
# that were defined here are re-exported above. ``Shape``: the union of the registered
# kinds' models (a kind whose model derives from another's, a cube from a mesh, is in it
# through that one).
Shape = functools.reduce(operator.or_, [
    m.MODEL for m in _shapes.REGISTRY.values()
    if not any(o.MODEL is not m.MODEL and issubclass(m.MODEL, o.MODEL)
               for o in _shapes.REGISTRY.values())])


@dataclass(frozen=True)
class Scene:
    path: str
    film: Film
    camera: Camera
    materials: dict[str, Material]
    lights: tuple[Light, ...]
    shapes: tuple[Shape, ...]
    description: str = ""
    #: parts of the scene that only the tracer models (``[compare] tracer_only``)
    tracer_only: tuple[str, ...] = ()
    #: named groups of shapes for ``instance`` shapes (object space)
    groups: dict[str, tuple] = field(default_factory=dict)
    #: imported from Mitsuba XML with parts outside the Whitted subset replaced by their
    #: nearest equivalents (``--approximate``)
    approximate: bool = False

    @property
    def name(self) -> str:
        return Path(self.path).stem

    def with_overrides(self, spp: int | None = None, max_depth: int | None = None,
                       size: tuple[int, int] | None = None) -> Scene:
        """The same scene with film settings replaced (the command line's options)."""
        film = self.film
        if spp is not None:
            film = replace(film, spp=spp)
        if max_depth is not None:
            film = replace(film, max_depth=max_depth)
        if size is not None:
            film = replace(film, width=size[0], height=size[1])
        return replace(self, film=film)

    def material_of(self, shape: Shape) -> Material | None:
        return None if shape.material is None else self.materials[shape.material]

    def all_shapes(self) -> list:
        """Every shape: the top-level ones and those of the groups that instances use."""
        out = list(self.shapes)
        for s in self.shapes:
            if isinstance(s, Instance):
                out += list(self.groups[s.group])
        return out

    def used_materials(self) -> list:
        names = {s.material for s in self.all_shapes() if s.material is not None}
        return [m for k, m in self.materials.items() if k in names]

    def has_specular(self) -> bool:
        """Some material in use has delta lobes (mirror reflection, refraction)."""
        return any(_materials.module_of(m).BSDF.lobes for m in self.used_materials())

    def shape_lights(self) -> tuple:
        """Lights that materials make of the shapes carrying them (Heckbert's light spheres).

        See :meth:`tracer.materials.base.MaterialModel.light_of`; the parser has
        already refused shapes a material cannot make a light of.
        """
        out = []
        for s in self.shapes:
            m = self.material_of(s)
            light = None if m is None else m.light_of(s)
            if light is not None:
                out.append(light)
        return tuple(out)

    def primitive_count(self) -> int:
        """Primitives the tracer builds tables for: triangles of meshes, shapes, instances'
        copies (:func:`tracer.limits.check_render` bounds it)."""
        def count(shapes) -> int:
            return sum(s.primitive_count() for s in shapes if not isinstance(s, Instance))

        per_group = {g: count(members) for g, members in self.groups.items()}
        return count(self.shapes) + sum(per_group[s.group] for s in self.shapes
                                        if isinstance(s, Instance))

    def has_area_lights(self) -> bool:
        return any(s.emitter is not None for s in self.shapes)

    def samples_lights(self) -> bool:
        """The tracer samples some light at random (area emitters, or a light kind that is
        not delta): its image is then an estimate with variance."""
        return self.has_area_lights() or any(
            not _emitters.LIGHTS[_emitters.type_of(light)].Emitter.delta for light in self.lights)

    def tracer_only_used(self) -> frozenset[str]:
        """The tracer-only parts (see ``TRACER_ONLY``) that materials in use have."""
        return frozenset().union(*(m.tracer_only_used() for m in self.used_materials()))

    def uses_schlick(self) -> bool:
        return "schlick" in self.tracer_only_used()

    def uses_ambient(self) -> bool:
        return "ambient" in self.tracer_only_used()

    def uses_textures(self) -> bool:
        return any(isinstance(t, Checkerboard) for m in self.used_materials()
                   for t in (*m.textures(), m.mask_opacity))

    def has_tessellated(self) -> bool:
        """Shapes Mitsuba lacks, which the conversion tessellates (paraboloids)."""
        return any(s.tessellated for s in self.all_shapes())


# ---------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------


#: Shape ``type``s: the registry of tracer/shapes/.
SHAPE_TYPES = tuple(_shapes.REGISTRY)
#: Material ``type``s: the registry of tracer/materials/.
MATERIAL_TYPES = tuple(_materials.REGISTRY)
#: Shapes that may carry an area emitter (their kind's module has a ``Sampler``).
EMITTER_SHAPES = _shapes.emitting()
#: ``[[lights]]`` ``type``s: the registry of tracer/emitters/.
LIGHT_TYPES = tuple(_emitters.LIGHTS)
CAMERA_TYPES = ("perspective", "orthographic")
#: ``fov_axis`` values (Mitsuba's): which extent of the film ``fov`` spans.
FOV_AXES = _fov.FOV_AXES
#: ``[film] filter`` values: Mitsuba's ``box``, ``gaussian`` and ``tent`` reconstruction filters.
FILTERS = ("box", "gaussian", "tent")
TOP_LEVEL = ("description", "film", "camera", "materials", "lights", "shapes", "compare",
             "groups")
#: Features a scene may declare tracer-only: Mitsuba has no counterpart (each kind
#: names its own, e.g. Schlick's approximation of the dielectric, the Phong ambient term).
TRACER_ONLY = _materials.tracer_only_parts()


#: Deepest nesting of tables and arrays a scene may use (the format needs five).
MAX_NESTING = 16


def _read_scene_bytes(path: str) -> bytes:
    """The file's bytes: a regular file no larger than the limit (no FIFO, no device)."""
    from whitted.tracer.files import NotRegularFile, read_regular, special_kind
    from whitted.tracer.limits import MAX_SCENE_BYTES, refuse

    limit = MAX_SCENE_BYTES.value()
    kind = special_kind(os.stat(path))
    if kind == "a folder":
        raise IsADirectoryError
    if kind is not None:
        raise SceneError(path, "", f"is {kind}, expected a regular file (a .toml scene)")
    try:
        data = read_regular(path, limit)  # a file may grow, or report a wrong size
    except NotRegularFile as e:
        raise SceneError(path, "", f"is {e.kind}, expected a regular file (a .toml scene)") \
            from None
    if len(data) > limit:
        try:
            refuse(MAX_SCENE_BYTES, f"the scene file is larger than {limit:,} bytes",
                   f"{limit:,}")
        except UserError as e:
            raise SceneError(path, "", str(e)) from None
    return data


def _check_nesting(path: str, data: Any) -> None:
    """Refuse documents nested deeper than MAX_NESTING (walked without recursion)."""
    stack = [(data, 0)]
    while stack:
        v, depth = stack.pop()
        if depth > MAX_NESTING:
            raise SceneError(path, "", f"tables and arrays nested more than {MAX_NESTING} "
                                       "levels deep; a scene needs far fewer")
        if isinstance(v, dict):
            stack.extend((x, depth + 1) for x in v.values())
        elif isinstance(v, list):
            stack.extend((x, depth + 1) for x in v)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene, given by its path or a built-in scene's name
    (``"glass_sphere"``, :func:`whitted.scenes.resolve`); raise :class:`SceneError` on bad
    input."""
    path = str(resolve_scene(path))
    try:
        text = _read_scene_bytes(path).decode("utf-8")
    except FileNotFoundError:
        raise SceneError(path, "", "no such scene file") from None
    except IsADirectoryError:
        raise SceneError(path, "", "is a directory, expected a .toml scene file") from None
    except UnicodeDecodeError as e:
        raise SceneError(path, "", f"not UTF-8 text ({e.reason})") from None
    except OSError as e:
        raise SceneError(path, "", f"cannot read: {e.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(path, "", f"not valid TOML: {e}") from None
    except RecursionError:
        raise SceneError(path, "", f"tables and arrays nested too deeply to read (more than "
                                   f"{MAX_NESTING} levels are refused anyway)") from None
    return parse_scene(data, path)


def load_any(path: str | Path, approximate: bool = False, warn=None) -> Scene:
    """A TOML scene, or a Mitsuba 3 XML scene (``.xml``) read without Mitsuba.

    XML is mapped onto the scene format by :func:`tracer.mitsuba_xml.read_xml`;
    ``approximate`` replaces what lies outside the Whitted subset by its nearest
    equivalent, calling ``warn(line)`` once per kind of substitution.
    """
    if str(path).lower().endswith(".xml"):
        from whitted.tracer.mitsuba_xml import read_xml

        imp = read_xml(path, approximate)
        for line in imp.warnings + imp.cautions:
            if warn is not None:
                warn(line)
        return replace(parse_scene(imp.data, str(path)), approximate=imp.approximate)
    return load_scene(path)


def parse_scene(data: dict, path: str = "<scene>") -> Scene:
    """Validate an already parsed TOML document (see :func:`load_scene`)."""
    _check_nesting(path, data)
    return _parse_top(Table(path, "", data, known=known_keys))


def known_keys(pattern: str, kind: str | None = None) -> frozenset[str]:
    """The keys a table at ``pattern`` (e.g. ``shapes[0]``, ``materials.NAME``) of ``type``
    ``kind`` may have (any kind's when None or unknown), recorded from the parsers
    (:mod:`tracer.settings_schema`); for the loader's messages about a missing key."""
    return settings_schema.known_keys(_parse_top, pattern, kind)


def _parse_top(top: Table) -> Scene:
    """The whole document (also run by :mod:`tracer.schema` to derive the format's schema)."""
    description = top.string("description", "")
    film = top.table("film", {}, parse=_parse_film)
    camera = top.table("camera", parse=_parse_camera)
    materials: dict[str, Material] = top.table("materials", {}, parse=_parse_materials)
    lights = tuple(top.tables("lights", _parse_light))
    base = Path(top.path).parent
    groups: dict[str, tuple] = top.table(
        "groups", {}, parse=lambda g: _parse_groups(g, materials, base))
    shapes = tuple(top.tables("shapes", lambda t: _parse_shape(t, materials, groups, base)))
    tracer_only = top.table("compare", {}, parse=_parse_compare)
    top.finish()
    return Scene(path=top.path, film=film, camera=camera, materials=materials, lights=lights,
                 shapes=shapes, description=description, tracer_only=tuple(tracer_only),
                 groups=groups)


def _parse_materials(t: Table) -> dict[str, Material]:
    return t.each(_parse_material)


def _parse_groups(t: Table, materials: dict[str, Material], base: Path) -> dict[str, tuple]:
    def group(g: Table, name: str) -> tuple:
        members = g.tables("shapes", lambda m: _parse_shape(m, materials, {}, base,
                                                            in_group=True))
        if not members:
            g.fail("shapes", "expected at least one [[groups.NAME.shapes]] table")
        g.finish()
        return tuple(members)
    return t.each(group)


def _parse_compare(t: Table) -> list[str]:
    what = "a list of: " + ", ".join(f'"{x}"' for x in TRACER_ONLY)
    tracer_only = t.raw("tracer_only", [], what,
                        {"type": "array", "items": {"enum": list(TRACER_ONLY)}})
    if not isinstance(tracer_only, list):
        t.fail("tracer_only", f"expected {what}, got {show(tracer_only)}")
    for i, x in enumerate(tracer_only):
        if x not in TRACER_ONLY:
            known = ", ".join(f'"{part}"' for part in TRACER_ONLY)
            t.fail(f"tracer_only[{i}]", f"expected one of: {known}, got {show(x)}")
    t.finish()
    return tracer_only


def _parse_film(t: Table) -> Film:
    d = Film()
    if t.has("depth") and t.has("max_depth"):
        t.fail("depth", "give either depth (Heckbert's DEPTH) or max_depth (= depth + 1), "
                        "not both")
    if t.has("depth"):  # Heckbert's DEPTH: trace calls (docs/scene-format.md)
        max_depth = t.integer("depth", lo=1) + 1
    else:
        max_depth = t.integer("max_depth", d.max_depth, lo=1)
    flt = t.string("filter", d.filter, FILTERS)
    stddev = d.stddev
    if flt == "gaussian":
        stddev = t.number("stddev", d.stddev, lo=0, lo_open=True, hi=4)
    elif t.has("stddev"):
        t.fail("stddev", 'stddev is for filter = "gaussian"')
    radius = t.number("radius", d.radius, lo=0, lo_open=True, hi=16) if flt == "tent" else \
        d.radius
    if flt != "tent" and t.has("radius"):
        t.fail("radius", 'radius is for filter = "tent"')
    jitter = t.raw("jitter", d.jitter)
    if not isinstance(jitter, bool):
        t.fail("jitter", f"expected true or false, got {show(jitter)}")
    film = Film(width=t.integer("width", d.width, lo=1), height=t.integer("height", d.height, lo=1),
                spp=t.integer("spp", d.spp, lo=1), max_depth=max_depth, filter=flt,
                stddev=stddev, radius=radius, jitter=jitter)
    t.finish()
    return film


def _parse_camera(t: Table) -> Camera:
    kind = t.string("type", "perspective", CAMERA_TYPES)
    matrix = steps = None
    if t.has("to_world"):
        given = [k for k in ("origin", "target", "up") if t.has(k)]
        if given:
            t.fail(given[0], "give either to_world or origin/target/up, not both")
        m, steps = read_steps(t, "to_world")
        if kind == "perspective" and not _orthonormal(m[:3, :3]):
            t.fail("to_world", "a perspective camera's to_world may rotate, mirror and "
                               "translate, not scale or shear (its rays would not be unit)")
        matrix = as_tuple(m)
        origin = tuple(float(x) for x in m[:3, 3])
        f = m[:3, 2] / norm(m[:3, 2])
        target = tuple(float(x) for x in m[:3, 3] + f)
        up = tuple(float(x) for x in m[:3, 1] / norm(m[:3, 1]))
    else:
        if not t.has("origin"):
            t.unknown_first("origin")  # a misspelt key is the likelier fault
            t.fail("origin", "missing; expected a list of 3 numbers (or give to_world instead "
                             "of origin/target/up)")
        origin, target = t.vec3("origin"), t.vec3("target")
        up = t.vec3("up", [0.0, 1.0, 0.0], nonzero=True)
        forward = check_distinct(t, "target", origin, target, "camera.origin")
        f_unit, up_unit = forward / norm(forward), np.asarray(up) / norm(up)
        if np.linalg.norm(np.cross(f_unit, up_unit)) <= 1e-6:
            t.fail("up", "expected a direction not parallel to target - origin")
    near = t.number("near_clip", 1e-2, lo=0, lo_open=True)
    far = t.number("far_clip", 1e4, lo=near, lo_open=True)
    offset = _pixel_offset(t)
    if kind == "perspective":
        fov = t.number("fov", 45.0, lo=0, hi=180, lo_open=True, hi_open=True)
        axis = t.string("fov_axis", "x", FOV_AXES)
        ppo = (t.number("principal_point_offset_x", 0.0, lo=-1, hi=1),
               t.number("principal_point_offset_y", 0.0, lo=-1, hi=1))
        cam = Camera("perspective", origin, target, up, fov=fov, near_clip=near, far_clip=far,
                     pixel_offset=offset, fov_axis=axis, principal_point=ppo, matrix=matrix,
                     steps=steps)
        note = " (width is for orthographic cameras)" if t.has("width") else ""
    else:
        if matrix is not None:  # the view is [-1, 1]^2 in camera space, scaled by to_world
            if t.has("width"):
                t.fail("width", "give either width or a to_world that scales the view, not both")
            width = 2 * norm(np.asarray(matrix)[:3, 0])
        else:
            width = t.number("width", lo=0, lo_open=True)
        cam = Camera("orthographic", origin, target, up, width=width, near_clip=near,
                     far_clip=far, pixel_offset=offset, matrix=matrix, steps=steps)
        note = (" (fov, fov_axis and principal_point_offset_x/y are for perspective cameras)"
                if any(t.has(k) for k in ("fov", "fov_axis", "principal_point_offset_x",
                                          "principal_point_offset_y")) else "")
    t.finish(note)
    return cam


def _orthonormal(a: np.ndarray, tol: float = 1e-5) -> bool:
    """The columns are unit and at right angles (a rotation, perhaps with a mirror)."""
    return bool(np.allclose(a.T @ a, np.eye(3), atol=tol))


def _pixel_offset(t: Table) -> tuple[float, float]:
    """``pixel_offset = [dx, dy]``: the pixel grid's samples moved by (dx, dy) pixels."""
    what = "[dx, dy]: two numbers from -1 to 1 (pixels)"
    one = {"type": "number", "minimum": -1, "maximum": 1}
    v = t.raw("pixel_offset", [0.0, 0.0], what,
              {"type": "array", "items": one, "minItems": 2, "maxItems": 2})
    if (not isinstance(v, list) or len(v) != 2 or
            any(isinstance(x, bool) or not isinstance(x, (int, float)) or
                not math.isfinite(x) or abs(x) > 1 for x in v)):
        t.fail("pixel_offset", f"expected {what}, got {show(v)}")
    return (float(v[0]), float(v[1]))


#: A colour, or ``{ checkerboard = {...} }`` (tracer/materials/textures.py).
_texture = parse_texture


def _parse_material(t: Table, name: str) -> Material:
    kind = t.string("type", choices=tuple(_materials.REGISTRY))
    m = _materials.REGISTRY[kind].parse(t, name)
    opacity = 1.0
    if "opacity" not in t.used:  # every kind's opacity, unless the kind has its own
        # A number, a colour or a texture, read as Mitsuba's mask reads it: one value
        # per point (the colour's mean, a bitmap's luminance; scalar_texture).
        opacity = scalar_texture(parse_texture(t, "opacity", 1.0, hi=1))
    t.finish()
    return replace(m, mask_opacity=opacity) if opacity != 1 else m


def _parse_emitter(t: Table) -> AreaEmitter:
    emitter = _area.parse(t)
    t.finish()
    return emitter


def _parse_light(t: Table) -> Light:
    kind = t.string("type", choices=tuple(_emitters.LIGHTS))
    light = _emitters.LIGHTS[kind].parse(t)
    t.finish()
    return light


def _parse_shape(t: Table, materials: dict[str, Material], groups: dict,
                 base: Path, in_group: bool = False) -> Shape:
    kind = t.string("type", choices=tuple(_shapes.REGISTRY))
    module = _shapes.REGISTRY[kind]
    if in_group and module.MODEL.not_in_groups:
        t.fail("type", module.MODEL.not_in_groups)
    emitter = None
    if t.has("emitter"):
        emitting = _shapes.emitting()
        if kind not in emitting or in_group:
            t.fail("emitter", "area lights are supported on " + ", ".join(emitting) +
                   (" outside groups" if in_group else "") + f", not on a {kind}")
        emitter = t.table("emitter", parse=_parse_emitter)
    if not module.MODEL.takes_material:
        material = None  # an instance: its group's shapes carry the materials
    elif emitter is None or t.has("material"):
        material = t.string("material")
        if material not in materials:
            known = ", ".join(sorted(materials)) or "none"
            t.fail("material", f'unknown material "{material}" (defined: {known})')
    else:
        material = None  # a pure emitter: black, reflects nothing
    ctx = _ShapeContext(t, material, emitter, materials, groups, base, in_group)
    shape = module.parse(t, ctx)
    if material is not None:  # a material may make a light of its shape (light_of)
        try:
            light = materials[material].light_of(shape)
        except ValueError as e:
            t.fail("material", str(e))
        if light is not None and in_group:
            t.fail("material", f'material "{material}" makes a light of its shape, and '
                               "lights cannot be instanced (use it outside groups)")
    t.finish()
    return shape
