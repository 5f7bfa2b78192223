"""The built-in scenes: their TOML files, meshes and textures, and the Mitsuba scenes of the
report's "imported" group, found as package data (``importlib.resources``), so that an
installed ``whitted`` finds them from any folder.

``whitted scenes`` lists :func:`builtin_scenes`; a command given a scene's name
(``glass_sphere``) reads ``SCENES_DIR / "glass_sphere.toml"`` (:func:`resolve`), and so
does :func:`whitted.tracer.load_scene`.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

#: the folder of the built-in scenes (package data of ``whitted.scenes``)
SCENES_DIR = Path(str(resources.files(__name__)))

#: scenes copied unchanged from Mitsuba 3's data repository (see its README.md)
MITSUBA_DATA_DIR = SCENES_DIR / "mitsuba-data"


def builtin_scenes() -> list[Path]:
    """The built-in scenes' files, sorted by name."""
    return sorted(SCENES_DIR.glob("*.toml"))


def resolve(name: str | os.PathLike) -> Path:
    """A scene path as given, or a built-in scene's name (``glass_sphere``:
    ``SCENES_DIR / "glass_sphere.toml"``) where no such file exists and the name has no
    suffix or folder."""
    p = Path(name)
    text = os.fspath(name)
    try:
        if p.exists() or p.suffix == ".toml" or os.sep in text:
            return p
        builtin = SCENES_DIR / f"{text}.toml"
        return builtin if builtin.exists() else p
    except (OSError, ValueError):  # a name too long, or with a NUL: the loader says why
        return p
