"""`whitted check` names the way a right image was written wrongly, or says it cannot name a cause.

A correct render of ``glass_sphere`` (the tracer at the user's seed, with a
renderer's noise: Gaussian of standard deviation 1 % of sqrt(value x mean),
none on black) is written as a student writes it: without the sRGB curve,
with a gamma of 2.2, channels in BGR order, upside down, ... The old ranking,
formula bugs alone, named plane-hit-behind-ray (98.6 % "explained") for the
first, camera-y-not-flipped for the second, plane-hit-behind-ray again for
the third; here each gives its convention as the first cause
(:mod:`reference.check.conventions`, :func:`reference.check.suspects.name_cause`).
"""

import json

import numpy as np
import pytest
from conftest import SCENES, run_cli

from whitted.reference.check import conventions as cv
from whitted.reference.check.judge import check_image, format_run, tracer_reference

SIZE = (96, 72)
SRGB8 = cv.FileEncoding("srgb", 255, 1.0)
FLOAT = cv.FileEncoding("float", None, None)


def _scene(name="glass_sphere", size=SIZE):
    from whitted.tracer import load_scene

    return load_scene(SCENES / f"{name}.toml").with_overrides(size=size)


def _render(scene, fault=None, seed=0, noise=0.01, rng_seed=1):
    from whitted.reference import mutants  # noqa: F401  (declares the catalog's ids)
    from whitted.tracer import faults
    from whitted.tracer.integrator import Integrator

    with faults.active(*([fault] if fault else [])):
        img = Integrator(scene, seed=seed).render().image.astype(np.float64)
    rng = np.random.default_rng(rng_seed)
    return img + rng.normal(0, 1, img.shape) * noise * np.sqrt(np.maximum(img, 0) * img.mean())


@pytest.fixture(scope="module")
def glass():
    scene = _scene()
    ref = tracer_reference(scene)
    big = scene.with_overrides(size=(2 * SIZE[0], 2 * SIZE[1]))
    return scene, ref, _render(scene), _render(big, rng_seed=2)


def _first(run):
    sp = run.suspects
    return sp["ranked"][0], sp


@pytest.mark.parametrize("convention, enc", [
    # the four cases of the issue
    ("no-srgb-curve", SRGB8), ("gamma-2.2", SRGB8), ("bgr-order", SRGB8),
    ("upside-down", SRGB8),
    # and more
    ("gamma-1.8", SRGB8), ("srgb-curve-twice", SRGB8), ("red-green-swapped", SRGB8),
    ("mirrored", SRGB8), ("exposure-scale", SRGB8), ("reinhard-tone-map", SRGB8),
    ("pixel-corners-top-left", SRGB8), ("srgb-in-linear-file", FLOAT),
    ("one-pixel-left", SRGB8), ("transposed", SRGB8),
])
def test_a_right_image_written_wrongly_is_named_by_its_convention_first(glass, convention,
                                                                        enc):
    scene, ref, img, fine = glass
    user = cv.write_as(cv.get(convention), img, enc, fine=fine)
    run = check_image(user, scene, reference=ref)
    assert not run.passed
    first, sp = _first(run)
    text = format_run(run, convention)
    assert sp["named"], text
    assert first["id"] == convention or convention in first["ties"], text
    assert first["kind"] == "convention" and first["at_noise"]
    assert first["source"] and first["formula"] and first["correct"]
    assert "your light transport agrees" in sp["cause"]
    assert first["explains"] > 0.8, text


def test_upside_down_ties_with_the_bug_that_flips_the_camera_and_is_named_first(glass):
    scene, ref, img, _ = glass
    run = check_image(cv.write_as(cv.get("upside-down"), img, SRGB8), scene, reference=ref)
    first, sp = _first(run)
    assert first["id"] == "upside-down" and "camera-y-not-flipped" in first["ties"]


