"""Reading a kind's settings from its TOML table, with one-line errors naming the key.

What pbrt-v4's ``ParameterDictionary`` (``src/pbrt/paramdict.h``) and Mitsuba 3's
``Properties`` are to their plugins: every parser of the scene format (the scene's
film, camera and shapes in :mod:`tracer.scene`, each material kind's ``parse`` in
``tracer/materials/``, each light kind's in ``tracer/emitters/``) reads its table
through a :class:`Table`. Each reader (``number``, ``integer``, ``color``, ``vec3``,
``string``, ``table``, ...) checks the value against what the key accepts and refuses
it with a :class:`~tracer.errors.SceneError` naming the file, the key path (e.g.
``materials.glass.int_ior``) and what was expected; :meth:`Table.finish` refuses the
keys nobody read, so a misspelt key is never silently ignored.

Each reader also hands :meth:`Table.raw` the JSON Schema of the values it accepts:
:mod:`tracer.schema` records the scene format's schema by running the same parsers
on a recording table, so a kind's settings appear in ``whitted schema`` as soon as
its parser reads them.

The module-level helpers check values a reader does not cover (a list of points,
a ``to_world`` transform, a direction) with the same messages, within the limits
float32 computation allows (``FLOAT32_MAX``, ``COORD_MAX``, ``COND_MAX``).

A kind reads its settings like this (``tracer/materials/diffuse.py``)::

    def parse(t: Table, name: str) -> Diffuse:
        return Diffuse(name, parse_texture(t, "reflectance", 0.5), base.parse_two_sided(t))
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from whitted.tracer import transform as tf
from whitted.tracer.errors import SceneError

Vec3 = tuple[float, float, float]
Color = tuple[float, float, float]
Matrix = tuple[tuple[float, ...], ...]


class Table:
    """A TOML table being read: remembers its key path and which keys were used."""

    def __init__(self, path: str, key: str, data: Any, what: str = "a table",
                 pattern: str | None = None, known: Any = None):
        self.path, self.key = path, key
        #: ``known(pattern, kind)``: the keys a table at ``pattern`` of ``type`` ``kind``
        #: may have, for messages (the scene's: :func:`tracer.scene.known_keys`); None: no
        #: such list. Sub-tables inherit it.
        self.known = known
        #: the key path with NAME for user-chosen names and [0] for indices
        self.pattern = key if pattern is None else pattern
        self.kind: str | None = None  # the ``type`` read, once read
        if not isinstance(data, dict):
            self.fail("", f"expected {what}, got {show(data)}")
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
        helpers below pass their own, and :mod:`tracer.settings_schema` builds the scene
        format's schema from them (this table ignores it).
        """
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                self.unknown_first(key)
                self.fail(key, f"missing; expected {required_what}")
            return default
        return self.data[key]

    def unknown_first(self, key: str) -> None:
        """Before saying ``key`` is missing: a key this kind of table does not know (a
        misspelling, or a key of another kind) is the likelier fault, and is named first."""
        if self.known is None:
            return
        known = self.known(self.pattern, self.kind)
        unknown = [k for k in self.data if k not in self.used and k not in known]
        if known and unknown:
            self.fail(unknown[0], f"unknown key (expected one of: {', '.join(sorted(known))}); "
                                  f"{key} is missing")

    def number(self, key: str, default: Any = ..., lo: float | None = None,
               hi: float | None = None, lo_open: bool = False, hi_open: bool = False) -> float:
        what = range_text("a number", lo, hi, lo_open, hi_open)
        v = self.raw(key, default, what, number_schema(lo, hi, lo_open, hi_open))
        return check_number(self, key, v, what, lo, hi, lo_open, hi_open)

    def integer(self, key: str, default: Any = ..., lo: int | None = None) -> int:
        what = "an integer" + (f" >= {lo}" if lo is not None else "")
        v = self.raw(key, default, what,
                     {"type": "integer"} | ({"minimum": lo} if lo is not None else {}))
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(key, f"expected {what}, got {show(v)}")
        if lo is not None and v < lo:
            self.fail(key, f"expected {what}, got {v}")
        return v

    def boolean(self, key: str, default: Any = ...) -> bool:
        v = self.raw(key, default, "true or false", {"type": "boolean"})
        if not isinstance(v, bool):
            self.fail(key, f"expected true or false, got {show(v)}")
        return v

    def string(self, key: str, default: Any = ..., choices: tuple[str, ...] | None = None) -> str:
        what = "a string" if not choices else "one of: " + ", ".join(f'"{c}"' for c in choices)
        v = self.raw(key, default, what,
                     {"enum": list(choices)} if choices else {"type": "string"})
        if not isinstance(v, str) or (choices and v not in choices):
            self.fail(key, f"expected {what}, got {show(v)}")
        if key == "type":
            self.kind = v
        return v

    def vec3(self, key: str, default: Any = ..., nonzero: bool = False) -> Vec3:
        v = self.raw(key, default, "a list of 3 numbers", VEC3_SCHEMA)
        return check_vec3(self, key, v, nonzero)

    def direction(self, key: str, default: Any = ...) -> Vec3:
        """A unit vector from a non-zero one (non-zero in float32)."""
        return check_unit(self, key, self.raw(key, default, "a list of 3 numbers", VEC3_SCHEMA))

    def distinct(self, key: str, a: Vec3, b: Vec3, other: str) -> None:
        """Refuse b unless float32 tells it apart from a (see :func:`check_distinct`)."""
        check_distinct(self, key, a, b, other)

    def color(self, key: str, default: Any = ..., hi: float | None = None) -> Color:
        what = "a colour: one number or a list of 3 numbers, each >= 0" + (
            f" and <= {hi}" if hi is not None else "")
        one = number_schema(0, hi, False, False)
        v = self.raw(key, default, what, {"anyOf": [
            one, {"type": "array", "items": one, "minItems": 3, "maxItems": 3}]})
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v, v, v]
        if not isinstance(v, list) or len(v) != 3:
            self.fail(key, f"expected {what}, got {show(v)}")
        out = []
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                self.fail(key, f"expected {what}, got {show(v)} (element {i} is {show(x)})")
            if x < 0 or (hi is not None and x > hi):
                self.fail(key, f"expected {what}, got {show(v)}")
            if x > FLOAT32_MAX:
                self.fail(key, f"expected {what}, within float32's range (up to "
                               f"{FLOAT32_MAX:.4g}), got {show(v)}")
            out.append(float(x))
        return (out[0], out[1], out[2])

    def table(self, key: str, default: Any = ..., parse: Any = None) -> Any:
        """The sub-table ``key``; with ``parse``, what ``parse(sub-table)`` makes of it."""
        v = self.raw(key, default, "a table", {"type": "object"})
        sub = Table(self.path, self._k(key), v, pattern=self._p(key), known=self.known)
        return sub if parse is None else parse(sub)

    def tables(self, key: str, parse: Any, what: str | None = None,
               item_what: str = "a table") -> list:
        """An array of tables (``[[key]]``), each made into ``parse(sub-table)``."""
        what = what or f"an array of tables ([[{key}]])"
        v = self.raw(key, [], what, {"type": "array"})
        if not isinstance(v, list):
            self.fail(key, f"expected {what}, got {show(v)}")
        return [parse(Table(self.path, f"{self._k(key)}[{i}]", x, item_what,
                            f"{self._p(key)}[0]", self.known)) for i, x in enumerate(v)]

    def each(self, parse: Any) -> dict:
        """Every key of this table, each a sub-table named by the user: ``parse(sub, name)``."""
        out = {}
        for name in list(self.data):
            self.used.add(name)
            out[name] = parse(Table(self.path, self._k(name), self.data[name],
                                    pattern=self._p("NAME"), known=self.known), name)
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


