"""`whitted check` names the suspect: the catalog's formula bug that explains a failing image.

An image made by the tracer with one bug of the catalog (``reference/mutants.py``,
switched on by :mod:`tracer.faults`) stands in for another renderer with that
bug. Its own noise is Gaussian, 1 % of the image's mean (as a renderer's
sampling noise; the check estimates it from the image). The hit rate over
the whole catalog is measured by ``benchmarks/bench_suspects.py``.
"""

import json

import numpy as np
import pytest
from conftest import SCENES, run_cli

from whitted.reference.check.images import UserImage
from whitted.reference.check.judge import check_image, format_run, tracer_reference

#: The user's seed where the tracer samples lights (the reference's is 0).
USER_SEED = 7


def _scene(name, size):
    from whitted.tracer import load_scene

    return load_scene(SCENES / f"{name}.toml").with_overrides(size=size)


def _bug_image(scene, fault_id, seed=0, noise=0.01, rng_seed=1):
    from whitted.reference import mutants  # noqa: F401  (declares the catalog's ids)
    from whitted.tracer import faults
    from whitted.tracer.integrator import Integrator

    with faults.active(*([fault_id] if fault_id else [])):
        img = Integrator(scene, seed=seed).render().image.astype(np.float64)
    rng = np.random.default_rng(rng_seed)
    return img + rng.normal(0, noise * float(img.mean()), img.shape)


def _user(img):
    return UserImage("<test>", "exr", "float32", img)


def test_a_catalog_bug_fails_whitted_check_which_names_it_first(tmp_path):
    # A Fresnel bug in light seen through glass: the command fails, names the bug first
    # at strength near 1 with its formula and lecture topic, places the difference on the
    # paths through glass, and writes the suspects into check.json and check.html.
    from whitted.tracer.imageio import write_exr

    scene = _scene("glass_sphere", (48, 36))
    write_exr(tmp_path / "bug.exr", _bug_image(scene, "fresnel-average-amplitudes")
              .astype(np.float32))
    r = run_cli("check", tmp_path / "bug.exr", "--scene", "glass_sphere", "--size", "48x36",
                "-o", tmp_path / "o")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "1. fresnel-average-amplitudes (lecture: lecture 1, \"The Fresnel equation\")" \
        in r.stdout, r.stdout
    assert "formula: R = ((r_s + r_p) / 2)^2" in r.stdout
    assert "suspects [" in r.stdout             # the progress lines
    data = json.loads((tmp_path / "o" / "check.json").read_text())
    top = data["suspects"]["top"]
    assert len(top) == 3 and top[0]["id"] == "fresnel-average-amplitudes"
    # strength: the fit of D by k (M - R) with D = M - R + noise; its standard error is
    # the fit's, 3 of them allowed
    assert abs(top[0]["scale"] - 1) < 3 * top[0]["scale_error"] + 1e-6
    assert top[0]["explains"] > top[1]["explains"]
    paths = data["decomposition"]["light_paths"]
    assert paths[0]["path"] in ("LS+E", "LDS+E"), paths
    html = (tmp_path / "o" / "check.html").read_text()
    assert "<h2>Suspects</h2>" in html and "fresnel-average-amplitudes" in html


@pytest.mark.parametrize("name, size, fault, path", [
    ("sphere_point", (48, 36), "point-light-linear-falloff", "LDE"),
    ("area_lights", (48, 36), "lambert-no-inv-pi", "LDE"),
    ("mirror_sphere", (48, 36), "reflect-sign", None),
])
def test_a_render_with_a_catalog_bug_is_explained_by_that_bug_first(name, size, fault, path):
    scene = _scene(name, size)
    ref = tracer_reference(scene)
    seed = USER_SEED if scene.samples_lights() else 0   # the user's own light samples
    run = check_image(_user(_bug_image(scene, fault, seed)), scene, reference=ref)
    assert not run.passed
    sp = run.suspects
    assert sp["top"][0]["id"] == fault or fault in sp["top"][0]["ties"], format_run(run, name)
    assert f"1. {sp['top'][0]['id']}" in format_run(run, name)
    if path is not None:
        assert run.decomposition["light_paths"][0]["path"] == path, run.decomposition


def test_a_correct_image_prints_no_suspects():
    # The tracer as written, at the user's own light samples and with noise: it passes,
    # and nothing is ranked.
    scene = _scene("area_lights", (48, 36))
    run = check_image(_user(_bug_image(scene, None, USER_SEED)), scene)
    assert run.passed, format_run(run, "correct")
    assert run.suspects is None and run.decomposition is None
    assert "suspects" not in format_run(run, "correct")


def test_the_bugs_images_are_cached_and_only_bugs_the_scene_reaches_are_ranked(tmp_path):
    from whitted.reference.check.suspects import rank_catalog, reached_faults

    scene = _scene("sphere_point", (32, 24))
    reached = reached_faults(scene)
    assert "point-light-no-falloff" in reached and "fresnel-average-amplitudes" not in reached
    ref = tracer_reference(scene)
    img = _bug_image(scene, "point-light-no-falloff")
    var = np.full(img.shape, (0.01 * img.mean()) ** 2)
    first = rank_catalog(scene, img - ref.image, var, None, cache=tmp_path)
    assert first.cached == 0 and first.candidates == len(reached)
    assert {f.id for f in first.ranked} | set(first.no_effect) <= reached
    assert first.ranked[0].id == "point-light-no-falloff"
    again = rank_catalog(scene, img - ref.image, var, None, cache=tmp_path)
    assert again.cached == first.candidates + 1           # every bug and the tracer as written
    assert [f.id for f in again.ranked] == [f.id for f in first.ranked]
    # Another scene (here: another size) is another key.
    other = rank_catalog(_scene("sphere_point", (32, 25)), np.zeros((25, 32, 3)),
                         np.ones((25, 32, 3)), None, cache=tmp_path)
    assert other.cached == 0


def test_bugs_with_the_same_image_tie_and_the_same_pattern_is_told_apart_by_strength():
    from whitted.reference.check.suspects import Suspect, rank_difference

    rng = np.random.default_rng(0)
    base = rng.uniform(0.2, 1, (20, 30, 3))
    pattern = np.zeros_like(base)
    pattern[5:12, 8:20] = 0.3
    other = np.zeros_like(base)
    other[:, :4] = 0.2
    cands = [Suspect(i, i, "t", lambda s: None) for i in ("a", "a-twin", "twice", "elsewhere")]
    images = [base + pattern, base + pattern, base + 2 * pattern, base + other]
    var = np.full(base.shape, 1e-4)
    d = 2 * pattern + rng.normal(0, 1e-2, base.shape)     # the "twice" bug, with noise
    fits = rank_difference(d, var, None, cands, images, base)
    assert fits[0].id == "twice" and fits[0].scale == pytest.approx(1, abs=0.01)
    assert set(fits[0].alike) == {"a", "a-twin"} and not fits[0].ties
    a = next(f for f in fits if f.id == "a")
    assert a.ties == ["a-twin"] and a.scale == pytest.approx(2, abs=0.02)
    assert fits[-1].id == "elsewhere" and fits[-1].explains < 0.01
    # A candidate whose image is the reference's is left out (the scene does not show it).
    fits = rank_difference(d, var, None, cands[:1], [base], base)
    assert fits == []