def test_the_srgb_curve_missing_says_so_and_draws_the_fitted_curve(tmp_path, glass):
    # From the command line, an 8-bit PNG: the verdict in words, curve.png and check.html.
    from whitted.reference import mitsuba

    scene, _, img, _ = glass
    mi = mitsuba()
    codes = np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)   # no sRGB curve
    mi.Bitmap(codes, mi.Bitmap.PixelFormat.RGB).write(str(tmp_path / "linear.png"))
    r = run_cli("check", tmp_path / "linear.png", "--scene", "glass_sphere", "--size",
                f"{SIZE[0]}x{SIZE[1]}", "-o", tmp_path / "o")
    assert r.returncode == 1, r.stdout + r.stderr
    assert ("cause: your light transport agrees; your output encoding differs: it looks like "
            "no sRGB curve") in r.stdout, r.stdout
    assert "1. no-srgb-curve (convention: transfer curve)" in r.stdout
    assert "source:  IEC 61966-2-1" in r.stdout
    assert (tmp_path / "o" / "curve.png").stat().st_size > 1000
    data = json.loads((tmp_path / "o" / "check.json").read_text())
    assert data["suspects"]["named"] and data["suspects"]["transport_agrees"]
    assert data["files"]["curve.png"].endswith("curve.png")
    html = (tmp_path / "o" / "check.html").read_text()
    assert "<h2>Cause</h2>" in html and "alt='fitted curve'" in html


def test_a_correct_8bit_image_still_passes(glass):
    scene, ref, img, _ = glass
    run = check_image(cv.write_as(None, img, SRGB8), scene, reference=ref)
    assert run.passed, format_run(run, "correct")
    assert run.suspects is None


def test_a_formula_bug_still_gets_its_suspect(glass):
    scene, ref, _, _ = glass
    run = check_image(cv.write_as(None, _render(scene, "fresnel-average-amplitudes"), SRGB8),
                      scene, reference=ref)
    first, sp = _first(run)
    assert sp["named"], format_run(run, "bug")
    assert first["id"] == "fresnel-average-amplitudes" and first["kind"] == "formula bug"
    assert "a formula bug of the catalog explains" in sp["cause"]


def test_a_difference_nothing_known_explains_gets_cannot_name_a_cause(glass):
    # 4 % more light in one block of the image: no convention, no bug, no curve.
    scene, ref, img, _ = glass
    odd = np.array(img, copy=True)
    odd[20:44, 30:60] *= 1.04
    run = check_image(cv.write_as(None, odd, SRGB8), scene, reference=ref)
    assert not run.passed
    first, sp = _first(run)
    text = format_run(run, "unknown")
    assert not sp["named"], text
    assert sp["cause"].startswith("cannot name a cause"), text
    assert not sp["transport_agrees"]
    assert "closest suspects (none leaves only noise" in text
    assert "where the difference sits:" in text        # the decomposition is still shown


def test_monotone_fit_is_isotonic_and_recovers_a_curve():
    rng = np.random.default_rng(0)
    r = rng.uniform(0, 1, (60, 80, 3))
    u = r ** 0.5 + rng.normal(0, 1e-3, r.shape)
    w = np.full(r.shape, 1e6)
    fitted, fit = cv.monotone_fit(u, r, w, np.ones((60, 80), dtype=bool))
    for c in range(3):
        assert (np.diff(fit.y[c]) >= 0).all()
    assert np.abs(fitted - r ** 0.5).max() < 0.02


def test_half_pixel_shift_is_the_box_moved_by_half_a_pixel():
    fine = np.arange(8 * 12, dtype=float).reshape(8, 12, 1).repeat(3, -1)
    out, unknown = cv._half_shifted(fine, (0.5, 0.5))
    assert out.shape == (4, 6, 3)
    assert out[0, 0, 0] == fine[1:3, 1:3, 0].mean()
    assert unknown[-1].all() and unknown[:, -1].all() and not unknown[0, 0]


