"""The scene model: TOML files validated into immutable dataclasses.

The format and its radiometric conventions are the public contract written in
``README.md`` (section "Scene format"), which follows Mitsuba 3's conventions
so that the same file means the same picture to the tracer and to the
reference. Any input the contract calls bad is refused by :func:`load_scene`
with a :class:`~tracer.errors.SceneError` naming the file, the key and what was
expected, before anything renders.

Each material and light kind is parsed by its own module (``tracer/materials/``,
``tracer/emitters/``), found through their registries by the ``type`` key;
this module reads the rest (film, camera, shapes, groups, ``[compare]``).

Two lines load and render a scene::

    >>> from tracer import load_scene, render            # doctest: +SKIP
    >>> image = render(load_scene("scenes/sphere_point.toml"))  # doctest: +SKIP
"""

from __future__ import annotations

import math
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
from whitted.tracer import materials as _materials
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

Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]
Matrix = tuple[tuple[float, ...], ...]

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
    #: the radius r = 4 stddev, normalised over the weights a pixel receives)
    filter: str = "box"
    stddev: float = 0.5
    #: samples at random inside their strata (Mitsuba's ``stratified`` with ``jitter``)
    #: instead of at the strata centres
    jitter: bool = False

    @property
    def filter_radius(self) -> float:
        """Radius of the pixel filter in pixels: 0.5 for the box, 4 stddev for the gaussian."""
        return 0.5 if self.filter == "box" else 4 * self.stddev

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

    def to_world(self) -> np.ndarray:
        if self.matrix is not None:
            return np.asarray(self.matrix, dtype=np.float64)
        return tf.look_at(self.origin, self.target, self.up)

    def fov_x(self, aspect: float) -> float:
        """The horizontal field of view in degrees for a film of this aspect (width / height).

        Mitsuba's conversion of ``fov`` along ``fov_axis`` (``parse_fov`` in its
        ``sensor.h``): the image plane at distance 1 spans 2 tan(fov_x / 2) across
        and 2 tan(fov_x / 2) / aspect down, so a vertical fov_y gives
        tan(fov_x / 2) = aspect tan(fov_y / 2), and a diagonal one
        tan(fov_x / 2) = tan(fov_d / 2) / sqrt(1 + 1 / aspect^2).
        """
        axis = self.fov_axis
        if axis == "smaller":
            axis = "y" if aspect > 1 else "x"
        elif axis == "larger":
            axis = "x" if aspect > 1 else "y"
        t = math.tan(math.radians(self.fov) / 2)
        if axis == "y":
            t *= aspect
        elif axis == "diagonal":
            t /= math.sqrt(1 + 1 / (aspect * aspect))
        return math.degrees(2 * math.atan(t))


# Materials and lights: one module per kind (tracer/materials/, tracer/emitters/), found
# through their registries; the kinds that were defined here are re-exported.
Material = MaterialModel
Light = LightModel


@dataclass(frozen=True)
class Sphere:
    center: Vec3
    radius: float
    material: str | None
    emitter: AreaEmitter | None = None
    #: rotation of the sphere's own frame (its texture coordinates), row-major 3x3
    rotation: Matrix = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

    def to_world(self) -> np.ndarray:
        """The whole placement as Mitsuba builds it: rotation, uniform scale, translation."""
        m = np.eye(4)
        m[:3, :3] = np.asarray(self.rotation) * self.radius
        m[:3, 3] = self.center
        return m


@dataclass(frozen=True)
class _Planar:
    """A flat shape in local xy (normal +z) placed by ``to_world``."""
    to_world: Matrix
    material: str | None
    emitter: AreaEmitter | None = None

    def corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centre and the images of local +x and +y (half-edges, or radii) in world space."""
        m = np.asarray(self.to_world)
        c = tf.apply_point(m, (0, 0, 0))
        return c, tf.apply_point(m, (1, 0, 0)) - c, tf.apply_point(m, (0, 1, 0)) - c

    def normal(self) -> np.ndarray:
        """Mitsuba's orientation: the inverse transpose of to_world applied to +z."""
        n = tf.apply_normal(np.asarray(self.to_world), (0, 0, 1))
        return n / np.linalg.norm(n)


@dataclass(frozen=True)
class Rectangle(_Planar):
    """Mitsuba's rectangle: [-1, 1]^2 in local xy, normal +z, placed by ``to_world``."""


@dataclass(frozen=True)
class Triangle:
    vertices: tuple[Vec3, Vec3, Vec3]  # world space, after to_world
    material: str | None
    emitter: AreaEmitter | None = None


@dataclass(frozen=True)
class Disk(_Planar):
    """Mitsuba's disk: the unit disk in local xy, normal +z, placed by ``to_world``."""


@dataclass(frozen=True)
class Cylinder:
    """Mitsuba's open cylinder from p0 to p1 with a radius, then ``to_world``."""
    p0: Vec3
    p1: Vec3
    radius: float
    to_world: Matrix
    material: str | None
    emitter: AreaEmitter | None = None

    def local_to_world(self) -> np.ndarray:
        """Unit cylinder x^2 + y^2 = 1, 0 <= z <= 1 to world, composed as Mitsuba does."""
        d = np.subtract(self.p1, self.p0)
        length = float(np.linalg.norm(d))
        frame = np.eye(4)
        s_, t_ = _mitsuba_frame(d / length)
        frame[:3, 0], frame[:3, 1], frame[:3, 2] = s_, t_, d / length
        return (np.asarray(self.to_world) @ tf.translate(self.p0) @ frame
                @ tf.scale((self.radius, self.radius, length)))


