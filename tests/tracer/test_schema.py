"""The JSON Schema of the scene format (tracer/schema.py, ``whitted schema``).

The schema is recorded from the loader's own parsers, so the tests check the
two against each other: every scene the loader accepts is valid under the
schema (the built-in and imported scenes, and a fuzzer's damaged scenes);
a scene with a wrong key or type is refused by both at the same key path; and
a kind that reads a new key shows it in the schema with nothing else changed.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from types import SimpleNamespace

import jsonschema
import pytest
from conftest import run_cli
from hypothesis import given, settings
from jsonschema.exceptions import best_match
from test_fuzz import BASE, QUICK, damaged_scenes, to_toml

import whitted.tracer.settings_schema as recording
from whitted.tracer import emitters, materials
from whitted.tracer.errors import SceneError
from whitted.tracer.materials import diffuse, textures
from whitted.tracer.scene import parse_scene
from whitted.tracer.schema import scene_schema

ROOT = Path(__file__).resolve().parents[2]
#: The built-in scenes and the scenes stored as test data (one imported from Mitsuba).
SCENES = sorted(ROOT.glob("scenes/*.toml")) + sorted((ROOT / "tests" / "data").rglob("*.toml"))


def validator() -> jsonschema.Draft202012Validator:
    s = scene_schema()
    jsonschema.Draft202012Validator.check_schema(s)
    return jsonschema.Draft202012Validator(s)


@pytest.fixture(scope="module")
def v():
    return validator()


def schema_error(v, doc: dict) -> tuple[str, str] | None:
    """The schema's most relevant error as (key path as the loader writes it, message)."""
    e = best_match(v.iter_errors(doc))
    if e is None:
        return None
    path = ""
    for p in e.absolute_path:
        path += f"[{p}]" if isinstance(p, int) else (f".{p}" if path else p)
    key = None
    if e.validator == "additionalProperties":  # said of the table: name the key
        key = next(k for k in e.instance if k not in e.schema.get("properties", {}))
    elif e.validator == "required":
        key = e.message.split("'")[1]
    if key is not None:
        path = f"{path}.{key}" if path else key
    return path, e.message


def loader_error(doc: dict, path: str = "x.toml") -> SceneError | None:
    try:
        parse_scene(doc, path)
    except SceneError as e:
        return e
    return None


def test_the_schema_is_a_valid_draft_2020_12_schema():
    s = validator().schema
    assert s["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    # every kind of every registry is a variant, found by its ``type``
    assert kinds(s["properties"]["materials"]["additionalProperties"]) == list(
        materials.REGISTRY)
    assert kinds(s["properties"]["lights"]["items"]) == list(emitters.LIGHTS)


def kinds(union: dict) -> list[str]:
    return union["allOf"][0]["properties"]["type"]["enum"]


def variant(union: dict, kind: str) -> dict:
    return next(m["then"] for m in union["allOf"][1:]
                if m["if"]["properties"]["type"]["const"] == kind)


def test_the_schema_uses_only_what_draft_7_has_too():
    """Editors' validators that know draft 7 only (Taplo's) read the schema alike: every
    scene is judged the same by a draft-7 validator."""
    s = dict(validator().schema)
    s.pop("$schema")
    old = jsonschema.Draft7Validator(s)
    jsonschema.Draft7Validator.check_schema(s)
    words = set()

    def walk(x):
        if isinstance(x, dict):
            words.update(x)
            for k, y in x.items():
                if k not in ("properties", "default"):
                    walk(y)
                elif k == "properties":
                    for z in y.values():
                        walk(z)
        elif isinstance(x, list):
            for y in x:
                walk(y)
    walk(s)
    assert words <= {"type", "properties", "additionalProperties", "required", "enum", "const",
                     "anyOf", "allOf", "if", "then", "items", "minItems", "maxItems", "minimum",
                     "maximum", "exclusiveMinimum", "exclusiveMaximum", "minProperties",
                     "maxProperties", "default", "description", "title"}, words
    for path in SCENES:
        assert not list(old.iter_errors(tomllib.loads(path.read_text()))), path


def test_there_are_scenes_to_check():
    names = {p.name for p in SCENES}
    assert len(SCENES) >= 20 and "floating_sphere.toml" in names and "whitted_1980.toml" in names


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.name)
def test_every_built_in_and_stored_scene_is_valid(v, path):
    doc = tomllib.loads(path.read_text())
    assert loader_error(doc, str(path)) is None
    assert schema_error(v, doc) is None, path