def _rgba_png(path, linear, alpha, premultiplied):
    """An 8-bit sRGB PNG with straight 8-bit alpha, colours multiplied by it on linear light."""
    from whitted.reference import mitsuba
    from whitted.reference.check.conventions import srgb_encode

    mi = mitsuba()
    a = np.round(alpha * 255) / 255                      # the alpha the file stores
    x = np.maximum(linear, 0) * (a[..., None] if premultiplied else 1.0)
    codes = np.round(np.clip(srgb_encode(x), 0, 1) * 255).astype(np.uint8)
    rgba = np.concatenate([codes, np.round(a * 255).astype(np.uint8)[..., None]], axis=-1)
    mi.Bitmap(np.ascontiguousarray(rgba), mi.Bitmap.PixelFormat.RGBA).write(str(path))
    return path


def _partial_alpha(h, w):
    """Alpha 1 on the left, a ramp down to 0.3 on the right half, 0 in a top-right block."""
    alpha = np.ones((h, w))
    alpha[:, w // 2:] = np.linspace(1.0, 0.3, w - w // 2)
    alpha[:10, -16:] = 0.0
    return alpha


def test_premultiplied_alpha_png_is_named_and_alpha_one_passes(tmp_path, glass):
    from whitted.reference.check.images import read_user_image

    scene, ref, img, _ = glass
    h, w = img.shape[:2]
    alpha = _partial_alpha(h, w)
    user = read_user_image(_rgba_png(tmp_path / "pre.png", img, alpha, True))
    assert user.alpha is not None and user.alpha.min() == 0 and (user.alpha < 1).mean() > 0.3
    run = check_image(user, scene, reference=ref)
    assert not run.passed
    first, sp = _first(run)
    text = format_run(run, "premultiplied")
    assert sp["named"], text
    assert first["id"] == "premultiplied-alpha" and first["kind"] == "convention", text
    assert first["at_noise"] and first["family"] == "alpha"
    assert first["formula"] == "code = round(255 * srgb(A L))"
    assert "Porter and Duff" in first["source"] and first["correct"]
    assert "your light transport agrees" in sp["cause"]
    assert "premultiplied alpha" in sp["cause"]
    # the same colours with alpha 1 everywhere: a correct image, as before
    one = read_user_image(_rgba_png(tmp_path / "one.png", img, np.ones((h, w)), True))
    run = check_image(one, scene, reference=ref)
    assert run.passed, format_run(run, "alpha 1")
    assert run.suspects is None


def test_an_image_without_alpha_reads_as_before(tmp_path, glass):
    from whitted.reference import mitsuba
    from whitted.reference.check.images import ALPHA_NOTE, read_user_image

    _, _, img, _ = glass
    mi = mitsuba()
    rgba = _rgba_png(tmp_path / "rgba.png", img, np.ones(img.shape[:2]), False)
    codes = np.array(mi.Bitmap(str(rgba)))[..., :3]
    mi.Bitmap(np.ascontiguousarray(codes), mi.Bitmap.PixelFormat.RGB).write(
        str(tmp_path / "rgb.png"))
    a, b = read_user_image(rgba), read_user_image(tmp_path / "rgb.png")
    assert b.alpha is None and b.notes == () and a.notes == (ALPHA_NOTE,)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.step, b.step)
    assert (a.alpha == 1).all()
    # and the convention is not tried without alpha below 1
    conv = cv.get("premultiplied-alpha")
    for alpha in (None, a.alpha):
        assert cv.predict(conv, SRGB8, None, b.image, None, None, None, alpha) is None


def test_write_as_premultiplied_alpha_is_named(glass):
    scene, ref, img, _ = glass
    for enc in (SRGB8, FLOAT):
        run = check_image(cv.write_as(cv.get("premultiplied-alpha"), img, enc), scene,
                          reference=ref)
        first, sp = _first(run)
        assert first["id"] == "premultiplied-alpha", format_run(run, enc.name)