@dataclass(frozen=True)
class Paraboloid:
    """z = x^2 / a^2 + y^2 / b^2 for 0 <= z <= height in local space, placed by ``to_world``."""
    a: float
    b: float
    height: float
    to_world: Matrix
    material: str | None
    emitter: AreaEmitter | None = None


@dataclass(frozen=True)
class Polygon:
    """A planar polygon (convex or not), vertices in world space after ``to_world``."""
    vertices: tuple[Vec3, ...]
    material: str | None
    emitter: AreaEmitter | None = None


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh from an OBJ or PLY file, in world space after ``to_world``."""
    file: str
    smooth: bool
    vertices: np.ndarray       # (V, 3) world space
    faces: np.ndarray          # (F, 3)
    normals: np.ndarray | None  # (V, 3) world space, unit; None: face normals
    uvs: np.ndarray | None     # (V, 2)
    to_world: Matrix
    material: str | None
    emitter: AreaEmitter | None = None


@dataclass(frozen=True)
class Instance:
    """A group of shapes placed by ``to_world`` (the group's own shapes are in object space)."""
    group: str
    to_world: Matrix
    material: str | None = None
    emitter: AreaEmitter | None = None


@dataclass(frozen=True, eq=False)
class Cube(Mesh):
    """Mitsuba's ``cube``: [-1, 1]^3 as 12 flat triangles, placed by ``to_world``."""


def cube_mesh() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, uvs) of [-1, 1]^3: four vertices a face, faces wound outwards.

    The same surface as Mitsuba's ``cube`` (a mesh of 24 vertices and 12 triangles
    with face normals); each face's uv spans [0, 1]^2.
    """
    verts, faces, uvs = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u_ax, v_ax = (axis + 1) % 3, (axis + 2) % 3
            base = len(verts)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis], p[u_ax], p[v_ax] = sign, a * sign, b
                verts.append(p)
                uvs.append(((a + 1) / 2, (b + 1) / 2))
            # (u x v) = +axis; flipping u on the negative face keeps the winding outward
            faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.asarray(verts), np.asarray(faces), np.asarray(uvs)


Shape = (Sphere | Rectangle | Triangle | Disk | Cylinder | Paraboloid | Polygon | Mesh
         | Instance)


def _mitsuba_frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tangents Mitsuba's Frame3f(n) chooses (Duff et al. 2017), so that uv agree."""
    sign = 1.0 if n[2] >= 0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return (np.array([1 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]]),
            np.array([b, sign + n[1] * n[1] * a, -n[1]]))


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
        return any(isinstance(s, Paraboloid) for s in self.all_shapes())


# ---------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------


