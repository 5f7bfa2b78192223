"""`whitted suite`: the scenes handed out with references and a derived manifest, and grading."""

import json

import numpy as np
import pytest
from conftest import SCENES, run_cli

from whitted.reference.check.suite import FORMULAS, read_reference, scene_formulas, scene_kinds


def test_every_registered_kind_has_its_formulas():
    # The manifest's formulas come from the scene's kinds: a kind added without its
    # entry would leave its scenes' formulas unnamed.
    import whitted.tracer.scene as model
    from whitted.tracer import emitters, materials

    for name in materials.REGISTRY:
        assert FORMULAS.get(("material", name)), name
    for name in (*emitters.LIGHTS, *emitters.SHAPE_LIGHTS):
        assert FORMULAS.get(("light", name)), name
    for cls in model.Shape.__args__:
        assert FORMULAS.get(("shape", cls.__name__.lower())), cls


def test_the_manifest_is_derived_from_the_scene():
    from whitted.tracer import load_scene

    glass = load_scene(SCENES / "glass_sphere.toml")
    kinds = scene_kinds(glass)
    assert kinds["materials"] == ["dielectric", "diffuse"]
    assert kinds["lights"] == ["directional", "point"]
    assert kinds["shapes"] == ["rectangle", "sphere"]
    formulas = {f["formula"] for f in scene_formulas(kinds)}
    assert any("Fresnel" in f for f in formulas) and any("Snell" in f for f in formulas)
    assert not any("Schlick" in f for f in formulas)
    schlick = scene_kinds(load_scene(SCENES / "schlick_diamond.toml"))
    assert "schlick" in schlick["features"]
    assert any("Schlick" in f["formula"] for f in scene_formulas(schlick))


@pytest.fixture(scope="module")
def suite_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("suite") / "suite"
    # glass_sphere and sphere_point
    r = run_cli("suite", "export", out, "--scenes", "[gs][lp]*_[sp]*")
    assert r.returncode == 0, r.stdout + r.stderr
    return out


def test_suite_export_writes_scenes_xml_references_and_manifest(suite_dir):
    from whitted.reference import mitsuba

    manifest = json.loads((suite_dir / "manifest.json").read_text())
    names = [s["name"] for s in manifest["scenes"]]
    assert names == ["glass_sphere", "sphere_point"]
    glass = manifest["scenes"][0]
    assert glass["size"] == [160, 120] and glass["max_depth"] == 8
    assert glass["light_paths"]["LDS+E"] > 0 and "LE" not in glass["light_paths"]
    assert any(f["topic"] == "The Fresnel equation" for f in glass["formulas"])
    for s in manifest["scenes"]:
        for key in ("scene", "reference_exr", "reference_png"):
            assert (suite_dir / s["files"][key]).is_file()
    assert "| glass_sphere | 160x120 |" in (suite_dir / "README.md").read_text()
    # The XML is stock Mitsuba (path integrator) and loads as it is.
    mi = mitsuba()
    ms = mi.load_file(str(suite_dir / "mitsuba" / "sphere_point.xml"))
    assert "PathIntegrator" in str(ms.integrator())
    ref = read_reference(suite_dir / "references" / "sphere_point.exr", "stored")
    assert ref.image.shape == (120, 160, 3) and ref.spread is not None
    assert ref.quadrature is not None and ref.quadrature.max() > 0   # edges in the image


def _tracer_image(name, monkeypatch=None, bug=None):
    from whitted.tracer import load_scene
    from whitted.tracer.integrator import Integrator

    scene = load_scene(SCENES / f"{name}.toml")
    if bug is None:
        return Integrator(scene).render().image
    with monkeypatch.context() as m:
        m.setattr(*bug)
        return Integrator(scene).render().image


