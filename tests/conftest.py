"""Shared fixtures: the backend (``--backend llvm|cuda``), Mitsuba, and running the CLI.

``tracer`` is imported before anything else so that a usable libLLVM is chosen
before Dr.Jit loads.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from whitted import tracer  # noqa: F401  (must precede drjit)

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"

# The tests mirror the packages (tests/tracer/, tests/reference/<role>/, tests/e2e/,
# tests/project/); a few share helpers across folders by module name (test_bvh's rays,
# test_fuzz's scenes, test_new_kinds' masks), so every test folder is on the path.
for _folder in sorted(p for p in Path(__file__).resolve().parent.rglob("*")
                      if p.is_dir() and p.name not in ("data", "__pycache__")
                      and "data" not in p.relative_to(Path(__file__).resolve().parent).parts):
    if str(_folder) not in sys.path:
        sys.path.append(str(_folder))


def jit_kernels(fn) -> list[dict]:
    """Dr.Jit's records of the JIT kernels ``fn()`` launches, in order (its kernel history,
    on for the call only; a record's "hash", "operation_count", "ir", "cache_hit"...)."""
    import drjit as dr

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()  # clears it
    try:
        fn()
        return [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


def pytest_addoption(parser):
    parser.addoption("--backend", default=None, choices=("auto", "llvm", "cuda"),
                     help="Dr.Jit backend for the tests (default: WHITTED_BACKEND or auto)")


def pytest_configure(config):
    b = config.getoption("--backend")
    if b:
        os.environ["WHITTED_BACKEND"] = b
    # whitted check's images of scenes with a formula bug: kept for the run, not in ~/.cache
    if not os.environ.get("WHITTED_SUSPECTS_CACHE"):
        import tempfile

        os.environ["WHITTED_SUSPECTS_CACHE"] = tempfile.mkdtemp(prefix="whitted-suspects-")
        config._whitted_suspects_cache = os.environ["WHITTED_SUSPECTS_CACHE"]


def pytest_unconfigure(config):
    made = getattr(config, "_whitted_suspects_cache", None)
    if made:
        import shutil

        shutil.rmtree(made, ignore_errors=True)
        os.environ.pop("WHITTED_SUSPECTS_CACHE", None)


@pytest.fixture(scope="session")
def jit():
    """The array types of the selected backend (drjit.llvm or drjit.cuda)."""
    from whitted.tracer import backend

    backend.use()
    return backend.jit


@pytest.fixture(scope="session")
def mi():
    """Mitsuba with the variant of the selected backend and our plugins registered."""
    from whitted.reference import mitsuba

    return mitsuba()


def run_cli(*args, env=None, cwd=None, timeout=600):
    """Run ``whitted`` in a fresh interpreter; return the CompletedProcess."""
    full_env = dict(os.environ)
    if env:
        full_env.update(env)
    return subprocess.run([sys.executable, "-m", "whitted.reference.cli", *map(str, args)],
                          capture_output=True, text=True, env=full_env, cwd=cwd or ROOT,
                          timeout=timeout)


def sweep_without_seconds(data: dict) -> dict:
    """A formula-bug sweep's JSON (reference.mutants.SweepResult.to_json) without its
    times, which differ from run to run."""
    out = {k: v for k, v in data.items() if k != "seconds"}
    out["scenes"] = [{k: v for k, v in s.items() if k != "seconds"} for s in data["scenes"]]
    out["mutants"] = [{k: v for k, v in m.items() if k != "seconds"} for m in data["mutants"]]
    return out


def approx_floats(data, rel: float):
    """``data`` (dicts, lists, numbers) with every float as ``pytest.approx(x, rel=rel)``,
    to compare with ``==`` (pytest.approx itself takes no nested structures)."""
    import pytest

    if isinstance(data, dict):
        return {k: approx_floats(v, rel) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [approx_floats(v, rel) for v in data]
    if isinstance(data, float):
        return pytest.approx(data, rel=rel, nan_ok=True)
    return data


def write_scene(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


MINIMAL = """
[film]
width = 8
height = 6
spp = 1
max_depth = 2

[camera]
origin = [0, 0, 5]
target = [0, 0, 0]

[materials.white]
type = "diffuse"
reflectance = 0.5

[[lights]]
type = "point"
position = [0, 3, 3]
intensity = 10

[[shapes]]
type = "sphere"
center = [0, 0, 0]
radius = 1
material = "white"
"""