class _Table:
    """A TOML table being read: remembers its key path and which keys were used."""

    def __init__(self, path: str, key: str, data: Any, what: str = "a table",
                 pattern: str | None = None):
        self.path, self.key = path, key
        #: the key path with NAME for user-chosen names and [0] for indices
        self.pattern = key if pattern is None else pattern
        self.kind: str | None = None  # the ``type`` read, once read
        if not isinstance(data, dict):
            self.fail("", f"expected {what}, got {_show(data)}")
        self.data = data
        self.used: set[str] = set()

    def _k(self, key: str) -> str:
        return f"{self.key}.{key}" if self.key and key else (self.key or key)

    def _p(self, key: str) -> str:
        return f"{self.pattern}.{key}" if self.pattern and key else (self.pattern or key)

    def fail(self, key: str, message: str):
        raise SceneError(self.path, self._k(key), message)

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = ..., required_what: str = "a value",
            schema: dict | None = None) -> Any:
        """The value of ``key`` as TOML gave it (``default`` when absent, ``...``: required).

        ``schema`` is the JSON Schema of the values the caller accepts: the
        helpers below pass their own, and :mod:`tracer.schema` builds the scene
        format's schema from them (this table ignores it).
        """
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                self._unknown_first(key)
                self.fail(key, f"missing; expected {required_what}")
            return default
        return self.data[key]

    def _unknown_first(self, key: str) -> None:
        """Before saying ``key`` is missing: a key this kind of table does not know (a
        misspelling, or a key of another kind) is the likelier fault, and is named first."""
        from whitted.tracer.schema import known_keys

        known = known_keys(self.pattern, self.kind)
        unknown = [k for k in self.data if k not in self.used and k not in known]
        if known and unknown:
            self.fail(unknown[0], f"unknown key (expected one of: {', '.join(sorted(known))}); "
                                  f"{key} is missing")

    def number(self, key: str, default: Any = ..., lo: float | None = None,
               hi: float | None = None, lo_open: bool = False, hi_open: bool = False) -> float:
        what = _range_text("a number", lo, hi, lo_open, hi_open)
        v = self.raw(key, default, what, _number_schema(lo, hi, lo_open, hi_open))
        return _check_number(self, key, v, what, lo, hi, lo_open, hi_open)

    def integer(self, key: str, default: Any = ..., lo: int | None = None) -> int:
        what = "an integer" + (f" >= {lo}" if lo is not None else "")
        v = self.raw(key, default, what,
                     {"type": "integer"} | ({"minimum": lo} if lo is not None else {}))
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(key, f"expected {what}, got {_show(v)}")
        if lo is not None and v < lo:
            self.fail(key, f"expected {what}, got {v}")
        return v

    def boolean(self, key: str, default: Any = ...) -> bool:
        v = self.raw(key, default, "true or false", {"type": "boolean"})
        if not isinstance(v, bool):
            self.fail(key, f"expected true or false, got {_show(v)}")
        return v

    def string(self, key: str, default: Any = ..., choices: tuple[str, ...] | None = None) -> str:
        what = "a string" if not choices else "one of: " + ", ".join(f'"{c}"' for c in choices)
        v = self.raw(key, default, what,
                     {"enum": list(choices)} if choices else {"type": "string"})
        if not isinstance(v, str) or (choices and v not in choices):
            self.fail(key, f"expected {what}, got {_show(v)}")
        if key == "type":
            self.kind = v
        return v

    def vec3(self, key: str, default: Any = ..., nonzero: bool = False) -> Vec3:
        v = self.raw(key, default, "a list of 3 numbers", _VEC3_SCHEMA)
        return _vec3(self, key, v, nonzero)

    def direction(self, key: str, default: Any = ...) -> Vec3:
        """A unit vector from a non-zero one (non-zero in float32)."""
        return _unit(self, key, self.raw(key, default, "a list of 3 numbers", _VEC3_SCHEMA))

    def distinct(self, key: str, a: Vec3, b: Vec3, other: str) -> None:
        """Refuse b unless float32 tells it apart from a (see :func:`_distinct`)."""
        _distinct(self, key, a, b, other)

    def color(self, key: str, default: Any = ..., hi: float | None = None) -> Color:
        what = "a colour: one number or a list of 3 numbers, each >= 0" + (
            f" and <= {hi}" if hi is not None else "")
        one = _number_schema(0, hi, False, False)
        v = self.raw(key, default, what, {"anyOf": [
            one, {"type": "array", "items": one, "minItems": 3, "maxItems": 3}]})
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v, v, v]
        if not isinstance(v, list) or len(v) != 3:
            self.fail(key, f"expected {what}, got {_show(v)}")
        out = []
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                self.fail(key, f"expected {what}, got {_show(v)} (element {i} is {_show(x)})")
            if x < 0 or (hi is not None and x > hi):
                self.fail(key, f"expected {what}, got {_show(v)}")
            if x > FLOAT32_MAX:
                self.fail(key, f"expected {what}, within float32's range (up to "
                               f"{FLOAT32_MAX:.4g}), got {_show(v)}")
            out.append(float(x))
        return (out[0], out[1], out[2])

    def table(self, key: str, default: Any = ..., parse: Any = None) -> Any:
        """The sub-table ``key``; with ``parse``, what ``parse(sub-table)`` makes of it."""
        v = self.raw(key, default, "a table", {"type": "object"})
        sub = _Table(self.path, self._k(key), v, pattern=self._p(key))
        return sub if parse is None else parse(sub)

    def tables(self, key: str, parse: Any, what: str | None = None,
               item_what: str = "a table") -> list:
        """An array of tables (``[[key]]``), each made into ``parse(sub-table)``."""
        what = what or f"an array of tables ([[{key}]])"
        v = self.raw(key, [], what, {"type": "array"})
        if not isinstance(v, list):
            self.fail(key, f"expected {what}, got {_show(v)}")
        return [parse(_Table(self.path, f"{self._k(key)}[{i}]", x, item_what,
                             f"{self._p(key)}[0]")) for i, x in enumerate(v)]

    def each(self, parse: Any) -> dict:
        """Every key of this table, each a sub-table named by the user: ``parse(sub, name)``."""
        out = {}
        for name in list(self.data):
            self.used.add(name)
            out[name] = parse(_Table(self.path, self._k(name), self.data[name],
                                     pattern=self._p("NAME")), name)
        return out

    def is_table(self, key: str) -> bool:
        """Whether ``key`` holds a table (a texture rather than a colour, say)."""
        return isinstance(self.data.get(key), dict)

    def choose(self, options: tuple[str, ...], noun: str) -> str:
        """The one key of this table, which names which of ``options`` it is (a step's
        ``translate``, a texture's ``checkerboard``)."""
        keys = list(self.data)
        if len(keys) != 1:
            self.fail("", f"expected exactly one of {', '.join(options)} in a {noun}, "
                          f"got {', '.join(keys) or 'none'}")
        if keys[0] not in options:
            self.fail(keys[0], f"unknown {noun} (expected one of: {', '.join(options)})")
        return keys[0]

    def finish(self, allowed_note: str = ""):
        """Refuse keys that were never read: a typo must not be silently ignored."""
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            known = ", ".join(sorted(self.used))
            self.fail(unknown[0], f"unknown key (expected one of: {known}){allowed_note}")


