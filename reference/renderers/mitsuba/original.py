"""The original Mitsuba XML judges every import: Mitsuba's reading of the original file
against Mitsuba's reading of the import, object by object.

``whitted compare scene.xml`` renders the *import* on both sides, so it cannot see
an importer bug: a dropped ``to_uv``, a transform composed the wrong way round or
an ignored ``fov_axis`` changes both images alike. This module loads the original
with ``mi.load_file`` (with the ``-D`` values) and the import's conversion to
Mitsuba (:func:`reference.renderers.mitsuba.scene.load`, what ``compare`` renders)
and compares what Mitsuba made of each, through ``mi.traverse`` and the objects:

* the sensor: ``to_world`` (its matrix and inverse transpose), the horizontal field of
  view (``x_fov``, which ``fov`` and ``fov_axis`` become), clip planes, principal point
  offsets, the film's size, crop size and offset, the filter (its kind and radius);
* every shape (matched between the two by kind and bounding box: Mitsuba keeps
  neither the file's order nor an id for unnamed shapes): its bounding box and every
  parameter ``mi.traverse`` gives (meshes: the world-space ``vertex_positions``,
  ``vertex_normals``, ``vertex_texcoords`` and ``faces``; analytic shapes and
  instances: ``to_world``), its area emitter's parameters, and its BSDF's kind and
  parameters (reflectance values, texture data and the texture's ``to_uv``, ``eta``, ...);
* every other emitter (matched by kind and parameters): its parameters (intensity,
  radiance, position, ``to_world``, direction, cutoff angle, envmap data, scale).

Tolerance (:data:`REL_TOL`): both readings hold float32 values (unit roundoff
u = 2^-24 = 6.0e-8). Mitsuba composes a ``<transform>``'s steps in float32; the import
composes them in float64 and Mitsuba rounds the result once. Each 4x4 product adds at
most 4u relative to the largest term it sums, so a matrix of k steps, then a vertex
through it, differ by at most about 4 (k + 1) u of the largest magnitude involved:
with k <= 40 steps, 1e-5 of the largest absolute value in the compared array (of the
matrix, the vertex buffer, the colour). Lookat frames and Mitsuba's own conversions
(fov, filter radius) add a few more roundings, well inside. Integer data (faces,
8-bit texels) must match exactly (1e-5 of 255 is below one step). Every planted
importer bug of the tests changes some value by far more than that.

Parts that the import *approximated* (``--approximate``: a rough BSDF made smooth, a
spectrum averaged) are not compared: Mitsuba's reading of them differs by design.
They are listed in :attr:`Structure.approximated`.

The images: :func:`original_reference` evaluates the deterministic reference on
Mitsuba's own reading of the original (at the tracer's sample positions) and
:func:`judge_against_original` judges the tracer's render of the import against it,
for ``compare`` and ``check`` of a scene given as XML; where the deterministic
reference cannot take the tracer's light samples, ``compare`` falls back on Mitsuba's
own render of the original at max_depth 2
(:func:`reference.renderers.mitsuba.importer.validate_case`, the report's "imported"
group).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from whitted.tracer.errors import UserError, one_line

#: Relative tolerance of a compared value: 1e-5 of the largest magnitude in the array
#: (float32 rounding of up to ~40 composed transform steps; the module's docstring).
REL_TOL = 1e-5

#: traverse keys that are not the scene's structure (sampling weights are Mitsuba's
#: own bookkeeping); keys under "bsdf." and "emitter." are compared with their object.
IGNORED_KEYS = ("silhouette_sampling_weight", "sampling_weight", "shutter_open",
                "shutter_open_time")

#: Parameters Mitsuba's traverse leaves out when they hold its default: absent on one
#: side, the other side's value is compared with this.
DEFAULTS = {"specular_reflectance.value": 1.0, "specular_transmittance.value": 1.0}

#: How many differences one array reports at most (the first ones; the count is given).
SHOWN = 3


@dataclass(frozen=True)
class Finding:
    """One difference between Mitsuba's reading of the original and of the import."""
    element: str     # the XML element ("file:line: <shape type=...>") or a description
    what: str        # the compared quantity ("to_world", "bsdf reflectance.to_uv", ...)
    original: str    # Mitsuba's reading of the original file
    imported: str    # Mitsuba's reading of the import
    #: how many times the largest difference exceeds its tolerance (REL_TOL x the array's
    #: scale); infinite where the two differ in kind, size or text, not in a number
    excess: float = math.inf

    def __str__(self) -> str:
        return (f"{self.element}: {self.what}: the original reads {self.original}, "
                f"the import {self.imported}")