@settings(QUICK, max_examples=300)
@given(damaged_scenes())
def test_the_schema_accepts_every_scene_the_loader_accepts(doc):
    """Hostile values anywhere in a valid scene: what the loader takes, the schema takes
    (the schema is laxer, never stricter: it must not mark a good scene in an editor)."""
    try:
        data = tomllib.loads(to_toml(doc))
    except (tomllib.TOMLDecodeError, UnicodeEncodeError):
        return
    if loader_error(data) is None:
        assert schema_error(_V, data) is None


_V = validator()


CAMERA = "[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\n"
MATERIAL = "[materials.m]\ntype = 'diffuse'\n"


@pytest.mark.parametrize("text,key", [
    (MATERIAL + "reflectanse = 0.5\n", "materials.m.reflectanse"),
    (MATERIAL + "reflectance = 'red'\n", "materials.m.reflectance"),
    (MATERIAL + "reflectance = 2\n", "materials.m.reflectance"),
    (MATERIAL + "reflectance = { marble = { scale = 2 } }\n",
     "materials.m.reflectance.marble"),
    (MATERIAL + f"reflectance = {{ bitmap = {{ filename = '{ROOT}/scenes/textures/tiles.png', "
                "filter = 'nearest' } }\n",
     "materials.m.reflectance.bitmap.filter"),
    (MATERIAL + "reflectance = { checkerboard = { color0 = 0.5, colour1 = 0.1 } }\n",
     "materials.m.reflectance.checkerboard.colour1"),
    ("[materials.m]\ntype = 'phong'\nmodel = 'cook-torrance'\n", "materials.m.model"),
    ("[materials.m]\ntype = 'dielectric'\nior = 0\n", "materials.m.ior"),
    ("[materials.m]\ntype = 'velvet'\n", "materials.m.type"),
    ("[materials.m]\nreflectance = 0.5\n", "materials.m.type"),
    (MATERIAL + "[[shapes]]\ntype = 'sphere'\nmaterial = 'm'\nradius = -1\n", "shapes[0].radius"),
    (MATERIAL + "[[shapes]]\ntype = 'sphere'\nmaterial = 'm'\nradios = 1\n", "shapes[0].radios"),
    (MATERIAL + "[[shapes]]\ntype = 'sphre'\nmaterial = 'm'\n", "shapes[0].type"),
    (MATERIAL + "[[shapes]]\ntype = 'triangle'\nmaterial = 'm'\nvertices = [[0, 0, 0]]\n",
     "shapes[0].vertices"),
    (MATERIAL + f"[[shapes]]\ntype = 'mesh'\nmaterial = 'm'\nfile = '{ROOT}/scenes/meshes/"
     "icosahedron.obj'\nsmooth = 1\n", "shapes[0].smooth"),
    (MATERIAL + "[[shapes]]\ntype = 'rectangle'\nmaterial = 'm'\n"
     "to_world = [{ translate = [1, 2] }]\n", "shapes[0].to_world[0].translate"),
    (MATERIAL + "[[shapes]]\ntype = 'rectangle'\nmaterial = 'm'\n"
     "to_world = [{ tranzlate = [1, 2, 3] }]\n", "shapes[0].to_world[0].tranzlate"),
    (MATERIAL + "[[shapes]]\ntype = 'rectangle'\nmaterial = 'm'\n"
     "to_world = [{ rotate = { axis = [0, 1, 0] } }]\n", "shapes[0].to_world[0].rotate.angle"),
    ("[[shapes]]\ntype = 'rectangle'\nemitter = { radiance = 1, power = 2 }\n",
     "shapes[0].emitter.power"),
    ("[[lights]]\ntype = 'point'\nposition = [0, 0]\nintensity = 1\n", "lights[0].position"),
    ("[[lights]]\ntype = 'point'\nposition = [0, 0, 1]\n", "lights[0].intensity"),
    ("[[lights]]\nposition = [0, 0, 1]\nintensity = 1\n", "lights[0].type"),
    ("[[lights]]\ntype = 'spot'\nposition = [0, 0, 1]\ntarget = [0, 0, 0]\nintensity = 1\n"
     "cutoff_angle = 180\n", "lights[0].cutoff_angle"),
    ("[film]\nwidth = 0\n", "film.width"),
    ("[film]\nwidth = 2.5\n", "film.width"),
    ("[film]\nsamples = 4\n", "film.samples"),
    ("[compare]\ntracer_only = ['fresnel']\n", "compare.tracer_only[0]"),
    ("[compare]\ntracer_only = 'schlick'\n", "compare.tracer_only"),
    ("colour = 1\n", "colour"),
])
def test_a_wrong_key_or_type_is_refused_by_both_at_the_same_key(v, text, key):
    doc = tomllib.loads(text + CAMERA)
    err = loader_error(doc)
    assert err is not None and err.key == key, str(err)
    got = schema_error(v, doc)
    assert got is not None and got[0] == key, got


