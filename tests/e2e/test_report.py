"""`whitted report`: files, schema, a real error caught, and the page in a real browser."""

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENES, run_cli

from whitted.reference.report.build import build_report, select_scenes


def test_quick_report_writes_html_markdown_and_json(tmp_path):
    r = run_cli("report", "--quick", "--scenes", "sphere_point*", "-o", tmp_path / "rep")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "[1/2] sphere_point" in r.stdout and "fresnel curves" in r.stdout
    out = tmp_path / "rep"
    data = json.loads((out / "report.json").read_text())
    # The schema documented in docs/report-json.md.
    assert data["pass"] is True and data["quick"] is True
    assert {"whitted", "mitsuba", "drjit", "backend"} <= set(data["versions"])
    (s,) = data["scenes"]
    assert {"name", "pass", "test", "metrics", "seconds", "checks", "reason"} <= set(s)
    assert s["name"] == "sphere_point" and s["test"] == "exact-strata"
    assert s["reference"] == "deterministic" and s["second_opinion"] is None
    assert {"tracer", "mitsuba"} <= set(s["seconds"])
    assert {"rmse", "median_rel", "p999_rel", "frac_over_01pct", "frac_over_5pct",
            "flip"} <= set(s["metrics"])
    assert len(data["fresnel"]) == 8 and data["fresnel_pass"] is True
    md = (out / "report.md").read_text()
    assert md.startswith("# whitted accuracy report: PASS") and "| sphere_point |" in md
    page = (out / "index.html").read_text()
    # tracer, Mitsuba, diff, Fresnel plot (no light-path split: no glass, mirror or area light)
    assert page.count("data:image/png;base64,") == 4


def test_report_refuses_bad_input(tmp_path):
    r = run_cli("report", "--scenes", "no_such_scene*", "-o", tmp_path / "rep")
    assert r.returncode == 2 and "no scene" in r.stderr
    bad = tmp_path / "scenes"
    bad.mkdir()
    (bad / "broken.toml").write_text("[camera]\norigin = [0, 0]\n")
    r = run_cli("report", "--scenes-dir", bad, "-o", tmp_path / "rep2")
    assert r.returncode == 2 and "camera.origin" in r.stderr
    assert not (tmp_path / "rep2").exists()


def _verdicts(report):
    return {s["name"]: s["pass"] for s in report.scenes}


ALL = select_scenes(SCENES, None)


def _uses_exact_fresnel(path: Path) -> bool:
    """The scene, as it is judged, has a dielectric in use whose weights are the exact
    Fresnel equations (a declared Schlick is judged with them too, see compare.comparable),
    or a thin dielectric or a plastic, whose weights are made of them; the classic model's
    fixed weights have no Fresnel term, a conductor's is the complex one."""
    from whitted.reference.verdicts.compare import comparable
    from whitted.tracer import load_scene
    from whitted.tracer.materials import plastic, thindielectric
    from whitted.tracer.scene import Dielectric

    scene = comparable(load_scene(path))
    return any((isinstance(m, Dielectric) and m.fresnel == "exact") or
               isinstance(m, (plastic.MODEL, thindielectric.MODEL))
               for m in scene.used_materials())


GLASS = {p.stem for p in ALL if _uses_exact_fresnel(p)}


def test_report_fails_exactly_the_glass_scenes_when_fresnel_is_wrong(tmp_path, monkeypatch):
    # A plausible bug: the s-polarised amplitude forgotten, R = r_p^2 / 2 instead of
    # (r_s^2 + r_p^2) / 2. Every scene whose glass has Fresnel weights must fail, and the
    # Fresnel curves; the others (no glass, or the classic model's fixed weights) must pass.
    import drjit as dr

    from whitted.tracer import fresnel

    def wrong(cos_i, eta):
        c, rel = fresnel._sides(cos_i, eta)
        cos_t, tir = fresnel.snell_cos_t(cos_i, eta)
        r_p = (rel * c - cos_t) / (rel * c + cos_t)
        return dr.select(tir, 1.0, 0.5 * r_p * r_p)

    monkeypatch.setattr(fresnel, "fresnel_exact", wrong)
    # The deterministic verdict decides; the one-lobe second opinion is tested elsewhere.
    report = build_report(tmp_path, ALL, quick=True, log=lambda *_: None,
                          second_opinion=False)
    verdicts = _verdicts(report)
    assert not report.passed and not report.fresnel_passed
    assert {n for n, ok in verdicts.items() if not ok} == GLASS, verdicts
    assert GLASS and len(GLASS) < len(verdicts)