@dataclass
class Structure:
    """The structural comparison: its findings and what was compared."""
    findings: list[Finding] = field(default_factory=list)
    shapes: int = 0
    bsdfs: int = 0
    emitters: int = 0
    approximated: list[str] = field(default_factory=list)
    #: why nothing was compared (Mitsuba cannot load the original in this variant), or None
    unchecked: str | None = None

    @property
    def agrees(self) -> bool:
        """No difference found (also when nothing could be compared: :attr:`unchecked`)."""
        return not self.findings

    @property
    def margin(self) -> float:
        """How many times the largest difference exceeds its tolerance (0: agrees)."""
        return max((f.excess for f in self.findings), default=0.0)

    def summary(self) -> str:
        """The one line the commands print when nothing differs."""
        if self.unchecked:
            return (f"structure: NOT CHECKED against Mitsuba's reading of the original "
                    f"({self.unchecked}); the verdict judges the import alone")
        skipped = (f"; {len(self.approximated)} approximated parts not compared"
                   if self.approximated else "")
        return (f"structure: agrees with Mitsuba's reading of the original ({self.shapes} "
                f"shapes, {self.bsdfs} BSDFs, {self.emitters} emitters compared{skipped})")

    def lines(self) -> list[str]:
        """One line per finding, then how many were compared."""
        out = [f"structure: {f}" for f in self.findings]
        out.append(f"structure: {len(self.findings)} difference(s) from Mitsuba's reading of "
                   f"the original ({self.shapes} shapes, {self.bsdfs} BSDFs, {self.emitters} "
                   "emitters compared)")
        return out

    def to_json(self) -> dict:
        return {"agrees": self.agrees, "unchecked": self.unchecked,
                "findings": [str(f) for f in self.findings],
                "shapes": self.shapes, "bsdfs": self.bsdfs, "emitters": self.emitters,
                "approximated": self.approximated}


class StructureMismatch(UserError):
    """The import differs from Mitsuba's reading of the original (its findings in
    ``structure``); the commands print them one a line and exit 1."""

    def __init__(self, structure: Structure):
        self.structure = structure
        f = structure.findings
        super().__init__(f"the import differs from Mitsuba's reading of the original in "
                         f"{len(f)} place(s); the first: {one_line(str(f[0]), 400)}")


# ---------------------------------------------------------------- values


def _arrays(key: str, v) -> list[tuple[str, object]]:
    """A traverse value as (key, numpy array or text) pairs; a transform gives its matrix
    and its inverse transpose (the one Mitsuba moves normals with)."""
    if hasattr(v, "matrix") and hasattr(v, "inverse_transpose"):
        return [(key, np.asarray(v.matrix, dtype=np.float64)),
                (f"{key} (inverse transpose)", np.asarray(v.inverse_transpose, dtype=np.float64))]
    if isinstance(v, str):
        return [(key, v)]
    try:
        return [(key, np.asarray(v, dtype=np.float64))]
    except (TypeError, ValueError):
        return [(key, str(v))]


def _show(a) -> str:
    if isinstance(a, str):
        return one_line(repr(a), 80)
    a = np.asarray(a)
    if a.size == 1:
        return f"{float(a.ravel()[0]):.7g}"
    if a.size <= 16:
        m = a.reshape(-1, a.shape[-1]) if a.ndim >= 2 else a
        return np.array2string(np.squeeze(m), precision=6, separator=", ",
                               suppress_small=True, max_line_width=10**6).replace("\n", "")
    return f"{a.size} values"


