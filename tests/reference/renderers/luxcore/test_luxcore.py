"""LuxCore, the third renderer: the scene conversion, the child process, the three-way vote.

The conversion tests need no LuxCore. The rendering tests need the extra
``whitted[luxcore]`` (pyluxcore): they are skipped in one line without it,
except where WHITTED_REQUIRE_LUXCORE=1 (CI, ``make test``), where a missing
pyluxcore fails them.
"""

import math
import os
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENES, run_cli

from whitted.tracer import load_scene
from whitted.tracer.errors import UserError

DATA = Path(__file__).resolve().parents[3] / "data" / "luxcore"


@pytest.fixture(scope="module")
def luxcore():
    from whitted.reference.renderers.luxcore import render as lx

    if not lx.available():
        if os.environ.get("WHITTED_REQUIRE_LUXCORE") == "1":
            pytest.fail("pyluxcore is required here (WHITTED_REQUIRE_LUXCORE=1) but missing")
        pytest.skip("pyluxcore is not installed: pip install 'whitted[luxcore]'")
    return lx


# ------------------------------------------------------------------ conversion


def test_point_light_intensity_is_gain_times_colour_over_four_pi():
    from whitted.reference.emitters import convert
    from whitted.tracer.emitters.point import PointLight

    p = convert(PointLight((1, 2, 3), (60, 30, 15)), "luxcore")
    # LuxCore: I = gain * color / (4 pi) without power and efficiency
    assert p["power"] == 0 and p["efficiency"] == 0
    assert np.allclose(np.multiply(p["gain"], p["color"]) / (4 * math.pi), (60, 30, 15))


def test_kinds_without_a_luxcore_conversion_refuse_in_one_line(monkeypatch):
    """The registry's default: any kind without luxcore(), a kind added later included."""
    import types

    from whitted.reference import materials
    from whitted.tracer.materials.phong import Phong

    with pytest.raises(UserError) as e:
        materials.convert(Phong("shiny"), "luxcore")
    assert str(e.value).startswith("phong: no LuxCore equivalent") and "\n" not in str(e.value)
    # a kind registered later with only a Mitsuba conversion
    monkeypatch.setitem(materials.REGISTRY, "phong", types.SimpleNamespace(mitsuba=lambda m: {}))
    with pytest.raises(UserError, match="^phong: no LuxCore equivalent"):
        materials.convert(Phong("shiny"), "luxcore")


@pytest.mark.parametrize("name, message", [
    ("heckbert_minray", "no LuxCore equivalent"),
    ("whitted_1980", "textured diffuse reflectance has no LuxCore equivalent"),
    ("phong_lobes", "phong: no LuxCore equivalent"),
])
def test_scenes_that_do_not_map_are_refused(name, message):
    from whitted.reference.renderers.luxcore.scene import describe

    with pytest.raises(UserError, match=message):
        describe(load_scene(SCENES / f"{name}.toml"))


def test_field_of_view_goes_to_the_longer_side():
    from whitted.reference.renderers.luxcore.scene import describe

    scene = load_scene(SCENES / "sphere_point.toml")
    wide = describe(scene.with_overrides(size=(80, 40))).props
    tall = describe(scene.with_overrides(size=(40, 80))).props
    assert wide["scene.camera.fieldofview"] == pytest.approx(scene.camera.fov)
    # horizontal fov f on a W x H image, H > W: the vertical one is 2 atan(tan(f/2) H / W)
    t = math.tan(math.radians(scene.camera.fov) / 2)
    assert tall["scene.camera.fieldofview"] == pytest.approx(math.degrees(2 * math.atan(2 * t)))


def test_tessellated_sphere_stays_within_its_chord_bound():
    from whitted.reference.renderers.luxcore.scene import TESSELLATION, sphere_mesh
    from whitted.tracer.scene import Sphere

    s = Sphere((1.0, -2.0, 0.5), 0.7, None)
    v, f, n = sphere_mesh(s)
    assert np.allclose(np.linalg.norm(v - s.center, axis=1), s.radius)   # vertices on it
    # the deepest points of the faces: their centroids and their edges' midpoints (the
    # circumcentre of a right triangle, the cells' halves); 1 % for second-order terms
    pts = np.concatenate([v[f].mean(1), (v[f[:, 0]] + v[f[:, 1]]) / 2,
                          (v[f[:, 1]] + v[f[:, 2]]) / 2, (v[f[:, 0]] + v[f[:, 2]]) / 2])
    depth = s.radius - np.linalg.norm(pts - s.center, axis=1)
    assert depth.max() <= TESSELLATION * s.radius * 1.01
    assert depth.max() > TESSELLATION * s.radius / 2   # and not far finer than needed
    assert np.allclose(np.linalg.norm(n, axis=1), 1)