@pytest.mark.parametrize("text,key", [
    (CAMERA + "[[lights]]\ntype = 'point'\nintensity = 1\n", "lights[0].position"),
    (CAMERA + "[[lights]]\ntype = 'directional'\nirradiance = 1\n", "lights[0].direction"),
])
def test_a_missing_key_is_refused_by_both_at_that_key(v, text, key):
    doc = tomllib.loads(text)
    assert loader_error(doc).key == key
    assert schema_error(v, doc)[0] == key


@pytest.mark.parametrize("text,key", [
    ("[camera]\ntarget = [0, 0, 0]\n", "camera.origin"),
    ("[camera]\ntype = 'orthographic'\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\n", "camera.width"),
])
def test_keys_required_unless_another_is_given_are_left_to_the_loader(v, text, key):
    """A camera is placed by origin/target/up or by to_world, and an orthographic one's
    width can come from to_world: which is required depends on another key, so the
    schema accepts either and the loader names the missing key."""
    doc = tomllib.loads(text)
    assert loader_error(doc).key == key
    assert schema_error(v, doc) is None


def test_bounds_that_depend_on_other_keys_are_left_to_the_loader(v):
    """A spot's beam_width is at most its cutoff_angle: 40 is fine under a cutoff of 60
    (the default cutoff, 20, must not become the schema's maximum), 70 is not."""
    spot = ("[[lights]]\ntype = 'spot'\nposition = [0, 0, 1]\ntarget = [0, 0, 0]\n"
            "intensity = 1\ncutoff_angle = 60\nbeam_width = {}\n")
    ok = tomllib.loads(CAMERA + spot.format(40))
    assert loader_error(ok) is None and schema_error(v, ok) is None
    bad = tomllib.loads(CAMERA + spot.format(70))
    assert loader_error(bad).key == "lights[0].beam_width" and schema_error(v, bad) is None
    near_far = tomllib.loads(CAMERA + "near_clip = 1e-4\nfar_clip = 5e-3\n")
    assert loader_error(near_far) is None and schema_error(v, near_far) is None


# ------------------------------------------------------------------ no second list


def _toy_material(t, name):
    glow = t.number("glow", 2.0, lo=0)
    if t.has("halo"):
        t.color("halo")
    if t.string("mood", "calm", ("calm", "wild")) == "wild":
        t.number("fury", 1.0, lo=0)  # a key that one value of another key brings
    return diffuse.Diffuse(name, (glow / 4,) * 3)


def test_a_new_kind_and_a_new_key_appear_in_the_schema(monkeypatch):
    """A toy material kind, light kind and texture kind, registered as a kind is (one
    line in a registry), and a key a kind's parser starts to read: each is in the schema
    with its type, default and bounds, accepted and refused as the loader does."""
    monkeypatch.setattr(recording, "_VOCABULARY", {})
    before = scene_schema()
    monkeypatch.setitem(materials.REGISTRY, "toy", SimpleNamespace(parse=_toy_material))
    monkeypatch.setitem(emitters.LIGHTS, "lamp", SimpleNamespace(
        parse=lambda t: (t.vec3("position"), t.boolean("on", True))))
    monkeypatch.setitem(textures.TEXTURES, "marble", lambda t, hi: (t.color("vein", hi=hi),
                                                                    t.finish())[0])
    old_parse = diffuse.parse
    monkeypatch.setattr(diffuse, "parse",
                        lambda t, name: (old_parse(t, name), t.integer("sheen", 0, lo=0))[0])
    after = scene_schema()
    assert after != before
    mats = after["properties"]["materials"]["additionalProperties"]
    assert kinds(mats)[-1] == "toy"
    toy = variant(mats, "toy")
    # opacity: read for every kind (Mitsuba's mask), after the kind's own parser
    assert set(toy["properties"]) == {"type", "glow", "halo", "mood", "fury", "opacity"}
    assert toy["properties"]["glow"]["minimum"] == 0 and toy["properties"]["glow"]["default"] == 2
    assert toy["properties"]["mood"]["enum"] == ["calm", "wild"]
    assert "halo" not in toy.get("required", [])  # read only when present
    dif = variant(mats, "diffuse")
    assert dif["properties"]["sheen"]["type"] == "integer"
    tex = next(f for f in dif["properties"]["reflectance"]["anyOf"] if f.get("type") == "object")
    assert set(tex["properties"]) == {"checkerboard", "bitmap", "marble"}
    lights = after["properties"]["lights"]["items"]
    lamp = variant(lights, "lamp")
    assert lamp["properties"]["on"]["type"] == "boolean" and lamp["required"] == ["type",
                                                                                   "position"]
    vv = jsonschema.Draft202012Validator(after)
    good = tomllib.loads(CAMERA + "[materials.t]\ntype = 'toy'\nglow = 3\nhalo = [1, 1, 0]\n"
                         "[materials.d]\ntype = 'diffuse'\nsheen = 2\n"
                         "reflectance = { marble = { vein = 0.5 } }\n"
                         "[[lights]]\ntype = 'lamp'\nposition = [0, 1, 0]\non = false\n")
    assert schema_error(vv, good) is None
    for bad, key in (("glow = -1", "materials.t.glow"), ("mood = 'sad'", "materials.t.mood"),
                     ("halo = 'x'", "materials.t.halo"), ("gloww = 1", "materials.t.gloww")):
        doc = tomllib.loads(CAMERA + "[materials.t]\ntype = 'toy'\n" + bad + "\n")
        assert loader_error(doc).key == key and schema_error(vv, doc)[0] == key
    monkeypatch.undo()
    assert scene_schema() == before


