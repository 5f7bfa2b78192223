"""`whitted check`: other renderers' images read, judged, and explained.

The statistical figures (false alarms over many seeds, power against
injected biases) are measured by ``docs/check_figures.py``; these tests check
the laws on a few seeds, small images and short renders.
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENES, run_cli

from whitted.reference.check.images import UserImage, code_steps, decode, read_user_image
from whitted.reference.check.judge import (
    Thresholds,
    judge_image,
    local_variance,
    rounding_bias_bound,
    tracer_reference,
)

#: Glass and a mirror before emitting panels: Mitsuba's path tracer converges to Whitted's
#: image there.
GLASS_LIGHTS = Path(__file__).resolve().parents[2] / "data" / "glass_before_lights.toml"


def _user(image, **kw) -> UserImage:
    return UserImage("<test>", "exr", "float32", np.asarray(image, dtype=np.float64), **kw)


def _scene(name, size=None):
    from whitted.tracer import load_scene

    s = load_scene(SCENES / f"{name}.toml")
    return s if size is None else s.with_overrides(size=size)


def _mitsuba_path(scene, seed, spp=64):
    """Mitsuba's own path tracer on the converted scene, samples jittered in their strata."""
    from whitted.reference import mitsuba
    from whitted.reference.renderers.mitsuba.scene import load

    mi = mitsuba()
    ms = load(scene, mi, "path", jitter=True)
    return np.asarray(mi.render(ms, seed=seed, spp=spp), dtype=np.float64)[..., :3]


def _judge(scene, image, ref=None, **kw):
    from whitted.tracer.integrator import material_ids

    ref = ref or tracer_reference(scene)
    return judge_image(_user(image) if isinstance(image, np.ndarray) else image, ref,
                       material_ids(scene), list(scene.materials), **kw)


# ------------------------------------------------------------------ reading images


def _linear_test_image():
    rng = np.random.default_rng(3)
    img = rng.uniform(0, 1.2, (6, 7, 3))
    img[0, 0] = 0
    img[0, 1] = [0.002, 0.5, 1.0]
    return img


def test_exr_pfm_and_hdr_read_back_what_was_written(tmp_path):
    from whitted.reference import mitsuba
    from whitted.tracer.imageio import write_exr

    img = _linear_test_image().astype(np.float32)
    write_exr(tmp_path / "a.exr", img)
    u = read_user_image(tmp_path / "a.exr")
    assert u.storage == "float32" and u.step is None
    assert np.array_equal(u.image, img)
    mi = mitsuba()
    mi.Bitmap(img).write(str(tmp_path / "a.pfm"))
    assert np.array_equal(read_user_image(tmp_path / "a.pfm").image, img)
    mi.Bitmap(img).write(str(tmp_path / "a.hdr"))
    u = read_user_image(tmp_path / "a.hdr")
    # RGBE keeps 8 bits per channel under a shared exponent: within one step (the writer
    # truncates, the reader takes the cell's centre: within half a step, plus the
    # writer's float rounding).
    assert u.storage == "RGBE"
    assert (np.abs(u.image - img) <= 0.5 * u.step + 1e-6).all()
    assert (u.step <= img.max(axis=-1, keepdims=True) / 128 + 1e-12).all()


def test_radiance_hdr_values_are_the_centres_of_their_cells(tmp_path):
    # Hand-made RGBE bytes (flat scanlines): mantissa m, exponent E means the cell
    # [m, m + 1) 2^(E - 136); Radiance's reader returns its centre.
    px = [(128, 64, 0, 129), (255, 255, 255, 128), (0, 0, 0, 0), (200, 100, 50, 130)]
    data = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 2\n" + bytes(sum(px, ()))
    (tmp_path / "k.hdr").write_bytes(data)
    u = read_user_image(tmp_path / "k.hdr")
    want = [[(c + 0.5) * 2.0 ** (e - 136) if e else 0.0 for c in p[:3]] for *p, e in
            [(*q[:3], q[3]) for q in px]]
    assert np.allclose(u.image.reshape(-1, 3), want, rtol=0, atol=1e-12)


