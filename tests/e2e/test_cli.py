"""The command line: outputs, help, exit codes, and that `render` never touches Mitsuba."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import MINIMAL, ROOT, run_cli, write_scene

from whitted.tracer.imageio import read_exr


def test_help_explains_every_subcommand():
    r = run_cli("--help")
    assert r.returncode == 0
    for cmd in ("render", "reference", "compare", "export", "scenes"):
        assert cmd in r.stdout
        sub = run_cli(cmd, "--help")
        assert sub.returncode == 0 and "usage: whitted " + cmd in sub.stdout
    render_help = run_cli("render", "--help").stdout
    for opt in ("--spp", "--max-depth", "--size", "--backend", ".exr", ".png", ".ppm"):
        assert opt in render_help


def test_installed_console_script_runs():
    exe = ROOT / ".venv" / "bin" / "whitted"
    cmd = [str(exe)] if exe.exists() else ["whitted"]
    r = subprocess.run(cmd + ["--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.startswith("whitted ")


def test_render_writes_exr_png_and_ppm(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    for ext in ("exr", "png", "ppm"):
        r = run_cli("render", scene, "-o", tmp_path / f"img.{ext}", "--size", "16x12",
                    "--spp", "4")
        assert r.returncode == 0, r.stderr
        assert "rays per level" in r.stdout
    img = read_exr(tmp_path / "img.exr")
    assert img.shape == (12, 16, 3) and img.dtype == np.float32 and img.max() > 0
    from PIL import Image

    png = np.asarray(Image.open(tmp_path / "img.png"))
    assert png.shape == (12, 16, 3) and png.dtype == np.uint8
    # sRGB-encoded: the PNG equals the EXR through the sRGB curve.
    from whitted.tracer.imageio import to_srgb8

    assert np.array_equal(png, to_srgb8(img))
    lines = (tmp_path / "img.ppm").read_text().splitlines()
    assert lines[:3] == ["P3", "16 12", "255"] and len(lines) == 3 + 16 * 12
    assert re.fullmatch(r"\d+ \d+ \d+", lines[3])
    first = np.clip(img[0, 0] * 255, 0, 255)
    assert [int(x) for x in lines[3].split()] == [int(f"{v:.0f}") for v in first]


def test_render_path_never_imports_mitsuba(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    code = ("import sys\nfrom whitted.reference.cli import main\n"
            f"rc = main(['render', {str(scene)!r}, '-o', {str(tmp_path / 'x.exr')!r}])\n"
            "assert rc == 0, rc\n"
            "assert 'mitsuba' not in sys.modules, 'render imported mitsuba'\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr


def test_size_spp_and_depth_options_override_the_scene(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    r = run_cli("render", scene, "-o", tmp_path / "x.exr", "--size", "10x7", "--spp", "9",
                "--max-depth", "1")
    assert r.returncode == 0, r.stderr
    assert "10x7, 9 spp, max_depth 1" in r.stdout
    # max_depth 1 sees only emitters: no area light here, so the image is black.
    assert read_exr(tmp_path / "x.exr").max() == 0


@pytest.mark.parametrize("args,words", [
    (["render", "x.toml", "-o", "y.exr", "--size", "12"], "WIDTHxHEIGHT"),
    (["render", "x.toml", "-o", "y.exr", "--spp", "0"], "positive integer"),
    (["render", "x.toml"], "required"),
    (["compare", "x.toml", "--integrator", "bogus"], "invalid choice"),
    (["compare", "x.toml", "--reference", "bogus"], "invalid choice"),
])
def test_bad_options_exit_2(args, words):
    r = run_cli(*args)
    assert r.returncode == 2 and words in r.stderr


def test_compare_writes_outputs_and_exits_0_within_tolerance(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    out = tmp_path / "cmp"
    r = run_cli("compare", scene, "-o", out, "--size", "32x24", "--spp", "16")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "PASS" in r.stdout and "median rel. difference" in r.stdout
    m = json.loads((out / "metrics.json").read_text())
    for key in ("rmse", "mean_rel", "max_rel", "frac_over_5pct", "flip"):
        assert key in m["metrics"]
    assert set(m["seconds"]) >= {"tracer", "mitsuba"}
    assert m["test"] == "exact-strata" and m["passed"] is True
    assert m["reference"] == "deterministic" and m["second_opinion"] is None
    assert (out / "diff.png").stat().st_size > 0


def test_compare_names_its_reference_and_keeps_the_older_integrator_option(tmp_path):
    from whitted.reference import cli

    scene = write_scene(tmp_path, MINIMAL)
    for args, reference in ((["--integrator", "whitted"], "onelobe"),
                            (["--reference", "onelobe"], "onelobe"),
                            (["--integrator", "direct"], "direct")):
        out = tmp_path / reference / args[0]
        assert cli.main(["compare", str(scene), "-o", str(out), "--size", "16x12",
                         "--spp", "4", *args]) == 0
        m = json.loads((out / "metrics.json").read_text())
        assert m["reference"] == reference
    r = run_cli("compare", scene, "--integrator", "whitted", "--reference", "deterministic")
    assert r.returncode == 2 and "contradicts" in r.stderr


def test_reference_command_renders_the_deterministic_reference(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    r = run_cli("reference", scene, "-o", tmp_path / "d.exr", "--integrator", "deterministic",
                "--size", "16x12", "--spp", "4")
    assert r.returncode == 0, r.stderr
    assert read_exr(tmp_path / "d.exr").max() > 0


def test_compare_exits_1_when_the_tracer_is_wrong(tmp_path, monkeypatch, capsys):
    # A tracer with a 3 % gain error: the comparison must catch it.
    from whitted.reference import cli
    from whitted.tracer import integrator

    original = integrator.Integrator.render

    def biased(self, *a, **k):
        res = original(self, *a, **k)
        res.image = res.image * 1.03
        return res

    monkeypatch.setattr(integrator.Integrator, "render", biased)
    scene = write_scene(tmp_path, MINIMAL)
    rc = cli.main(["compare", str(scene), "-o", str(tmp_path / "c"), "--size", "32x24",
                   "--spp", "4"])
    assert rc == 1
    assert "FAIL" in capsys.readouterr().out


def test_export_writes_xml(tmp_path):
    scene = write_scene(tmp_path, MINIMAL)
    r = run_cli("export", scene, "-o", tmp_path / "s.xml")
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "s.xml").read_text()
    assert '<integrator type="whitted">' in text and '<sampler type="stratified">' in text
    assert '<boolean name="jitter" value="false"/>' in text and '<rfilter type="box">' in text


def test_builtin_scene_names_resolve(tmp_path):
    r = run_cli("render", "sphere_point", "-o", tmp_path / "x.png", "--size", "8x6",
                "--spp", "1")
    assert r.returncode == 0, r.stderr
    r = run_cli("scenes")
    assert r.returncode == 0 and "sphere_point" in r.stdout