def _show(v: Any, depth: int = 0) -> str:
    """A value as the message shows it: strings escaped, long lists cut (a few elements)."""
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    if isinstance(v, str):
        text = v if len(v) <= 60 else v[:60] + "..."
        return '"' + text.encode("unicode_escape").decode("ascii").replace('"', '\\"') + '"'
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list):
        if depth >= 2:
            return "[...]"
        items = [_show(x, depth + 1) for x in v[:6]]
        more = f", ... ({len(v):,} elements)" if len(v) > 6 else ""
        return "[" + ", ".join(items) + more + "]"
    return repr(v)


def _number_schema(lo, hi, lo_open, hi_open) -> dict:
    """The JSON Schema of the numbers ``_range_text`` describes."""
    out: dict = {"type": "number"}
    if lo is not None:
        out["exclusiveMinimum" if lo_open else "minimum"] = lo
    if hi is not None:
        out["exclusiveMaximum" if hi_open else "maximum"] = hi
    return out


_VEC3_SCHEMA = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}


def _range_text(base: str, lo, hi, lo_open, hi_open) -> str:
    parts = []
    if lo is not None:
        parts.append(f"{'>' if lo_open else '>='} {lo:g}")
    if hi is not None:
        parts.append(f"{'<' if hi_open else '<='} {hi:g}")
    return base + (" " + " and ".join(parts) if parts else "")


#: The tracer computes in float32: the largest finite value and the smallest normal one.
FLOAT32_MAX = float(np.finfo(np.float32).max)
FLOAT32_TINY = float(np.finfo(np.float32).tiny)
#: Largest coordinate (and inverse scale) of the world: intersection tests square
#: coordinates and sum three squares, which must stay below FLOAT32_MAX (3 x 2^120 < 2^128).
COORD_MAX = float(2.0**60)
#: Largest ratio of a transform's largest to smallest scale (its condition number): float32
#: round-trips a point through the transform and its inverse within about that many ulps.
COND_MAX = 1e6


def _check_number(t: _Table, key: str, v, what, lo, hi, lo_open, hi_open) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        t.fail(key, f"expected {what}, got {_show(v)}")
    if not math.isfinite(v):
        t.fail(key, f"expected a finite number ({what}), got {_show(v)}")
    if abs(v) > FLOAT32_MAX:
        t.fail(key, f"expected {what} within float32's range (up to {FLOAT32_MAX:.4g}), "
                    f"got {v:g}")
    # The bounds must hold for the float32 value the tracer uses, too (1e-200 > 0 is 0).
    v32 = float(np.float32(v))
    for x in (v, v32):
        if lo is not None and (x <= lo if lo_open else x < lo):
            t.fail(key, f"expected {what}, got {v:g}" + (" (0 in float32)" if x == 0 != v
                                                           else ""))
        if hi is not None and (x >= hi if hi_open else x > hi):
            t.fail(key, f"expected {what}, got {v:g}")
    return float(v)


def _vec3(t: _Table, key: str, v, nonzero: bool = False) -> Vec3:
    what = "a list of 3 finite numbers"
    if not isinstance(v, list) or len(v) != 3:
        got = f"a list of {len(v):,}" if isinstance(v, list) else _show(v)
        t.fail(key, f"expected {what}, got {got}")
    for i, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            t.fail(key, f"expected {what}, got {_show(v)} (element {i} is {_show(x)})")
        if abs(x) > FLOAT32_MAX:
            t.fail(key, f"expected numbers within float32's range (up to {FLOAT32_MAX:.4g}), "
                        f"got {_show(v)}")
    out = (float(v[0]), float(v[1]), float(v[2]))
    if nonzero and max(abs(x) for x in out) < FLOAT32_TINY:
        t.fail(key, f"expected a non-zero vector, got {_show(v)} (zero in float32)")
    return out


def _norm_or_1(v) -> float:
    n = _norm(v)
    return n if n > 0 else 1.0


def _norm(v) -> float:
    """Euclidean length without underflow or overflow (scaled by the largest component)."""
    a = np.asarray(v, dtype=np.float64)
    m = float(np.max(np.abs(a)))
    return 0.0 if m == 0 else m * float(np.linalg.norm(a / m))


def _unit(t: _Table, key: str, v) -> Vec3:
    """A direction: non-zero in float32 (relative to nothing: any scale is a direction)."""
    d = np.asarray(_vec3(t, key, v, nonzero=True))
    d = d / np.max(np.abs(d))
    d = d / np.linalg.norm(d)
    return (float(d[0]), float(d[1]), float(d[2]))


def _distinct(t: _Table, key: str, a, b, other: str) -> np.ndarray:
    """b - a, refused unless float32 tells the two points apart with room to spare.

    Relative test: the difference must exceed 2^-20 of the points' magnitude
    (16 float32 ulps), so that the direction a -> b is known to about 1e-6.
    """
    d = np.subtract(b, a)
    scale = max(float(np.max(np.abs(a))), float(np.max(np.abs(b))))
    if float(np.max(np.abs(d))) <= max(scale * 2.0**-20, FLOAT32_TINY):
        t.fail(key, f"expected a point different from {other} "
                    "(in float32 the two are the same or too close)")
    return d


def _check_extent(t: _Table, key: str, points, what: str = "coordinates") -> None:
    """World coordinates within COORD_MAX, where float32 intersection tests stay finite."""
    m = float(np.max(np.abs(points))) if np.size(points) else 0.0
    if not m <= COORD_MAX:
        t.fail(key, f"{what} reach {m:.3g}, beyond the {COORD_MAX:.3g} that float32 "
                    "intersection tests can square")


