"""Bad input is refused in one line with exit status 2 before any work; valid extremes render.

One group of tests per class of failure: seeds, work and memory, float32 range
and degeneracy, the file system, nesting and automaton size, the commands'
options and messages, many instances, interrupts and a full stdout.
"""

import contextlib
import io
import json
import math
import os
import signal
import stat
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import MINIMAL, ROOT, write_scene

from whitted.tracer.imageio import read_exr

AREA = """
[film]
width = 6
height = 4
spp = 4
max_depth = 2

[camera]
origin = [0, 0, 5]
target = [0, 0, 0]

[materials.white]
type = "diffuse"
reflectance = 0.5

[[shapes]]
type = "rectangle"
material = "white"
to_world = [ { scale = 3 } ]

[[shapes]]
type = "sphere"
center = [0.5, 0.5, 1.5]
radius = 0.3
emitter = { radiance = 4 }
"""


def cli(*args) -> tuple[int, str, str]:
    """``whitted ARGS`` in this process: (exit status, stdout, stderr)."""
    from whitted.reference.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) if not isinstance(a, bytes) else os.fsdecode(a) for a in args])
    return rc, out.getvalue(), err.getvalue()


def refused(rc: int, err: str, *words: str) -> bool:
    """Exit 2 with exactly one line on stderr that holds every word."""
    lines = err.strip("\n").split("\n")
    return rc == 2 and len(lines) == 1 and all(w in err for w in words)


def files_under(path) -> list:
    return sorted(p for p in path.rglob("*"))


# ------------------------------------------------------------------ 1. seeds


@pytest.mark.parametrize("seed", [16384, -1, 2**32, 2**40, -(10**30)])
def test_any_integer_seed_renders_an_area_light_scene(tmp_path, seed):
    scene = write_scene(tmp_path, AREA)
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr", "--seed", seed)
    assert rc == 0, err
    assert np.isfinite(read_exr(tmp_path / "x.exr")).all()


def test_large_seeds_are_hashed_not_folded_onto_small_ones(tmp_path):
    from whitted.tracer.sampling import seed32

    assert seed32(7) == 7 and seed32(2**32 - 1) == 2**32 - 1
    for big in (2**32, 2**32 + 7, -1, -(2**40), 10**30):
        assert 0 <= seed32(big) < 2**32
    assert len({seed32(s) for s in (-1, 2**32, 2**32 + 7, 2**40, 2**64, 10**30)}) == 6
    scene = write_scene(tmp_path, AREA)
    imgs = []
    for s in (0, 16384, 2**40):
        assert cli("render", scene, "-o", tmp_path / f"{s}.exr", "--seed", s)[0] == 0
        imgs.append(read_exr(tmp_path / f"{s}.exr"))
    assert not np.array_equal(imgs[0], imgs[1]) and not np.array_equal(imgs[1], imgs[2])


def test_reference_accepts_a_seed_beyond_32_bits(tmp_path, mi):
    scene = write_scene(tmp_path, AREA)
    rc, _, err = cli("reference", scene, "-o", tmp_path / "r.exr", "--seed", 2**40)
    assert rc == 0, err
    assert np.isfinite(read_exr(tmp_path / "r.exr")).all()


# ------------------------------------------------------------------ 2. work and memory


@pytest.mark.parametrize("args,words", [
    (["--spp", 2**31, "--size", "1x1"], ("WHITTED_MAX_MEMORY",)),
    (["--spp", 2**32, "--size", "1x1"], ("WHITTED_MAX_SAMPLES",)),
    (["--size", "100000x100000"], ("WHITTED_MAX_SAMPLES",)),
    (["--max-depth", 10**10], ("WHITTED_MAX_DEPTH",)),
])
def test_a_render_that_cannot_finish_is_refused_at_once(tmp_path, args, words):
    scene = write_scene(tmp_path, MINIMAL)
    t0 = time.perf_counter()
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr", *args)
    assert refused(rc, err, *words), err
    assert time.perf_counter() - t0 < 20 and files_under(tmp_path) == [scene]