def show(v: Any, depth: int = 0) -> str:
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
        items = [show(x, depth + 1) for x in v[:6]]
        more = f", ... ({len(v):,} elements)" if len(v) > 6 else ""
        return "[" + ", ".join(items) + more + "]"
    return repr(v)


def number_schema(lo, hi, lo_open, hi_open) -> dict:
    """The JSON Schema of the numbers ``range_text`` describes."""
    out: dict = {"type": "number"}
    if lo is not None:
        out["exclusiveMinimum" if lo_open else "minimum"] = lo
    if hi is not None:
        out["exclusiveMaximum" if hi_open else "maximum"] = hi
    return out


VEC3_SCHEMA = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}


def range_text(base: str, lo, hi, lo_open, hi_open) -> str:
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


def check_number(t: Table, key: str, v, what, lo, hi, lo_open, hi_open) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        t.fail(key, f"expected {what}, got {show(v)}")
    if not math.isfinite(v):
        t.fail(key, f"expected a finite number ({what}), got {show(v)}")
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


def check_vec3(t: Table, key: str, v, nonzero: bool = False) -> Vec3:
    what = "a list of 3 finite numbers"
    if not isinstance(v, list) or len(v) != 3:
        got = f"a list of {len(v):,}" if isinstance(v, list) else show(v)
        t.fail(key, f"expected {what}, got {got}")
    for i, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            t.fail(key, f"expected {what}, got {show(v)} (element {i} is {show(x)})")
        if abs(x) > FLOAT32_MAX:
            t.fail(key, f"expected numbers within float32's range (up to {FLOAT32_MAX:.4g}), "
                        f"got {show(v)}")
    out = (float(v[0]), float(v[1]), float(v[2]))
    if nonzero and max(abs(x) for x in out) < FLOAT32_TINY:
        t.fail(key, f"expected a non-zero vector, got {show(v)} (zero in float32)")
    return out