def test_choices_among_many_values_do_not_multiply(monkeypatch):
    """Three keys naming one of 40 values each: varied one at a time (1 + 3 x 39 runs of the
    parser, not 40^3), and a key that a non-default value brings is still found."""
    names = tuple(f"glass{i}" for i in range(40))
    runs = []

    def parse(t, name):
        picks = [t.string(k, names[0], names) for k in ("ior", "ext_ior", "coat")]
        runs.append(tuple(picks))
        if picks[2] == names[-1]:
            t.number("coat_depth", 1.0)
        return diffuse.Diffuse(name)

    monkeypatch.setattr(recording, "_VOCABULARY", {})
    monkeypatch.setitem(materials.REGISTRY, "glassy", SimpleNamespace(parse=parse))
    glassy = variant(scene_schema()["properties"]["materials"]["additionalProperties"],
                     "glassy")
    # Every kind's ``opacity`` is read after its parser and its form (a colour or a
    # texture) decides keys, so each combination of picks is run once per form: the
    # distinct combinations are counted.
    assert "coat_depth" in glassy["properties"] and len(set(runs)) == 1 + 3 * 39


# ------------------------------------------------------------------ messages


@pytest.mark.parametrize("text,key,words", [
    # A camera placed by a misspelt key: named, with what it expected.
    ("[camera]\norgin = [0, 0, 5]\ntarget = [0, 0, 0]\n", "camera.orgin",
     "unknown key (expected one of: "),
    # placed twice over
    ("[camera]\nto_world = [{ translate = [0, 0, 5] }]\norigin = [0, 0, 5]\n", "camera.origin",
     "give either to_world or origin/target/up, not both"),
    ("[camera]\norigin = [0, 0, 5]\ntraget = [0, 0, 0]\n", "camera.traget", "target is missing"),
    # the keys of the light's own kind, not of every kind
    (CAMERA + "[[lights]]\ntype = 'point'\npositon = [0, 0, 1]\nintensity = 1\n",
     "lights[0].positon", "(expected one of: intensity, position, type); position is missing"),
    (CAMERA + "[camera.x]\n", "camera.x", "unknown key"),
    # nothing unknown: the missing key itself
    ("[camera]\norigin = [0, 0, 5]\nfov = 30\n", "camera.target",
     "missing; expected a list of 3 numbers"),
])
def test_messages_name_the_key_at_fault(text, key, words):
    err = loader_error(tomllib.loads(text))
    assert err is not None and err.key == key, str(err)
    assert words in str(err)


# ------------------------------------------------------------------ the command


def test_whitted_schema_prints_the_schema_and_writes_it(tmp_path):
    r = run_cli("schema")
    assert r.returncode == 0 and json.loads(r.stdout) == scene_schema()
    out = tmp_path / "scene.schema.json"
    r = run_cli("schema", "-o", out)
    assert r.returncode == 0 and json.loads(out.read_text()) == scene_schema()
    r = run_cli("schema", "-o", tmp_path / "scene.txt")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and ".json" in r.stderr


def test_a_schema_line_is_a_comment_to_the_loader(v):
    doc = tomllib.loads("#:schema ./scene.schema.json\n" + to_toml(BASE))
    assert loader_error(doc) is None and schema_error(v, doc) is None