def test_a_scene_max_depth_beyond_the_limit_is_refused(tmp_path):
    scene = write_scene(tmp_path, MINIMAL.replace("max_depth = 2", "max_depth = 10000000000"))
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert refused(rc, err, "WHITTED_MAX_DEPTH"), err


def test_the_limits_are_changed_by_environment_variables(tmp_path, monkeypatch):
    scene = write_scene(tmp_path, MINIMAL)
    monkeypatch.setenv("WHITTED_MAX_SAMPLES", "10")
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")     # 8 x 6 x 1 = 48 samples
    assert refused(rc, err, "WHITTED_MAX_SAMPLES", "10"), err
    monkeypatch.setenv("WHITTED_MAX_SAMPLES", "48")
    assert cli("render", scene, "-o", tmp_path / "x.exr")[0] == 0
    monkeypatch.setenv("WHITTED_MAX_SAMPLES", "lots")
    rc, _, err = cli("render", scene, "-o", tmp_path / "y.exr")
    assert refused(rc, err, "WHITTED_MAX_SAMPLES"), err


def test_huge_depth_ranges_and_repeats_are_refused_before_expanding(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    t0 = time.perf_counter()
    rc, _, err = cli("depth-sweep", scene, "--depths", "1-300000000", "-o", tmp_path / "d")
    assert refused(rc, err, "--depths"), err
    rc, _, err = cli("depth-sweep", scene, "--repeat", 10**9, "-o", tmp_path / "d")
    assert refused(rc, err, "--repeat"), err
    assert time.perf_counter() - t0 < 10 and not (tmp_path / "d").exists()


def test_fresnel_tables_beyond_the_sample_limit_are_refused(tmp_path):
    rc, _, err = cli("fresnel", "-o", tmp_path / "f", "--step", "1e-9")
    assert refused(rc, err, "WHITTED_MAX_SAMPLES"), err
    assert not (tmp_path / "f").exists()


# ------------------------------------------------------------------ 3. float32 range


@pytest.mark.parametrize("old,new", [
    ("intensity = 10", "intensity = 1e39"),
    ("position = [0, 3, 3]", "position = [0, 3, 1e39]"),
    ("center = [0, 0, 0]", "center = [1e39, 0, 0]"),
    ('material = "white"', 'material = "white"\nto_world = [ { translate = [0, 1e39, 0] } ]'),
    ('type = "sphere"\ncenter = [0, 0, 0]\nradius = 1',
     'type = "rectangle"\nto_world = [ { rotate = { axis = [1e-170, 0, 0], angle = 30 } } ]'),
    ('material = "white"', 'material = "white"\nto_world = [ { scale = 1e-30 } ]'),
    ('material = "white"', 'material = "white"\nto_world = [ { scale = [1, 1, 1e-12] } ]'),
    ("radius = 1", "radius = 1e-200"),
])
def test_values_beyond_float32_or_degenerate_in_it_are_refused(tmp_path, old, new):
    scene = write_scene(tmp_path, MINIMAL.replace(old, new))
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert refused(rc, err, str(scene)), err
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("light", [
    'type = "directional"\ndirection = [1e-200, -1e-200, 0]\nirradiance = 1',
    'type = "spot"\nposition = [0, 3, 3]\ntarget = [0, 3, 3.000000000000001]\n'
    'intensity = 1',
])
def test_near_zero_light_directions_are_refused(tmp_path, light):
    text = MINIMAL.replace('type = "point"\nposition = [0, 3, 3]\nintensity = 10', light)
    scene = write_scene(tmp_path, text)
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert refused(rc, err, "lights[0]"), err


def test_a_cylinder_shorter_than_float32_resolves_is_refused(tmp_path):
    text = MINIMAL.replace('type = "sphere"\ncenter = [0, 0, 0]\nradius = 1',
                           'type = "cylinder"\np0 = [0, 0, 0]\np1 = [0, 0, 1e-200]')
    scene = write_scene(tmp_path, text)
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert refused(rc, err, "shapes[0]"), err


def test_a_small_uniform_scale_is_a_valid_transform(tmp_path):
    text = MINIMAL.replace('material = "white"',
                           'material = "white"\nto_world = [ { scale = 1e-5 }, { scale = 1e5 } ]')
    scene = write_scene(tmp_path, text)
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert rc == 0, err
    img = read_exr(tmp_path / "x.exr")
    assert np.isfinite(img).all() and img.max() > 0
    # Alone, too: a sphere of radius 1e-5 is a valid (tiny) sphere.
    text = MINIMAL.replace('material = "white"',
                           'material = "white"\nto_world = [ { scale = 1e-5 } ]')
    scene = write_scene(tmp_path, text, "tiny.toml")
    assert cli("render", scene, "-o", tmp_path / "y.exr")[0] == 0


def test_an_image_that_overflows_float32_is_refused_not_written(tmp_path):
    # A legal intensity, but 3e38 W/sr at 0.5 m or less gives over 1.2e39 W/m^2: beyond
    # float32 where the light reaches the sphere.
    text = MINIMAL.replace("intensity = 10", "intensity = 3e38").replace(
        "position = [0, 3, 3]", "position = [0, 0, 1.5]")
    scene = write_scene(tmp_path, text)
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert refused(rc, err, "float32"), err
    assert not (tmp_path / "x.exr").exists()


def test_metrics_json_is_strict_json_even_for_infinite_metrics(tmp_path):
    from whitted.reference.verdicts.compare import write_json

    write_json(tmp_path / "m.json", {"a": math.inf, "b": [math.nan, 1.0], "c": {"d": -math.inf}})

    def no_constants(name):
        raise AssertionError(f"{name} in JSON")

    data = json.loads((tmp_path / "m.json").read_text(), parse_constant=no_constants)
    assert data == {"a": None, "b": [None, 1.0], "c": {"d": None}}


# ------------------------------------------------------------------ 4. file system


def test_outputs_that_cannot_be_written_are_refused_before_rendering(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    (tmp_path / "file").write_text("x")
    for out in ("/proc/whitted.exr", "/sys/whitted.png", tmp_path / "file" / "x.png",
                tmp_path / ("a" * 300 + ".png"), tmp_path / "no" / "such" / "x.png"):
        rc, _, err = cli("render", scene, "-o", out)
        assert refused(rc, err), (out, err)
    for cmd in (["compare", scene], ["depth-sweep", scene, "--no-mitsuba"], ["fresnel"],
                ["export", scene], ["paths", scene, "--no-mitsuba"]):
        out = tmp_path / "file" / ("x.xml" if cmd[0] == "export" else
                                   "x.png" if cmd[0] == "paths" else "sub")
        rc, _, err = cli(*cmd, "-o", out)
        assert refused(rc, err), (cmd, err)
        rc, _, err = cli(*cmd, "-o", "/proc/whitted_out" + (".xml" if cmd[0] == "export" else
                                                           ".png" if cmd[0] == "paths" else ""))
        assert refused(rc, err), (cmd, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "scene.toml"]


def test_a_long_name_whose_temporary_name_would_be_too_long_is_written(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    out = tmp_path / ("a" * 250 + ".png")
    rc, _, err = cli("render", scene, "-o", out)
    assert rc == 0, err
    assert out.exists() and [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_name_that_is_not_utf8_is_written_and_printed_escaped(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    folder = os.path.join(os.fsencode(tmp_path), b"\xfe")
    os.mkdir(folder)
    out = os.path.join(folder, b"\xff.exr")
    code = ("import sys\nfrom whitted.reference.cli import main\n"
            f"sys.exit(main(['render', {str(scene)!r}, '-o', "
            f"__import__('os').fsdecode({out!r})]))\n")
    # Outside the C locale, where Python's stdout is strict UTF-8 and would refuse to print it.
    env = dict(os.environ, LC_ALL="C.UTF-8", PYTHONUTF8="0", PYTHONIOENCODING="")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, cwd=ROOT, env=env)
    assert r.returncode == 0, r.stderr
    assert os.path.exists(out) and b"Traceback" not in r.stderr


def test_os_errors_while_writing_are_one_line(tmp_path, monkeypatch):
    import errno

    from whitted.tracer import imageio

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(imageio, "_write_png_file", full)
    scene = write_scene(tmp_path, MINIMAL)
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.png")
    assert refused(rc, err, "No space left on device"), err
    assert files_under(tmp_path) == [scene]


def test_scene_files_that_are_devices_fifos_huge_or_long_named_are_refused(tmp_path,
                                                                           monkeypatch):
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    big = write_scene(tmp_path, MINIMAL + "\n# " + "x" * 5000, "big.toml")
    monkeypatch.setenv("WHITTED_MAX_SCENE_BYTES", "4096")
    t0 = time.perf_counter()
    for path, words in (("/dev/zero", ("regular file",)), (fifo, ("regular file",)),
                        (big, ("WHITTED_MAX_SCENE_BYTES",)),
                        (tmp_path / ("s" * 300 + ".toml"), ()),
                        ("x" * 100_000, ())):
        rc, _, err = cli("render", path, "-o", tmp_path / "x.exr")
        assert refused(rc, err, *words), (str(path)[:80], err[:300])
        assert len(err) < 1200
    assert time.perf_counter() - t0 < 10


def test_written_files_get_the_mode_the_umask_gives(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    old = os.umask(0o022)
    try:
        assert cli("render", scene, "-o", tmp_path / "x.png")[0] == 0
        assert cli("export", scene, "-o", tmp_path / "s.xml")[0] == 0
    finally:
        os.umask(old)
    for name in ("x.png", "s.xml"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644


def test_two_scenes_exported_into_one_folder_keep_their_meshes(tmp_path):
    tri = MINIMAL.replace('type = "sphere"\ncenter = [0, 0, 0]\nradius = 1',
                          'type = "triangle"\nvertices = [[0, 0, 0], [1, 0, 0], [0, {y}, 0]]')
    a = write_scene(tmp_path, tri.replace("{y}", "1"), "a.toml")
    b = write_scene(tmp_path, tri.replace("{y}", "2"), "b.toml")
    out = tmp_path / "out"
    out.mkdir()
    assert cli("export", a, "-o", out / "a.xml")[0] == 0
    assert cli("export", b, "-o", out / "b.xml")[0] == 0
    meshes = sorted((out / "meshes").iterdir())
    assert len(meshes) == 2
    for xml in ("a.xml", "b.xml"):
        text = (out / xml).read_text()
        refs = [m.name for m in meshes if f"meshes/{m.name}" in text]
        assert len(refs) == 1


# ------------------------------------------------------------------ 5. nesting and blow-up


@pytest.mark.parametrize("text", [
    "x = " + "[" * 5000 + "]" * 5000,
    "x = " + "{a = " * 3000 + "1" + "}" * 3000,
    "x = " + "[" * 500 + "]" * 500,
])
def test_deeply_nested_toml_is_refused_in_one_line(tmp_path, text):
    scene = write_scene(tmp_path, MINIMAL + "\n[compare]\n" + text + "\n")
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert refused(rc, err, "nest"), err[:300]


@pytest.mark.parametrize("expr", ["(" * 3000 + "L" + ")" * 3000 + "E", "LDE" * 400,
                                  "L" + "." * 19 + "D.*E", "L" + "((((((((((D+)+)+)+)+)+)+)+)+)+)"
                                  * 3 + "E"])
def test_light_path_expressions_are_bounded_in_size_and_states(tmp_path, expr):
    from whitted.tracer.lpe import LPEError, compile_lpe

    t0 = time.perf_counter()
    try:
        dfa = compile_lpe(expr)
        assert len(dfa.transitions) <= 1000
    except LPEError as e:
        assert "\n" not in str(e) and len(str(e)) < 600
    assert time.perf_counter() - t0 < 5


def test_lpe_beyond_the_state_limit_names_the_limit(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr", "--lpe", "L" + "." * 19 + "D.*E")
    assert refused(rc, err, "WHITTED_LPE_MAX_STATES"), err


# ------------------------------------------------------------------ 7. commands


def test_paths_on_a_scene_without_any_light_path_is_not_a_crash(tmp_path):
    text = MINIMAL.replace('[[lights]]\ntype = "point"\nposition = [0, 3, 3]\nintensity = 10', "")
    scene = write_scene(tmp_path, text)
    rc, out, err = cli("paths", scene, "-o", tmp_path / "p.png", "--no-mitsuba")
    assert rc == 0, err
    assert (tmp_path / "p.png").exists() and "no pixel" in out


def test_compare_with_direct_on_a_glass_scene_is_refused_before_rendering(tmp_path):
    t0 = time.perf_counter()
    rc, _, err = cli("compare", "glass_sphere", "--integrator", "direct", "-o", tmp_path / "c")
    assert refused(rc, err, "--integrator"), err
    assert time.perf_counter() - t0 < 10 and not (tmp_path / "c").exists()


def test_seed_is_offered_only_where_it_is_used():
    from whitted.reference.cli import build_parser

    p = build_parser()
    subs = next(a for a in p._actions if a.dest == "command").choices
    for cmd in ("render", "reference", "compare", "depth-sweep", "paths", "fresnel"):
        assert "--seed" in subs[cmd].format_help(), cmd
    assert "--seed" not in subs["export"].format_help()


def test_depth_sweep_and_paths_honour_the_seed(tmp_path):
    scene = write_scene(tmp_path, AREA)
    for s in (1, 2):
        rc, _, err = cli("depth-sweep", scene, "--depths", "1", "--repeat", "1", "--no-mitsuba",
                         "--seed", s, "-o", tmp_path / f"d{s}")
        assert rc == 0, err
    a, b = ((tmp_path / f"d{s}" / "depth_01.png").read_bytes() for s in (1, 2))
    assert a != b


def test_paths_takes_several_pixels_after_one_option(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    rc, out, err = cli("paths", scene, "--pixel", "1,2", "3,4", "--pixel", "5,5",
                       "--no-mitsuba", "-o", tmp_path / "p.png")
    assert rc == 0, err
    assert "pixel 1,2" in out and "pixel 3,4" in out and "pixel 5,5" in out


def test_commands_page_is_generated_from_the_parser_and_documents_every_option():
    import importlib.util
    import re

    from whitted.reference.cli import build_parser

    spec = importlib.util.spec_from_file_location("make_commands",
                                                  ROOT / "docs" / "make_commands.py")
    make_commands = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_commands)
    page = (ROOT / "docs" / "commands.md").read_text()
    # Regenerate with: python docs/make_commands.py > docs/commands.md
    assert page == make_commands.render(), "docs/commands.md is stale: regenerate it"

    subs = next(a for a in build_parser()._actions if a.dest == "command").choices
    assert set(make_commands.DESCRIPTIONS) == set(subs)
    sections = dict(re.findall(r"^## `whitted ([a-z-]+)`\n(.*?)(?=^## |\Z)", page, re.M | re.S))
    assert set(sections) == set(subs)
    for cmd, sp in subs.items():
        opts = {o for a in sp._actions for o in a.option_strings} - {"-h", "--help"}
        # Every option of the parser has its row in the command's section ...
        rows = set(re.findall(r"^\| `(-[-\w]+)", sections[cmd], re.M))
        rows |= set(re.findall(r", `(-[-\w]+)", sections[cmd]))
        assert opts <= rows, (cmd, opts - rows)
        # ... and the hand-written description names no option the command lacks
        # (but for one it says is not there: "no `--lpe`").
        named = set(re.findall(r"(?<![\w-])(?<!no `)--[a-z][a-z-]*",
                               make_commands.DESCRIPTIONS[cmd]))
        assert named <= opts, (cmd, named - opts)


@pytest.mark.parametrize("args", [["render"], ["render", "x.toml", "--spp", "zero"],
                                  ["bogus"], [], ["compare", "x", "--integrator", "y"]])
def test_parser_errors_are_one_line_pointing_to_help(args):
    rc, out, err = cli(*args)
    assert refused(rc, err, "--help"), err
    assert out == ""


def test_newlines_in_keys_and_huge_lists_make_one_short_line(tmp_path):
    scene = write_scene(tmp_path, MINIMAL + '\n[materials."a\\nb"]\ntype = "bogus"\n')
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert refused(rc, err, "a\\nb"), err
    big = MINIMAL.replace("center = [0, 0, 0]", "center = [" + "0, " * 200_000 + "0]")
    scene = write_scene(tmp_path, big, "big.toml")
    rc, _, err = cli("render", scene, "-o", tmp_path / "x.exr")
    assert refused(rc, err, "center"), err[:300]
    assert len(err) < 1000
    rc, _, err = cli("paths", scene, "-o", tmp_path / "p.png", "--pixel", *["1,1"] * 100)
    assert rc == 2 and len(err) < 1000


# ------------------------------------------------------------------ 8. many instances


def _instances(n: int, **kw):
    import tomllib

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_instances import instances_scene_text

    from whitted.tracer.scene import parse_scene

    return parse_scene(tomllib.loads(instances_scene_text(n, **kw)), f"inst{n}.toml")


def test_many_instances_sit_in_one_hierarchy_of_logarithmic_depth(jit):
    from whitted.tracer.geometry import Geometry, _InstanceSetBlock

    scene = _instances(1000)
    geo = Geometry(scene)
    sets = [b for b in geo.blocks if isinstance(b, _InstanceSetBlock)]
    assert len(sets) == 1 and len(geo.blocks) == 2      # the floor and one set
    assert sets[0].depth <= 2 * math.ceil(math.log2(1000))


def test_instances_behind_the_hierarchy_render_as_instances_one_by_one(jit):
    from whitted.tracer import geometry
    from whitted.tracer.integrator import Integrator

    scene = _instances(40, width=48, height=36, spp=4)
    tree = Integrator(scene).render().image
    old = geometry.INSTANCE_SET_MIN
    geometry.INSTANCE_SET_MIN = 10**9
    try:
        flat = Integrator(scene).render().image
    finally:
        geometry.INSTANCE_SET_MIN = old
    # Each instance is intersected by the same float32 operations either way.
    assert tree.max() > 0 and np.array_equal(tree, flat)


def test_a_hierarchy_of_mesh_instances_renders_as_the_instances_one_by_one(jit):
    """A group with a mesh (its own BVH, traversed inside the instances' one) and glass."""
    import tomllib

    from whitted.tracer import geometry
    from whitted.tracer.integrator import Integrator
    from whitted.tracer.scene import parse_scene

    text = ("[film]\nwidth = 32\nheight = 24\nspp = 4\nmax_depth = 3\n"
            "[camera]\norigin = [0, 6, 14]\ntarget = [0, 0, 0]\n"
            "[materials.m]\ntype = 'diffuse'\n[materials.glass]\ntype = 'dielectric'\n"
            "[[lights]]\ntype = 'point'\nposition = [0, 8, 6]\nintensity = 80\n"
            f"[[groups.k.shapes]]\ntype = 'mesh'\nfile = '{ROOT}/scenes/meshes/icosahedron.obj'\n"
            "material = 'm'\n[[groups.k.shapes]]\ntype = 'sphere'\nradius = 0.4\n"
            "center = [0, 1.5, 0]\nmaterial = 'glass'\n")
    for i in range(12):
        text += (f"[[shapes]]\ntype = 'instance'\ngroup = 'k'\nto_world = [{{ rotate = "
                 f"{{ axis = [0, 1, 0], angle = {30 * i} }} }}, {{ translate = "
                 f"[{(i % 4 - 1.5) * 3}, 0, {(i // 4 - 1) * 3}] }}]\n")
    scene = parse_scene(tomllib.loads(text), str(ROOT / "scenes" / "x.toml"))
    tree = Integrator(scene).render().image
    old = geometry.INSTANCE_SET_MIN
    geometry.INSTANCE_SET_MIN = 10**9
    try:
        flat = Integrator(scene).render().image
    finally:
        geometry.INSTANCE_SET_MIN = old
    assert tree.max() > 0 and np.array_equal(tree, flat)


def test_many_instances_convert_to_mitsuba(mi):
    from whitted.reference.renderers.mitsuba.scene import load

    scene = _instances(1000)
    t0 = time.perf_counter()
    ms = load(scene, mi, "direct")
    assert len(ms.shapes()) >= 2 and time.perf_counter() - t0 < 60


# ------------------------------------------------------------------ 9. interrupts, stdout


def test_interrupted_depth_sweep_leaves_no_partial_folder(tmp_path):
    out = tmp_path / "sweep"
    # Ctrl-C as at a terminal: a shell that started this run in the background without job
    # control leaves SIGINT ignored, and a child inherits that (it then never sees the signal).
    p = subprocess.Popen([sys.executable, "-m", "whitted.reference.cli", "depth-sweep",
                          "heckbert_minray", "--depths", "1-60", "--no-mitsuba", "-o", str(out)],
                         cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    line = p.stdout.readline()
    while line and not line.startswith("DEPTH"):
        line = p.stdout.readline()
    assert line.startswith("DEPTH"), p.stderr.read()
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130 and "Traceback" not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_ctrl_c_inside_a_symbolic_loop_is_an_interrupt(tmp_path, monkeypatch, capsys):
    """Dr.Jit re-raises a KeyboardInterrupt from a loop body it traces as a RuntimeError
    caused by it; the command still reports an interrupt (exit 130), not an error.
    (The test above met it by chance, when its Ctrl-C fell inside the tracing.)"""
    import drjit as dr

    from whitted.reference import cli
    from whitted.reference.commands import render
    from whitted.tracer.backend import jit

    def body(i):
        raise KeyboardInterrupt

    def interrupted(args):
        dr.while_loop((jit.UInt32(0),), lambda i: i < 3, body)

    def failing(args):
        raise RuntimeError("another failure")

    scene = write_scene(tmp_path, MINIMAL)
    monkeypatch.setattr(render, "run", interrupted)
    assert cli.main(["render", str(scene), "-o", str(tmp_path / "x.exr")]) == 130
    assert capsys.readouterr().err == "whitted: interrupted\n"
    monkeypatch.setattr(render, "run", failing)
    with pytest.raises(RuntimeError, match="another failure"):
        cli.main(["render", str(scene), "-o", str(tmp_path / "x.exr")])


def test_a_full_stdout_is_one_line_not_a_traceback(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    with open("/dev/full", "w") as full:
        r = subprocess.run([sys.executable, "-m", "whitted.reference.cli", "render", str(scene),
                            "-o", str(tmp_path / "x.exr")], cwd=ROOT, stdout=full,
                           stderr=subprocess.PIPE, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().split("\n")) == 1, r.stderr
    assert "standard output" in r.stderr and "Traceback" not in r.stderr


def test_compare_of_an_image_smaller_than_a_block(tmp_path):
    """An image lower or narrower than the 4 x 4 blocks of the statistical verdict is one
    block (found by the long command-line fuzzer: `compare --size 4x3` on an area-lit
    scene raised a ValueError in the block means)."""
    import numpy as np

    from whitted.reference.verdicts.compare import block_mean, block_metrics, block_pixels

    a = np.arange(36, dtype=np.float32).reshape(3, 4, 3)
    assert block_mean(a).shape == (1, 1, 3) and block_pixels(a) == 12
    np.testing.assert_allclose(block_mean(a)[0, 0], a.reshape(-1, 3).mean(0))
    m = block_metrics(a, a, np.ones_like(a))
    assert m["block_frac_over_5pct"] == 0.0
    code, out, err = cli("compare", "area_lights", "--size", "4x3", "--spp", "1",
                         "--max-depth", "1", "-o", str(tmp_path / "c"))
    assert code in (0, 1) and "Traceback" not in err, err