def _check_transform(t: _Table, key: str, m: np.ndarray, what: str = "transform") -> None:
    """An affine transform float32 can apply and invert: relative tests on its scales.

    Its singular values (the scales along its principal axes) must lie within
    [1 / COORD_MAX, COORD_MAX] and their ratio (the condition number) within
    COND_MAX; a NaN anywhere fails both. A uniform scale of 1e-5 passes, a
    rotation about an axis that underflows, or [1, 1, 1e-12], does not.
    """
    if not np.isfinite(m).all():
        t.fail(key, f"expected a finite {what} (it has NaN or infinite entries)")
    _check_extent(t, key, m[:3, 3], "its translation")
    sv = np.linalg.svd(m[:3, :3], compute_uv=False)
    if not (sv[-1] > 0 and 1 / COORD_MAX <= sv[-1] and sv[0] <= COORD_MAX):
        t.fail(key, f"expected an invertible {what} with scales between {1 / COORD_MAX:.3g} "
                    f"and {COORD_MAX:.3g} (its scales range from {sv[-1]:.3g} to {sv[0]:.3g})")
    if sv[0] / sv[-1] > COND_MAX:
        t.fail(key, f"expected an invertible {what}: its scales range from {sv[-1]:.3g} to "
                    f"{sv[0]:.3g}, a ratio beyond the {COND_MAX:.0g} float32 can invert")


SHAPE_TYPES = ("sphere", "rectangle", "triangle", "disk", "cylinder", "paraboloid", "polygon",
               "mesh", "cube", "instance")
#: Material ``type``s: the registry of tracer/materials/.
MATERIAL_TYPES = tuple(_materials.REGISTRY)
#: Shapes that may carry an area emitter (the tracer samples them): tracer/emitters/area.py.
EMITTER_SHAPES = tuple(_area.SAMPLERS)
#: ``[[lights]]`` ``type``s: the registry of tracer/emitters/.
LIGHT_TYPES = tuple(_emitters.LIGHTS)
CAMERA_TYPES = ("perspective", "orthographic")
#: ``fov_axis`` values (Mitsuba's): which extent of the film ``fov`` spans.
FOV_AXES = ("x", "y", "diagonal", "smaller", "larger")
#: ``[film] filter`` values: Mitsuba's ``box`` and ``gaussian`` reconstruction filters.
FILTERS = ("box", "gaussian")
TOP_LEVEL = ("description", "film", "camera", "materials", "lights", "shapes", "compare",
             "groups")
#: Features a scene may declare tracer-only: Mitsuba has no counterpart (each kind
#: names its own, e.g. Schlick's approximation of the dielectric, the Phong ambient term).
TRACER_ONLY = _materials.tracer_only_parts()


#: Deepest nesting of tables and arrays a scene may use (the format needs five).
MAX_NESTING = 16


def _read_scene_bytes(path: str) -> bytes:
    """The file's bytes: a regular file no larger than the limit (no FIFO, no device)."""
    import stat

    from whitted.tracer.limits import MAX_SCENE_BYTES, refuse

    limit = MAX_SCENE_BYTES.value()
    st = os.stat(path)
    if stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError
    if not stat.S_ISREG(st.st_mode):
        kind = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device"
                if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "a socket"
                if stat.S_ISSOCK(st.st_mode) else "not a file")
        raise SceneError(path, "", f"is {kind}, expected a regular file (a .toml scene)")
    with open(path, "rb") as f:
        data = f.read(limit + 1)  # a file may grow, or report a wrong size
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
        for line in imp.warnings:
            if warn is not None:
                warn(line)
        return replace(parse_scene(imp.data, str(path)), approximate=imp.approximate)
    return load_scene(path)


def parse_scene(data: dict, path: str = "<scene>") -> Scene:
    """Validate an already parsed TOML document (see :func:`load_scene`)."""
    _check_nesting(path, data)
    return _parse_top(_Table(path, "", data))


def _parse_top(top: _Table) -> Scene:
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


def _parse_materials(t: _Table) -> dict[str, Material]:
    return t.each(_parse_material)


def _parse_groups(t: _Table, materials: dict[str, Material], base: Path) -> dict[str, tuple]:
    def group(g: _Table, name: str) -> tuple:
        members = g.tables("shapes", lambda m: _parse_shape(m, materials, {}, base,
                                                            in_group=True))
        if not members:
            g.fail("shapes", "expected at least one [[groups.NAME.shapes]] table")
        g.finish()
        return tuple(members)
    return t.each(group)


def _parse_compare(t: _Table) -> list[str]:
    what = "a list of: " + ", ".join(f'"{x}"' for x in TRACER_ONLY)
    tracer_only = t.raw("tracer_only", [], what,
                        {"type": "array", "items": {"enum": list(TRACER_ONLY)}})
    if not isinstance(tracer_only, list):
        t.fail("tracer_only", f"expected {what}, got {_show(tracer_only)}")
    for i, x in enumerate(tracer_only):
        if x not in TRACER_ONLY:
            known = ", ".join(f'"{part}"' for part in TRACER_ONLY)
            t.fail(f"tracer_only[{i}]", f"expected one of: {known}, got {_show(x)}")
    t.finish()
    return tracer_only