def test_pfm_rows_run_from_the_bottom_in_either_byte_order(tmp_path):
    rows = np.arange(12, dtype=np.float32).reshape(2, 2, 3)   # top row first
    (tmp_path / "le.pfm").write_bytes(b"PF\n2 2\n-1.0\n" + rows[::-1].astype("<f4").tobytes())
    (tmp_path / "be.pfm").write_bytes(b"PF\n2 2\n1.0\n" + rows[::-1].astype(">f4").tobytes())
    for f in ("le.pfm", "be.pfm"):
        assert np.array_equal(read_user_image(tmp_path / f).image, rows)


def test_half_exr_records_its_rounding_step(tmp_path):
    import OpenEXR

    img = _linear_test_image().astype(np.float16)
    with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"RGB": img}) as f:
        f.write(str(tmp_path / "h.exr"))
    u = read_user_image(tmp_path / "h.exr")
    assert u.storage == "half"
    x = img.astype(np.float64)
    nz = x > 2 ** -14
    # 11 significant bits: a step between 2^-11 and 2^-10 of the value.
    assert ((u.step[nz] / x[nz] > 2 ** -11 - 1e-12) & (u.step[nz] / x[nz] <= 2 ** -10)).all()


@pytest.mark.parametrize("encoding", ["srgb", "linear", "minray"])
def test_each_8bit_encoding_round_trips_within_half_a_step(tmp_path, encoding):
    from PIL import Image

    from whitted.tracer.imageio import to_srgb8, write_ppm

    img = _linear_test_image()
    if encoding == "srgb":
        Image.fromarray(to_srgb8(img), "RGB").save(tmp_path / "a.png")
        path, clip = tmp_path / "a.png", 1.0
    elif encoding == "linear":
        codes = np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)
        Image.fromarray(codes, "RGB").save(tmp_path / "a.png")
        path, clip = tmp_path / "a.png", 1.0
    else:
        write_ppm(tmp_path / "a.ppm", img)   # minray's numbers: values above 255 stay
        path, clip = tmp_path / "a.ppm", None
    u = read_user_image(path, encoding)
    want = img if clip is None else np.minimum(img, clip)
    assert u.encoding == encoding and u.step is not None
    # Each value lies in its code's cell: within half the cell's width in linear light
    # (exact for linear codes; through the sRGB curve the cell is not symmetric about
    # the code's value, so the bound is the whole cell's width).
    slack = 0.5 if encoding != "srgb" else 1.0
    assert (np.abs(u.image - want) <= slack * u.step + 1e-9).all()   # ties: exactly half
    if clip is None:
        assert u.image.max() > 1   # values above 255 read as they are
    else:
        assert (u.saturated == (img >= 1 - 1e-9) | (u.image >= 1)).all()


def test_minray_values_above_maxval_need_the_minray_encoding(tmp_path):
    (tmp_path / "m.ppm").write_text("P3\n1 1\n255\n300 255 0\n")
    u = read_user_image(tmp_path / "m.ppm", "minray")
    assert np.allclose(u.image[0, 0], [300 / 255, 1, 0])
    with pytest.raises(Exception, match="--encoding minray"):
        read_user_image(tmp_path / "m.ppm")


def test_code_steps_follow_the_srgb_curve():
    c = np.array([0, 1, 128, 254])
    step = code_steps(c, 255, "srgb")
    assert step[0] == pytest.approx(2 * decode(0.5, 255, "srgb"))
    assert step[2] == pytest.approx(decode(128.5, 255, "srgb") - decode(127.5, 255, "srgb"))
    # The dark end is linear (slope 1 / 12.92), the bright end steep.
    assert step[1] == pytest.approx(1 / 255 / 12.92, rel=1e-9)
    assert step[3] > 10 * step[1]


# ------------------------------------------------------------------ bad input: exit 2


def test_wrong_size_unreadable_and_non_images_are_exit_2_in_one_line(tmp_path):
    from whitted.tracer.imageio import write_exr

    write_exr(tmp_path / "small.exr", np.zeros((10, 12, 3), np.float32))
    (tmp_path / "text.png").write_text("this is not a picture\n")
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"x" * 40)
    (tmp_path / "short.pfm").write_bytes(b"PF\n4 4\n-1\nabc")
    cases = [("small.exr", "is 12x10 pixels, the film of sphere_point is 160x120"),
             ("text.png", "not an image"), ("broken.png", "unreadable PNG"),
             ("short.pfm", "unreadable PFM"), ("missing.exr", "cannot read")]
    for name, msg in cases:
        r = run_cli("check", tmp_path / name, "--scene", "sphere_point", "-o", tmp_path / "o")
        assert r.returncode == 2, (name, r.stdout, r.stderr)
        assert msg in r.stderr and r.stderr.count("\n") == 1, (name, r.stderr)
        assert not (tmp_path / "o").exists()
    r = run_cli("check", tmp_path / "small.exr", "--scene", "sphere_point", "--encoding",
                "srgb")
    assert r.returncode == 2 and "applies to 8-bit" in r.stderr
    r = run_cli("check", tmp_path / "small.exr", "--scene", "sphere_point", "--fail-percent",
                "120")
    assert r.returncode == 2 and "--fail-percent" in r.stderr


