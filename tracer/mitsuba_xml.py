"""Mitsuba 3 scene XML read into the scene format, without Mitsuba.

:func:`read_xml` parses a Mitsuba scene file with Python's expat (keeping each
element's line for messages), resolves what Mitsuba's own parser resolves
before it builds plugins, and maps the plugins onto the scene format's keys:

* ``<default name value>`` and ``$name`` in any attribute (values given to
  :func:`read_xml` win over the file's defaults, as ``mi.load_file(path,
  name=value)`` does);
* ``<include filename>`` (its scene's children spliced in place), ``<path
  value>`` (a folder searched for files, relative to the scene), ``<ref id>``
  and objects declared once with an ``id`` and used by reference;
* ``<transform>`` with ``translate``, ``rotate``, ``scale``, ``matrix`` and
  ``lookat`` in Mitsuba's order: each step applies after the ones above it,
  which is the order of a ``to_world`` list of steps (first step first);
* ``rgb`` values as given (the tracer is RGB), ``spectrum`` values (one number or
  wavelength:value pairs) as the colour Mitsuba 3.9.1's RGB variants make of them
  (:mod:`tracer.spectra`: as a reflectance, an illuminant or an unbounded value);
* named indices of refraction (:mod:`tracer.mitsuba_ior`) as numbers.

Input is read defensively, as the TOML loader reads it: every file a scene
names (the scene, includes, meshes, textures, serialized meshes) is looked up
with its symbolic links followed and must be a regular file (no folder, FIFO
or device; files outside the scene's folder are allowed, as Mitsuba allows
them); the scene and all its includes together are read within
``WHITTED_MAX_SCENE_BYTES`` (checked from their sizes before reading, reads
bounded), at most ``WHITTED_MAX_INCLUDES`` includes in all and 16 levels deep;
every number is parsed strictly (an integer where Mitsuba wants one, finite and
within float32's range) and values echoed in messages are cut to
:data:`VALUE_SHOWN` characters.

The result is a TOML document as a dictionary (:class:`Imported`), plus a note
for every place where something was approximated, keyed by the document's
path ("camera", "materials.glass", "shapes[2]"). ``whitted import`` writes it
with the notes as comments; ``whitted render scene.xml`` parses it directly.

Elements outside the subset the tracer renders (rough BSDFs, media,
spectral-only inputs, other sensors, ...) raise :class:`XMLImportError`
naming the element and its line; with ``approximate=True`` those that have a
nearest smooth equivalent (rough conductor -> conductor, and so on) are
mapped onto it, each substitution reported once in :attr:`Imported.warnings`.
"""

from __future__ import annotations

import math
import os
import re
import xml.parsers.expat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from whitted.tracer import faults, spectra
from whitted.tracer import transform as tf
from whitted.tracer.errors import UserError
from whitted.tracer.files import NotRegularFile, read_regular, special_kind
from whitted.tracer.limits import MAX_INCLUDES, MAX_SCENE_BYTES, refuse
from whitted.tracer.mitsuba_ior import IOR

#: The longest value (an attribute, a -D value, a file name) echoed in a message.
VALUE_SHOWN = 60
#: The largest finite float32: numbers beyond it are refused (the tracer and Mitsuba are float32).
FLOAT32_MAX = 3.4028234663852886e38
#: Includes nested deeper than this are refused (a file that includes itself stops here).
MAX_INCLUDE_DEPTH = 16


class XMLImportError(UserError):
    """A Mitsuba XML scene outside the subset, or malformed; names the file, line and element."""


def shown_value(value) -> str:
    """A value as a message echoes it: cut to VALUE_SHOWN characters, with an ellipsis."""
    text = str(value)
    return text if len(text) <= VALUE_SHOWN else text[:VALUE_SHOWN - 3] + "..."


def _cut(value) -> str:
    """:func:`shown_value`, quoted."""
    return repr(shown_value(value))


@dataclass
class Node:
    tag: str
    attrs: dict
    children: list
    line: int
    file: str

    @property
    def type(self) -> str:
        return self.attrs.get("type", "")

    def where(self) -> str:
        t = f' type="{shown_value(self.type)}"' if self.type else ""
        n = f' name="{shown_value(self.attrs["name"])}"' if "name" in self.attrs else ""
        return f"{self.file}:{self.line}: <{shown_value(self.tag)}{t}{n}>"


@dataclass
class Imported:
    """A scene read from Mitsuba XML: the TOML document, and what was approximated."""
    data: dict
    #: TOML path ("camera", "shapes[3]", "materials.glass") -> notes on approximations
    notes: dict = field(default_factory=dict)
    #: one line per kind of substitution made under ``approximate`` (outside the subset)
    warnings: list = field(default_factory=list)
    #: TOML path ("camera", "film", "shapes[3]", "lights[0]", "materials.glass",
    #: "materials.glass.reflectance") -> the XML element it came from ("file:line: <tag ...>")
    origins: dict = field(default_factory=dict)
    #: where Mitsuba's reading departs from the usual meaning of the XML (imported as
    #: Mitsuba reads it, e.g. a rotation about an axis that is not a unit vector)
    cautions: list = field(default_factory=list)

    @property
    def approximate(self) -> bool:
        """Something outside the Whitted subset was replaced by its nearest equivalent."""
        return bool(self.warnings)


# ---------------------------------------------------------------- parsing


def regular_file(path: Path, what: str, where: str) -> tuple[Path, os.stat_result]:
    """``path`` with its symbolic links followed, and its status: it must be a regular file.

    A folder, FIFO, device or socket is refused before it is opened (a FIFO would
    block, /dev/zero never ends); ``what`` names the file in messages ("an include"),
    ``where`` is the message's prefix (the file or the element naming it; with an
    empty ``what`` the file itself)."""
    subject = f"{what} {_cut(path)} " if what else ""
    try:
        real = Path(os.path.realpath(path))
        st = os.stat(real)
    except FileNotFoundError:
        raise XMLImportError(f"{where}: {subject or 'no such file'}"
                             f"{'not found' if subject else ''}") from None
    except (OSError, ValueError) as e:  # a loop of links, a name too long, a NUL in it
        raise XMLImportError(f"{where}: cannot read {subject or 'it '}"
                             f"({getattr(e, 'strerror', None) or e})") from None
    kind = special_kind(st)
    if kind == "a folder":
        raise XMLImportError(f"{where}: {subject}is a folder, expected "
                             f"{'a file' if subject else 'a Mitsuba .xml scene'}")
    if kind is not None:
        raise XMLImportError(f"{where}: {subject}is {kind}, expected a regular file")
    return real, st