def _parse_film(t: _Table) -> Film:
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
    jitter = t.raw("jitter", d.jitter)
    if not isinstance(jitter, bool):
        t.fail("jitter", f"expected true or false, got {_show(jitter)}")
    film = Film(width=t.integer("width", d.width, lo=1), height=t.integer("height", d.height, lo=1),
                spp=t.integer("spp", d.spp, lo=1), max_depth=max_depth, filter=flt,
                stddev=stddev, jitter=jitter)
    t.finish()
    return film


def _parse_camera(t: _Table) -> Camera:
    kind = t.string("type", "perspective", CAMERA_TYPES)
    matrix = None
    if t.has("to_world"):
        given = [k for k in ("origin", "target", "up") if t.has(k)]
        if given:
            t.fail(given[0], "give either to_world or origin/target/up, not both")
        m = _parse_steps(t, "to_world")
        if kind == "perspective" and not _orthonormal(m[:3, :3]):
            t.fail("to_world", "a perspective camera's to_world may rotate, mirror and "
                               "translate, not scale or shear (its rays would not be unit)")
        matrix = _as_tuple(m)
        origin = tuple(float(x) for x in m[:3, 3])
        f = m[:3, 2] / _norm(m[:3, 2])
        target = tuple(float(x) for x in m[:3, 3] + f)
        up = tuple(float(x) for x in m[:3, 1] / _norm(m[:3, 1]))
    else:
        if not t.has("origin"):
            t._unknown_first("origin")  # a misspelt key is the likelier fault
            t.fail("origin", "missing; expected a list of 3 numbers (or give to_world instead "
                             "of origin/target/up)")
        origin, target = t.vec3("origin"), t.vec3("target")
        up = t.vec3("up", [0.0, 1.0, 0.0], nonzero=True)
        forward = _distinct(t, "target", origin, target, "camera.origin")
        f_unit, up_unit = forward / _norm(forward), np.asarray(up) / _norm(up)
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
                     pixel_offset=offset, fov_axis=axis, principal_point=ppo, matrix=matrix)
        note = " (width is for orthographic cameras)" if t.has("width") else ""
    else:
        if matrix is not None:  # the view is [-1, 1]^2 in camera space, scaled by to_world
            if t.has("width"):
                t.fail("width", "give either width or a to_world that scales the view, not both")
            width = 2 * _norm(np.asarray(matrix)[:3, 0])
        else:
            width = t.number("width", lo=0, lo_open=True)
        cam = Camera("orthographic", origin, target, up, width=width, near_clip=near,
                     far_clip=far, pixel_offset=offset, matrix=matrix)
        note = (" (fov, fov_axis and principal_point_offset_x/y are for perspective cameras)"
                if any(t.has(k) for k in ("fov", "fov_axis", "principal_point_offset_x",
                                          "principal_point_offset_y")) else "")
    t.finish(note)
    return cam


def _orthonormal(a: np.ndarray, tol: float = 1e-5) -> bool:
    """The columns are unit and at right angles (a rotation, perhaps with a mirror)."""
    return bool(np.allclose(a.T @ a, np.eye(3), atol=tol))


def _pixel_offset(t: _Table) -> tuple[float, float]:
    """``pixel_offset = [dx, dy]``: the pixel grid's samples moved by (dx, dy) pixels."""
    what = "[dx, dy]: two numbers from -1 to 1 (pixels)"
    one = {"type": "number", "minimum": -1, "maximum": 1}
    v = t.raw("pixel_offset", [0.0, 0.0], what,
              {"type": "array", "items": one, "minItems": 2, "maxItems": 2})
    if (not isinstance(v, list) or len(v) != 2 or
            any(isinstance(x, bool) or not isinstance(x, (int, float)) or
                not math.isfinite(x) or abs(x) > 1 for x in v)):
        t.fail("pixel_offset", f"expected {what}, got {_show(v)}")
    return (float(v[0]), float(v[1]))


#: A colour, or ``{ checkerboard = {...} }`` (tracer/materials/textures.py).
_texture = parse_texture


def _parse_material(t: _Table, name: str) -> Material:
    kind = t.string("type", choices=tuple(_materials.REGISTRY))
    m = _materials.REGISTRY[kind].parse(t, name)
    opacity = 1.0
    if "opacity" not in t.used:  # every kind's opacity, unless the kind has its own
        # A number, a colour or a texture, read as Mitsuba's mask reads it: one value
        # per point (the colour's mean, a bitmap's luminance; scalar_texture).
        opacity = scalar_texture(parse_texture(t, "opacity", 1.0, hi=1))
    t.finish()
    return replace(m, mask_opacity=opacity) if opacity != 1 else m


def _parse_emitter(t: _Table) -> AreaEmitter:
    emitter = _area.parse(t)
    t.finish()
    return emitter


def _parse_light(t: _Table) -> Light:
    kind = t.string("type", choices=tuple(_emitters.LIGHTS))
    light = _emitters.LIGHTS[kind].parse(t)
    t.finish()
    return light


#: The kinds of a ``to_world`` step, each the one key of its table.
STEPS = ("translate", "scale", "rotate", "matrix")