def _differs(a, b) -> tuple[str, str, float] | None:
    """None when the two values agree within :data:`REL_TOL`, else how each reads and how
    many times the largest difference exceeds the tolerance (:attr:`Finding.excess`)."""
    if isinstance(a, str) or isinstance(b, str):
        return None if str(a) == str(b) else (_show(a), _show(b), math.inf)
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.size == 1 and b.size > 1:   # a uniform value against its colour (one per channel)
        a = np.broadcast_to(a.ravel(), b.shape)
    elif b.size == 1 and a.size > 1:
        b = np.broadcast_to(b.ravel(), a.shape)
    if a.size != b.size:
        return f"{a.size} values", f"{b.size} values", math.inf
    a, b = a.ravel(), b.ravel()
    if a.size == 0:
        return None
    scale = max(float(np.abs(a).max()), float(np.abs(b).max()))
    d = np.abs(a - b)
    bad = ~(d <= REL_TOL * scale)   # NaN differs too
    if not bad.any():
        return None
    worst = float(d[bad].max()) if not np.isnan(d[bad]).any() else math.inf
    excess = worst / (REL_TOL * scale) if scale > 0 else math.inf
    if a.size <= 16:
        return _show(a), _show(b), excess
    idx = np.flatnonzero(bad)
    first = ", ".join(f"[{i}] {a[i]:.7g}" for i in idx[:SHOWN])
    other = ", ".join(f"[{i}] {b[i]:.7g}" for i in idx[:SHOWN])
    tail = f" (of {idx.size} differing values, largest difference {d[bad].max():.3g})"
    return first + tail, other, excess


def _params(mi, obj, skip_prefixes=()) -> dict:
    p = mi.traverse(obj)
    out = {}
    for k in p.keys():
        if k in IGNORED_KEYS or any(k.startswith(s) for s in skip_prefixes):
            continue
        for name, v in _arrays(k, p[k]):
            out[name] = v
    return out


def _is_default(key: str, value) -> bool:
    for name, default in DEFAULTS.items():
        if key == name or key.endswith("." + name):
            return _differs(np.asarray(value), np.asarray(default)) is None
    return False


def _compare_params(element: str, prefix: str, po: dict, pc: dict, out: list,
                    where_of=None) -> None:
    failed = set()
    for k in list(po) + [k for k in pc if k not in po]:
        label = element if where_of is None else where_of(k) or element
        what = f"{prefix}{k}"
        base = k.removesuffix(" (inverse transpose)")
        if base != k and base in failed:
            continue   # said once: the matrix differs (its inverse transpose with it)
        if k not in pc and _is_default(k, po[k]):
            continue
        if k not in po and _is_default(k, pc[k]):
            continue
        if k not in pc:
            out.append(Finding(label, what, _show(po[k]), "nothing (no such parameter)"))
        elif k not in po:
            out.append(Finding(label, what, "nothing (no such parameter)", _show(pc[k])))
        else:
            d = _differs(po[k], pc[k])
            if d:
                failed.add(k)
                out.append(Finding(label, what, *d))


# ---------------------------------------------------------------- objects


def _kind(obj) -> str:
    """A shape's kind as compared: meshes of any loader alike, else the class."""
    return "mesh" if obj.is_mesh() else obj.class_name()


def _bbox(obj) -> np.ndarray:
    b = obj.bbox()
    return np.concatenate([np.asarray(b.min, np.float64).ravel(),
                           np.asarray(b.max, np.float64).ravel()])


def _match(originals: list, imports: list, kind, distance) -> tuple[list, list, list]:
    """Pairs (original, import) of the same kind, greedily by the least distance; then the
    originals and the imports left over."""
    left = list(range(len(imports)))
    pairs, lone = [], []
    for o in originals:
        same = [j for j in left if kind(imports[j]) == kind(o)]
        if not same:
            lone.append(o)
            continue
        j = min(same, key=lambda j: distance(o, imports[j]))
        left.remove(j)
        pairs.append((o, imports[j]))
    return pairs, lone, [imports[j] for j in left]