# ------------------------------------------------------------------ the noise estimate


def test_local_variance_is_unbiased_for_independent_noise_under_a_smooth_bias():
    # E[(d_a - d_b)^2 / 2] = Var for independent noise, whatever slowly varying bias
    # rides on it (Rice 1984). Over 4,800 pixels the mean estimate's standard error is
    # about 1.5 % (36 pairs a pixel, overlapping); 5 % is over 3 of them.
    rng = np.random.default_rng(7)
    sd = np.ones((60, 80))
    sd[:, 40:] = 3.0
    d = rng.normal(size=(60, 80)) * sd + np.linspace(0, 4, 80)[None, :]
    v = local_variance(d)
    assert v[:, 3:37].mean() == pytest.approx(1.0, rel=0.05)
    assert v[:, 43:77].mean() == pytest.approx(9.0, rel=0.05)


def test_local_variance_leaves_the_pixel_itself_out():
    d = np.zeros((9, 9))
    d[4, 4] = 100.0     # a lone wrong pixel must not raise its own noise estimate
    v = local_variance(d)
    assert v[4, 4] == 0 and v[4, 5] > 0


def test_local_variance_far_from_a_firefly_is_the_noise_around_it():
    # One pixel 1e7 off (an unnormalised highlight) must not change the estimate of
    # windows that do not hold it: a summed-area table lost them (0 beyond it).
    rng = np.random.default_rng(3)
    d = rng.normal(0, 1e-3, (48, 64))
    far = local_variance(d)[20:, 20:]
    d[5, 5] = 5.5e7
    assert np.allclose(local_variance(d)[20:, 20:], far, rtol=1e-9, atol=0)


def test_rounding_bias_bound_is_half_a_step_without_noise_and_vanishes_with_it():
    b = rounding_bias_bound(np.array([0.0, 0.1, 0.5, 1.0]))
    assert b[0] == 0.5 and 0.3 < b[1] < 0.5
    # s = 1/2: exp(-pi^2 / 2) / pi; s = 1: exp(-2 pi^2) / pi (the first terms dominate)
    assert b[2] == pytest.approx(math.exp(-math.pi ** 2 / 2) / math.pi, rel=1e-3)
    assert b[3] < 1e-8
    # The bound holds: the mean rounding error of x + noise, over many draws.
    rng = np.random.default_rng(0)
    for s in (0.1, 0.2, 0.35, 0.5):
        for x in (0.1, 0.25, 0.33, 0.4):
            n = rng.normal(0, s, 400_000)
            err = np.mean(np.round(x + n) - (x + n))
            assert abs(err) <= rounding_bias_bound(np.array(s)) + 4 * 0.29 / math.sqrt(4e5)


# ------------------------------------------------------------------ verdicts


def test_the_tracers_own_image_passes_in_every_format(tmp_path):
    from whitted.tracer.imageio import to_srgb8

    scene = _scene("sphere_point", (64, 48))
    ref = tracer_reference(scene)
    assert _judge(scene, ref.image, ref).passed
    codes = to_srgb8(ref.image).astype(np.int64)
    u = UserImage("<png>", "png", "8-bit srgb", decode(codes, 255, "srgb"),
                  code_steps(codes, 255, "srgb"), clip=1.0, saturated=codes >= 255,
                  encoding="srgb")
    assert _judge(scene, u, ref).passed


@pytest.mark.parametrize("name", ["sphere_point", "three_lights"])
def test_mitsubas_own_path_tracer_passes_on_direct_light(name):
    # Mitsuba's `path` integrator at max_depth 2 (these scenes' depth) on the converted
    # scene, samples jittered: a correct image from another renderer, with the noise of
    # picking one light per sample and of where samples land at edges.
    scene = _scene(name, (64, 48))
    ref = tracer_reference(scene)
    for seed in range(3):
        r = _judge(scene, _mitsuba_path(scene, seed), ref)
        assert r.passed, (seed, r.pixels, r.regions["max_abs_z"])