class _Budget:
    """What a scene and its includes may read together: WHITTED_MAX_SCENE_BYTES in all,
    WHITTED_MAX_INCLUDES includes."""

    def __init__(self):
        self.limit = MAX_SCENE_BYTES.value()
        self.bytes_left = self.limit
        self.includes_limit = MAX_INCLUDES.value()
        self.includes = 0

    def include(self, node: Node) -> None:
        self.includes += 1
        if self.includes > self.includes_limit:
            try:
                refuse(MAX_INCLUDES, f"{node.where()}: include number {self.includes:,}")
            except UserError as e:
                raise XMLImportError(str(e)) from None

    def _too_big(self, where: str) -> None:
        try:
            refuse(MAX_SCENE_BYTES, f"{where}: the scene and its includes are larger than "
                                    f"{self.limit:,} bytes in all", f"{self.limit:,}")
        except UserError as e:
            raise XMLImportError(str(e)) from None

    def read(self, path: Path, what: str, where: str) -> bytes:
        """The bytes of a regular file (:func:`regular_file`), within what is left of the
        budget: checked from its size before reading, and the read bounded too (a file
        may grow, or report a wrong size)."""
        real, st = regular_file(path, what, where)
        if st.st_size > self.bytes_left:
            self._too_big(where)
        subject = f"{what} {_cut(path)}" if what else "it"
        try:
            data = read_regular(real, self.bytes_left)
        except NotRegularFile:
            raise XMLImportError(f"{where}: {subject} is no longer a regular file") from None
        except OSError as e:
            raise XMLImportError(f"{where}: cannot read {subject} ({e.strerror or e})") \
                from None
        if len(data) > self.bytes_left:
            self._too_big(where)
        self.bytes_left -= len(data)
        return data


def _parse_file(path: Path, data: bytes) -> Node:
    """The XML text of ``path`` as a tree of Nodes with line numbers (expat, no entities)."""
    parser = xml.parsers.expat.ParserCreate()
    root = Node("#document", {}, [], 0, str(path))
    stack = [root]

    def start(tag, attrs):
        node = Node(tag, dict(attrs), [], parser.CurrentLineNumber, str(path))
        stack[-1].children.append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    # Refuse DTDs and entities: a scene needs neither (and they can expand without bound).
    parser.SetParamEntityParsing(xml.parsers.expat.XML_PARAM_ENTITY_PARSING_NEVER)

    def no_entities(*_):
        raise XMLImportError(f"{path}: XML entity declarations are not accepted in a scene")

    parser.EntityDeclHandler = no_entities
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as e:
        raise XMLImportError(f"{path}:{e.lineno}: not well-formed XML "
                             f"({xml.parsers.expat.ErrorString(e.code)})") from None
    except (LookupError, ValueError) as e:  # encoding="..." that Python does not know
        raise XMLImportError(f"{path}: unsupported XML encoding declaration "
                             f"({shown_value(e)})") from None
    if len(root.children) != 1 or root.children[0].tag != "scene":
        raise XMLImportError(f"{path}: expected a Mitsuba scene (<scene version=...>) as the "
                             "root element")
    return root.children[0]


_PARAM = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


class _Resolver:
    """default/$param substitution, include, path and id lookup, as Mitsuba's parser does."""

    def __init__(self, path: Path, params: dict):
        self.root_dir = Path(os.path.realpath(path)).parent
        self.search = [self.root_dir]
        self.params = dict(params)
        self.ids: dict[str, Node] = {}
        self.depth = 0
        self.budget = _Budget()

    def substitute(self, node: Node) -> None:
        for k, v in node.attrs.items():
            def repl(m, node=node):
                if m.group(1) not in self.params:
                    raise XMLImportError(f"{node.where()}: ${shown_value(m.group(1))} has no "
                                         f"value (no <default> of that name and none given)")
                return str(self.params[m.group(1)])
            node.attrs[k] = _PARAM.sub(repl, v)

    def expand(self, node: Node) -> list[Node]:
        """The node's children with defaults applied, includes spliced, ids recorded."""
        out = []
        for child in node.children:
            if child.tag == "default":
                name, value = child.attrs.get("name"), child.attrs.get("value")
                if name is None or value is None:
                    raise XMLImportError(f"{child.where()}: expected name and value")
                if name not in self.params:  # its value may use the defaults above it
                    self.substitute(child)
                    self.params[name] = child.attrs["value"]
                continue
            self.substitute(child)
            if child.tag == "path":
                self.search.insert(0, (self.root_dir / child.attrs.get("value", "")).resolve())
                continue
            if child.tag == "include":
                out += self._include(child)
                continue
            child.children = self.expand(child)
            if "id" in child.attrs and child.tag not in ("ref", "alias"):
                self.ids[child.attrs["id"]] = child
            if child.tag == "alias":
                if child.attrs.get("id") not in self.ids or "as" not in child.attrs:
                    raise XMLImportError(f"{child.where()}: expected id (of an object "
                                         "declared above) and as")
                self.ids[child.attrs["as"]] = self.ids[child.attrs["id"]]
                continue
            out.append(child)
        return out

    def _include(self, node: Node) -> list[Node]:
        self.depth += 1
        if self.depth > MAX_INCLUDE_DEPTH:
            raise XMLImportError(f"{node.where()}: includes nested more than "
                                 f"{MAX_INCLUDE_DEPTH} deep")
        self.budget.include(node)
        path = self.find(node, node.attrs.get("filename"), "an include")
        scene = _parse_file(path, self.budget.read(path, "the include", node.where()))
        kids = self.expand(scene)
        self.depth -= 1
        return kids

    def find(self, node: Node, name: str | None, what: str = "file") -> Path:
        """A file named in the scene: absolute, or in a folder of <path> or the scene's
        (the first that has it, as Mitsuba's resolver), symbolic links followed; it must
        be a regular file. Files outside the scene's folder are allowed, as in Mitsuba."""
        if not name:
            raise XMLImportError(f"{node.where()}: expected a filename")
        p = Path(name)
        found = p if p.is_absolute() else next(
            (d / p for d in self.search if os.path.lexists(d / p)), None)
        if found is None:
            raise XMLImportError(f"{node.where()}: {what} {_cut(name)} not found (searched "
                                 + ", ".join(shown_value(d) for d in self.search[:4])
                                 + (", ..." if len(self.search) > 4 else "") + ")")
        return regular_file(found, what, node.where())[0]

    def deref(self, node: Node) -> Node:
        if node.tag != "ref":
            return node
        target = self.ids.get(node.attrs.get("id", ""))
        if target is None:
            raise XMLImportError(f"{node.where()}: no object with id "
                                 f"{_cut(node.attrs.get('id', ''))}")
        return target


# ---------------------------------------------------------------- values


_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_INTEGER = re.compile(r"[+-]?\d{1,19}")


def _number(node: Node, text, what: str = "") -> float:
    """A decimal number written in the scene: finite, within float32's range.

    Python's ``float`` would also take "inf", "nan", "1_000" and Unicode digits;
    a scene's numbers are plain decimals (as Mitsuba reads them), and a value
    float32 cannot hold is refused here, naming the element, not later."""
    t = text.strip() if isinstance(text, str) else None
    label = f"{what} " if what else ""
    if t is None or not _NUMBER.fullmatch(t):
        got = "nothing" if not t else _cut(text)
        raise XMLImportError(f"{node.where()}: expected {label}a finite number, got {got}")
    v = float(t)
    if not abs(v) <= FLOAT32_MAX:
        raise XMLImportError(f"{node.where()}: {label}{_cut(t)} is beyond float32's range "
                             f"(up to {FLOAT32_MAX:.4g})")
    return v


def _integer(node: Node, text, what: str = "") -> int:
    """An integer written in the scene: decimal digits only ("1e3" and "2.5" are not), in
    64 bits (Mitsuba's integer properties)."""
    t = text.strip() if isinstance(text, str) else None
    if t is None or not _INTEGER.fullmatch(t) or not -(1 << 63) <= int(t) < (1 << 63):
        label = f"{what} " if what else ""
        got = "nothing" if not t else _cut(text)
        raise XMLImportError(f"{node.where()}: expected {label}an integer, got {got}")
    return int(t)


