"""whitted as a user installs it: one top-level name, the built-in scenes as package data,
and every command working from any folder after ``pip install`` of the wheel.

The repository keeps its folders (tracer/, reference/, scenes/); pyproject.toml maps them
to whitted.tracer, whitted.reference and whitted.scenes (docs/install.md).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = {"tracer": "whitted.tracer", "reference": "whitted.reference",
           "scenes": "whitted.scenes"}


def _package_folders() -> set[str]:
    """Every folder of the repository's packages that Python can import, as installed names."""
    out = set()
    for folder, name in FOLDERS.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder)
            if "__pycache__" in rel.parts:
                continue
            out.add(".".join((name, *rel.parts)))
    return out


def test_pyproject_lists_every_package_folder():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert set(config["packages"]) == _package_folders()
    assert config["package-dir"] == {name: folder for folder, name in FOLDERS.items()}


def test_builtin_scenes_are_found_as_package_data():
    from whitted.scenes import MITSUBA_DATA_DIR, SCENES_DIR, builtin_scenes

    names = {p.stem for p in builtin_scenes()}
    assert {"glass_sphere", "mesh_knot", "textured"} <= names
    assert (SCENES_DIR / "meshes" / "knot.ply").is_file()
    assert (MITSUBA_DATA_DIR / "common" / "meshes" / "sphere.obj").is_file()


def _run(cmd, cwd, env, timeout=600):
    r = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True,
                       text=True, timeout=timeout)
    assert r.returncode == 0, (cmd, r.stdout[-2000:], r.stderr[-2000:])
    return r


def test_wheel_installed_in_a_fresh_environment_works_from_any_folder(tmp_path):
    """Build the sdist and the wheel, install the wheel into a new virtual environment
    (its dependencies from the package index or pip's cache), and run the commands from
    a folder outside the checkout, with a home of its own and no PYTHONPATH."""
    dist = tmp_path / "dist"
    _run([sys.executable, "-m", "build", "--sdist", "--wheel", "--outdir", dist, ROOT],
         cwd=tmp_path, env=dict(os.environ))
    wheel = next(dist.glob("whitted-*.whl"))
    sdist = next(dist.glob("whitted-*.tar.gz"))

    names = zipfile.ZipFile(wheel).namelist()
    # one top-level name of its own: no `tracer` or `reference` beside other projects
    assert {n.split("/")[0] for n in names} == {"whitted", wheel.name.split("-py")[0]
                                                + ".dist-info"}
    assert "whitted/scenes/glass_sphere.toml" in names
    assert "whitted/scenes/meshes/knot.ply" in names
    import tarfile
    with tarfile.open(sdist) as t:
        assert any(n.endswith("scenes/textures/tiles.png") for n in t.getnames())

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv], cwd=tmp_path, env=dict(os.environ))
    py, whitted = venv / "bin" / "python", venv / "bin" / "whitted"
    _run([py, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", wheel],
         cwd=tmp_path, env=dict(os.environ))

    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "HOME": str(work),
           "LANG": "C.UTF-8", "WHITTED_BACKEND": "llvm"}
    assert _run([whitted, "--version"], work, env).stdout.startswith("whitted ")
    listed = _run([whitted, "scenes"], work, env).stdout
    assert "glass_sphere" in listed and "mesh_knot" in listed
    _run([whitted, "compare", "glass_sphere", "--size", "40x30", "--spp", "16", "-o", "cmp"],
         work, env)
    assert (work / "cmp" / "metrics.json").is_file()
    _run([whitted, "render", "glass_sphere", "--size", "40x30", "--spp", "4", "-o", "g.exr"],
         work, env)
    _run([whitted, "check", "g.exr", "--scene", "glass_sphere", "--size", "40x30",
          "--spp", "4", "-o", "ck"], work, env)
    # the README's two lines, with the installed names; the checkout's names are absent
    code = ("from whitted.tracer import load_scene, render\n"
            "img = render(load_scene('glass_sphere').with_overrides(size=(8, 6), spp=1))"
            ".image\n"
            "assert img.shape == (6, 8, 3)\n"
            "import importlib.util\n"
            "assert importlib.util.find_spec('tracer') is None\n"
            "assert importlib.util.find_spec('reference') is None\n"
            "import whitted.tracer\n"
            f"assert {str(ROOT)!r} not in whitted.tracer.__file__\n")
    _run([py, "-c", code], work, env)