def test_mitsubas_own_path_tracer_passes_through_glass(tmp_path):
    from whitted.tracer import load_scene

    scene = load_scene(GLASS_LIGHTS)
    ref = tracer_reference(scene)
    for seed in range(3):
        r = _judge(scene, _mitsuba_path(scene, seed), ref)
        assert r.passed, (seed, r.pixels, r.regions["max_abs_z"])


def test_a_one_percent_bias_in_a_correct_noisy_render_fails():
    # The region sums' power: a 1 % bias in Mitsuba's noisy render of three_lights is far
    # beyond the image's detectable bias (0.3 % at 64 x 48).
    scene = _scene("three_lights", (64, 48))
    ref = tracer_reference(scene)
    img = _mitsuba_path(scene, 0)
    r = _judge(scene, img * 1.01, ref)
    assert not r.passed and not r.regions["passed"]
    image = next(g for g in r.regions["regions"] if g["name"] == "image")
    assert image["detectable_bias"] < 0.01
    assert _judge(scene, img, ref).passed


def _render_with(monkeypatch, scene, module, name, fn):
    from whitted.tracer.integrator import Integrator

    with monkeypatch.context() as m:
        m.setattr(module, name, fn)
        return Integrator(scene).render().image.astype(np.float64)


def _no_cosine(n, wi):
    import drjit as dr

    return dr.maximum(dr.sign(dr.dot(n, wi)), 0.0)   # Lambert's cosine forgotten (0 or 1)


def _no_falloff(intensity, dist):
    return intensity                                  # the inverse square forgotten


def _rp_only(cos_i, eta):
    import drjit as dr

    from whitted.tracer import fresnel

    c, rel = fresnel._sides(cos_i, eta)
    cos_t, tir = fresnel.snell_cos_t(cos_i, eta)
    r_p = (rel * c - cos_t) / (rel * c + cos_t)
    return dr.select(tir, 1.0, 0.5 * r_p * r_p)      # the s-polarised term forgotten


def test_an_image_with_a_formula_bug_fails_from_the_command_line(tmp_path, monkeypatch):
    from whitted.tracer import lights
    from whitted.tracer.imageio import write_png

    scene = _scene("sphere_point")
    write_png(tmp_path / "bug.png", _render_with(monkeypatch, scene, lights, "lambert_cosine",
                                                 _no_cosine))
    r = run_cli("check", tmp_path / "bug.png", "--scene", "sphere_point", "-o", tmp_path / "o",
                "--no-suspects")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "FAIL" in r.stdout and "where the difference sits" in r.stdout
    assert "suspects" not in r.stdout          # --no-suspects: the catalog is not ranked
    data = json.loads((tmp_path / "o" / "check.json").read_text())
    assert data["pass"] is False and data["check"]["method"] == "local"
    assert data["suspects"] is None
    assert {"diff.png", "side_by_side.png", "check.html", "reference.exr"} <= {
        p.name for p in (tmp_path / "o").iterdir()}


def test_a_glass_formula_bug_is_placed_in_the_light_seen_through_glass(monkeypatch):
    from whitted.reference.check.judge import decomposition
    from whitted.tracer import fresnel
    from whitted.tracer.integrator import material_ids

    scene = _scene("glass_sphere", (64, 48))
    ref = tracer_reference(scene)
    bug = _render_with(monkeypatch, scene, fresnel, "fresnel_exact", _rp_only)
    r = _judge(scene, bug, ref)
    assert not r.passed
    d = decomposition(scene, r, material_ids(scene), list(scene.materials))
    through_glass = sum(p["share"] for p in d["light_paths"] if p["path"] in ("LS+E", "LDS+E"))
    assert d["light_paths"][0]["path"] in ("LS+E", "LDS+E") and through_glass > 0.9, d
    assert d["materials"][0]["name"] == "material glass"
    assert d["materials"][0]["share"] > 0.9


