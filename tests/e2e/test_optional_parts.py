"""The report never fails for an optional part: LuxCore missing, failing or slow.

LuxCore's vote never changes the report's verdict (the tracer's against Mitsuba), so
neither may LuxCore's absence, its failure or its time limits: the report is written,
says "not available: <why>" in index.html, report.md and report.json (and in one line
on stderr), and exits with the tracer's status. WHITTED_REQUIRE_LUXCORE=1 (CI) makes
LuxCore's tests fail without it (tests/reference/renderers/luxcore/test_luxcore.py), not the report.

Each report here is one glass scene at the quick sizes, without the Fresnel curves.
"""

import html
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from whitted.reference import cli
from whitted.reference.renderers.luxcore import render as lx
from whitted.tracer import load_scene
from whitted.tracer.errors import UserError

ROOT = Path(__file__).resolve().parents[2]
REPORT = ["report", "--scenes", "glass_sphere", "--quick", "--no-fresnel"]


@pytest.fixture
def luxcore():
    if not lx.available():
        if os.environ.get("WHITTED_REQUIRE_LUXCORE") == "1":
            pytest.fail("pyluxcore is required here (WHITTED_REQUIRE_LUXCORE=1) but missing")
        pytest.skip("pyluxcore is not installed: pip install 'whitted[luxcore]'")
    return lx


def _report(tmp_path, capsys):
    out = tmp_path / "report"
    rc = cli.main([*REPORT[:1], "-o", str(out), *REPORT[1:]])
    return rc, out, capsys.readouterr().err


def _reports_not_available(rc: int, out: Path, err: str, why: str) -> None:
    """The report's exit status is the tracer's, its three files are written, and each
    says that LuxCore is not available and why; stderr says it in one line."""
    data = json.loads((out / "report.json").read_text())
    assert data["pass"] is True and rc == 0       # glass_sphere passes against Mitsuba
    assert why in data["not_available"]["luxcore"]
    assert all("luxcore" not in s for s in data["scenes"])
    for name in ("index.html", "report.md"):
        text = html.unescape((out / name).read_text())
        assert "not available" in text and why in text, name
    lines = [line for line in err.splitlines() if "not available" in line]
    assert len(lines) == 1 and why in lines[0], err


def test_missing_luxcore_is_not_available_and_the_report_passes(
        tmp_path, capsys, monkeypatch):
    """Even under WHITTED_REQUIRE_LUXCORE=1: that is the tests' requirement, not the
    report's."""
    monkeypatch.setattr(lx, "available", lambda: False)
    monkeypatch.setenv("WHITTED_REQUIRE_LUXCORE", "1")
    rc, out, err = _report(tmp_path, capsys)
    _reports_not_available(rc, out, err, "LuxCore is not installed")


def test_a_luxcore_pass_past_its_cpu_limit_is_not_available_and_the_report_passes(
        luxcore, tmp_path, capsys, monkeypatch):
    """The real child, its passes given a microsecond of CPU time: it exits with its
    reason, which reaches the report whole (the child's log is read through a handle of
    its own)."""
    monkeypatch.setattr(lx, "pass_cpu_limit", lambda *a, **k: 1e-6)
    monkeypatch.setenv("WHITTED_REQUIRE_LUXCORE", "1")
    rc, out, err = _report(tmp_path, capsys)
    _reports_not_available(rc, out, err, "took more than 1e-06 s of CPU time")