# ------------------------------------------------------------------ rendering


def test_passes_become_pixel_means_with_their_noise():
    """A pixel is the mean of its k x k sub-pixels over the passes; its variance the
    per-sample second moment over those P k^2 samples / (P k^2); the spread of the
    passes' channel sums / P. Checked pixel by pixel against those definitions, on
    films whose sub-pixels all differ (a wrong grouping of rows or columns fails)."""
    from types import SimpleNamespace

    from whitted.reference.renderers.luxcore.render import _result
    from whitted.reference.renderers.luxcore.runner import pass_moments

    k, h, w, p = 3, 4, 5, 3
    rng = np.random.default_rng(7)
    films = rng.random((p, h * k, w * k, 3)).astype(np.float32)
    moments = [pass_moments(f, k) for f in films]          # as the child sums each pass
    sums = np.stack([m[0] for m in moments])
    squares = sum(m[1] for m in moments)
    r = _result(SimpleNamespace(subsamples=k, height=h, width=w), sums, squares, 1, 0.0)
    for y in range(h):
        for x in range(w):
            sub = films[:, y * k:(y + 1) * k, x * k:(x + 1) * k].astype(np.float64)
            samples = sub.reshape(-1, 3)
            assert np.allclose(r.image[y, x], samples.mean(0), rtol=1e-6)
            assert np.allclose(r.variance[y, x], samples.var(0) / len(samples), rtol=1e-5)
            passes = sub.mean(axis=(1, 2)).sum(-1)
            assert np.isclose(r.pass_variance[y, x], passes.var(ddof=1) / p, rtol=1e-9)
    assert r.samples == p * k * k


def test_dr_jit_gives_up_a_thread_while_the_child_runs_and_gets_it_back():
    import drjit as dr

    from whitted.reference.renderers.luxcore.render import SharedCores

    class Job:
        alive = True

        def running(self):
            return self.alive

    before = dr.thread_count()
    if before < 2:
        pytest.skip("Dr.Jit has one thread here: nothing to share")
    job = Job()
    with SharedCores(job) as cores:
        assert dr.thread_count() == 1
        cores.poll()
        assert dr.thread_count() == 1          # the child still renders
        job.alive = False
        cores.poll()
        assert dr.thread_count() == before     # given back as soon as the child is gone
    assert dr.thread_count() == before
    job.alive = True
    with pytest.raises(KeyError):
        with SharedCores(job):
            raise KeyError("a failing sweep")
    assert dr.thread_count() == before         # given back on the way out, too
    with SharedCores(None):
        assert dr.thread_count() == before     # no child: nothing given up


def _completes_in_a_child(code: str, what: str) -> None:
    """Run ``code`` in a child with a time limit (the bug is a hang); it prints 'loaded'."""
    import subprocess
    import sys

    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=60, cwd=Path(__file__).resolve().parents[4])
    except subprocess.TimeoutExpired:
        pytest.fail(f"{what} hung with Dr.Jit on one thread")
    assert out.returncode == 0, out.stderr[-2000:]
    assert "loaded" in out.stdout


def test_mitsuba_loads_an_exr_map_while_dr_jit_has_one_thread():
    """SharedCores leaves Dr.Jit one thread during the report's sweep, and Mitsuba
    3.9.1's parser never returns from reading an EXR map on a pool of one thread:
    reference.renderers.mitsuba.scene.load gives the pool two threads for the load. Run in a
    child with a time limit, as the bug is a hang (without the two threads: killed)."""
    _completes_in_a_child(
        "import whitted.tracer, drjit as dr\n"
        "from whitted.tracer import load_scene\n"
        "from whitted.reference import mitsuba\n"
        "from whitted.reference.renderers.mitsuba.scene import load\n"
        f"scene = load_scene({str(SCENES / 'envmap.toml')!r})\n"
        "dr.set_thread_count(1)\n"
        "load(scene, mitsuba())\n"
        "assert dr.thread_count() == 1\n"
        "print('loaded')\n", "Mitsuba's load of an EXR map")


