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

from reference.report import build_report, select_scenes


def test_quick_report_writes_html_markdown_and_json(tmp_path):
    r = run_cli("report", "--quick", "--scenes", "sphere_point*", "-o", tmp_path / "rep")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "[1/2] sphere_point" in r.stdout and "fresnel curves" in r.stdout
    out = tmp_path / "rep"
    data = json.loads((out / "report.json").read_text())
    # The schema documented in the README.
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
    Fresnel equations (a declared Schlick is judged with them too, see compare.comparable);
    the classic model's fixed weights have no Fresnel term."""
    from reference.compare import comparable
    from tracer import load_scene
    from tracer.scene import Dielectric

    scene = comparable(load_scene(path))
    return any(isinstance(m, Dielectric) and m.fresnel == "exact"
               for m in scene.used_materials())


GLASS = {p.stem for p in ALL if _uses_exact_fresnel(p)}


def test_report_fails_exactly_the_glass_scenes_when_fresnel_is_wrong(tmp_path, monkeypatch):
    # A plausible bug: the s-polarised amplitude forgotten, R = r_p^2 / 2 instead of
    # (r_s^2 + r_p^2) / 2. Every scene whose glass has Fresnel weights must fail, and the
    # Fresnel curves; the others (no glass, or the classic model's fixed weights) must pass.
    import drjit as dr

    from tracer import fresnel

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
    from tracer import integrator
    from tracer.camera import generate_rays

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
