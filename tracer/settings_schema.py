"""The JSON Schema of what a parser reads through :mod:`tracer.settings`, recorded by running it.

:func:`record_schema` runs a parser (the scene's, :func:`tracer.scene._parse_top`,
which runs every kind's ``parse`` in ``tracer/materials/`` and ``tracer/emitters/``)
on a *recording* table, :class:`_Recorder`, instead of a document. Each key a
parser reads goes through one of the :class:`~tracer.settings.Table` readers
(``number``, ``color``, ``vec3``, ``string``, ``table``, ...), and each reader hands
``Table.raw`` the JSON Schema of the values it accepts; the recorder notes
the key, that schema, its default and whether it was required, and answers
with a plausible value so that the parser goes on to its next key. Where a
parser branches (on a ``type``, on whether a key is present, on a colour
against a texture, on which kind of ``to_world`` step), the recorder takes
each branch in turn, re-running the parser until every combination of its
answers has been seen. The runs are merged into one schema: the keys read in
any run of a table are its properties, the keys read without a default in
every run are required, and runs that chose different ``type``s become the
variants of a ``oneOf``, each with ``type`` as its constant.

The same recording gives :func:`known_keys`, the keys each table may have, which the
loader names when a required key is missing beside one it does not know. This module
knows no scene: :mod:`tracer.schema` hands it the scene's parser, and so does
:mod:`tracer.scene` for its messages (so neither it nor the settings import the scene).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from whitted.tracer.settings import Table

#: The most runs of one parser while exploring its branches: far above what the kinds
#: need (a shape takes 26), a guard against a parser whose branches multiply.
MAX_RUNS = 4096


class TooManyRuns(RuntimeError):
    """A parser whose branches multiply beyond MAX_RUNS (never swallowed by a run)."""


class _Run:
    """One run of a parser: the answers given at its branch points (a depth-first walk).

    Every combination of answers is tried at the branch points that decide which keys a
    table has (its ``type``, whether a key is present, a colour or a texture, which step),
    but a choice among other values (a Fresnel formula, a named index of refraction) is
    varied one at a time, the others at their first answer: such choices multiply (two
    keys naming one of 20 glasses each would take 400 runs) and rarely decide a key
    together.
    """

    def __init__(self, script: list[int]):
        self.script = script
        self.trace: list[tuple[int, int, bool]] = []  # (answers, the one given, one at a time)
        self.rng = np.random.default_rng(len(script) + 1)

    def decide(self, n: int, single: bool = False) -> int:
        i = len(self.trace)
        choice = self.script[i] if i < len(self.script) else 0
        self.trace.append((n, choice, single))
        return choice

    def next_script(self) -> list[int] | None:
        """The answers of the next run: the last branch point with an answer left, advanced."""
        trace = list(self.trace)
        while trace:
            n, choice, single = trace[-1]
            varied = any(s and c for _, c, s in trace[:-1])
            if choice + 1 < n and not (single and varied):
                return [c for _, c, _ in trace[:-1]] + [choice + 1]
            trace.pop()
        return None


class _Sample(float):
    """A number the recorder made up (or a default it returned): whatever is computed from
    it stays one, so that a bound or a default that depends on another key (a spot's
    ``beam_width`` at most its ``cutoff_angle``) is told from a fixed one."""


def _sample_op(name):
    op = getattr(float, name)
    return lambda a, *b: _wrap(op(a, *b))


def _wrap(x):
    return _Sample(x) if isinstance(x, float) and not isinstance(x, _Sample) else x


for _name in ("__add__", "__radd__", "__sub__", "__rsub__", "__mul__", "__rmul__",
              "__truediv__", "__rtruediv__", "__neg__", "__pow__", "__rpow__"):
    setattr(_Sample, _name, _sample_op(_name))

#: JSON Schema words whose value may be a bound taken from another key.
_BOUNDS = ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum")


class _Record:
    """What one run read of one table."""

    def __init__(self):
        self.props: dict[str, list] = {}      # key -> specs (see _Recorder._note)
        self.required: list[str] = []
        self.present: set[str] = set()        # keys a branch point assumed present
        self.discriminant: str | None = None  # the ``type`` this run chose
        self.named: list[_Record] | None = None  # tables of user-chosen names (each)
        self.exactly_one = False                 # choose(): one key names the kind


def _explore(parse, make) -> tuple[list[_Record], Any]:
    """Run ``parse`` on fresh recorders (``make(run)``) until every branch was taken.

    Returns each run's record and the value of the first run that finished.
    """
    records, value, script = [], None, []
    for _ in range(MAX_RUNS):
        run = _Run(script)
        t = make(run)
        with np.errstate(all="ignore"):
            try:
                v = parse(t)
                if value is None:
                    value = v
            except TooManyRuns:
                raise
            except Exception:  # noqa: BLE001 - a plausible value can still fail a later
                pass           # check; every key up to there is recorded
        records.append(t.record)
        script = run.next_script()
        if script is None:
            return records, value
    raise TooManyRuns(f"a parser branches more than {MAX_RUNS} ways; see "
                      "tracer/settings_schema.py")


#: Every key a table may have, by its key pattern (``Table.pattern``) and its ``type``
#: (None: any type): filled as a side effect of recording, for the loader's messages.
_VOCABULARY: dict[tuple[str, str | None], set[str]] = {}


def known_keys(parse, pattern: str, kind: str | None = None) -> frozenset[str]:
    """The keys a table at ``pattern`` (e.g. ``shapes[0]``, ``materials.NAME``) of ``type``
    ``kind`` may have (any kind's when None or unknown) when ``parse`` reads the document
    (recorded once, on the first call); empty for a pattern no parser reads."""
    if not _VOCABULARY:
        _explore(parse, lambda run: _Recorder(run))
    keys = _VOCABULARY.get((pattern, kind)) or _VOCABULARY.get((pattern, None), ())
    return frozenset(keys)


class _Recorder(Table):
    """A ``Table`` that records what is read of it instead of reading a scene."""

    def __init__(self, run: _Run, path: str = "<schema>", key: str = ""):
        self.path, self.key, self.pattern, self.run = path, key, key, run
        self.kind = None
        self.known = None  # a recording names no unknown key (it fails nothing)
        self.data: dict = {}
        self.used: set[str] = set()
        self.record = _Record()
        self.answers: dict[str, bool] = {}

    def _note(self, key: str, spec: Any, required: bool) -> None:
        _VOCABULARY.setdefault((self.key, None), set()).add(key)
        if self.record.discriminant is not None:
            _VOCABULARY.setdefault((self.key, self.record.discriminant), {"type"}).add(key)
        self.used.add(key)
        self.record.props.setdefault(key, []).append(spec)
        if required and key not in self.record.present and key not in self.record.required:
            self.record.required.append(key)

    # -- what the helpers read

    def raw(self, key, default=..., required_what="a value", schema=None):
        spec = dict(schema or {})
        spec["description"] = "expected " + required_what
        dynamic = [b for b in _BOUNDS if isinstance(spec.get(b), _Sample)]
        for b in dynamic:  # a bound from another key: the loader checks it, not the schema
            del spec[b]
        if dynamic:
            spec["description"] = ("expected a number (within bounds that depend on other "
                                   "keys of this table)")
        if default is not ... and _jsonable(default) and not isinstance(default, _Sample):
            spec["default"] = default
        self._note(key, spec, default is ...)
        if "enum" in spec:  # a choice: every value is a branch (a ``type`` picks a kind)
            values = list(spec["enum"])
            if default in values:  # the default first: the other choices vary from it
                values.remove(default)
                values.insert(0, default)
            value = values[self.run.decide(len(values), single=key != "type")]
            if key == "type":
                self.record.discriminant = value
            return value
        if default is not ...:
            return _wrap(default)
        return _wrap(_example(spec, self.run.rng))

    def number(self, key, *args, **kwargs):
        return _wrap(super().number(key, *args, **kwargs))  # still a sample once checked

    def has(self, key: str) -> bool:
        if key not in self.answers:
            self.answers[key] = bool(self.run.decide(2))
            if self.answers[key]:
                self.record.present.add(key)
        return self.answers[key]

    def is_table(self, key: str) -> bool:
        # A choice of its own: a key known to be present (``has``) may still be a table
        # or not (a ``to_world`` of one step or a list of steps).
        if self.answers.get(key) is False:
            return False
        if ("table", key) not in self.answers:
            self.answers[("table", key)] = bool(self.run.decide(2))
            if self.answers[("table", key)]:
                self.record.present.add(key)
        return self.answers[("table", key)]

    def choose(self, options, noun):
        self.record.exactly_one = True
        return options[self.run.decide(len(options))]

    def table(self, key, default=..., parse=None):
        if parse is None:  # read in this run
            sub = _Recorder(self.run, self.path, self._k(key))
            self._note(key, ("tables", [sub.record]), default is ...)
            return sub
        records, value = _explore(parse, lambda run: _Recorder(run, self.path, self._k(key)))
        self._note(key, ("tables", records), default is ...)
        return value

    def tables(self, key, parse, what=None, item_what="a table"):
        what = what or f"an array of tables ([[{key}]])"
        records, value = _explore(parse, lambda run: _Recorder(run, self.path,
                                                               f"{self._k(key)}[0]"))
        self._note(key, ("array", records, what), False)
        return [value]

    def each(self, parse):
        records, value = _explore(lambda t: parse(t, "NAME"),
                                  lambda run: _Recorder(run, self.path, self._k("NAME")))
        self.record.named = records
        return {"NAME": value}

    # -- what the parsers check: the schema does not judge values, the loader does

    def fail(self, key: str, message: str):
        return None

    def finish(self, allowed_note: str = ""):
        return None


def _jsonable(v: Any) -> bool:
    try:
        json.dumps(v)
        return True
    except (TypeError, ValueError):
        return False


def _example(spec: dict, rng) -> Any:
    """A value the schema fragment accepts, for a parser to go on with."""
    if "anyOf" in spec:
        return _example(spec["anyOf"][0], rng)
    kind = spec.get("type")
    if kind == "array":
        n = spec.get("minItems", 1)
        return [_example(spec.get("items", {}), rng) for _ in range(n)]
    if kind in ("number", "integer"):
        lo = spec.get("minimum", spec.get("exclusiveMinimum"))
        hi = spec.get("maximum", spec.get("exclusiveMaximum"))
        if lo is not None and hi is not None:
            x = (lo + hi) / 2
        elif lo is not None:
            x = lo + 1
        elif hi is not None:
            x = hi - 1
        else:
            x = float(rng.normal())
        return int(x) if kind == "integer" else float(x)
    if kind == "boolean":
        return True
    if kind == "object":
        return {}
    return "NAME"


# ----------------------------------------------------------------------------- merging


def _object(records: list[_Record]) -> dict:
    """The schema of a table from the records of every run: one object, or, where runs chose
    different ``type``s, one object per ``type`` chosen by ``if``/``then`` on the ``type``
    (a discriminated union: a bad key is reported against its own kind)."""
    groups: dict[str | None, list[_Record]] = {}
    for r in records:
        groups.setdefault(r.discriminant, []).append(r)
    if list(groups) == [None]:
        return _merge(records)
    kinds = [k for k in groups if k is not None]
    spec = dict(next(s for r in records for s in r.props["type"]))
    spec["enum"] = kinds
    variants = {kind: _merge(groups[kind]) for kind in kinds}
    # First, every kind's keys together, for editors that complete keys from the members
    # of ``allOf`` and do not evaluate if/then (Taplo): a key that every kind having it
    # reads alike keeps its schema (and so its own keys: a shape's ``to_world`` steps),
    # others only their description. Each kind's ``then`` below judges them all.
    union: dict = {"type": "object", "properties": {"type": spec}}
    if "default" not in spec:
        union["required"] = ["type"]
    for key in dict.fromkeys(k for v in variants.values() for k in v["properties"]):
        if key == "type":
            continue
        have = [kind for kind in kinds if key in variants[kind]["properties"]]
        forms = [variants[kind]["properties"][key] for kind in have]
        note = f" (type = {' | '.join(have)})" if len(have) < len(kinds) else ""
        if all(f == forms[0] for f in forms):
            entry = dict(forms[0])
            entry["description"] = entry.get("description", "") + note
        else:
            entry = {"description": forms[0].get("description", "") + note}
        union["properties"][key] = entry
    members: list = [union]
    for kind, then in variants.items():
        then["properties"]["type"] = {"const": kind}
        when: dict = {"properties": {"type": {"const": kind}}}
        if spec.get("default") != kind:
            when["required"] = ["type"]  # an absent type is the default kind only
        members.append({"if": when, "then": then})
    return {"type": "object", "allOf": members}


def _merge(records: list[_Record]) -> dict:
    specs: dict[str, list] = {}
    for r in records:
        for key, s in r.props.items():
            specs.setdefault(key, []).extend(s)
    present = set().union(*(r.present for r in records))
    required = [k for k in records[0].required
                if k not in present and all(k in r.required for r in records)]
    out: dict = {"type": "object", "properties": {k: _combine(s) for k, s in specs.items()}}
    exactly_one = any(r.exactly_one for r in records)
    if required and not exactly_one:  # one key of a few: said by the counts below
        out["required"] = required
    named = [x for r in records for x in (r.named or [])]
    out["additionalProperties"] = _object(named) if named else False
    if exactly_one:
        out["minProperties"] = out["maxProperties"] = 1
    return out


def _combine(specs: list) -> dict:
    """The schema of one key from what each run read of it."""
    leaves: list[dict] = []
    tables: list[_Record] = []
    arrays: list[_Record] = []
    what = None
    for s in specs:
        if isinstance(s, dict):
            if not any(_same(s, x) for x in leaves):
                leaves.append(s)
        elif s[0] == "tables":
            tables += s[1]
        else:
            arrays += s[1]
            what = s[2]
    out = list(leaves)
    if tables:
        out.append(_object(tables))
    if arrays:
        out.append({"type": "array", "items": _object(arrays), "description": "expected " + what})
    if len(out) == 1:
        return out[0]
    # A colour or a texture: a table's form joins the other forms of the key.
    described = next((s.get("description") for s in out if "description" in s), None)
    forms = [f for s in out for f in s.get("anyOf", [s])]  # one level: a form each
    merged = {"anyOf": [{k: v for k, v in f.items() if k not in ("description", "default")}
                        for f in forms]}
    defaults = [s["default"] for s in out if "default" in s]
    if described:
        merged["description"] = described
    if defaults:
        merged["default"] = defaults[0]
    return merged


def _same(a: dict, b: dict) -> bool:
    """Two leaf schemas alike but for their description and default."""
    def strip(s):
        return json.dumps({k: v for k, v in s.items() if k not in ("description", "default")},
                          sort_keys=True)
    return strip(a) == strip(b)


def record_schema(parse) -> dict:
    """The JSON Schema of the documents ``parse`` reads: the object its runs on recording
    tables read (every branch taken), merged as the module docstring says."""
    records, _ = _explore(parse, lambda run: _Recorder(run))
    return _object(records)
