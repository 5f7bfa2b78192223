"""Every built-in scene rendered by the tracer and by Mitsuba, compared.

The criteria are those of :mod:`reference.verdicts.compare` (derived there): against
the deterministic reference, which follows both lobes of every mirror and
glass and samples area lights at the tracer's own points, every scene must
agree to float precision (median relative difference below 1e-5, 99.9 % of
the pixels within 1e-3, means within 1e-4), except the paraboloid's, which
Mitsuba sees tessellated; every scene where the one-lobe reference samples
must also pass its statistical verdict (the second opinion of area-lit
scenes), here at the report's quick size.
"""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENES

from whitted.reference.renderers.mitsuba.render import render_reference
from whitted.reference.report.build import quick_overrides
from whitted.reference.verdicts.compare import (
    EXACT_LIMITS,
    choose_test,
    compare_scene,
    image_metrics,
    judge,
    statistical_comparison,
)
from whitted.tracer import load_scene
from whitted.tracer.scene import Dielectric

BUILTIN = sorted(SCENES.glob("*.toml"))


def _direct_only(path: Path) -> bool:
    return choose_test(load_scene(path), "onelobe") == "exact-strata"


@pytest.mark.parametrize("path", BUILTIN, ids=[p.stem for p in BUILTIN])
def test_builtin_scene_agrees_with_mitsuba(path, tmp_path):
    scene = load_scene(path)
    # The one-lobe second opinion of area-lit scenes is judged below at the report's
    # quick size (test_one_lobe_reference_agrees_statistically).
    result, tracer_img, ref_img = compare_scene(scene, tmp_path, second_opinion=False)
    assert tracer_img.shape == (scene.film.height, scene.film.width, 3)
    assert np.isfinite(tracer_img).all() and tracer_img.max() > 0
    failed = {k: v for k, v in result.checks.items() if not v["pass"]}
    assert result.passed, f"{path.stem}: {result.test} failed {failed}"
    # The deterministic reference judges every scene whose lights it can sample as the
    # tracer does (SAMPLE_MAPS); a scene lit by emitters it cannot (shape_lights: a mesh,
    # a polygon and a cylinder light) is judged by the one-lobe reference's z-test.
    from whitted.reference.renderers.mitsuba.deterministic import shares_light_samples

    expected = "deterministic" if shares_light_samples(scene) else "onelobe"
    assert result.reference == expected
    assert result.test == ("z-test" if expected == "onelobe" else
                           "tessellated" if scene.has_tessellated() else "exact-strata")
    if result.test == "exact-strata":    # the accuracy target, area lights included
        assert result.metrics["median_rel"] < 1e-5
        assert result.metrics["frac_over_01pct"] < 1e-3
    assert result.second_opinion is None
    for f in ("tracer.exr", "mitsuba.exr", "diff.png", "metrics.json"):
        assert (tmp_path / f).stat().st_size > 0
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["reference"] == expected and saved["passed"] == result.passed


GLASS = [p for p in BUILTIN if p.stem in ("glass_sphere", "whitted_mix", "whitted_1980",
                                          "tir_prisms")]


@pytest.mark.parametrize("path", GLASS, ids=[p.stem for p in GLASS])
def test_undeclared_schlick_in_glass_fails_the_comparison(path):
    # Mitsuba's dielectric is exact; Schlick's approximation swapped in without
    # `[compare] tracer_only = ["schlick"]` changes the glass by up to ~25 % on 13-18 %
    # of the pixels: far beyond float precision. (The one-lobe reference's z-test
    # alone let this pass before its region rule.)
    scene = quick_overrides(load_scene(path))
    mats = {k: replace(m, fresnel="schlick") if isinstance(m, Dielectric) else m
            for k, m in scene.materials.items()}
    result, _, _ = compare_scene(replace(scene, materials=mats))
    assert not result.passed
    assert not result.checks["frac_over_01pct"]["pass"]
    assert "declare [compare] tracer_only" in result.reason