def test_an_imported_scene_with_an_exr_map_loads_while_dr_jit_has_one_thread(tmp_path):
    """The report's imported scenes run while SharedCores leaves Dr.Jit one thread: the
    importer's own loads of the original file (its sensor, its render) take two threads
    too. The envmap scene written as Mitsuba XML (its EXR map beside it)."""
    from whitted.reference import cli

    xml = tmp_path / "envmap.xml"
    assert cli.main(["export", str(SCENES / "envmap.toml"), "-o", str(xml)]) == 0
    _completes_in_a_child(
        "import whitted.tracer, drjit as dr\n"
        "from whitted.reference.renderers.mitsuba.importer import mitsuba_view, "
        "render_original\n"
        "dr.set_thread_count(1)\n"
        f"mitsuba_view({str(xml)!r})\n"
        f"render_original({str(xml)!r}, 'direct', spp=1, passes=1)\n"
        "assert dr.thread_count() == 1\n"
        "print('loaded')\n", "The importer's load of an EXR map")


def test_missing_luxcore_is_one_line(monkeypatch, capsys, tmp_path):
    from whitted.reference import cli
    from whitted.reference.renderers.luxcore import render as lx

    monkeypatch.setattr(lx, "available", lambda: False)
    rc = cli.main(["reference", "sphere_point", "-o", str(tmp_path / "x.exr"),
                   "--renderer", "luxcore"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and "pip install 'whitted[luxcore]'" in err


def test_child_past_its_time_limit_is_one_line(luxcore):
    scene = load_scene(SCENES / "sphere_point.toml").with_overrides(size=(8, 6))
    with pytest.raises(UserError, match="time limit of 0.1 s"):
        luxcore.render_many([scene], passes=1, timeout=0.1)


def test_a_started_child_left_unread_is_stopped_and_its_files_removed(luxcore):
    """``whitted report`` starts LuxCore and goes on; if the report fails or is
    interrupted before it reads the results, closing the job kills the child and removes
    its folder (no orphan process, no files left in the temporary directory)."""
    scene = load_scene(SCENES / "sphere_point.toml").with_overrides(size=(8, 6))
    job = luxcore.start_many([scene], passes=2)
    assert job.proc.poll() is None and job.tmp.is_dir()
    job.close()
    assert job.proc.poll() is not None and not job.tmp.exists()


def test_spot_light_profile_is_pbrt_falloff_over_cos(luxcore):
    """LuxCore's spot: I falloff(theta) / cos(theta), the finding behind spot_floor.

    An orthographic camera looks straight down on a diffuse floor under the spot
    (tests/data/luxcore/spot_probe.toml). Inside the beam (theta < 15 degrees)
    LuxCore / tracer = 1 / cos(theta); between beam and cutoff it follows
    ((cos theta - cos cutoff) / (cos beam - cos cutoff))^4 / cos theta over the
    tracer's (and Mitsuba's) linear falloff. A spot converted with the point
    light's 4 pi gain, or a profile equal to the tracer's, fails.
    """
    from whitted.tracer.integrator import Integrator

    scene = load_scene(DATA / "spot_probe.toml")
    lux = luxcore.render(scene, passes=2, subsamples=4)
    t = Integrator(scene).render().image[..., 0].astype(np.float64)
    l, var = lux.image[..., 0].astype(np.float64), lux.variance[..., 0]
    n = scene.film.width
    xs = (np.arange(n) + 0.5) / n * 6 - 3
    X, Z = np.meshgrid(xs, xs)
    theta = np.degrees(np.arctan2(np.hypot(X, Z), 4))
    inner = (theta < 13) & (t > 0)
    cos = np.cos(np.radians(theta[inner]))
    # per pixel: LuxCore's mean over the pixel against the tracer's centre value times
    # 1 / cos; the pixel's spread of 1 / cos (< 2e-4 at 64 px over 6 units) stays far
    # below 5 sigma of LuxCore's 16-sample noise, so |z| < 5 with Sidak over ~1000 pixels.
    z = (l[inner] - t[inner] / cos) / np.sqrt(var[inner] + (2e-4 * l[inner]) ** 2)
    assert np.abs(z).max() < 5, np.abs(z).max()
    ratio = l[inner].sum() / t[inner].sum()
    assert ratio > 1.005   # not the tracer's profile: 1 / cos averages above 1 there


def test_three_renderers_agree_on_specular_scenes(luxcore):
    """Direct light and mirror / glass chains: the tracer, Mitsuba and LuxCore agree.

    Each pair by the statistical verdict (reference/renderers/luxcore/vote.py) at the quick
    sizes, in one LuxCore child; a wrong light gain, a camera one row off or the
    glass's indices swapped in the conversion makes LuxCore the odd one out.
    """
    from whitted.reference.renderers.luxcore.vote import compare_three
    from whitted.reference.report.build import quick_overrides

    names = ["glass_sphere", "tir_prisms", "whitted_mix"]
    threes = compare_three([quick_overrides(load_scene(SCENES / f"{n}.toml")) for n in names],
                           quick=True)
    for t in threes:
        assert t.verdict == "all agree", (t.scene, t.verdict, t.detail, {
            k: {c: v["value"] for c, v in p["checks"].items()} for k, p in t.pairs.items()})


def test_area_lights_with_mirrors_are_not_compared(luxcore):
    from whitted.reference.renderers.luxcore.vote import compare_three

    [t] = compare_three([load_scene(SCENES / "area_lights.toml")], quick=True)
    assert t.verdict == "not compared" and "caustics" in t.detail


def test_cli_reference_and_compare(luxcore, tmp_path):
    out = tmp_path / "lux.exr"
    r = run_cli("reference", "glass_sphere", "-o", out, "--renderer", "luxcore",
                "--size", "32x24", "--spp", "4")
    assert r.returncode == 0, r.stderr
    assert out.exists() and "LuxCore 2.11.2" in r.stdout
    r = run_cli("compare", "tir_prisms", "--renderer", "luxcore", "--size", "48x28", "--spp",
                "4", "-o", tmp_path / "c")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "all agree" in r.stdout and (tmp_path / "c" / "luxcore.json").exists()


def test_report_shows_the_vote_and_keeps_the_tracers_exit_status(luxcore, tmp_path):
    """LuxCore the odd one out is a finding in the report, not a failure of the tracer.

    spot_floor: LuxCore's spot profile differs (test above), and the vote names it.
    """
    from whitted.reference.report.build import build_report

    report = build_report(tmp_path, [SCENES / "spot_floor.toml"], quick=True,
                          log=lambda *_: None, fresnel=False, luxcore=True)
    (s,) = report.scenes
    assert s["pass"] and report.passed
    assert s["luxcore"]["odd"] == "luxcore"
    md = (tmp_path / "report.md").read_text()
    assert "## Three renderers" in md and "luxcore is the odd one out" in md
    assert "luxcore is the odd one out" in (tmp_path / "index.html").read_text()


def test_block_allowance_is_the_binomial_quantile_of_noise():
    """The vote's rule 3 allows as many blocks beyond 3 sigma as noise alone makes at a
    family-wise 1e-3: checked against the binomial tail computed here directly."""
    from math import comb, erf, sqrt

    from whitted.reference.renderers.luxcore.vote import blocks_allowed

    p = 1 - erf(3 / sqrt(2))
    def tail(n, j):  # P(count > j); terms beyond j + 40 are below 1e-60 here
        return sum(comb(n, i) * p ** i * (1 - p) ** (n - i)
                   for i in range(j + 1, min(n, j + 40) + 1))

    for n in (12, 48, 192, 1200):
        k = blocks_allowed(n)
        assert tail(n, k) < 1e-3 <= tail(n, k - 1), (n, k)
    assert blocks_allowed(48) == 2        # 32 x 24 pixels: 2 % would allow none
    assert blocks_allowed(1200) < 0.02 * 1200  # large images keep rule 3's 2 %


def test_every_builtin_scene_is_voted_on_or_given_a_reason(monkeypatch):
    """One scene the vote cannot take (emitters without the deterministic reference's
    sample maps: shape_lights) gets its reason; it never stops the vote of the others (it
    did: the report said LuxCore was not available for all of them)."""
    from whitted.reference.renderers.luxcore import render as luxcore
    from whitted.reference.renderers.luxcore import vote

    monkeypatch.setattr(luxcore, "start_many", lambda todo, nice=0: None)
    scenes = [load_scene(p) for p in sorted(SCENES.glob("*.toml"))]
    started = vote.start_three(scenes, quick=True)
    why = dict(zip([s.name for s in scenes], started.why, strict=True))
    assert "shared light samples" in why["shape_lights"]
    assert sum(w is None for w in why.values()) >= 9   # the scenes the vote compares