def _index(obj, prefix: str) -> int | None:
    """i of the conversion's id ``shape_i`` / ``light_i`` (reference.renderers.mitsuba.scene)."""
    name = obj.id()
    if name.startswith(prefix) and name[len(prefix):].isdigit():
        return int(name[len(prefix):])
    return None


_WRAPPERS = ("brdf_0.", "nested_bsdf.", "bsdf.", "nested.")


def _bsdf_key_where(imp, material: str | None):
    def where(key: str):
        k = key
        while True:
            for w in _WRAPPERS:
                if k.startswith(w):
                    k = k[len(w):]
                    break
            else:
                break
        head = k.split(".")[0]
        return imp.origins.get(f"materials.{material}.{head}") or \
            imp.origins.get(f"materials.{material}")
    return where


def _approximated(imp, where: str) -> bool:
    return any(n.startswith("approximated") for n in imp.notes.get(where, []))


def _sensor(mi, so, sc, imp, out: list) -> None:
    element = imp.origins.get("camera", "the sensor")
    _compare_params(element, "", _params(mi, so), _params(mi, sc), out)
    fo, fc = so.film(), sc.film()
    film = imp.origins.get("film", element)
    for what, a, b in (("film kind", fo.class_name(), fc.class_name()),
                       ("film filter", fo.rfilter().class_name(), fc.rfilter().class_name()),
                       ("film filter radius", fo.rfilter().radius(), fc.rfilter().radius()),
                       ("film size", list(fo.size()), list(fc.size())),
                       ("film crop size", list(fo.crop_size()), list(fc.crop_size())),
                       ("film crop offset", list(fo.crop_offset()), list(fc.crop_offset()))):
        d = _differs(a, b)
        if d:
            out.append(Finding(film, what, *d))


def _emitter_params(mi, e) -> dict:
    p = _params(mi, e)
    if e.class_name() == "SpotLight" and "texture.data" not in p:
        # A spot without a texture is symmetric about its axis: its frame's roll (the
        # up vector that the import's look_at picks) is no part of the light.
        for k in [k for k in p if k.startswith("to_world")]:
            m = p.pop(k)
            if "inverse" not in k:
                m = np.asarray(m).reshape(4, 4)
                axis = m[:3, 2] / np.linalg.norm(m[:3, 2])
                p["position"] = m[:3, 3]
                p["direction"] = axis
    return p


def _box_distance(o, c) -> float:
    """How far apart two shapes' bounding boxes are (their largest corner difference)."""
    return float(np.abs(_bbox(o) - _bbox(c)).max())


def _light_distance(mi, o, c) -> float:
    """How far apart two emitters' parameters are (the sum of their differences; a key on
    one side only, or of another size, counts as infinitely far): for pairing them."""
    po, pc = _emitter_params(mi, o), _emitter_params(mi, c)
    total = 0.0
    for k in set(po) | set(pc):
        a, b = po.get(k), pc.get(k)
        if isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.size == b.size:
            total += float(np.abs(a - b).sum())
        else:
            total += 1e30
    return total