def _attr_number(node: Node, key: str, default: float) -> float:
    """The attribute ``key`` of ``node`` as a number; ``default`` where it is absent."""
    return _number(node, node.attrs[key], key) if key in node.attrs else default


def _floats(node: Node, text: str | None, n: int | None = None) -> list[float]:
    if text is None:
        raise XMLImportError(f"{node.where()}: expected a value")
    vals = [_number(node, x) for x in re.split(r"[,\s]+", text.strip()) if x]
    if n is not None and len(vals) != n:
        raise XMLImportError(f"{node.where()}: expected {n} numbers, got {_cut(text)}")
    return vals


def _xyz(node: Node, default: float = 0.0) -> list[float]:
    """A point or vector: value="x, y, z", or x= y= z= attributes (missing ones default)."""
    if "value" in node.attrs:
        v = _floats(node, node.attrs["value"])
        return v * 3 if len(v) == 1 else _check_len(node, v, 3)
    return [_attr_number(node, k, default) for k in "xyz"]


def _check_len(node: Node, v: list, n: int) -> list:
    if len(v) != n:
        raise XMLImportError(f"{node.where()}: expected {n} numbers, got {len(v)}")
    return v


#: How far from 1 a rotation axis's length may be and still be read as a unit axis (its
#: three numbers written to 7 or more digits).
UNIT_AXIS = 1e-6


def mitsuba_rotate(axis, angle_deg: float) -> np.ndarray:
    """Mitsuba 3.9.1's ``<rotate>``: Rodrigues' formula with the axis *as written*,
    c I + (1 - c) a a^T + s [a]x (Dr.Jit's ``rotate``; the XML parser does not normalise
    the axis). For a unit axis it is the rotation; otherwise it also scales and shears."""
    a = np.asarray(axis, dtype=np.float64)
    t = math.radians(angle_deg)
    c, s = math.cos(t), math.sin(t)
    ax = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = c * np.eye(3) + (1 - c) * np.outer(a, a) + s * ax
    return m


def unit_axis(axis) -> bool:
    """Is the axis of a ``<rotate>`` a unit vector (then Mitsuba's step is a rotation)?"""
    return abs(math.sqrt(sum(float(x) * float(x) for x in axis)) - 1) <= UNIT_AXIS


def transform_matrix(node: Node) -> np.ndarray:
    """A ``<transform>`` element as a 4x4 matrix: its steps applied first to last."""
    steps = []
    for s in node.children:
        if s.tag == "translate":
            steps.append(tf.translate(_xyz(s)))
        elif s.tag == "scale":
            if "value" in s.attrs:
                steps.append(tf.scale(_xyz(s)))
            else:
                steps.append(tf.scale([_attr_number(s, k, 1.0) for k in "xyz"]))
        elif s.tag == "rotate":
            axis = _xyz(s)
            if not any(axis):
                raise XMLImportError(f"{s.where()}: a rotation needs a non-zero axis")
            angle = _attr_number(s, "angle", 0.0)
            steps.append(tf.rotate(axis, angle) if unit_axis(axis) else
                         mitsuba_rotate(axis, angle))
        elif s.tag == "matrix":
            v = _floats(s, s.attrs.get("value"))
            if len(v) == 9:  # a 3x3 matrix (Mitsuba accepts it for to_uv)
                m = np.eye(4)
                m[:3, :3] = np.reshape(v, (3, 3))
            else:
                m = np.reshape(_check_len(s, v, 16), (4, 4))
            steps.append(m)
        elif s.tag == "lookat":
            origin = _floats(s, s.attrs.get("origin"), 3)
            target = _floats(s, s.attrs.get("target"), 3)
            up = _floats(s, s.attrs.get("up", "0, 1, 0"), 3)
            if np.allclose(origin, target):
                raise XMLImportError(f"{s.where()}: origin and target are the same point")
            steps.append(tf.look_at(origin, target, up))
        else:
            raise XMLImportError(f"{s.where()}: unknown transform step (expected translate, "
                                 "rotate, scale, matrix or lookat)")
    return tf.compose(in_order(steps))


def in_order(steps: list) -> list:
    """A ``<transform>``'s steps in the order Mitsuba applies them: as written, the first
    step first (its parser multiplies each new step on the left)."""
    reverse = len(steps) > 1 and faults.on("xml-steps-reversed")
    return steps[::-1] if reverse else steps


# ---------------------------------------------------------------- the importer


#: BSDFs outside the subset -> (nearest smooth kind, what is lost): used with ``approximate``.
APPROXIMATIONS = {
    "roughconductor": ("conductor", "its roughness (a smooth conductor instead)"),
    "roughdielectric": ("dielectric", "its roughness (a smooth dielectric instead)"),
    "roughplastic": ("plastic", "its roughness (a smooth plastic instead)"),
    "principled": ("diffuse", "all but base_color (a diffuse of that colour instead)"),
    "principledthin": ("diffuse", "all but base_color (a diffuse of that colour instead)"),
    "bumpmap": ("inner", "the bump map (the BSDF it wraps instead)"),
    "normalmap": ("inner", "the normal map (the BSDF it wraps instead)"),
}


#: How Mitsuba's plugins read a spectrum property, by its name (src/emitters/*.cpp read these
#: with get_emissive_texture, src/bsdfs/conductor.cpp eta and k with get_unbounded_texture;
#: every other colour is read with get_texture, as a reflectance): tracer/spectra.py.
SPECTRUM_KINDS = {
    "radiance": spectra.ILLUMINANT,
    "intensity": spectra.ILLUMINANT,
    "irradiance": spectra.ILLUMINANT,
    "eta": spectra.UNBOUNDED,
    "k": spectra.UNBOUNDED,
}

#: Mitsuba BSDF plugin -> the importer's method that maps it (one line per plugin).
BSDFS = {
    "twosided": "_twosided",
    "mask": "_mask",
    "diffuse": "_diffuse",
    "dielectric": "_dielectric",
    "thindielectric": "_thindielectric",
    "conductor": "_conductor",
    "plastic": "_plastic",
    "whitted_phong": "_whitted_phong",
    "blendbsdf": "_blendbsdf",
}

#: Mitsuba emitter plugin (outside shapes) -> the importer's method that maps it.
LIGHTS = {
    "point": "_point",
    "spot": "_spot",
    "directional": "_directional",
    "constant": "_constant",
    "envmap": "_envmap",
    "projector": "_projector",
    "whitted_background": "_whitted_background",
}


#: Mitsuba shape plugin -> the importer's method that maps it (one line per plugin; an
#: ``instance`` of a ``shapegroup`` is the importer's own, :meth:`_Importer.shape`).
SHAPES = {
    "sphere": "_sphere",
    "rectangle": "_placed",
    "disk": "_placed",
    "cube": "_placed",
    "cylinder": "_cylinder",
    "obj": "_mesh_file",
    "ply": "_mesh_file",
    "serialized": "_serialized",
}


