"""Bad scenes are refused before anything renders (scene format, "Bad input").

Each kind of bad input named by the contract is checked through the command
line: exit status 2, one line on stderr naming the file, the key and what was
expected, no traceback, and an existing output file left untouched.
"""

import math

import pytest
from conftest import MINIMAL, ROOT, run_cli, write_scene

from whitted.tracer.errors import SceneError
from whitted.tracer.scene import (
    Dielectric,
    Mirror,
    Rectangle,
    Sphere,
    Triangle,
    load_scene,
    parse_scene,
)

# (test id, replacement applied to MINIMAL, key expected in the message, words expected)
BAD = [
    ("invalid_toml", ("[film]", "[film"), "", "not valid TOML"),
    ("unknown_key", ("radius = 1", "radius = 1\nradiuss = 2"), "shapes[0].radiuss",
     "unknown key"),
    ("unknown_shape_type", ('type = "sphere"', 'type = "torus"'), "shapes[0].type",
     "expected one of"),
    ("unknown_material_type", ('type = "diffuse"', 'type = "velvet"'), "materials.white.type",
     "expected one of"),
    ("unknown_light_type", ('type = "point"', 'type = "laser"'), "lights[0].type",
     "expected one of"),
    ("wrong_length_vector", ("center = [0, 0, 0]", "center = [0, 0]"), "shapes[0].center",
     "expected a list of 3"),
    ("zero_radius", ("radius = 1", "radius = 0"), "shapes[0].radius", "> 0"),
    ("negative_radius", ("radius = 1", "radius = -0.5"), "shapes[0].radius", "> 0"),
    ("nan", ("radius = 1", "radius = nan"), "shapes[0].radius", "finite"),
    ("infinity", ("center = [0, 0, 0]", "center = [0, inf, 0]"), "shapes[0].center", "finite"),
    ("unknown_material_name", ('material = "white"', 'material = "whte"'),
     "shapes[0].material", 'unknown material "whte"'),
]


def _bad_scene(tmp_path, old_new):
    old, new = old_new
    assert old in MINIMAL
    return write_scene(tmp_path, MINIMAL.replace(old, new, 1))


@pytest.mark.parametrize("case", BAD, ids=[b[0] for b in BAD])
def test_bad_scene_is_refused_with_one_line_and_exit_2(tmp_path, case):
    _, old_new, key, words = case
    scene = _bad_scene(tmp_path, old_new)
    out = tmp_path / "out.png"
    out.write_bytes(b"previous result")
    r = run_cli("render", scene, "-o", out)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    assert str(scene) in lines[0]
    assert key in lines[0]
    assert words in lines[0]
    assert out.read_bytes() == b"previous result"  # not clobbered
    assert r.stdout == ""


def test_ior_not_positive_is_refused(tmp_path):
    text = MINIMAL.replace('type = "diffuse"\nreflectance = 0.5',
                           'type = "dielectric"\nior = 0')
    scene = write_scene(tmp_path, text)
    out = tmp_path / "never.exr"
    r = run_cli("render", scene, "-o", out)
    assert r.returncode == 2
    assert "materials.white.ior" in r.stderr and "> 0" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_missing_scene_file_is_refused(tmp_path):
    r = run_cli("render", tmp_path / "nope.toml", "-o", tmp_path / "x.png")
    assert r.returncode == 2
    assert "nope.toml" in r.stderr and "no such scene file" in r.stderr
    assert not (tmp_path / "x.png").exists()


