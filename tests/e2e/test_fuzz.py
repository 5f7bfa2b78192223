"""Property-based fuzzing of the scene loader, the light-path expressions and the command line.

The contract, for any input: the loader returns a scene or raises a SceneError;
an expression compiles to an automaton that agrees with Python's ``re`` or is
refused with an LPEError; and ``whitted`` exits 0 with a finite image or 2
with exactly one line on stderr and nothing written. Hypothesis
(https://hypothesis.readthedocs.io) draws the inputs: a valid scene with a few
of its values replaced by hostile ones (NaN, 1e39, 1e-200, huge integers,
wrong types and lengths, control characters in names, deep nesting), random
expressions over the expression alphabet, and command lines assembled from
the commands' options with valid and invalid values.

The default run is derandomized and bounded (a few hundred loader and
expression cases, a few dozen command lines: about 20 s on two cores); the
``slow`` tests run the same properties on many more, random, cases, Mitsuba's
commands included.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from whitted.tracer.errors import SceneError
from whitted.tracer.lpe import ALPHABET, LPEError, compile_lpe
from whitted.tracer.scene import parse_scene

QUICK = settings(derandomize=True, deadline=None, database=None,
                 suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
LONG = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                       HealthCheck.data_too_large])

# ------------------------------------------------------------------ a scene to damage

BASE = {
    "description": "fuzz base",
    "film": {"width": 6, "height": 4, "spp": 1, "max_depth": 3},
    "camera": {"origin": [0, 1, 6], "target": [0, 0.5, 0], "fov": 45},
    "materials": {
        "white": {"type": "diffuse", "reflectance": 0.6},
        "check": {"type": "diffuse", "reflectance": {"checkerboard": {"color0": 0.2,
                                                                     "scale": 4}}},
        "glass": {"type": "dielectric", "ior": 1.5},
        "steel": {"type": "mirror", "reflectance": [0.9, 0.9, 0.9]},
        "plastic": {"type": "phong", "diffuse": 0.5, "specular": 0.3, "exponent": 20},
    },
    "lights": [
        {"type": "point", "position": [2, 4, 3], "intensity": 40},
        {"type": "directional", "direction": [0.3, -1, -0.2], "irradiance": 0.5},
        {"type": "spot", "position": [-2, 4, 2], "target": [0, 0, 0], "intensity": 30},
    ],
    "groups": {"g": {"shapes": [{"type": "sphere", "radius": 0.3, "material": "plastic"}]}},
    "shapes": [
        {"type": "rectangle", "material": "check",
         "to_world": [{"scale": 4}, {"rotate": {"axis": [1, 0, 0], "angle": -90}}]},
        {"type": "sphere", "center": [0, 0.7, 0], "radius": 0.7, "material": "glass"},
        {"type": "triangle", "vertices": [[1, 0, 0], [2, 0, 0], [1.5, 1, 0]],
         "material": "steel"},
        {"type": "disk", "material": "white", "to_world": [{"translate": [-1.5, 0.5, -1]}]},
        {"type": "cylinder", "p0": [1.5, 0, -1], "p1": [1.5, 1, -1], "radius": 0.3,
         "material": "white"},
        {"type": "paraboloid", "a": 0.3, "b": 0.3, "height": 0.5, "material": "plastic",
         "to_world": [{"translate": [-1, 0, 1]}]},
        {"type": "polygon", "vertices": [[0, 2, -2], [1, 2, -2], [1, 3, -2], [0.5, 2.5, -2],
                                         [0, 3, -2]], "material": "white"},
        {"type": "instance", "group": "g", "to_world": [{"translate": [-2, 0.3, 0]}]},
        {"type": "sphere", "center": [0, 2.5, 0], "radius": 0.2,
         "emitter": {"radiance": 5}},
    ],
}

EXTREMES = [0, -0.0, 1, -1, 0.5, 1e-5, 1e-30, 1e-45, 1e-200, 1e-38, 1e18, 1e19, 1e30, 1e38,
            3.4e38, 3.5e38, 1e39, 1e300, math.nan, math.inf, -math.inf, 2**31, 2**32,
            2**63 - 1, -(2**63), 7, 16, 100000]

numbers = st.one_of(st.sampled_from(EXTREMES), st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(min_value=-(2**63), max_value=2**63 - 1),
                    st.floats(min_value=-10, max_value=10))
names = st.one_of(st.sampled_from(["white", "glass", "g", "type", "nope", "a\nb", "\x1b[2J",
                                   "", " ", "é", "x" * 300]),
                  st.text(max_size=12))
leaves = st.one_of(numbers, st.booleans(), names,
                   st.sampled_from(["sphere", "mesh", "instance", "point", "phong", "exact",
                                    "schlick", "orthographic", "blinn-phong"]))
values = st.recursive(leaves, lambda inner: st.one_of(
    st.lists(inner, max_size=5), st.dictionaries(names, inner, max_size=4)), max_leaves=12)
vectors = st.lists(numbers, min_size=0, max_size=4)


@st.composite
def damaged_scenes(draw, least: int = 1) -> dict:
    """BASE with ``least`` to 4 values replaced, removed or added, anywhere in the tree."""
    doc = json.loads(json.dumps(BASE))
    for _ in range(draw(st.integers(least, 4))):
        node = doc
        while True:
            keys = list(node) if isinstance(node, dict) else list(range(len(node)))
            if not keys:
                break
            key = draw(st.sampled_from(keys))
            child = node[key]
            if isinstance(child, (dict, list)) and child and draw(st.booleans()):
                node = child
                continue
            action = draw(st.sampled_from(["value", "vector", "number", "delete", "add"]))
            if action == "delete":
                del node[key]
            elif action == "add" and isinstance(node, dict):
                node[draw(names)] = draw(values)
            elif action == "vector":
                node[key] = draw(vectors)
            elif action == "number":
                node[key] = draw(numbers)
            else:
                node[key] = draw(values)
            break
    return doc


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) \
            else repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"


def to_toml(doc: dict) -> str:
    """A document as TOML: every top-level key one line, tables written inline."""
    return "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in doc.items())


# ------------------------------------------------------------------ the loader


def loader_contract(doc: dict) -> None:
    try:
        text = to_toml(doc)
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, UnicodeEncodeError):
        return  # not a TOML document (e.g. a lone surrogate): load_scene's own error
    try:
        scene = parse_scene(data, "fuzz.toml")
    except SceneError as e:
        assert e.path == "fuzz.toml" and str(e)
        return
    # Accepted: every number the tracer will use is finite in float32.
    f32 = np.float32
    with np.errstate(over="ignore"):
        for s in scene.all_shapes():
            for name in ("radius", "a", "b", "height"):
                if hasattr(s, name):
                    assert np.isfinite(f32(getattr(s, name))) and f32(getattr(s, name)) > 0
            for name in ("to_world", "vertices", "center"):
                if hasattr(s, name) and not callable(getattr(s, name)):
                    assert np.isfinite(np.asarray(getattr(s, name), dtype=f32)).all()
        for light in scene.lights:
            for name in ("direction", "axis", "position"):
                if hasattr(light, name):
                    assert np.isfinite(np.asarray(getattr(light, name), dtype=f32)).all()


@settings(QUICK, max_examples=600)
@given(damaged_scenes())
def test_the_loader_returns_a_scene_or_a_scene_error(doc):
    loader_contract(doc)


@pytest.mark.slow
@settings(LONG, max_examples=5000)
@given(damaged_scenes())
def test_the_loader_returns_a_scene_or_a_scene_error_long(doc):
    loader_contract(doc)


@settings(QUICK, max_examples=60)
@given(st.binary(max_size=400) | st.text(alphabet="[]{}=\"'.,#\n \\0123456789aeflnrstux-+",
                                         max_size=400))
def test_any_bytes_as_a_scene_file_load_or_fail_with_a_scene_error(tmp_path_factory, blob):
    from whitted.tracer.scene import load_scene

    p = tmp_path_factory.mktemp("blob") / "s.toml"
    p.write_bytes(blob if isinstance(blob, bytes) else blob.encode())
    try:
        load_scene(p)
    except SceneError:
        pass


# ------------------------------------------------------------------ light-path expressions

lpe_text = st.text(alphabet=ALPHABET + ".|*+?()[] ", max_size=40) | st.text(max_size=12)
long_lpe_text = st.text(alphabet=ALPHABET + ".|*+?()", min_size=100, max_size=300)


def lpe_contract(expr: str) -> None:
    t0 = time.perf_counter()
    try:
        dfa = compile_lpe(expr)
    except LPEError as e:
        assert str(e) and len(str(e)) < 600
        return
    finally:
        assert time.perf_counter() - t0 < 5
    # The automaton accepts exactly the paths Python's regular expressions match, where
    # their syntax agrees: Python reads two postfix operators in a row (*+, +?, ??, ...)
    # as possessive or lazy quantifiers, the expressions as one applied after the other.
    text = expr.replace(" ", "")
    if re.search(r"[*+?]{2}", text):
        return
    try:
        pattern = re.compile(text)
    except (re.error, RecursionError, OverflowError):
        return
    rng = np.random.default_rng(len(expr))
    paths = ["", "LE", "LDE", "LSE", "LDSE", "LSSE", "LDDE", "E", "L"]
    paths += ["".join(rng.choice(list(ALPHABET), size=rng.integers(1, 7))) for _ in range(30)]
    for path in paths:
        assert dfa.matches(path) == bool(pattern.fullmatch(path)), (expr, path)


@settings(QUICK, max_examples=1000)
@given(lpe_text | long_lpe_text)
def test_light_path_expressions_compile_to_re_or_are_refused(expr):
    lpe_contract(expr)


@pytest.mark.slow
@settings(LONG, max_examples=10000)
@given(lpe_text | long_lpe_text)
def test_light_path_expressions_compile_to_re_or_are_refused_long(expr):
    lpe_contract(expr)


# ------------------------------------------------------------------ the command line

FAST_COMMANDS = ["render", "render", "render", "export", "paths", "depth-sweep", "scenes",
                 "bogus"]
MITSUBA_COMMANDS = ["reference", "compare", "fresnel"]

# Values: valid ones more often than invalid ones, so that many command lines run.
option_values = {
    "--spp": st.sampled_from(["1", "1", "4", "2", "10", "0", "-3", "x", str(2**31),
                              str(2**64)]),
    "--size": st.sampled_from(["4x3", "8x6", "1x1", "5X4", "7x2", "0x5", "100000x100000", "x",
                               "3", "2x" + "9" * 30]),
    "--max-depth": st.sampled_from(["1", "2", "5", "3", "0", str(10**10), "nan"]),
    "--seed": st.one_of(st.integers(min_value=-(2**70), max_value=2**70).map(str),
                        st.sampled_from(["x", "2**40", ""])),
    "--lpe": st.one_of(lpe_text.filter(lambda s: not s.startswith("-")),
                       st.sampled_from(["LDE", "LDS+E", "L" + "." * 19 + "D.*E"])),
    "--min-weight": st.sampled_from(["0", "1e-3", "-1", "nan", "inf", "x"]),
    "--pixel": st.lists(st.sampled_from(["0,0", "1,2", "3,1", "-1,0", "99,99", "a,b", "1"]),
                        min_size=1, max_size=3),
    "--depths": st.sampled_from(["1", "1-2", "2,1", "0", "1-300000000", "3-1", "x", "1,,2"]),
    "--repeat": st.sampled_from(["1", "0", str(10**9), "x"]),
    "--integrator": st.sampled_from(["whitted", "direct", "path", "bogus"]),
    "--backend": st.sampled_from(["llvm", "gpu"]),
    "--ior": st.lists(st.sampled_from(["1.5", "0", "-1", "nan", "1e9"]), min_size=1, max_size=3),
    "--step": st.sampled_from(["5", "0", "46", "1e-9", "nan"]),
    "--samples": st.sampled_from(["100", "99", str(10**12)]),
    "--bogus": st.just(None),
    "--no-mitsuba": st.just(None),
}
SCENE_OPTIONS = ["--spp", "--size", "--max-depth", "--backend"]
COMMAND_OPTIONS = {
    "render": SCENE_OPTIONS + ["--seed", "--lpe", "--min-weight"],
    "reference": SCENE_OPTIONS + ["--seed", "--integrator"],
    "compare": SCENE_OPTIONS + ["--seed", "--integrator"],
    "export": SCENE_OPTIONS + ["--integrator"],
    "paths": SCENE_OPTIONS + ["--seed", "--pixel", "--no-mitsuba"],
    "depth-sweep": SCENE_OPTIONS + ["--seed", "--depths", "--repeat", "--min-weight",
                                    "--no-mitsuba"],
    "fresnel": ["--ior", "--step", "--samples", "--seed", "--backend"],
    "scenes": [],
    "bogus": [],
}


@st.composite
def command_lines(draw, commands, scenes_dir: Path, out: Path):
    """(argv, output path or None): a command with a scene, an output and some options."""
    cmd = draw(st.sampled_from(commands))
    argv = [cmd]
    if cmd in ("render", "reference", "compare", "export", "paths", "depth-sweep"):
        kind = draw(st.sampled_from(["damaged", "damaged", "damaged", "builtin", "missing",
                                     "junk"]))
        if kind == "damaged":
            p = scenes_dir / f"s{draw(st.integers(0, 10**9))}.toml"
            try:
                p.write_text(to_toml(draw(damaged_scenes(least=0))))
            except UnicodeEncodeError:
                p.write_text("film = 1\n")
            argv.append(str(p))
        elif kind == "builtin":
            argv.append(draw(st.sampled_from(["sphere_point", "three_lights", "area_lights"])))
        elif kind == "missing":
            argv.append(str(scenes_dir / "missing.toml"))
        else:
            argv.append(draw(st.sampled_from(["-", "", "x" * 300, "/dev/zero", "a\nb"])))
    target = None
    if cmd != "scenes" and draw(st.sampled_from([True] * 9 + [False])):
        ext = {"export": ".xml", "paths": ".png"}.get(cmd, ".exr")
        name = draw(st.sampled_from(["out" + ext] * 5 + ["out.txt", "sub/out" + ext, "d",
                                                       "x" * 260 + ext]))
        if cmd in ("compare", "depth-sweep", "fresnel"):
            name = name.removesuffix(ext)
        target = out / name
        argv += ["-o", str(target)]
    pool = COMMAND_OPTIONS[cmd] + ([] if draw(st.integers(0, 5)) else ["--bogus", "--pixel"])
    for opt in draw(st.lists(st.sampled_from(pool), max_size=4, unique=True)) if pool else []:
        v = draw(option_values[opt])
        argv += [opt] if v is None else [opt, *v] if isinstance(v, list) else [opt, v]
    if cmd in ("paths", "depth-sweep") and "reference" not in commands:
        argv.append("--no-mitsuba")   # Mitsuba's commands run in the slow profile only
    if cmd in ("render", "reference", "compare", "paths", "depth-sweep") and \
            "--size" not in argv and draw(st.booleans()):
        argv += ["--size", "6x4"]
    return argv, target


def run_main(argv) -> tuple[int, str, str]:
    from whitted.reference.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    return rc, out.getvalue(), err.getvalue()


def cli_contract(argv, target, out: Path) -> None:
    rc, _, err = run_main(argv)
    written = sorted(out.rglob("*"))
    allowed = {0, 2} | ({1} if argv[0] in ("compare", "fresnel") else set())
    assert rc in allowed, (argv, rc, err)
    if rc == 2:
        lines = err.rstrip("\n").split("\n")
        assert len(lines) == 1 and lines[0].startswith("whitted"), (argv, err)
        assert len(err) < 1000, argv
        assert written == [], (argv, written)
    else:
        assert "Traceback" not in err
        if target is not None and argv[0] in ("render", "reference") \
                and target.suffix == ".exr":
            from whitted.tracer.imageio import read_exr

            assert np.isfinite(read_exr(target)).all(), argv
    for p in sorted(written, reverse=True):  # the next example starts from an empty folder
        p.rmdir() if p.is_dir() else p.unlink()


@pytest.fixture
def fuzz_env(monkeypatch, tmp_path):
    # Small limits: the fuzzer explores refusals and keeps every accepted job small.
    monkeypatch.setenv("WHITTED_MAX_SAMPLES", "20000")
    monkeypatch.setenv("WHITTED_MAX_MEMORY", "2G")
    monkeypatch.setenv("WHITTED_MAX_DEPTH", "12")
    (tmp_path / "scenes").mkdir()
    (tmp_path / "out").mkdir()
    return tmp_path


def test_the_command_line_exits_0_with_a_finite_image_or_2_in_one_line(fuzz_env):
    scenes, out = fuzz_env / "scenes", fuzz_env / "out"

    @settings(QUICK, max_examples=50)
    @given(command_lines(FAST_COMMANDS, scenes, out))
    def check(case):
        cli_contract(*case, out)

    check()


@pytest.mark.slow
def test_the_command_line_contract_long(fuzz_env):
    scenes, out = fuzz_env / "scenes", fuzz_env / "out"

    @settings(LONG, max_examples=300)
    @given(command_lines(FAST_COMMANDS + MITSUBA_COMMANDS, scenes, out))
    def check(case):
        cli_contract(*case, out)

    check()


def test_the_fuzzer_draws_hostile_values():
    """The strategies reach the classes they are meant to (else the fuzzer tests little)."""
    from hypothesis import find

    find(damaged_scenes(), lambda d: any(
        isinstance(v, float) and (math.isnan(v) or abs(v) > 3.5e38)
        for v in _leaves(d)), settings=settings(database=None, derandomize=True))


def _leaves(v):
    if isinstance(v, dict):
        for x in v.values():
            yield from _leaves(x)
    elif isinstance(v, list):
        for x in v:
            yield from _leaves(x)
    else:
        yield v