class _Importer:
    def __init__(self, path: Path, approximate: bool, params: dict, convert=None):
        self.convert = convert
        self.path = path
        self.approximate = approximate
        self.res = _Resolver(path, params)
        self.out: dict = {"film": {}, "camera": {}, "materials": {}, "lights": [],
                          "shapes": []}
        self.notes: dict[str, list[str]] = {}
        self.origins: dict[str, str] = {}
        self.cautions: list[str] = []
        self.warnings: list[str] = []
        self._warned: set[str] = set()
        self.material_ids: dict[int, str] = {}   # id(bsdf node) -> material name
        self.groups: dict[str, list] = {}
        self.emitter_owner: dict[int, str] = {}  # id(area emitter node) -> its shape's place
        self.loose_area: list[Node] = []         # area emitters declared outside a shape

    # -------------------------------------------------------------- helpers

    def note(self, where: str, text: str) -> None:
        lst = self.notes.setdefault(where, [])
        if text not in lst:
            lst.append(text)

    def caution(self, node: Node, text: str) -> None:
        """Say where Mitsuba's reading departs from the usual meaning (imported as Mitsuba
        reads it; not an approximation)."""
        line = f"{node.where()}: {text}"
        if line not in self.cautions:
            self.cautions.append(line)

    def outside(self, node: Node, what: str, nearest: str | None, where: str) -> None:
        """Refuse an element outside the subset, or note its substitute under ``approximate``."""
        if not self.approximate or nearest is None:
            hint = f"; --approximate maps it to {nearest}" if nearest else ""
            raise XMLImportError(f"{node.where()}: {what} is outside what the Whitted tracer "
                                 f"renders{hint}")
        key = f"{node.tag} {node.type} -> {nearest}"
        if key not in self._warned:
            self._warned.add(key)
            self.warnings.append(f"{node.where()}: {what} approximated by {nearest} "
                                 "(further ones alike not repeated)")
        self.note(where, f"approximated: {what} -> {nearest} (line {node.line})")

    def props(self, node: Node) -> dict:
        """Named property children: name -> Node (objects and values alike)."""
        out = {}
        for c in node.children:
            name = c.attrs.get("name")
            if name is not None:
                out[name] = c
        return out

    def number(self, node: Node | None, default=None):
        """A <float> or <integer> property: a float or an int (checked: :func:`_number`)."""
        if node is None:
            return default
        if node.tag not in ("float", "integer"):
            raise XMLImportError(f"{node.where()}: expected <float> or <integer>")
        if node.tag == "integer":
            return _integer(node, node.attrs.get("value"))
        return _number(node, node.attrs.get("value"))

    def integer(self, node: Node | None, default: int | None = None) -> int | None:
        """An <integer> property (a <float> of a whole value is taken too)."""
        v = self.number(node, default)
        if isinstance(v, float):
            if v != int(v):
                raise XMLImportError(f"{node.where()}: expected an integer, got "
                                     f"{_cut(node.attrs.get('value'))}")
            v = int(v)
        return v

    def string(self, node: Node | None, default=None):
        return default if node is None else node.attrs.get("value", "")

    def boolean(self, node: Node | None, default=None):
        if node is None:
            return default
        return node.attrs.get("value", "").strip().lower() == "true"

    def color(self, node: Node | None, where: str, default=None):
        """rgb, spectrum (one value), float, or a texture: a colour or a texture table."""
        if node is None:
            return default
        node = self.res.deref(node)
        if node.tag == "rgb":
            vals = _floats(node, node.attrs.get("value", ""))
            return vals * 3 if len(vals) == 1 else _check_len(node, vals, 3)
        if node.tag in ("float", "integer"):
            return [float(self.number(node))] * 3
        if node.tag == "spectrum":
            return self.spectrum(node, where)
        if node.tag == "texture":
            return self.texture(node, where)
        raise XMLImportError(f"{node.where()}: expected a colour (rgb, spectrum, float) or a "
                             "texture")

    def spectrum(self, node: Node, where: str) -> list[float]:
        """A <spectrum> as the colour Mitsuba 3.9.1's RGB variants make of it
        (:mod:`tracer.spectra`): as a reflectance, an illuminant or an unbounded value,
        by the property it gives (:data:`SPECTRUM_KINDS`)."""
        if "filename" in node.attrs or node.type:
            what = "a spectrum from a file" if "filename" in node.attrs else \
                f'a spectrum plugin "{shown_value(node.type)}"'
            self.outside(node, f"{what} (spectral-only input)", None, where)
        kind = SPECTRUM_KINDS.get(node.attrs.get("name", ""), spectra.REFLECTANCE)
        try:
            parsed = spectra.parse(node.attrs.get("value", ""))
        except ValueError as e:
            raise XMLImportError(f"{node.where()}: {e}") from None
        if isinstance(parsed, float):
            return list(spectra.uniform_to_rgb(parsed, kind))
        wavelengths, values = parsed
        if spectra.out_of_gamut(wavelengths, values, kind):
            self.note(where, f"the spectrum of line {node.line} is out of gamut: clamped as "
                             "Mitsuba clamps it")
        return list(spectra.to_rgb(wavelengths, values, kind))

    def texture(self, node: Node, where: str):
        p = self.props(node)
        if "name" in node.attrs:
            self.origins.setdefault(f"{where}.{node.attrs['name']}", node.where())
        if node.type == "checkerboard":
            tex = {"color0": self.color(p.get("color0"), where, [0.4] * 3),
                   "color1": self.color(p.get("color1"), where, [0.2] * 3)}
            if "to_uv" in p:
                m = transform_matrix(p["to_uv"])
                if not np.allclose(m[:2, 2:], 0) or not np.allclose(m[:2, :2],
                                                                     np.diag(np.diag(m[:2, :2]))):
                    self.outside(p["to_uv"], "a to_uv that is not a scale", None, where)
                tex["scale"] = [float(m[0, 0]), float(m[1, 1])]
            return {"checkerboard": tex}
        if node.type == "bitmap":
            fname = self.string(p.get("filename"))
            bm = {"filename": str(self.res.find(node, fname, "image"))}
            for k in ("filter_type", "wrap_mode"):
                if k in p:
                    bm[k] = self.string(p[k])
            if "raw" in p:
                bm["raw"] = self.boolean(p["raw"])
            if "to_uv" in p and not faults.on("xml-to-uv-dropped"):
                # Mitsuba's bitmap: the 4x4's 2D affine part (x, y, translation)
                m = transform_matrix(p["to_uv"])
                rows = [[float(m[i, 0]), float(m[i, 1]), float(m[i, 3])] for i in (0, 1)]
                if rows != [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]:
                    bm["to_uv"] = rows
            return {"bitmap": bm}
        self.outside(node, f'texture "{shown_value(node.type)}"', None, where)

    def to_world(self, node: Node | None) -> list:
        """A to_world as a list of steps: the XML's own translate/rotate/scale steps in its
        order (which is the scene format's: first step first), else one matrix step."""
        if node is None:
            return []
        steps = []
        for s in node.children:
            if s.tag == "translate":
                steps.append({"translate": _xyz(s)})
            elif s.tag == "scale":
                v = _xyz(s) if "value" in s.attrs else \
                    [_attr_number(s, k, 1.0) for k in "xyz"]
                steps.append({"scale": v[0] if len(set(v)) == 1 else v})
            elif s.tag == "rotate":
                axis, angle = _xyz(s), _attr_number(s, "angle", 0.0)
                if not any(axis):
                    raise XMLImportError(f"{s.where()}: a rotation needs a non-zero axis")
                if unit_axis(axis) or faults.on("xml-rotate-axis-normalised"):
                    steps.append({"rotate": {"axis": axis, "angle": angle}})
                    continue
                self.caution(s, f"a rotation axis of length "
                                f"{math.sqrt(sum(x * x for x in axis)):.6g}: Mitsuba 3.9.1 does "
                                "not normalise it, so the step also scales and shears (Rodrigues' "
                                "formula with the axis as written); imported as Mitsuba's matrix, "
                                "not as the rotation the usual meaning would give")
                m = mitsuba_rotate(axis, angle)
                steps.append({"matrix": [[float(x) for x in row] for row in m]})
            else:
                break
        else:
            return in_order(steps)
        m = transform_matrix(node)
        return [{"matrix": [[float(x) for x in row] for row in m]}]

    def ior(self, node: Node | None, default: float, where: str) -> float:
        if node is None:
            return default
        if node.tag == "string":
            name = node.attrs.get("value", "").strip().lower()
            if name not in IOR:
                raise XMLImportError(f"{node.where()}: unknown IOR name {_cut(name)} (known: "
                                     + ", ".join(IOR) + ")")
            self.note(where, f"{node.attrs.get('name')} = \"{name}\": Mitsuba's table "
                             f"({IOR[name]})")
            return IOR[name]
        return float(self.number(node))

    # -------------------------------------------------------------- scene

    def run(self) -> Imported:
        scene = _parse_file(self.path, self.res.budget.read(self.path, "", str(self.path)))
        self.res.substitute(scene)
        children = self.res.expand(scene)
        sensors = [c for c in children if c.tag == "sensor"]
        for c in children:
            if c.tag == "shape" and c.type == "shapegroup":
                self.shapegroup(c)
        for c in children:
            if c.tag == "sensor":
                if c is not sensors[0]:
                    self.note("camera", f"only the first sensor is imported (line {c.line} "
                                        "ignored)")
                    continue
                self.sensor(c)
            elif c.tag == "integrator":
                self.integrator(c)
            elif c.tag == "emitter":
                self.light(c)
            elif c.tag == "shape":
                if c.type != "shapegroup":
                    self.shape(c, self.out["shapes"], f"shapes[{len(self.out['shapes'])}]")
            elif c.tag in ("bsdf", "texture", "spectrum", "rgb"):
                continue  # declared for reference; imported where used
            elif c.tag in ("medium", "phase", "volume"):
                self.outside(c, "a participating medium", None, "")
            else:
                raise XMLImportError(f"{c.where()}: unexpected element in a scene")
        for e in self.loose_area:  # Mitsuba loads it and ignores it
            if id(e) not in self.emitter_owner:
                self.note("lights", f"the area emitter of line {e.line} belongs to no shape "
                                    "(Mitsuba ignores it too)")
        if not sensors:
            raise XMLImportError(f"{self.path}: no <sensor>; the scene format needs a camera")
        if "max_depth" not in self.out["film"]:
            self.out["film"]["max_depth"] = 2
            self.note("film", "no integrator: Mitsuba's default path tracer; Whitted's "
                              "light at the first hit (max_depth 2)")
        if self.groups:
            self.out["groups"] = {k: {"shapes": v} for k, v in self.groups.items()}
        data = {k: v for k, v in self.out.items() if v or k in ("film", "camera")}
        data["description"] = f"Imported from Mitsuba XML {self.path.name}"
        notes = {k: v for k, v in self.notes.items() if v}
        return Imported(data, notes, self.warnings, self.origins, self.cautions)

    def integrator(self, node: Node) -> None:
        p = self.props(node)
        if node.type in ("moment", "aov"):  # wrappers: the integrator inside renders
            inner = [c for c in node.children if c.tag == "integrator"]
            if inner:
                self.integrator(inner[0])
            return
        film = self.out["film"]
        if node.type == "direct":
            film["max_depth"] = 2
        elif node.type in ("path", "whitted"):
            depth = self.integer(p.get("max_depth"), -1)
            if depth < -1:
                raise XMLImportError(f"{p['max_depth'].where()}: expected -1 (unbounded) or "
                                     f"a max_depth of at least 0, got {depth}")
            if depth < 0:
                film["max_depth"] = 8
                self.note("film", "max_depth -1 (unbounded) becomes 8 specular bounces")
            else:
                film["max_depth"] = max(int(depth), 1)
            if node.type == "path" and film["max_depth"] > 2:
                self.note("film", "Mitsuba's path integrator also follows diffuse bounces; "
                                  "Whitted's tracer follows only specular ones")
        else:
            self.outside(node, f'integrator "{shown_value(node.type)}"',
                         "Whitted's (max_depth as given)", "film")
            film["max_depth"] = self.integer(p.get("max_depth"), 2)

    def sensor(self, node: Node) -> None:
        p = self.props(node)
        cam: dict = self.out["camera"]
        kind = node.type
        self.origins["camera"] = node.where()
        if kind == "thinlens":
            self.outside(node, "a thin-lens camera (depth of field)", "a pinhole perspective",
                         "camera")
            kind = "perspective"
        if kind not in ("perspective", "orthographic"):
            self.outside(node, f'sensor "{shown_value(kind)}"', None, "camera")
        cam["type"] = kind
        film = [c for c in node.children if c.tag == "film"]
        sampler = [c for c in node.children if c.tag == "sampler"]
        width, height = self.film(film[0] if film else None)
        m = transform_matrix(p["to_world"]) if "to_world" in p else np.eye(4)
        single_lookat = ("to_world" in p and len(p["to_world"].children) == 1 and
                         p["to_world"].children[0].tag == "lookat")
        if single_lookat:  # the common case, in the scene format's own words
            la = p["to_world"].children[0]
            cam["origin"] = _floats(la, la.attrs.get("origin"), 3)
            cam["target"] = _floats(la, la.attrs.get("target"), 3)
            cam["up"] = _floats(la, la.attrs.get("up", "0, 1, 0"), 3)
            if kind == "orthographic":  # Mitsuba's view: [-1, 1] across, unscaled
                cam["width"] = 2.0
        else:
            cam["to_world"] = [{"matrix": [[float(x) for x in row] for row in m]}]
        for k in ("near_clip", "far_clip"):
            if k in p:
                cam[k] = float(self.number(p[k]))
        if kind == "perspective":
            cam.update(self.field_of_view(node, p, "camera"))
            for k in ("principal_point_offset_x", "principal_point_offset_y"):
                if k in p:
                    cam[k] = float(self.number(p[k]))
        self.sampler(sampler[0] if sampler else None)
        del width, height

    def film(self, node: Node | None) -> tuple[int, int]:
        film = self.out["film"]
        p = self.props(node) if node is not None else {}
        if node is not None:
            self.origins["film"] = node.where()
        if node is not None and node.type != "hdrfilm":
            self.outside(node, f'film "{shown_value(node.type)}"', "hdrfilm", "film")
        film["width"] = self.integer(p.get("width"), 768)
        film["height"] = self.integer(p.get("height"), 576)
        for k in ("crop_width", "crop_height", "crop_offset_x", "crop_offset_y"):
            if k in p:
                self.outside(p[k], "a cropped film", None, "film")
        if self.boolean(p.get("sample_border"), False):
            self.note("film", "sample_border: samples outside the film are not taken")
        rf = [c for c in (node.children if node is not None else []) if c.tag == "rfilter"]
        rtype = rf[0].type if rf else "gaussian"
        if rtype == "box":
            film["filter"] = "box"
        elif rtype == "tent":
            film["filter"] = "tent"
            radius = self.number(self.props(rf[0]).get("radius"), 1.0)
            if radius != 1.0:
                film["radius"] = float(radius)
        else:
            if rtype != "gaussian":
                self.outside(rf[0], f'pixel filter "{shown_value(rtype)}"',
                             "a gaussian (stddev 0.5)", "film")
            film["filter"] = "gaussian"
            stddev = self.number(self.props(rf[0]).get("stddev"), 0.5) if rf and \
                rtype == "gaussian" else 0.5
            film["stddev"] = float(stddev)
        return film["width"], film["height"]

    def sampler(self, node: Node | None) -> None:
        film = self.out["film"]
        p = self.props(node) if node is not None else {}
        count = self.integer(p.get("sample_count"), 4)
        if count < 1:
            raise XMLImportError(f"{p['sample_count'].where()}: expected a sample_count of at "
                                 f"least 1, got {count}")
        n = math.isqrt(count)
        if n * n != count:
            n += 1
            self.note("film", f"sample_count {count} rounded up to {n * n} ({n}x{n} strata)")
        film["spp"] = n * n
        kind = node.type if node is not None else "independent"
        if kind == "stratified":
            film["jitter"] = bool(self.boolean(p.get("jitter"), True))
        else:
            film["jitter"] = True
            self.note("film", f'sampler "{shown_value(kind)}": jittered strata (the same expected '
                              "image, another noise)")

    # -------------------------------------------------------------- BSDFs

    def material(self, node: Node, where: str) -> str:
        """The material of a <bsdf> (or ref): its name in [materials], imported once."""
        node = self.res.deref(node)
        key = id(node)
        if key in self.material_ids:
            return self.material_ids[key]
        base = re.sub(r"[^A-Za-z0-9_-]", "_", node.attrs.get("id", "")) or node.type
        name, i = base, 1
        while name in self.out["materials"]:
            i += 1
            name = f"{base}_{i}"
        self.material_ids[key] = name
        self.origins[f"materials.{name}"] = node.where()
        self.out["materials"][name] = self.bsdf(node, f"materials.{name}", two_sided=False)
        return name

    def bsdf(self, node: Node, where: str, two_sided: bool) -> dict:
        """A <bsdf> as a [materials] table, through the table of Mitsuba plugins (BSDFS)."""
        p = self.props(node)
        kind = node.type
        if kind in APPROXIMATIONS and APPROXIMATIONS[kind] is not None:
            nearest, lost = APPROXIMATIONS[kind]
            if nearest == "inner":
                self.outside(node, f'a "{shown_value(kind)}" BSDF', "the BSDF it wraps", where)
                return self.bsdf(self._inner(node), where, two_sided)
            self.outside(node, f'a "{shown_value(kind)}" BSDF ({lost.split(" (")[0]} lost)',
                         f'a smooth "{nearest}"', where)
            if nearest == "diffuse":
                colour = p.get("base_color") or p.get("reflectance")
                return self._sided({"type": "diffuse",
                                    "reflectance": self.color(colour, where, [0.5] * 3)},
                                   two_sided)
            kind = nearest
        if kind not in BSDFS:
            self.outside(node, f'a "{shown_value(kind)}" BSDF', None, where)
        return getattr(self, BSDFS[kind])(node, p, where, two_sided)

    def _inner(self, node: Node) -> Node:
        inner = [c for c in node.children if c.tag in ("bsdf", "ref")]
        if len(inner) != 1:
            raise XMLImportError(f"{node.where()}: expected one nested BSDF")
        return self.res.deref(inner[0])

    def _twosided(self, node, p, where, two_sided):
        inner = [c for c in node.children if c.tag in ("bsdf", "ref")]
        if len(inner) == 2:
            self.outside(node, "a twosided BSDF with different front and back BSDFs", None,
                         where)
        nested = self._inner(node)
        # Mitsuba's twosided refuses transmission ("Only materials without a transmission
        # component can be nested!"), and with allow_transmission reads the back side as
        # the front, which a dielectric or a mask is not: refused here either way.
        if nested.type in ("dielectric", "thindielectric", "mask"):
            self.outside(node, f'a twosided around "{shown_value(nested.type)}" (a BSDF with '
                               "transmission, which Mitsuba's twosided refuses)", None, where)
        return self.bsdf(nested, where, two_sided=True)

    def _mask(self, node, p, where, two_sided):
        out = self.bsdf(self._inner(node), where, two_sided)
        opacity = self.scalar_or_color(p.get("opacity"), where, 0.5)
        if isinstance(opacity, dict) and "checkerboard" in opacity:
            # Mitsuba's checkerboard swaps its colours in eval_1, the one-value lookup
            # the mask reads its opacity with (src/textures/checkerboard.cpp): the scene
            # format's checkerboard is the one Mitsuba renders with them swapped back.
            board = opacity["checkerboard"]
            board["color0"], board["color1"] = board["color1"], board["color0"]
        out["opacity"] = opacity
        return out

    def _diffuse(self, node, p, where, two_sided):
        return self._sided({"type": "diffuse",
                            "reflectance": self.color(p.get("reflectance"), where, [0.5] * 3)},
                           two_sided)

    def _dielectric(self, node, p, where, two_sided):
        for k in ("specular_reflectance", "specular_transmittance"):
            if k in p and self.color(p[k], where) != [1.0] * 3:
                self.outside(p[k], f"a dielectric's {k} other than 1", None, where)
        return {"type": "dielectric", "ior": self.ior(p.get("int_ior"), 1.5046, where),
                "ext_ior": self.ior(p.get("ext_ior"), 1.000277, where)}

    def _thindielectric(self, node, p, where, two_sided):
        return {"type": "thindielectric", "ior": self.ior(p.get("int_ior"), 1.5046, where),
                "ext_ior": self.ior(p.get("ext_ior"), 1.000277, where)}

    def _conductor(self, node, p, where, two_sided):
        spec = self.color(p.get("specular_reflectance"), where, [1.0] * 3)
        mat = self.string(p.get("material"), "none" if "eta" not in p else None)
        if mat == "none" and "eta" not in p:
            self.note(where, 'conductor with material "none": a perfect mirror')
            return self._sided({"type": "mirror", "reflectance": spec}, two_sided)
        out = {"type": "conductor"}
        if "eta" in p:
            out["eta"] = self.color(p["eta"], where)
            out["k"] = self.color(p.get("k"), where, [0.0] * 3)
        else:
            out["material"] = mat
        if spec != [1.0] * 3:
            out["specular_reflectance"] = spec
        return self._sided(out, two_sided)

    def _whitted_phong(self, node, p, where, two_sided):
        # the tracer's own Phong model, as `whitted export` writes it
        return self._sided({"type": "phong",
                            "diffuse": self.color(p.get("diffuse"), where, [0.5] * 3),
                            "specular": self.color(p.get("specular"), where, [0.2] * 3),
                            # the plugin's default (reference/materials/phong.py), not
                            # the scene format's 32
                            "exponent": float(self.number(p.get("exponent"), 30.0)),
                            "model": self.string(p.get("model"), "phong")}, two_sided)

    def _plastic(self, node, p, where, two_sided):
        out = {"type": "plastic",
               "diffuse_reflectance": self.color(p.get("diffuse_reflectance"), where,
                                                 [0.5] * 3),
               "specular_reflectance": self.color(p.get("specular_reflectance"), where,
                                                  [1.0] * 3),
               "ior": self.ior(p.get("int_ior"), 1.49, where),
               "ext_ior": self.ior(p.get("ext_ior"), 1.000277, where)}
        if self.boolean(p.get("nonlinear"), False):
            out["nonlinear"] = True
        return self._sided(out, two_sided)

    def _blendbsdf(self, node, p, where, two_sided):
        """Mitsuba's blendbsdf of two smooth BSDFs with a constant weight: a "blend"
        (tracer/materials/blend.py); others are refused (--approximate: a diffuse of the
        first BSDF's colour, as before)."""
        inner = [b for b in (self.res.deref(c) for c in node.children
                             if c.tag in ("bsdf", "ref")) if b.tag == "bsdf"]
        weight = p.get("weight")
        weight = self.res.deref(weight) if weight is not None else None
        if len(inner) != 2:
            raise XMLImportError(f"{node.where()}: a blendbsdf needs two nested BSDFs, "
                                 f"got {len(inner)}")
        if weight is None:
            raise XMLImportError(f"{node.where()}: a blendbsdf needs a weight")
        smooth = ("diffuse", "whitted_phong")
        reason = None
        if weight.tag not in ("float", "integer"):
            reason = f"a weight given as <{shown_value(weight.tag)}>, not one number"
        elif not 0 <= self.number(weight) <= 1:
            reason = "a weight outside [0, 1]"
        elif any(b.type not in smooth for b in inner):
            kinds = ", ".join(f'"{shown_value(b.type)}"' for b in inner if b.type not in smooth)
            reason = (f"a blend of {kinds}: only smooth BSDFs (diffuse, whitted_phong) are "
                      "blended, not delta lobes or wrappers")
        if reason is not None:
            self.outside(node, f'a "blendbsdf" BSDF ({reason})', 'a smooth "diffuse"', where)
            colour = self.props(inner[0]).get("reflectance")
            return self._sided({"type": "diffuse",
                                "reflectance": self.color(colour, where, [0.5] * 3)},
                               two_sided)
        parts = {}
        for key, b in zip(("first", "second"), inner, strict=True):
            part = self.bsdf(b, where, two_sided=False)
            part.pop("two_sided", None)
            parts[key] = part
        return self._sided({"type": "blend", **parts, "weight": float(self.number(weight))},
                           two_sided)

    def scalar_or_color(self, node, where, default):
        v = self.color(node, where, [default] * 3)
        return v[0] if isinstance(v, list) and len(set(v)) == 1 else v

    def _sided(self, out: dict, two_sided: bool) -> dict:
        """Mitsuba's bare BSDFs are black from behind; the scene format's default is two-sided."""
        if not two_sided:
            out["two_sided"] = False
        return out

    def field_of_view(self, node: Node, p: dict, where: str) -> dict:
        """``fov`` and ``fov_axis`` of a perspective sensor or a projector, as Mitsuba's
        ``parse_fov`` reads them: ``fov`` along ``fov_axis``, or ``focal_length`` as the
        diagonal field of view of a 35 mm film (36 x 24 mm)."""
        if "fov" in p and "focal_length" in p:
            raise XMLImportError(f"{node.where()}: give fov or focal_length, not both")
        if "fov" in p:
            ignored = "fov_axis" in p and faults.on("xml-fov-axis-ignored")
            return {"fov": float(self.number(p["fov"])),
                    "fov_axis": "x" if ignored else self.string(p.get("fov_axis"), "x").lower()}
        text = self.string(p.get("focal_length"), "50mm")
        f = _number(p.get("focal_length") or node, text.lower().removesuffix("mm"),
                    "focal_length")
        if f <= 0:
            raise XMLImportError(f"{node.where()}: expected a positive focal_length, "
                                 f"got {_cut(text)}")
        self.note(where, f"focal_length {text}: the diagonal field of view of a "
                         "35 mm film (Mitsuba's conversion)")
        return {"fov": math.degrees(2 * math.atan(math.hypot(36, 24) / (2 * f))),
                "fov_axis": "diagonal"}

    # -------------------------------------------------------------- emitters

    def light(self, node: Node) -> None:
        """An <emitter> as a [[lights]] table, through the table of Mitsuba plugins (LIGHTS)."""
        p = self.props(node)
        where = f"lights[{len(self.out['lights'])}]"
        if node.type == "area":  # declared for a shape that takes it by <ref> (run())
            self.loose_area.append(node)
            return
        if node.type not in LIGHTS:
            self.outside(node, f'emitter "{shown_value(node.type)}"', None, where)
        self.origins[where] = node.where()
        m = transform_matrix(p["to_world"]) if "to_world" in p else np.eye(4)
        self.out["lights"].append(getattr(self, LIGHTS[node.type])(node, p, m, where))

    def _point(self, node, p, m, where):
        pos = _xyz(p["position"]) if "position" in p else list(m[:3, 3])
        return {"type": "point", "position": [float(x) for x in pos],
                "intensity": self.color(p.get("intensity"), where, [1.0] * 3)}

    def _spot(self, node, p, m, where):
        cutoff = float(self.number(p.get("cutoff_angle"), 20.0))
        light = {"type": "spot",
                 "position": [float(x) for x in tf.apply_point(m, (0, 0, 0))],
                 "target": [float(x) for x in tf.apply_point(m, (0, 0, 1))],
                 "intensity": self.color(p.get("intensity"), where, [1.0] * 3),
                 "cutoff_angle": cutoff,
                 "beam_width": float(self.number(p.get("beam_width"), cutoff * 0.75))}
        if "texture" in p:
            light["texture"] = self.color(p["texture"], where)
        return light

    def _directional(self, node, p, m, where):
        d = _xyz(p["direction"]) if "direction" in p else tf.apply_vector(m, (0, 0, 1))
        return {"type": "directional", "direction": [float(x) for x in d],
                "irradiance": self.color(p.get("irradiance"), where, [1.0] * 3)}

    def _constant(self, node, p, m, where):
        return {"type": "constant", "radiance": self.color(p.get("radiance"), where, [1.0] * 3)}

    def _envmap(self, node, p, m, where):
        light = {"type": "envmap",
                 "filename": str(self.res.find(node, self.string(p.get("filename")), "image"))}
        if "scale" in p:
            light["scale"] = float(self.number(p["scale"]))
        if "to_world" in p:
            light["to_world"] = self.to_world(p["to_world"])
        return light

    def _projector(self, node, p, m, where):
        light = {"type": "projector",
                 "irradiance": self.color(p.get("irradiance"), where, [1.0] * 3),
                 **self.field_of_view(node, p, where)}
        if "scale" in p:
            light["scale"] = float(self.number(p["scale"]))
        if "to_world" in p:
            light["to_world"] = self.to_world(p["to_world"])
        return light

    def _whitted_background(self, node, p, m, where):
        # the tracer's background, as `whitted export` writes it
        return {"type": "background",
                "radiance": self.color(p.get("radiance"), where, [1.0] * 3)}

    # -------------------------------------------------------------- shapes

    def shapegroup(self, node: Node) -> None:
        gid = node.attrs.get("id")
        if not gid:
            raise XMLImportError(f"{node.where()}: a shapegroup needs an id")
        members: list = []
        for c in node.children:
            if c.tag == "shape":
                self.shape(c, members, f"groups.{gid}.shapes[{len(members)}]", in_group=True)
        self.groups[gid] = members

    def shape(self, node: Node, out: list, where: str, in_group: bool = False) -> None:
        node = self.res.deref(node)
        p = self.props(node)
        kind = node.type
        shape: dict = {}
        self.origins[where] = node.where()
        if kind == "instance":
            refs = [self.res.deref(c) for c in node.children if c.tag in ("ref", "shape")]
            gid = refs[0].attrs.get("id") if refs else None
            if gid not in self.groups:
                raise XMLImportError(f"{node.where()}: an instance must reference a shapegroup")
            shape = {"type": "instance", "group": gid}
            shape["to_world"] = self.to_world(p.get("to_world"))
            out.append(shape)
            return
        method = SHAPES.get(kind)
        if method is None:
            self.outside(node, f'shape "{shown_value(kind)}"', None, where)
        else:
            shape = getattr(self, method)(node, p, where)
        if "flip_normals" in p and kind != "obj" and kind != "ply" and \
                self.boolean(p["flip_normals"], False):
            self.outside(p["flip_normals"], "flip_normals", None, where)
        steps = self.to_world(p.get("to_world"))
        if steps:
            shape["to_world"] = steps
        bsdfs = [c for c in node.children if c.tag in ("bsdf",) or
                 (c.tag == "ref" and self.res.deref(c).tag == "bsdf")]
        # an emitter inside the shape, or one declared with an id and taken by <ref>
        emitters = [e for e in (self.res.deref(c) for c in node.children
                                if c.tag in ("emitter", "ref")) if e.tag == "emitter"]
        if bsdfs:
            shape["material"] = self.material(bsdfs[0], where)
        elif not emitters:  # Mitsuba gives a shape without a BSDF a grey diffuse one
            shape["material"] = self._default_material()
        if emitters:
            e = emitters[0]
            if e.type != "area":
                self.outside(e, f'emitter "{shown_value(e.type)}" on a shape', None, where)
            if len(emitters) > 1:
                raise XMLImportError(f"{emitters[1].where()}: a shape takes one area emitter "
                                     "(Mitsuba refuses a second)")
            if id(e) in self.emitter_owner:  # Mitsuba: "An endpoint can be only be attached
                raise XMLImportError(        # to a single shape"
                    f"{node.where()}: the area emitter of line {e.line} is already the "
                    f"emitter of {self.emitter_owner[id(e)]} (Mitsuba attaches an emitter "
                    "to one shape only)")
            self.emitter_owner[id(e)] = where
            shape["emitter"] = {"radiance": self.color(self.props(e).get("radiance"), where,
                                                       [1.0] * 3)}
            if not bsdfs:
                shape["material"] = self._default_material()
        out.append(shape)

    # Each Mitsuba shape plugin of SHAPES: (node, its properties, the TOML path) -> the
    # shape's table, without what every shape has (to_world, bsdf, emitter: shape()).

    def _sphere(self, node: Node, p: dict, where: str) -> dict:
        shape: dict = {"type": "sphere"}
        if "center" in p:
            shape["center"] = _xyz(p["center"])
        if "radius" in p:
            shape["radius"] = float(self.number(p["radius"]))
        return shape

    def _placed(self, node: Node, p: dict, where: str) -> dict:
        return {"type": node.type}   # rectangle, disk, cube: all in to_world

    def _cylinder(self, node: Node, p: dict, where: str) -> dict:
        shape: dict = {"type": "cylinder"}
        for k in ("p0", "p1"):
            if k in p:
                shape[k] = _xyz(p[k])
        if "radius" in p:
            shape["radius"] = float(self.number(p["radius"]))
        return shape

    def _mesh_file(self, node: Node, p: dict, where: str) -> dict:
        shape: dict = {"type": "mesh"}
        shape["file"] = str(self.res.find(node, self.string(p.get("filename")), "mesh file"))
        shape["smooth"] = not self.boolean(p.get("face_normals"), False)
        triangle = _single_triangle(Path(shape["file"]))
        if triangle is not None and not shape["smooth"]:  # one flat face: a triangle
            shape = {"type": "triangle", "vertices": triangle}
        if self.boolean(p.get("flip_normals"), False):
            self.outside(p["flip_normals"], "flip_normals on a mesh", None, where)
        return shape

    def _serialized(self, node: Node, p: dict, where: str) -> dict:
        if self.convert is None:
            self.outside(node, "a serialized mesh (`whitted import` converts it through "
                               "Mitsuba; render the imported TOML)", None, where)
            return {}
        source = self.res.find(node, self.string(p.get("filename")), "serialized mesh")
        index = self.integer(p.get("shape_index"), 0)
        if index < 0:
            raise XMLImportError(f"{node.where()}: expected a shape_index of at least 0, "
                                 f"got {index}")
        shape: dict = {"type": "mesh"}
        try:
            shape["file"] = str(self.convert(source, index))
        except UserError as e:  # the file is not a mesh Mitsuba reads, or too large
            raise XMLImportError(f"{node.where()}: {e}") from None
        shape["smooth"] = not self.boolean(p.get("face_normals"), False)
        self.note(where, f"serialized mesh {source.name} converted by Mitsuba to "
                         f"{Path(shape['file']).name}")
        return shape

    def _default_material(self) -> str:
        mats = self.out["materials"]
        if "default" not in mats:
            mats["default"] = {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5],
                               "two_sided": False}
            self.note("materials.default", "Mitsuba's default BSDF of a shape without one "
                                           "(a one-sided diffuse of reflectance 0.5)")
        return "default"


def _single_triangle(path: Path) -> list | None:
    """The three vertices of a mesh file with exactly one triangle (else None)."""
    from whitted.tracer.meshio import MeshError, load_mesh

    try:
        if path.stat().st_size > 4096:  # a one-face mesh is a few lines
            return None
        data = load_mesh(path)
    except (MeshError, OSError):
        return None
    if len(data.faces) != 1:
        return None
    return [[float(x) for x in data.vertices[i]] for i in data.faces[0]]


def read_xml(path: str | Path, approximate: bool = False, convert=None,
             **params) -> Imported:
    """A Mitsuba 3 XML scene as a scene-format document (see the module's docstring).

    ``params``: values for the file's ``$name`` parameters (they override its
    ``<default>``s), as ``mi.load_file(path, name=value)`` takes them. ``convert``:
    ``convert(serialized_file, shape_index) -> mesh file`` for Mitsuba's
    ``serialized`` meshes (the importer's, through Mitsuba); without it they are
    refused.
    """
    try:
        return _Importer(Path(path), approximate, params, convert).run()
    except RecursionError:
        raise XMLImportError(f"{path}: elements nested too deeply") from None