def norm_or_1(v) -> float:
    n = norm(v)
    return n if n > 0 else 1.0


def norm(v) -> float:
    """Euclidean length without underflow or overflow (scaled by the largest component)."""
    a = np.asarray(v, dtype=np.float64)
    m = float(np.max(np.abs(a)))
    return 0.0 if m == 0 else m * float(np.linalg.norm(a / m))


def check_unit(t: Table, key: str, v) -> Vec3:
    """A direction: non-zero in float32 (relative to nothing: any scale is a direction)."""
    d = np.asarray(check_vec3(t, key, v, nonzero=True))
    d = d / np.max(np.abs(d))
    d = d / np.linalg.norm(d)
    return (float(d[0]), float(d[1]), float(d[2]))


def check_distinct(t: Table, key: str, a, b, other: str) -> np.ndarray:
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


def check_extent(t: Table, key: str, points, what: str = "coordinates") -> None:
    """World coordinates within COORD_MAX, where float32 intersection tests stay finite."""
    m = float(np.max(np.abs(points))) if np.size(points) else 0.0
    if not m <= COORD_MAX:
        t.fail(key, f"{what} reach {m:.3g}, beyond the {COORD_MAX:.3g} that float32 "
                    "intersection tests can square")


def check_transform(t: Table, key: str, m: np.ndarray, what: str = "transform") -> None:
    """An affine transform float32 can apply and invert: relative tests on its scales.

    Its singular values (the scales along its principal axes) must lie within
    [1 / COORD_MAX, COORD_MAX] and their ratio (the condition number) within
    COND_MAX; a NaN anywhere fails both. A uniform scale of 1e-5 passes, a
    rotation about an axis that underflows, or [1, 1, 1e-12], does not.
    """
    if not np.isfinite(m).all():
        t.fail(key, f"expected a finite {what} (it has NaN or infinite entries)")
    check_extent(t, key, m[:3, 3], "its translation")
    sv = np.linalg.svd(m[:3, :3], compute_uv=False)
    if not (sv[-1] > 0 and 1 / COORD_MAX <= sv[-1] and sv[0] <= COORD_MAX):
        t.fail(key, f"expected an invertible {what} with scales between {1 / COORD_MAX:.3g} "
                    f"and {COORD_MAX:.3g} (its scales range from {sv[-1]:.3g} to {sv[0]:.3g})")
    if sv[0] / sv[-1] > COND_MAX:
        t.fail(key, f"expected an invertible {what}: its scales range from {sv[-1]:.3g} to "
                    f"{sv[0]:.3g}, a ratio beyond the {COND_MAX:.0g} float32 can invert")



#: The kinds of a ``to_world`` step, each the one key of its table.
STEPS = ("translate", "scale", "rotate", "matrix")