def compare_loaded(mi, original, converted, imp, approximate: bool = False) -> Structure:
    """Compare two loaded Mitsuba scenes: ``original`` (``mi.load_file`` of the XML) and
    ``converted`` (the import's conversion); ``imp`` (:class:`tracer.mitsuba_xml.Imported`)
    names the XML elements and what was approximated."""
    res = Structure()
    out = res.findings
    so, sc = original.sensors(), converted.sensors()
    if so and sc:
        _sensor(mi, so[0], sc[0], imp, out)

    shapes_data = imp.data.get("shapes", [])

    def shape_where(c) -> str | None:
        i = _index(c, "shape_")
        return None if i is None else f"shapes[{i}]"

    def shape_label(c) -> str:
        w = shape_where(c)
        return imp.origins.get(w, w or "a shape") if w else "a shape"

    pairs, lone_o, lone_c = _match(list(original.shapes()), list(converted.shapes()), _kind,
                                   _box_distance)
    for o in lone_o:
        out.append(Finding(f"a {_kind(o)} shape of the original", "shape",
                           f"{_kind(o)} at {_show(_bbox(o).reshape(2, 3))}", "no such shape"))
    for c in lone_c:
        out.append(Finding(shape_label(c), "shape", "no such shape",
                           f"{_kind(c)} at {_show(_bbox(c).reshape(2, 3))}"))
    bsdfs_seen = set()
    for o, c in pairs:
        res.shapes += 1
        label = shape_label(c)
        d = _differs(_bbox(o), _bbox(c))
        if d:
            out.append(Finding(label, "bounding box", *d))
        _compare_params(label, "", _params(mi, o, ("bsdf.", "emitter.")),
                        _params(mi, c, ("bsdf.", "emitter.")), out)
        where = shape_where(c)
        i = _index(c, "shape_")
        material = (shapes_data[i].get("material") if i is not None and i < len(shapes_data)
                    else None)
        bo, bc = o.bsdf(), c.bsdf()
        if bo is not None and bc is not None and _kind(o) != "Instance":
            mwhere = f"materials.{material}" if material else None
            if mwhere and _approximated(imp, mwhere):
                res.approximated.append(imp.origins.get(mwhere, mwhere))
            else:
                key = bo.ptr if hasattr(bo, "ptr") else id(bo)
                if key not in bsdfs_seen:
                    bsdfs_seen.add(key)
                    res.bsdfs += 1
                belement = imp.origins.get(mwhere, label) if mwhere else label
                if bo.class_name() != bc.class_name():
                    out.append(Finding(belement, "BSDF kind", bo.class_name(), bc.class_name()))
                else:
                    _compare_params(belement, "bsdf ", _params(mi, bo), _params(mi, bc), out,
                                    _bsdf_key_where(imp, material))
        eo, ec = o.emitter(), c.emitter()
        if (eo is None) != (ec is None):
            out.append(Finding(label, "area emitter", "none" if eo is None else eo.class_name(),
                               "none" if ec is None else ec.class_name()))
        elif eo is not None:
            res.emitters += 1
            if where and _approximated(imp, where):
                res.approximated.append(label)
            else:
                _compare_params(label, "emitter ", _params(mi, eo), _params(mi, ec), out)

    def lights(scene):
        return [e for e in scene.emitters() if e.class_name() != "AreaLight"]

    lpairs, lone_o, lone_c = _match(lights(original), lights(converted),
                                    lambda e: e.class_name(),
                                    lambda o, c: _light_distance(mi, o, c))
    for e in lone_o:
        out.append(Finding(f"a {e.class_name()} emitter of the original", "emitter",
                           e.class_name(), "no such emitter"))
    for e in lone_c:
        i = _index(e, "light_")
        out.append(Finding(imp.origins.get(f"lights[{i}]", "an emitter of the import"),
                           "emitter", "no such emitter", e.class_name()))
    for o, c in lpairs:
        res.emitters += 1
        i = _index(c, "light_")
        where = f"lights[{i}]" if i is not None else None
        label = imp.origins.get(where, where or "an emitter")
        if where and _approximated(imp, where):
            res.approximated.append(label)
            continue
        _compare_params(label, "", _emitter_params(mi, o), _emitter_params(mi, c), out)
    res.approximated = list(dict.fromkeys(res.approximated))
    return res