def _parse_steps(t: _Table, key: str) -> np.ndarray:
    if t.is_table(key):  # one step given as a table: { matrix = [...] }
        mats = [_parse_step(t.table(key))]
    else:
        mats = t.tables(key, _parse_step,
                        "a list of steps like [{ translate = [x, y, z] }]",
                        "a step: { translate = [..] }, { scale = .. }, { rotate = {..} } or "
                        "{ matrix = [[..] x4] }")
    m = tf.compose(mats)
    _check_transform(t, key, m)
    return m


def _parse_step(s: _Table) -> np.ndarray:
    op = s.choose(STEPS, "step")
    if op == "translate":
        m = tf.translate(s.vec3("translate"))
    elif op == "scale":
        v = s.raw("scale", ..., "a number or a list of 3 numbers",
                  {"anyOf": [{"type": "number"}, _VEC3_SCHEMA]})
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v, v, v]
        sv = _vec3(s, "scale", v)
        if any(abs(x) < FLOAT32_TINY for x in sv):
            s.fail("scale", f"expected non-zero scale factors, got {_show(v)} "
                            "(a factor is zero in float32)")
        m = tf.scale(sv)
    elif op == "rotate":
        r = s.table("rotate")
        axis = r.direction("axis")
        m = tf.rotate(axis, r.number("angle"))
        r.finish()
    else:
        row = {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4}
        v = s.raw("matrix", ..., "4 rows of 4 numbers (or 16 numbers, row by row)",
                  {"anyOf": [{"type": "array", "items": row, "minItems": 4, "maxItems": 4},
                             {"type": "array", "items": {"type": "number"},
                              "minItems": 16, "maxItems": 16}]})
        if isinstance(v, list) and len(v) == 16 and not any(isinstance(x, list) for x in v):
            v = [v[0:4], v[4:8], v[8:12], v[12:16]]  # 16 numbers, row by row (Mitsuba's)
        if (not isinstance(v, list) or len(v) != 4 or
                any(not isinstance(row, list) or len(row) != 4 for row in v)):
            s.fail("matrix", "expected 4 rows of 4 numbers (or 16 numbers, row by row)")
        flat = [x for row in v for x in row]
        if any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x)
               for x in flat):
            s.fail("matrix", "expected 4 rows of 4 finite numbers")
        m = np.asarray(v, dtype=np.float64)
        if not np.allclose(m[3], [0, 0, 0, 1]):
            s.fail("matrix", "expected an affine matrix (last row [0, 0, 0, 1])")
    s.finish()
    return m


def _as_tuple(m: np.ndarray) -> Matrix:
    return tuple(tuple(float(x) for x in row) for row in m)


def _parse_shape(t: _Table, materials: dict[str, Material], groups: dict,
                 base: Path, in_group: bool = False) -> Shape:
    kind = t.string("type", choices=SHAPE_TYPES)
    if in_group and kind == "instance":
        t.fail("type", "a group may not contain instances (nested instancing is not supported)")
    emitter = None
    if t.has("emitter"):
        if kind not in _area.SAMPLERS or in_group:
            t.fail("emitter", "area lights are supported on " + ", ".join(_area.SAMPLERS) +
                   (" outside groups" if in_group else "") + f", not on a {kind}")
        emitter = t.table("emitter", parse=_parse_emitter)
    if kind == "instance":
        material = None
        group = t.string("group")
        if group not in groups:
            known = ", ".join(sorted(groups)) or "none"
            t.fail("group", f'unknown group "{group}" (defined: {known})')
    elif emitter is None or t.has("material"):
        material = t.string("material")
        if material not in materials:
            known = ", ".join(sorted(materials)) or "none"
            t.fail("material", f'unknown material "{material}" (defined: {known})')
    else:
        material = None  # a pure emitter: black, reflects nothing
    m = _parse_steps(t, "to_world")
    if kind == "sphere":
        center = np.asarray(t.vec3("center", [0.0, 0.0, 0.0]))
        radius = t.number("radius", 1.0, lo=0, lo_open=True)
        if not tf.is_similarity(m) or np.linalg.det(m[:3, :3]) < 0:
            t.fail("to_world", "a sphere takes only translations, rotations and uniform "
                               "positive scales (the result must stay a sphere)")
        scale = float(np.linalg.norm(m[:3, 0]))
        shape = Sphere(tuple(float(x) for x in tf.apply_point(m, center)), radius * scale,
                       material, emitter, _as_tuple(m[:3, :3] / scale))
        _check_transform(t, "radius", shape.to_world(), "placement (centre and radius)")
    elif kind == "rectangle":
        shape = Rectangle(_as_tuple(m), material, emitter)
    elif kind == "disk":
        shape = Disk(_as_tuple(m), material, emitter)
    elif kind == "triangle":
        verts = _points(t, "vertices", m, exactly=3)
        e1, e2 = verts[1] - verts[0], verts[2] - verts[0]
        # Relative: the sine of the angle between the edges, as float32 can resolve it.
        if not _norm(np.cross(e1 / _norm_or_1(e1), e2 / _norm_or_1(e2))) > 2.0**-23:
            t.fail("vertices", "expected a triangle with non-zero area "
                               "(the vertices are collinear, or nearly so for float32)")
        shape = Triangle(tuple(tuple(float(x) for x in p) for p in verts), material, emitter)
    elif kind == "polygon":
        verts = _points(t, "vertices", m)
        _check_polygon(t, verts)
        shape = Polygon(tuple(tuple(float(x) for x in p) for p in verts), material, emitter)
    elif kind == "cylinder":
        p0, p1 = t.vec3("p0", [0.0, 0.0, 0.0]), t.vec3("p1", [0.0, 0.0, 1.0])
        t.distinct("p1", p0, p1, "p0")
        shape = Cylinder(p0, p1, t.number("radius", 1.0, lo=0, lo_open=True), _as_tuple(m),
                         material, emitter)
        _check_transform(t, "radius", shape.local_to_world(),
                         "placement (radius against length)")
        lin = shape.local_to_world()[:3, :3]
        x, y, z = lin[:, 0], lin[:, 1], lin[:, 2]
        tol = 1e-6 * max(np.linalg.norm(x), np.linalg.norm(z))
        if (abs(np.dot(x, y)) > tol * np.linalg.norm(y) or abs(np.dot(x, z)) > tol *
                np.linalg.norm(z) or abs(np.dot(y, z)) > tol * np.linalg.norm(z) or
                abs(np.linalg.norm(x) - np.linalg.norm(y)) > tol or np.linalg.det(lin) < 0):
            t.fail("to_world", "a cylinder's to_world may not shear it, mirror it or scale its "
                               "cross-section unevenly (Mitsuba's cylinder does not support it)")
    elif kind == "paraboloid":
        shape = Paraboloid(t.number("a", 1.0, lo=0, lo_open=True),
                           t.number("b", 1.0, lo=0, lo_open=True),
                           t.number("height", 1.0, lo=0, lo_open=True), _as_tuple(m),
                           material, emitter)
        h = math.sqrt(shape.height)
        _check_transform(t, "height", m @ tf.scale((shape.a * h, shape.b * h, shape.height)),
                         "shape (a, b and height against each other)")
    elif kind == "mesh":
        shape = _parse_mesh(t, m, material, emitter, base)
    elif kind == "cube":
        verts, faces, uvs = cube_mesh()
        world = tf.apply_point(m, verts)
        _check_extent(t, "to_world", world, "vertices")
        shape = Cube("cube", False, world, faces, None, uvs, _as_tuple(m), material, emitter)
    else:
        shape = Instance(group, _as_tuple(m))
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