def test_a_bad_timeout_variable_is_not_available_and_the_report_passes(
        luxcore, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("WHITTED_LUXCORE_TIMEOUT", "soon")
    rc, out, err = _report(tmp_path, capsys)
    _reports_not_available(rc, out, err, "WHITTED_LUXCORE_TIMEOUT='soon'")


def test_waiting_past_the_timeout_variable_is_one_line_naming_it(luxcore, monkeypatch):
    """The caller's wait: WHITTED_LUXCORE_TIMEOUT seconds from when it starts waiting."""
    monkeypatch.setenv("WHITTED_LUXCORE_TIMEOUT", "1e-9")
    scene = load_scene(ROOT / "scenes" / "sphere_point.toml").with_overrides(size=(8, 6))
    job = luxcore.start_many([scene], passes=1)
    with pytest.raises(UserError, match=r"time limit of 1e-09 s .*WHITTED_LUXCORE_TIMEOUT"):
        job.results()
    assert job.proc.poll() is not None and not job.tmp.exists()


def test_time_limits_follow_the_work_and_the_variable(monkeypatch):
    monkeypatch.delenv("WHITTED_LUXCORE_TIMEOUT", raising=False)
    assert lx.wait_limit(4) == lx.STARTUP_TIMEOUT + 4 * lx.PASS_TIMEOUT
    assert lx.pass_cpu_limit((1024, 768)) == lx.PASS_CPU_FLOOR      # a report's film
    big = lx.pass_cpu_limit((4096, 3072))
    assert big == pytest.approx(4096 * 3072 * lx.PASS_CPU_PER_SAMPLE) and big > 60
    monkeypatch.setenv("WHITTED_LUXCORE_TIMEOUT", "120")
    assert lx.wait_limit(4) == 120
    for bad in ("0", "-1", "nan", "inf", "soon"):
        monkeypatch.setenv("WHITTED_LUXCORE_TIMEOUT", bad)
        with pytest.raises(UserError, match="WHITTED_LUXCORE_TIMEOUT"):
            lx.wait_limit(4)


class _FakeLuxCore:
    """pyluxcore's few calls that reference.renderers.luxcore.runner.run_job makes; a pass is done
    after ``wall`` seconds of sleep (no CPU time) and ``cpu`` seconds of spinning."""

    def __init__(self, wall: float, cpu: float):
        fake = self

        class Session:
            def __init__(self, config):
                self.start = None

            def Start(self):
                self.start = time.monotonic()

            def UpdateStats(self):
                if fake.cpu:
                    t = time.process_time()
                    while time.process_time() - t < 0.01:
                        pass

            def HasDone(self):
                return time.monotonic() - self.start > fake.wall + fake.cpu

            def Stop(self):
                pass

            def GetFilm(self):
                return self

            def GetOutputFloat(self, kind, img):
                img[...] = 1.0

            def GetStats(self):
                return self

            def Get(self, name):
                return self

            def GetInt(self):
                return 1

        class Properties:
            def SetFromString(self, text):
                pass

        class Scene:
            def Parse(self, props):
                pass

        self.wall, self.cpu = wall, cpu
        self.Scene, self.Properties, self.RenderSession = Scene, Properties, Session
        self.RenderConfig = lambda cfg, scene: None
        self.FilmOutputType = type("FilmOutputType", (), {"RGB": 0})


def _job(tmp_path, pass_cpu: float) -> str:
    path = tmp_path / "job0.npz"
    np.savez(path, props=np.array(""), config=np.array("renderengine.seed = @SEED@\n"),
             film=np.array([4, 4]), seeds=np.array([0], dtype=np.int64),
             subsamples=np.array(2), pass_cpu=np.array(pass_cpu))
    return str(path)


def test_a_pass_is_limited_by_its_cpu_time_not_by_the_wall_clock(tmp_path, capsys):
    """A pass that waits 1 s for a core (here: sleeps) uses no CPU time and is within a
    0.3 s limit; one that spins 0.5 s is not. At nice 19 beside a busy machine a pass
    may wait minutes, which a wall-clock limit took for LuxCore being slow."""
    from whitted.reference.renderers.luxcore.runner import run_job

    run_job(_FakeLuxCore(wall=1.0, cpu=0.0), _job(tmp_path, 0.3))
    with np.load(tmp_path / "job0.out.npz") as out:
        assert out["sums"].shape == (1, 2, 2, 3) and np.all(out["sums"] == 4)
    with pytest.raises(SystemExit, match="took more than 0.3 s of CPU time"):
        run_job(_FakeLuxCore(wall=0.0, cpu=5.0), _job(tmp_path, 0.3))


#: Seconds the saturated report waits for LuxCore at the most (WHITTED_LUXCORE_TIMEOUT).
SATURATED_WAIT = 10


def test_a_tiny_report_passes_while_the_cpu_is_saturated(tmp_path):
    """Two busy loops (this machine's cores) for the whole report. LuxCore's child, at
    the lowest priority, gets almost no CPU: it either votes or is not available within
    SATURATED_WAIT seconds of waiting; either way the report passes and is written."""
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(2)]
    try:
        out = tmp_path / "report"
        r = subprocess.run([sys.executable, "-m", "whitted.reference.cli", REPORT[0], "-o",
                            str(out), *REPORT[1:]], capture_output=True, text=True, timeout=240,
                           cwd=ROOT, env={**os.environ,
                                          "WHITTED_LUXCORE_TIMEOUT": str(SATURATED_WAIT)})
    finally:
        for p in busy:
            p.send_signal(signal.SIGKILL)
            p.wait()
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert (out / "index.html").exists()
    data = json.loads((out / "report.json").read_text())
    assert data["pass"] is True
    voted = all("luxcore" in s for s in data["scenes"])
    assert voted != ("luxcore" in data["not_available"]) or not lx.available()
    assert sum("not available" in line for line in r.stderr.splitlines()) <= 1