def test_suspects_are_ranked_with_the_injected_bug_first(monkeypatch):
    # Three formula bugs switched on by monkeypatching; an image made with each (plus
    # noise of 1 % of the image's mean) must name that bug first, at a strength near 1.
    from whitted.reference.check.judge import rank_suspects
    from whitted.reference.check.suspects import Suspect, format_suspects
    from whitted.tracer import fresnel, lights

    scene = _scene("glass_sphere", (48, 36))
    bugs = [("no-cosine", "Lambert's cosine n . l", "The illumination equation",
             lights, "lambert_cosine", _no_cosine),
            ("no-falloff", "inverse-square falloff I / r^2", "Point lights",
             lights, "inverse_square", _no_falloff),
            ("fresnel-rp", "Fresnel R = (r_s^2 + r_p^2) / 2", "The Fresnel equation",
             fresnel, "fresnel_exact", _rp_only)]
    candidates = [Suspect(i, f, t, lambda s, mod=mod, n=n, fn=fn:
                          _render_with(monkeypatch, s, mod, n, fn))
                  for i, f, t, mod, n, fn in bugs]
    ref = tracer_reference(scene)
    rng = np.random.default_rng(1)
    for bug_id, *_ in bugs:
        image = next(c for c in candidates if c.id == bug_id).render(scene)
        noisy = image + rng.normal(0, 0.01 * ref.image.mean(), image.shape)
        fits = rank_suspects(noisy, scene, candidates, reference=ref.image)
        assert fits[0].id == bug_id, format_suspects(fits)
        assert fits[0].beyond_noise > 0.9 and abs(fits[0].scale - 1) < 0.05
        assert "lecture:" in format_suspects(fits)


# ------------------------------------------------------------------ thresholds


def test_idiff_thresholds_replace_the_per_pixel_rule_but_not_the_region_sums():
    scene = _scene("sphere_point", (64, 48))
    ref = tracer_reference(scene)
    img = ref.image.copy()
    img[10, 10] += 0.5          # one pixel off by 0.5: 1 of 3,072 pixels (0.03 %)
    r = _judge(scene, img, ref)
    assert r.pixels["failing"] == 1 and r.pixels["passed"]
    r = _judge(scene, img, ref, thresholds=Thresholds(hard_fail=0.4))
    assert not r.passed and r.pixels["max_abs"] == pytest.approx(0.5)
    r = _judge(scene, img, ref, thresholds=Thresholds(fail=0.6))
    assert r.pixels["failing"] == 0
    r = _judge(scene, img, ref, thresholds=Thresholds(fail=0.1, fail_percent=0))
    assert not r.pixels["passed"]
    r = _judge(scene, img, ref, thresholds=Thresholds(warn=0.1))
    assert r.passed and r.warned
    # A 2 % bias everywhere passes a loose absolute threshold, but not the region sums.
    r = _judge(scene, ref.image * 1.02, ref, thresholds=Thresholds(fail=1.0))
    assert r.pixels["passed"] and not r.regions["passed"] and not r.passed


def test_a_variance_layer_is_used_as_the_images_noise(tmp_path):
    from whitted.tracer.imageio import write_exr

    scene = _scene("sphere_point", (64, 48))
    ref = tracer_reference(scene)
    rng = np.random.default_rng(5)
    sd = 0.02 * (ref.image + 0.05)
    noisy = ref.image + rng.normal(size=ref.image.shape) * sd
    var = sd ** 2
    write_exr(tmp_path / "v.exr", noisy, {f"variance.{c}": var[..., i]
                                          for i, c in enumerate("RGB")})
    u = read_user_image(tmp_path / "v.exr")
    assert u.variance is not None
    r = _judge(scene, u, ref)
    assert r.method == "variance" and r.passed
    # The same image claiming a hundred times less variance fails.
    u.variance = var / 100
    assert not _judge(scene, u, ref).passed


@pytest.mark.slow
def test_check_with_mitsuba_and_spp_from_the_command_line(tmp_path):
    from whitted.tracer.imageio import write_exr

    scene = _scene("three_lights")
    write_exr(tmp_path / "path.exr", _mitsuba_path(scene, 2).astype(np.float32))
    r = run_cli("check", tmp_path / "path.exr", "--scene", "three_lights", "--mitsuba",
                "--spp", "64", "-o", tmp_path / "o")
    assert r.returncode == 0, r.stdout + r.stderr
    data = json.loads((tmp_path / "o" / "check.json").read_text())
    assert data["check"]["method"] == "spp" and data["reference_vs_mitsuba"]["passed"]
    assert data["mitsuba"]["passed"]