def test_undeclared_schlick_fails_the_one_lobe_verdict_by_its_region_rule():
    scene = load_scene(SCENES / "glass_sphere.toml").with_overrides(size=(64, 48))
    mats = {k: replace(m, fresnel="schlick") if isinstance(m, Dielectric) else m
            for k, m in scene.materials.items()}
    st = statistical_comparison(replace(scene, materials=mats))
    assert not st.verdict.passed and not st.verdict.checks["region_max_z"]["pass"]
    assert st.verdict.checks["z_fraction_passed"]["pass"]   # per pixel it hides in the noise


def test_compare_cli_fails_on_undeclared_schlick(tmp_path):
    from whitted.reference import cli

    text = (SCENES / "glass_sphere.toml").read_text().replace('fresnel = "exact"',
                                                              'fresnel = "schlick"')
    assert 'fresnel = "schlick"' in text
    (tmp_path / "glass_sphere.toml").write_text(text)
    rc = cli.main(["compare", str(tmp_path / "glass_sphere.toml"), "-o", str(tmp_path / "c"),
                   "--size", "96x72", "--spp", "16"])
    assert rc == 1
    m = json.loads((tmp_path / "c" / "metrics.json").read_text())
    assert m["reference"] == "deterministic" and m["test"] == "exact-strata"
    assert m["checks"]["frac_over_01pct"]["value"] > 0.05


SAMPLED = [p for p in BUILTIN if choose_test(load_scene(p), "onelobe") == "z-test"]


@pytest.mark.parametrize("path", SAMPLED, ids=[p.stem for p in SAMPLED])
def test_one_lobe_reference_agrees_statistically(path):
    # The independent opinion, at the report's quick size: Mitsuba's own lobe choices and
    # light samples, 1024 pooled samples per pixel, judged by the z-test's rules.
    scene = quick_overrides(load_scene(path))
    result, _, _ = compare_scene(scene, reference="onelobe")
    assert result.reference == "onelobe" and result.test == "z-test"
    assert result.passed, {k: v for k, v in result.checks.items() if not v["pass"]}
    assert EXACT_LIMITS["median_rel"] == 1e-5


ONE_LIGHT = [p for p in BUILTIN if _direct_only(p) and len(load_scene(p).lights) == 1]
SEVERAL = [p for p in BUILTIN if _direct_only(p) and len(load_scene(p).lights) > 1]


@pytest.mark.parametrize("path", ONE_LIGHT, ids=[p.stem for p in ONE_LIGHT])
def test_reference_integrator_equals_mitsubas_direct_with_one_light(path):
    # With a single delta light, `direct` picks it with probability 1 and its BSDF
    # samples cannot hit it: the same deterministic picture as our integrator.
    scene = load_scene(path)
    ours = render_reference(scene, "whitted").image
    stock = render_reference(scene, "direct").image
    verdict, _ = judge("exact-strata", image_metrics(ours, stock, with_flip=False), ours, stock)
    assert verdict.passed, verdict.checks


@pytest.mark.parametrize("path", SEVERAL, ids=[p.stem for p in SEVERAL])
def test_reference_integrator_matches_mitsubas_direct_in_expectation(path):
    # With L lights `direct` picks one at random (weight L): unbiased but noisy, provided
    # the samples are jittered (see the next test). Over K independent seeds the image
    # mean is normal to good approximation; ours must lie within 4 standard errors of
    # it (a 6e-5 two-sided false-alarm rate). Ours is jittered too: at strata centres it
    # is a midpoint rule over each pixel, whose error does not average out where
    # textures have edges (instances_scaled's checkerboards: 1.2e-3 of the mean, 10
    # standard errors of the jittered means, which agree).
    scene = load_scene(path).with_overrides(size=(64, 48), spp=16)
    k = 12
    ours = np.array([render_reference(scene, "whitted", seed=s, jitter=True).image.mean()
                     for s in range(k)])
    means = np.array([render_reference(scene, "direct", seed=s, jitter=True).image.mean()
                      for s in range(k)])
    se = np.hypot(ours.std(ddof=1), means.std(ddof=1)) / np.sqrt(k)
    assert abs(ours.mean() - means.mean()) < 4 * se + 1e-6 * ours.mean(), (
        ours.mean(), means.mean(), se)