def compare_structure(source: str | Path, scene=None, imported=None,
                      approximate: bool = False, **params) -> Structure:
    """Mitsuba's reading of the original XML ``source`` against its reading of the import.

    ``scene`` and ``imported``: the import (:class:`tracer.scene.Scene` and
    :class:`tracer.mitsuba_xml.Imported`) if already made, else the file is imported
    here (``approximate``, ``params`` as ``whitted import`` takes them). ``params``
    are also handed to ``mi.load_file`` (the ``-D`` values). Returns a
    :class:`Structure`; its ``findings`` are the differences, one each.

    >>> s = compare_structure("tests/data/real_scenes/mitsuba-data/scenes/hello.xml")
    >>> s.agrees, s.summary()   # doctest: +SKIP
    """
    from whitted.reference import mitsuba, mitsuba_error
    from whitted.reference.renderers.mitsuba.scene import loading_threads, scene_tree, to_dict

    if imported is None or scene is None:
        from whitted.tracer.mitsuba_xml import read_xml
        from whitted.tracer.scene import parse_scene

        imported = read_xml(source, approximate, **params)
        scene = parse_scene(imported.data, str(source))
    mi = mitsuba()
    try:
        original = _load_original(mi, source, params)
    except (RuntimeError, ValueError) as e:  # Mitsuba's C++ exceptions
        # e.g. cbox_pol.xml's `stokes` integrator, which only a polarized variant
        # loads (the import approximated it): nothing to compare, and said so
        return Structure(unchecked=f"Mitsuba ({mi.variant()}) cannot load it: "
                                   f"{mitsuba_error(e)}")
    with loading_threads():   # optimize=False, as _load_original says
        converted = mi.load_dict(to_dict(scene_tree(scene, "direct"), mi), optimize=False)
    return compare_loaded(mi, original, converted, imported, approximate)


def _load_original(mi, source, params: dict):
    """Mitsuba's reading of the original XML, with the ``-D`` values ``params``.
    optimize=False: Mitsuba would merge the meshes that share a BSDF, on each side alike
    or not (an approximated BSDF may make two alike), and the shapes could not be matched.
    Mitsuba's own errors (RuntimeError, ValueError) are the caller's to word."""
    from whitted.reference.renderers.mitsuba.scene import loading_threads

    with loading_threads():
        return mi.load_file(str(source), optimize=False,
                            **{k: str(v) for k, v in params.items()})


def findings(source: str | Path, approximate: bool = False, **params) -> list[Finding]:
    """The differences alone (:func:`compare_structure`); ``[]`` when the import agrees."""
    return compare_structure(source, approximate=approximate, **params).findings


def is_xml(path) -> bool:
    """Is the scene given as Mitsuba XML (then the original judges its import)?"""
    return str(path).lower().endswith(".xml")


def check_and_print(source, approximate: bool = False, **params) -> Structure:
    """:func:`compare_structure`, its outcome printed on stdout: the summary line, or one
    line per finding and their count (what ``compare``, ``check`` and ``render --verify``
    print for a scene given as XML)."""
    s = compare_structure(source, approximate=approximate, **params)
    print(s.summary() if s.agrees else "\n".join(s.lines()), flush=True)
    return s


# ---------------------------------------------------------------- the original rendered


def original_reference(source: str | Path, scene, approximate: bool = False, seed: int = 0,
                       **params):
    """The deterministic reference evaluated on Mitsuba's own reading of the original XML.

    :func:`compare_structure` compares what Mitsuba makes of the file with what it makes
    of the import, object by object; this renders the first. The scene Mitsuba reads
    from ``source`` (``mi.load_file``, with the ``-D`` values ``params``) is evaluated by
    :class:`reference.renderers.mitsuba.deterministic.DeterministicReference` at the
    tracer's film positions and light samples of ``scene`` (the import, as the tracer
    renders it): nothing of the import reaches Mitsuba but where its samples lie and
    which of its emitters is which (the original's emitters are matched with the
    conversion's as the structural comparison matches them: by kind, and by bounding box
    or parameters). The film is the original's own, so the import's must have its shape.

    Returns ``(image, "")``, or ``(None, why)`` where it cannot be made: parts approximated
    (``--approximate``), a film of another shape (``--size``), an emitter the tracer's
    light samples cannot reach, a file Mitsuba cannot load in this variant.
    """
    from whitted.reference import mitsuba, mitsuba_error
    from whitted.reference.renderers.mitsuba.deterministic import (
        DeterministicReference,
        shares_light_samples,
    )
    from whitted.reference.renderers.mitsuba.scene import load

    if approximate or getattr(scene, "approximate", False):
        return None, "parts of the import are approximations of the original's"
    if not shares_light_samples(scene):
        return None, "an emitter has no shared light samples (the one-lobe reference's case)"
    mi = mitsuba()
    try:
        original = _load_original(mi, source, params)
    except (RuntimeError, ValueError) as e:  # Mitsuba's C++ exceptions
        return None, f"Mitsuba ({mi.variant()}) cannot load it: {mitsuba_error(e)}"
    sensors = original.sensors()
    if not sensors:
        return None, "the original has no sensor"
    film = sensors[0].film()
    w, h = (int(x) for x in film.size())
    cw, ch = (int(x) for x in film.crop_size())
    W, H = scene.film.width, scene.film.height
    if (cw, ch) != (w, h) or any(int(x) for x in film.crop_offset()):
        return None, f"the original's film is cropped ({cw}x{ch} of {w}x{h})"
    if abs(w * H - h * W) > 0:
        return None, (f"the film is {W}x{H}, the original's {w}x{h}: not the same shape "
                      "(a --size of the original's aspect keeps it)")
    names = _emitter_names(mi, original, lambda: load(scene, mi))
    if isinstance(names, str):
        return None, names
    ref = DeterministicReference(scene, seed, ms=original, names=names)
    return ref.render().image, ""