#: A ``to_world`` step as the file gives it, before anything is composed: the reader's
#: output, which the tracer composes with :mod:`tracer.transform` and the Mitsuba side with
#: Mitsuba's own transforms (:mod:`reference.renderers.mitsuba.transforms`).
#: ``("translate", (x, y, z))``, ``("scale", (sx, sy, sz))``, ``("rotate", (ax, ay, az),
#: degrees)`` with a unit axis (docs/scene-format.md: "the axis is normalised"), or
#: ``("matrix", 4 rows of 4)``; a list of them applies the first step first.
Step = tuple


def read_steps(t: Table, key: str) -> tuple[np.ndarray, tuple[Step, ...]]:
    """A ``to_world`` value: its steps as read (:data:`Step`) and the tracer's composition
    of them (:func:`tracer.transform.compose`), checked."""
    if t.is_table(key):  # one step given as a table: { matrix = [...] }
        steps = [parse_step(t.table(key))]
    else:
        steps = t.tables(key, parse_step,
                         "a list of steps like [{ translate = [x, y, z] }]",
                         "a step: { translate = [..] }, { scale = .. }, { rotate = {..} } or "
                         "{ matrix = [[..] x4] }")
    m = tf.compose([tf.step_matrix(s) for s in steps])
    check_transform(t, key, m)
    return m, tuple(steps)


def parse_step(s: Table) -> Step:
    op = s.choose(STEPS, "step")
    if op == "translate":
        step = ("translate", tuple(s.vec3("translate")))
    elif op == "scale":
        v = s.raw("scale", ..., "a number or a list of 3 numbers",
                  {"anyOf": [{"type": "number"}, VEC3_SCHEMA]})
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v, v, v]
        sv = check_vec3(s, "scale", v)
        if any(abs(x) < FLOAT32_TINY for x in sv):
            s.fail("scale", f"expected non-zero scale factors, got {show(v)} "
                            "(a factor is zero in float32)")
        step = ("scale", tuple(float(x) for x in sv))
    elif op == "rotate":
        r = s.table("rotate")
        axis = r.direction("axis")
        step = ("rotate", tuple(float(x) for x in axis), float(r.number("angle")))
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
        step = ("matrix", as_tuple(m))
    s.finish()
    return step


def as_tuple(m: np.ndarray) -> Matrix:
    return tuple(tuple(float(x) for x in row) for row in m)



def read_points(t: Table, key: str, m: np.ndarray, exactly: int | None = None) -> list:
    """The points of ``key`` moved by ``m`` (world space)."""
    return read_local_points(t, key, m, exactly)[1]


def read_local_points(t: Table, key: str, m: np.ndarray,
                      exactly: int | None = None) -> tuple[tuple, list]:
    """The points of ``key`` as the file gives them (a tuple of 3-tuples) and moved by
    ``m`` (a list of arrays, world space), checked."""
    what = (f"a list of {exactly} vertices [[x, y, z], ...]" if exactly
            else "a list of at least 3 vertices [[x, y, z], ...]")
    counts = {"minItems": exactly, "maxItems": exactly} if exactly else {"minItems": 3}
    v = t.raw(key, ..., what, {"type": "array", "items": VEC3_SCHEMA} | counts)
    if not isinstance(v, list) or (len(v) != exactly if exactly else len(v) < 3):
        got = f"a list of {len(v)}" if isinstance(v, list) else show(v)
        t.fail(key, f"expected {what}, got {got}")
    local = tuple(tuple(float(x) for x in check_vec3(t, f"{key}[{i}]", p))
                  for i, p in enumerate(v))
    pts = [tf.apply_point(m, p) for p in local]
    check_extent(t, key, np.asarray(pts), "vertices")
    return local, pts


__all__ = ["COND_MAX", "COORD_MAX", "FLOAT32_MAX", "FLOAT32_TINY", "STEPS", "VEC3_SCHEMA",
           "Color", "Matrix", "Table", "Vec3", "as_tuple", "check_distinct", "check_extent",
           "check_number", "check_transform", "check_unit", "check_vec3", "norm", "norm_or_1",
           "number_schema", "parse_step", "range_text", "read_local_points",
           "read_points", "read_steps", "show", "Step"]