def test_suite_check_grades_a_folder_and_update_refuses_a_failing_run(suite_dir, tmp_path,
                                                                      monkeypatch):
    import drjit as dr

    from whitted.tracer import fresnel
    from whitted.tracer.imageio import write_exr, write_png

    def schlick_everywhere(cos_i, eta):   # Schlick's approximation where exact is asked for
        return dr.select(fresnel.snell_cos_t(cos_i, eta)[1], 1.0,
                         fresnel.fresnel_schlick(cos_i, eta))

    images = tmp_path / "images"
    images.mkdir()
    write_png(images / "sphere_point.png", _tracer_image("sphere_point"))
    write_exr(images / "glass_sphere.exr", _tracer_image(
        "glass_sphere", monkeypatch, (fresnel, "fresnel_exact", schlick_everywhere)))
    (images / "unrelated.png").write_bytes((images / "sphere_point.png").read_bytes())
    before = (suite_dir / "references" / "glass_sphere.exr").read_bytes()
    r = run_cli("suite", "check", images, "--suite", suite_dir, "--update")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "references not updated" in r.stdout
    assert (suite_dir / "references" / "glass_sphere.exr").read_bytes() == before
    data = json.loads((images / "whitted-check" / "suite.json").read_text())
    status = {s["name"]: s["status"] for s in data["scenes"]}
    assert status == {"glass_sphere": "FAIL", "sphere_point": "pass"}
    assert data["ignored"] == ["unrelated.png"]
    # The failing image is explained by the catalog's bug that does the same
    assert "suspect: schlick-for-exact" in r.stdout, r.stdout
    glass = next(s for s in data["scenes"] if s["name"] == "glass_sphere")
    assert glass["check"]["suspects"]["top"][0]["id"] == "schlick-for-exact"
    page = (images / "whitted-check" / "index.html").read_text()
    assert "first suspect: <code>schlick-for-exact</code>" in page
    assert page.count("class='wv'") == 2 and "http" not in page.split("<body>")[1]
    # A missing image fails too.
    (images / "glass_sphere.exr").unlink()
    r = run_cli("suite", "check", images, "--suite", suite_dir)
    assert r.returncode == 1 and "missing" in r.stdout


def test_suite_update_stores_golden_images_when_the_run_passes(suite_dir, tmp_path):
    from whitted.tracer.imageio import write_exr

    images = tmp_path / "golden"
    images.mkdir()
    golden = _tracer_image("sphere_point")
    write_exr(images / "sphere_point.exr", golden)
    r = run_cli("suite", "check", images, "--suite", suite_dir, "--scenes", "sphere_point",
                "--update")
    assert r.returncode == 0, r.stdout + r.stderr
    manifest = json.loads((suite_dir / "manifest.json").read_text())
    entry = next(s for s in manifest["scenes"] if s["name"] == "sphere_point")
    assert entry["reference"]["source"] == "golden image sphere_point.exr"
    stored = read_reference(suite_dir / "references" / "sphere_point.exr", "stored")
    assert np.array_equal(stored.image, golden)
    # Now graded against the golden image: 2 % brighter fails.
    write_exr(images / "sphere_point.exr", golden * 1.02)
    r = run_cli("suite", "check", images, "--suite", suite_dir, "--scenes", "sphere_point")
    assert r.returncode == 1, r.stdout


def test_suite_refuses_bad_input(tmp_path):
    r = run_cli("suite", "check", tmp_path / "nowhere")
    assert r.returncode == 2 and "no such folder" in r.stderr
    r = run_cli("suite", "check", tmp_path, "--update")
    assert r.returncode == 2 and "--suite" in r.stderr
    r = run_cli("suite", "check", tmp_path, "--suite", tmp_path)
    assert r.returncode == 2 and "not a suite folder" in r.stderr
    r = run_cli("suite", "export", tmp_path / "x", "--update")
    assert r.returncode == 2 and "not export" in r.stderr
    r = run_cli("suite", "export", tmp_path / "x", "--scenes", "nothing*")
    assert r.returncode == 2 and not (tmp_path / "x").exists()