def _emitter_names(mi, original, convert) -> list[str] | str:
    """For each emitter of ``original``, the name the conversion (``convert()``, loaded
    only where an emitter needs a name) gives the same emitter (``shape_K`` for one on a
    shape, ``light_K`` for one of the lights), or why one has none. Delta emitters need
    no name (they take no light sample)."""
    converted = None
    names = []
    for e in original.emitters():
        if mi.has_flag(e.flags(), mi.EmitterFlags.Delta):
            names.append("")
            continue
        if converted is None:
            converted = convert()
            shapes = list(converted.shapes())
            lights = [c for c in converted.emitters() if c.get_shape() is None]
        shape = e.get_shape()
        if shape is not None:
            same = [c for c in shapes if _kind(c) == _kind(shape)]
            if not same:
                return f"an emitting {_kind(shape)} of the original has no counterpart"
            c = min(same, key=lambda c: _box_distance(shape, c))
            names.append(c.id())
            continue
        same = [c for c in lights if c.class_name() == e.class_name()]
        if not same:
            return f"the original's {e.class_name()} has no counterpart in the import"
        names.append(min(same, key=lambda c, e=e: _light_distance(mi, e, c)).id())
    return names


def judge_against_original(source: str | Path, scene, tracer_image=None,
                           approximate: bool = False, seed: int = 0, **params):
    """The tracer's image of ``scene`` (the import; rendered here at its strata centres
    when ``tracer_image`` is None) judged against :func:`original_reference`, by the test
    compare gives the scene. Returns ``(verdict, reference image, "")`` or
    ``(None, None, why not)``."""
    from whitted.reference.verdicts.compare import (
        at_strata_centres,
        choose_test,
        image_metrics,
        judge,
    )

    judged = at_strata_centres(scene)
    image, why = original_reference(source, judged, approximate, seed, **params)
    if image is None:
        return None, None, why
    if tracer_image is None:
        from whitted.tracer.integrator import Integrator

        tracer_image = Integrator(judged, seed=seed).render().image
    test = choose_test(judged)
    metrics = image_metrics(tracer_image, image, with_flip=False)
    verdict, _ = judge(test, metrics, tracer_image, image, scene=judged)
    return verdict, image, ""


def original_lines(verdict, why: str) -> list[str]:
    """What ``compare`` and ``check`` print of :func:`judge_against_original` (the check
    lines come from the caller, which formats them as its own)."""
    if verdict is None:
        return [f"original: not rendered ({why}); the images judge the import's conversion, "
                "and the structure its agreement with the original"]
    return [f"original: the deterministic reference on Mitsuba's own reading of the original "
            f"file, test {verdict.test}: {'pass' if verdict.passed else 'FAIL'}"]