def _points(t: _Table, key: str, m: np.ndarray, exactly: int | None = None) -> list:
    what = (f"a list of {exactly} vertices [[x, y, z], ...]" if exactly
            else "a list of at least 3 vertices [[x, y, z], ...]")
    counts = {"minItems": exactly, "maxItems": exactly} if exactly else {"minItems": 3}
    v = t.raw(key, ..., what, {"type": "array", "items": _VEC3_SCHEMA} | counts)
    if not isinstance(v, list) or (len(v) != exactly if exactly else len(v) < 3):
        got = f"a list of {len(v)}" if isinstance(v, list) else _show(v)
        t.fail(key, f"expected {what}, got {got}")
    pts = [tf.apply_point(m, _vec3(t, f"{key}[{i}]", p)) for i, p in enumerate(v)]
    _check_extent(t, key, np.asarray(pts), "vertices")
    return pts


def _check_polygon(t: _Table, verts: list) -> None:
    """Planar, not degenerate and simple (no edge crosses another)."""
    from whitted.tracer.shapes.polygon import plane_frame, self_intersects

    pts = np.asarray(verts)
    frame = plane_frame(pts)
    if frame is None:
        t.fail("vertices", "expected a polygon with non-zero area")
    origin, u, v, n = frame
    size = float(np.max(np.linalg.norm(pts - pts.mean(axis=0), axis=1)))
    off = np.abs((pts - origin) @ n)
    if off.max() > 1e-6 * size:
        t.fail("vertices", f"expected a planar polygon (a vertex lies {off.max():.3g} "
                           "off the plane of the others)")
    if self_intersects((pts - origin) @ np.stack([u, v], axis=1)):
        t.fail("vertices", "expected a simple polygon (two of its edges cross)")


def _parse_mesh(t: _Table, m: np.ndarray, material, emitter, base: Path) -> Mesh:
    from whitted.tracer.meshio import MeshError, compute_vertex_normals, load_mesh

    name = t.string("file")
    path = Path(name) if Path(name).is_absolute() else base / name
    if not path.exists():  # a FIFO, device or folder: load_mesh says what it is
        t.fail("file", f"no such mesh file: {path}")
    smooth = t.boolean("smooth", True)
    try:
        data = load_mesh(path)
    except MeshError as e:
        t.fail("file", str(e))
    verts = tf.apply_point(m, data.vertices)
    _check_extent(t, "file", verts, "vertices")
    normals = None
    if smooth:
        if data.normals is not None:  # normals transform by the inverse transpose
            normals = tf.apply_normal(m, data.normals)
        else:  # as Mitsuba does: from the faces, after to_world
            normals = compute_vertex_normals(verts, data.faces)
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    return Mesh(str(path), smooth, verts, np.asarray(data.faces), normals, data.uvs,
                _as_tuple(m), material, emitter)