def test_direct_with_centred_strata_picks_lights_unevenly():
    # Mitsuba's `direct` chooses emitter floor(x L) from its 2D sample's x. At strata
    # centres, x takes only the n values (i + 1/2) / n, so with L = 3 lights and
    # n = 4 they are chosen 1 : 2 : 1 times instead of evenly, each weighted by L: the
    # image converges to sum_e (count_e / n) L image_e, not to sum_e image_e. This is
    # why the harness's own integrator samples every light once per sample.
    from dataclasses import replace

    scene = load_scene(SCENES / "three_lights.toml").with_overrides(size=(48, 32), spp=16)
    n, L = 4, len(scene.lights)
    singles = [render_reference(replace(scene, lights=(light,)), "whitted").image.mean()
               for light in scene.lights]
    counts = np.bincount(np.minimum((((np.arange(n) + 0.5) / n) * L).astype(int), L - 1),
                         minlength=L)
    assert counts.tolist() == [1, 2, 1]
    predicted = sum(c / n * L * m for c, m in zip(counts, singles, strict=True))
    direct = np.mean([render_reference(scene, "direct", seed=s).image.mean() for s in range(4)])
    ours = render_reference(scene, "whitted").image.mean()
    assert abs(direct - predicted) < 2e-3 * predicted          # the bias is as derived
    assert abs(ours - sum(singles)) < 1e-5 * ours              # ours sums the lights
    assert abs(direct - ours) > 5e-3 * ours                    # and the two differ


def test_exported_xml_renders_the_same_picture_on_mitsuba(mi, tmp_path):
    from whitted.reference.renderers.mitsuba.scene import write_xml

    scene = load_scene(SCENES / "ortho_transforms.toml").with_overrides(size=(80, 60), spp=16)
    files = write_xml(scene, tmp_path / "scene.xml")
    assert (tmp_path / "meshes").is_dir() and len(files) == 2  # the triangle's .obj
    from_xml = np.asarray(mi.render(mi.load_file(str(files[0])), spp=16))[..., :3]
    direct = render_reference(scene, "whitted").image
    # Values round-trip through 9 significant digits: float32 exact up to one rounding.
    assert np.allclose(from_xml, direct, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("name", ["shapes_zoo", "whitted_1980", "mesh_knot"])
def test_exported_xml_of_the_second_lectures_shapes_renders_the_same(mi, tmp_path, name):
    # Groups and instances, polygons and paraboloids as meshes (obj with uvs and normals),
    # mesh files, cylinders, disks, checkerboards and the Phong BSDF, through XML.
    from whitted.reference.renderers.mitsuba.scene import write_xml

    scene = load_scene(SCENES / f"{name}.toml").with_overrides(size=(64, 48), spp=4)
    files = write_xml(scene, tmp_path / "scene.xml")
    img = np.asarray(mi.render(mi.load_file(str(files[0])), seed=0, spp=4))[..., :3]
    ref = render_reference(scene, "whitted", seed=0).image
    # The same plugins and the same random streams (seed 0): equal up to the rounding of
    # numbers printed with 9 digits, which could flip a lobe choice only where a random
    # number falls within ~1e-7 of R, or a sample's hit at a grazing edge.
    close = np.isclose(img, ref, rtol=1e-4, atol=1e-6).all(axis=-1)
    assert close.mean() > 0.999, close.mean()


def test_exported_xml_with_stock_direct_integrator_renders_on_plain_mitsuba(mi, tmp_path):
    from whitted.reference.renderers.mitsuba.scene import write_xml

    scene = load_scene(SCENES / "sphere_point.toml").with_overrides(size=(64, 48), spp=16)
    xml = write_xml(scene, tmp_path / "scene.xml", integrator="direct")[0]
    assert 'type="direct"' in xml.read_text() and 'type="whitted"' not in xml.read_text()
    img = np.asarray(mi.render(mi.load_file(str(xml)), spp=16))[..., :3]
    ours = render_reference(scene, "whitted").image
    verdict, _ = judge("exact-strata", image_metrics(img, ours, with_flip=False), img, ours)
    assert verdict.passed, verdict.checks