def test_report_covers_the_light_inside_glass_with_a_second_opinion(tmp_path):
    # The scene with a light inside glass: compared at float precision with the
    # deterministic reference, and by the one-lobe reference's z-test, whose
    # zero-variance rule keeps the correct tracer from failing on rare paths.
    report = build_report(tmp_path, [SCENES / "emitter_in_glass.toml"], quick=True,
                          log=lambda *_: None, fresnel=False)
    (s,) = report.scenes
    assert s["pass"] and s["reference"] == "deterministic" and s["test"] == "exact-strata"
    so = s["second_opinion"]
    assert so["reference"] == "onelobe" and so["test"] == "z-test" and so["passed"]
    assert so["checks"]["z_fraction_passed"]["zero_variance"] > 0
    assert so["checks"]["region_max_z"]["regions"]
    md = (tmp_path / "report.md").read_text()
    assert "| emitter_in_glass |" in md and "deterministic + onelobe" in md
    page = (tmp_path / "index.html").read_text()
    assert "Second opinion" in page and "smallest detectable bias" in page


def test_report_fails_when_the_camera_is_mirrored(tmp_path, monkeypatch):
    # Another: the image's x axis flipped (world +x drawn on the left).
    from whitted.tracer import integrator
    from whitted.tracer.camera import generate_rays

    def mirrored(camera, width, height, film_x, film_y):
        return generate_rays(camera, width, height, width - film_x, film_y)

    monkeypatch.setattr(integrator, "generate_rays", mirrored)
    picked = [p for p in ALL if p.stem in ("three_lights", "ortho_transforms")]
    report = build_report(tmp_path, picked, quick=True, log=lambda *_: None, fresnel=False)
    assert _verdicts(report) == {"ortho_transforms": False, "three_lights": False}


def _chromium():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--hide-scrollbars"]


def test_report_page_loads_every_image_in_a_real_browser(tmp_path):
    browser = _chromium()
    if browser is None:
        if os.environ.get("WHITTED_REQUIRE_BROWSER"):
            pytest.fail("chromium is required here (WHITTED_REQUIRE_BROWSER) but missing")
        pytest.skip("no chromium: `make setup` installs Debian's package where it can")
    out = tmp_path / "rep"
    build_report(out, [SCENES / "glass_sphere.toml", SCENES / "three_lights.toml"], quick=True,
                 log=lambda *_: None)
    page = (out / "index.html").resolve()
    n_img = page.read_text().count("<img ")
    profile = tempfile.mkdtemp()
    shot = tmp_path / "shot.png"
    subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                    "--window-size=1280,2200", f"--screenshot={shot}", page.as_uri()],
                   capture_output=True, timeout=120, check=False)
    dom = subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                          "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
                         capture_output=True, text=True, timeout=120).stdout
    # The page's own script counts images that decoded (naturalWidth > 0) after load.
    assert f'data-images-loaded="{n_img}/{n_img}"' in dom, dom[:300]
    # 2 scenes x (tracer, Mitsuba, diff), the glass scene's 4 light-path images, Fresnel plot
    assert n_img == 11
    from PIL import Image

    pixels = np.asarray(Image.open(shot).convert("RGB"), dtype=np.float32)
    assert pixels.shape[0] >= 2000 and pixels.std() > 20  # a page, not a blank screen
    Path(os.environ.get("WHITTED_SCREENSHOT_DIR", tmp_path)).mkdir(exist_ok=True)
    shutil.copy(shot, Path(os.environ.get("WHITTED_SCREENSHOT_DIR", tmp_path)) / "report.png")


# ------------------------------------------------------------------ the viewer, in a browser


def _srgb8(x: float) -> int:
    from whitted.tracer.imageio import srgb_encode

    return int(np.round(float(srgb_encode(np.array(x))) * 255))


def _numbers(line: str) -> list[float]:
    return [float(v) for v in line.split(":", 1)[1].split()]