def test_bad_output_extension_is_refused_before_rendering(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    r = run_cli("render", scene, "-o", tmp_path / "x.jpg")
    assert r.returncode == 2 and "unknown image format" in r.stderr


@pytest.mark.parametrize("text,key", [
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,1]\n", "camera.target"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\nup=[0,0,2]\n", "camera.up"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\nfov=180\n", "camera.fov"),
    ("[camera]\ntype='orthographic'\norigin=[0,0,1]\ntarget=[0,0,0]\nfov=40\nwidth=2\n",
     "camera.fov"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[film]\nspp=0\n", "film.spp"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[film]\nwidth=2.5\n", "film.width"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[[lights]]\ntype='spot'\nposition=[0,1,0]\n"
     "target=[0,0,0]\nintensity=1\ncutoff_angle=10\nbeam_width=20\n", "lights[0].beam_width"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[[lights]]\ntype='point'\nposition=[0,1,0]\n"
     "intensity=[1,-1,1]\n", "lights[0].intensity"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[materials.m]\ntype='diffuse'\n"
     "reflectance=1.5\n", "materials.m.reflectance"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[materials.m]\ntype='diffuse'\n"
     "[[shapes]]\ntype='rectangle'\nmaterial='m'\nto_world=[{scale=[1,0,1]}]\n",
     "shapes[0].to_world[0].scale"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[materials.m]\ntype='diffuse'\n"
     "[[shapes]]\ntype='sphere'\nmaterial='m'\nto_world=[{scale=[1,2,1]}]\n",
     "shapes[0].to_world"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[materials.m]\ntype='diffuse'\n"
     "[[shapes]]\ntype='triangle'\nmaterial='m'\nvertices=[[0,0,0],[1,1,1],[2,2,2]]\n",
     "shapes[0].vertices"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[materials.m]\ntype='diffuse'\n"
     "[[shapes]]\ntype='rectangle'\nmaterial='m'\nto_world=[{shear=1}]\n",
     "shapes[0].to_world[0].shear"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n[[shapes]]\ntype='sphere'\n", "shapes[0].material"),
    ("[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\ncolour=1\n", "camera.colour"),
    ("scenery = 1\n[camera]\norigin=[0,0,1]\ntarget=[0,0,0]\n", "scenery"),
])
def test_more_bad_values_name_their_key(text, key):
    with pytest.raises(SceneError) as e:
        parse_scene(__import__("tomllib").loads(text), "x.toml")
    assert e.value.key == key, str(e.value)
    assert str(e.value).startswith(f"x.toml: {key}: ")


CONTRACT_EXAMPLE = ROOT / "tests" / "data" / "contract_example.toml"


def test_the_contracts_example_is_accepted_as_written():
    s = load_scene(CONTRACT_EXAMPLE)
    assert (s.film.width, s.film.height, s.film.spp, s.film.max_depth) == (320, 240, 16, 6)
    assert s.camera.type == "perspective" and s.camera.fov == 45
    assert isinstance(s.materials["glass"], Dielectric) and s.materials["glass"].eta == 1.5
    assert isinstance(s.materials["chrome"], Mirror)
    assert [type(x).__name__ for x in s.lights] == ["PointLight", "DirectionalLight", "SpotLight"]
    assert [type(x) for x in s.shapes] == [Sphere, Rectangle, Triangle]
    # The directional light's direction is stored normalised, as Mitsuba does.
    assert math.isclose(sum(c * c for c in s.lights[1].direction), 1.0)
    # Spot defaults follow Mitsuba's: beam_width given here, kept as given.
    assert s.lights[2].beam_width == 20 and s.lights[2].cutoff_angle == 30


def test_to_world_steps_apply_first_step_first():
    text = ("[camera]\norigin=[0,0,5]\ntarget=[0,0,0]\n[materials.m]\ntype='diffuse'\n"
            "[[shapes]]\ntype='triangle'\nmaterial='m'\nvertices=[[1,0,0],[0,1,0],[0,0,1]]\n"
            "to_world=[{scale=2},{translate=[1,0,0]}]\n")
    s = parse_scene(__import__("tomllib").loads(text))
    # scale first, then translate: (1,0,0) -> (2,0,0) -> (3,0,0)
    assert s.shapes[0].vertices[0] == (3.0, 0.0, 0.0)


def test_non_square_spp_rounds_up_like_mitsuba():
    text = "[film]\nspp=10\n[camera]\norigin=[0,0,5]\ntarget=[0,0,0]\n"
    s = parse_scene(__import__("tomllib").loads(text))
    assert s.film.strata == 4  # Mitsuba's stratified sampler: ceil(sqrt(10))^2 = 16


BASE = "[camera]\norigin=[0,0,5]\ntarget=[0,0,0]\n[materials.m]\ntype='diffuse'\n"


def test_missing_mesh_file_is_refused_with_one_line(tmp_path):
    scene = write_scene(tmp_path, BASE + "[[shapes]]\ntype='mesh'\nfile='nowhere.obj'\n"
                                         "material='m'\n")
    out = tmp_path / "out.exr"
    r = run_cli("render", scene, "-o", out)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "shapes[0].file" in r.stderr and "nowhere.obj" in r.stderr
    assert "Traceback" not in r.stderr and not out.exists()


@pytest.mark.parametrize("shapes,key,words", [
    ("[[shapes]]\ntype='instance'\ngroup='nope'\n", "shapes[0].group", 'unknown group "nope"'),
    ("[groups.g]\n[[groups.g.shapes]]\ntype='instance'\ngroup='g'\n", "groups.g.shapes[0].type",
     "nested instancing"),
    ("[[shapes]]\ntype='paraboloid'\nmaterial='m'\nemitter={radiance=1}\n", "shapes[0].emitter",
     "not on a paraboloid"),
    ("[[shapes]]\ntype='polygon'\nmaterial='m'\nvertices=[[0,0,0],[1,0,0],[1,1,0],[0,1,0.5]]\n",
     "shapes[0].vertices", "planar"),
    # A pentagram drawn point to point: its edges cross.
    ("[[shapes]]\ntype='polygon'\nmaterial='m'\nvertices=[[0.0,1.0,0],[-0.5878,-0.809,0],[0.9511,0.309,0],[-0.9511,0.309,0],[0.5878,-0.809,0]]\n",
     "shapes[0].vertices", "simple"),
    ("[[shapes]]\ntype='polygon'\nmaterial='m'\nvertices=[[0,0,0],[1,0,0]]\n",
     "shapes[0].vertices", "at least 3"),
    ("[[shapes]]\ntype='paraboloid'\nmaterial='m'\na=0\n", "shapes[0].a", "> 0"),
    ("[[shapes]]\ntype='cylinder'\nmaterial='m'\nto_world=[{scale=[1,2,1]}]\n",
     "shapes[0].to_world", "cross-section"),
    ("[[shapes]]\ntype='cylinder'\nmaterial='m'\np0=[1,1,1]\np1=[1,1,1]\n", "shapes[0].p1",
     "different from p0"),
    ("[[shapes]]\ntype='mesh'\nmaterial='m'\nfile='x.obj'\nsmooth='yes'\n", "shapes[0].file",
     "no such mesh file"),
])
def test_bad_new_shapes_name_their_key(shapes, key, words):
    with pytest.raises(SceneError) as e:
        parse_scene(__import__("tomllib").loads(BASE + shapes), "x.toml")
    assert e.value.key == key, str(e.value)
    assert words in str(e.value)


@pytest.mark.parametrize("material,key,words", [
    ("type='phong'\ndiffuse=0.7\nspecular=0.5\n", "materials.p.specular", "diffuse + specular"),
    ("type='phong'\nexponent=0\n", "materials.p.exponent", "> 0"),
    ("type='phong'\nmodel='cook-torrance'\n", "materials.p.model", "blinn-phong"),
    ("type='diffuse'\nreflectance={checkerboard={color0=0.5,scale=-1}}\n",
     "materials.p.reflectance.checkerboard.scale", "positive"),
    # An unknown texture kind is named as such, at its own key (not "checkerboard: missing").
    ("type='diffuse'\nreflectance={marble={}}\n", "materials.p.reflectance.marble",
     "unknown texture (expected one of: checkerboard, bitmap)"),
    ("type='diffuse'\nreflectance={bitmap={filename='t.png'}}\n",
     "materials.p.reflectance.bitmap.filename", "no such image file"),
    ("type='diffuse'\nreflectance={}\n", "materials.p.reflectance",
     "expected exactly one of checkerboard, bitmap in a texture, got none"),
])
def test_bad_new_materials_name_their_key(material, key, words):
    text = "[camera]\norigin=[0,0,5]\ntarget=[0,0,0]\n[materials.p]\n" + material
    with pytest.raises(SceneError) as e:
        parse_scene(__import__("tomllib").loads(text), "x.toml")
    assert e.value.key == key, str(e.value)
    assert words in str(e.value)


def test_ambient_and_schlick_may_be_declared_tracer_only():
    text = ("[compare]\ntracer_only=['ambient','schlick']\n[camera]\norigin=[0,0,5]\n"
            "target=[0,0,0]\n")
    assert parse_scene(__import__("tomllib").loads(text)).tracer_only == ("ambient", "schlick")
    with pytest.raises(SceneError):
        parse_scene(__import__("tomllib").loads(text.replace("'ambient'", "'fog'")))