def exercise_viewer(b, index: int, first: np.ndarray, second: np.ndarray, names) -> None:
    """Hover, flip, pick, zoom and reset one viewer with real mouse and key events."""
    sel = f"document.querySelectorAll('.wv')[{index}]"
    b.wait(f"{sel} && {sel}.dataset.ready === '1'")
    b.eval(f"{sel}.scrollIntoView({{block: 'center'}})")
    rect = b.eval(f"(function(){{var r = {sel}.querySelector('canvas').getBoundingClientRect();"
                  "return [r.left, r.top, r.width, r.height];})()")
    h, w = first.shape[:2]
    diff = np.abs(first - second).sum(-1)
    y, x = np.unravel_index(np.argmax(diff + 1e-3 * (first.sum(-1) > 0)), diff.shape)

    def at(px, py):   # the centre of pixel (px, py) on the page, unzoomed
        return rect[0] + (px + 0.5) * rect[2] / w, rect[1] + (py + 0.5) * rect[3] / h

    def canvas_pixel(px, py):
        return b.eval(f"(function(){{var c = {sel}.querySelector('canvas');"
                      f"var s = c.width / {w};"
                      f"return Array.from(c.getContext('2d').getImageData("
                      f"Math.floor(({px} + 0.5) * s), Math.floor(({py} + 0.5) * s), 1, 1).data)"
                      ".slice(0, 3);})()")

    # Hover: the pixel, both images' linear values and the relative difference.
    b.mouse("mouseMoved", *at(x, y))
    lines = b.wait(f"{sel}.dataset.hover === '{x},{y}' && "
                   f"{sel}.querySelector('.wv-readout').textContent").split("\n")
    assert lines[0] == f"pixel {x}, {y}"
    assert np.allclose(_numbers(lines[1]), first[y, x], rtol=1e-4, atol=1e-7), lines
    assert np.allclose(_numbers(lines[2]), second[y, x], rtol=1e-4, atol=1e-7), lines
    ref_sum = np.abs(second).sum(-1)
    rel = diff[y, x] / max(ref_sum[y, x], 1e-3 * ref_sum.mean())
    assert float(lines[3].split(":")[1]) == pytest.approx(rel, rel=1e-3, abs=1e-9)
    # What is drawn is the shown image's value through the sRGB curve.
    assert b.eval(f"{sel}.dataset.shown") == names[0]
    assert canvas_pixel(x, y) == [_srgb8(v) for v in first[y, x]]
    # A click flips to the other image, F flips back, 3 shows the difference, 1 the first.
    b.click(*at(x, y))
    assert b.eval(f"{sel}.dataset.shown") == names[1]
    assert canvas_pixel(x, y) == [_srgb8(v) for v in second[y, x]]
    b.key("f")
    assert b.eval(f"{sel}.dataset.shown") == names[0]
    b.key("3")
    assert b.eval(f"{sel}.dataset.shown") == "relative difference"
    b.key("1")
    assert b.eval(f"{sel}.dataset.shown") == names[0]
    # E: half a stop brighter.
    b.key("e")
    brighter = canvas_pixel(x, y)
    assert brighter == [_srgb8(v * 2 ** 0.5) for v in first[y, x]]
    b.key("E")
    # The wheel zooms around the pointer: the pixel under it stays under it.
    b.mouse("mouseWheel", *at(x, y), deltaY=-100)
    assert float(b.eval(f"{sel}.dataset.zoom")) == pytest.approx(1.25)
    b.mouse("mouseMoved", *at(x, y))
    assert b.wait(f"{sel}.dataset.hover") == f"{x},{y}"
    b.key("r")
    assert float(b.eval(f"{sel}.dataset.zoom")) == 1
    # Shift + drag: zoom onto the region dragged over (a quarter of the image's width).
    x0, y0 = w // 4, h // 4
    b.drag(*at(x0, y0), *at(x0 + w // 4, y0 + h // 4), modifiers=8)
    zoom = float(b.eval(f"{sel}.dataset.zoom"))
    ox, oy = (float(v) for v in b.eval(f"{sel}.dataset.view").split(","))
    assert zoom == pytest.approx(4, rel=0.1)
    assert (ox, oy) == (pytest.approx(x0 + 0.5, abs=0.6), pytest.approx(y0 + 0.5, abs=0.6))
    b.mouse("mouseMoved", rect[0] + 1, rect[1] + 1)   # the top left is now that region's
    assert b.wait(f"{sel}.dataset.hover") == f"{x0},{y0}"
    b.key("r")
    # A plain drag pans.
    b.mouse("mouseWheel", *at(w // 2, h // 2), deltaY=-100)
    before = b.eval(f"{sel}.dataset.view")
    b.drag(*at(w // 2, h // 2), *at(w // 2 - 4, h // 2))
    assert b.eval(f"{sel}.dataset.view") != before
    assert b.eval(f"{sel}.dataset.shown") == names[0]   # a drag is not a click


def _need_browser():
    from browser import chromium

    exe = chromium()
    if exe is None:
        if os.environ.get("WHITTED_REQUIRE_BROWSER"):
            pytest.fail("chromium is required here (WHITTED_REQUIRE_BROWSER) but missing")
        pytest.skip("no chromium: `make setup` installs Debian's package where it can")
    return exe


def _offline(page: str) -> None:
    """Nothing on the page comes from elsewhere: one file."""
    body = page.lower()
    assert "src='http" not in body and 'src="http' not in body and "<link" not in body
    assert "@import" not in body and "url(http" not in body


def test_report_viewer_compares_tracer_and_mitsuba_in_a_real_browser(tmp_path):
    from browser import Browser

    exe = _need_browser()
    out = tmp_path / "rep"
    report = build_report(out, [SCENES / "three_lights.toml"], quick=True, log=lambda *_: None,
                          fresnel=False)
    page = (out / "index.html").read_text()
    _offline(page)
    from whitted.tracer.imageio import read_exr

    files = report.scenes[0]["files"]
    tracer_img, mitsuba_img = read_exr(files["tracer.exr"]), read_exr(files["mitsuba.exr"])
    with Browser(exe) as b:
        b.open((out / "index.html").resolve().as_uri())
        exercise_viewer(b, 0, tracer_img, mitsuba_img, ("tracer", "Mitsuba"))


def test_check_page_viewer_in_a_real_browser(tmp_path):
    from browser import Browser

    exe = _need_browser()
    from whitted.tracer import load_scene
    from whitted.tracer.imageio import write_exr
    from whitted.tracer.integrator import Integrator

    scene = load_scene(SCENES / "sphere_point.toml").with_overrides(size=(64, 48))
    img = Integrator(scene).render().image
    img[36:48, 36:60] *= 1.5                     # a wrong patch of floor: failing pixels
    assert (img[36:48, 36:60] > 0.01).all()
    write_exr(tmp_path / "mine.exr", img)
    r = run_cli("check", tmp_path / "mine.exr", "--scene", "sphere_point", "--size", "64x48",
                "-o", tmp_path / "ck")
    assert r.returncode == 1, r.stdout + r.stderr
    page = (tmp_path / "ck" / "check.html").read_text()
    _offline(page)
    from whitted.tracer.imageio import read_exr

    ref = read_exr(tmp_path / "ck" / "reference.exr")
    with Browser(exe) as b:
        b.open((tmp_path / "ck" / "check.html").resolve().as_uri())
        exercise_viewer(b, 0, img, ref, ("your image", "reference"))
        # The difference view outlines the failing pixels (cyan).
        b.key("r")
        b.key("3")
        cyan = b.eval("(function(){var c = document.querySelector('.wv canvas');"
                      "var s = c.width / 64; var d = c.getContext('2d').getImageData("
                      "Math.floor(48.5 * s), Math.floor(43.5 * s), 1, 1).data;"
                      "return [d[0], d[1], d[2]];})()")
        assert cyan == [0, 255, 255]
        b.screenshot(tmp_path / "check.png")
    shots = os.environ.get("WHITTED_SCREENSHOT_DIR")
    if shots:
        Path(shots).mkdir(exist_ok=True)
        shutil.copy(tmp_path / "check.png", Path(shots) / "check.png")


def test_suite_page_has_one_working_viewer_per_graded_scene(tmp_path):
    from browser import Browser

    exe = _need_browser()
    from whitted.tracer import load_scene
    from whitted.tracer.imageio import write_exr
    from whitted.tracer.integrator import Integrator

    images = tmp_path / "imgs"
    images.mkdir()
    renders = {}
    for name in ("sphere_point", "three_lights"):
        renders[name] = Integrator(load_scene(SCENES / f"{name}.toml")).render().image
        write_exr(images / f"{name}.exr", renders[name] * (1.03 if name == "three_lights"
                                                            else 1.0))
    r = run_cli("suite", "check", images, "--scenes", "[st]*_[pl]*", "-o", tmp_path / "out")
    assert r.returncode == 1, r.stdout + r.stderr        # three_lights is 3 % too bright
    page = (tmp_path / "out" / "index.html").read_text()
    _offline(page)
    assert page.count("class='wv'") == 2
    with Browser(exe) as b:
        b.open((tmp_path / "out" / "index.html").resolve().as_uri())
        b.wait("document.querySelectorAll('.wv[data-ready=\"1\"]').length === 2")
        exercise_viewer(b, 1, renders["three_lights"] * 1.03, renders["three_lights"],
                        ("your image", "reference"))


def test_heat_map_colours_follow_the_log_scale(tmp_path):
    """diff.png: a pixel's colour is inferno's at log10(rel) between 1e-8 and 1 (a
    relative difference of 1e-4 sits halfway), each pixel drawn as one square block (of
    32 x 32, the most, for an image this small)."""
    from PIL import Image

    from whitted.reference.verdicts.compare import _inferno_lut, heat_map

    heat_map(np.array([[1e-8, 1e-4, 1.0, 10.0]]), tmp_path / "d.png")
    img = np.asarray(Image.open(tmp_path / "d.png").convert("RGB"))
    lut = _inferno_lut()
    k = 32   # the image's corner at (8, 8)
    centre = [img[8 + k // 2, 8 + k * i + k // 2] for i in range(4)]
    assert [tuple(c) for c in centre] == [tuple(lut[i]) for i in (0, 128, 255, 255)]
