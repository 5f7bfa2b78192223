"""The comparison's power and false alarms on real Mitsuba scenes it was not tuned on.

Every stored real scene (``tests/data/real_scenes``) that imports as it stands is
imported (``whitted import``) into a folder of TOML scenes, and ``whitted mutants
--scenes-dir`` runs the formula-bug sweep over them at quick sizes: the tracer as
written must pass each (a failure is a false alarm), and each bug of the catalog is
judged on the scenes whose render reaches its switch. Prints the sweep's table, then
how many (scene, bug) pairs that reach each other the verdicts catch, and which bugs a
reaching scene never catches. Usage (from the repository root; about 6 minutes on two
cores)::

    .venv/bin/python benchmarks/real_power.py [-o OUT]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WHITTED = str(Path(sys.executable).with_name("whitted"))


def as_they_stand() -> list[Path]:
    """The stored real scenes that import without ``--approximate``."""
    from whitted.tracer.errors import UserError
    from whitted.tracer.mitsuba_xml import read_xml
    from whitted.tracer.scene import parse_scene

    out = []
    for p in sorted((ROOT / "tests" / "data" / "real_scenes").rglob("*.xml")):
        if "fragments" in p.parts or "include" in p.parts:
            continue
        try:
            parse_scene(read_xml(p).data, str(p))
        except UserError:
            continue
        out.append(p)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", help="keep the imports and mutants.json here")
    args = ap.parse_args(argv)
    out = Path(args.output or tempfile.mkdtemp(prefix="whitted-real-power-"))
    scenes = out / "scenes"
    scenes.mkdir(parents=True, exist_ok=True)
    for p in as_they_stand():
        name = f"{p.parent.name}__{p.stem}.toml"
        subprocess.run([WHITTED, "import", str(p), "-o", str(scenes / name)], check=True,
                       capture_output=True)
    print(f"{len(list(scenes.glob('*.toml')))} real scenes imported as they stand", flush=True)
    subprocess.run([WHITTED, "mutants", "--scenes-dir", str(scenes), "-o", str(out)])
    data = json.loads((out / "mutants.json").read_text())
    reached = caught = 0
    never = []
    for m in data["mutants"]:
        c, p = len(m["caught_by"]), len(m["passed"])
        reached, caught = reached + c + p, caught + c
        if p and not c:
            never.append(f"{m['id']} ({p} scene{'s' if p > 1 else ''})")
    clean = sum(s["passed"] for s in data["scenes"])
    print(f"\ntracer as written: {clean} of {len(data['scenes'])} pass (the rest: false alarms)")
    print(f"bugs caught by some real scene: {sum(bool(m['caught_by']) for m in data['mutants'])}"
          f" of {len(data['mutants'])}")
    print(f"(scene, bug) pairs where the scene's render reaches the bug: {reached}; "
          f"caught: {caught} ({100 * caught / max(reached, 1):.0f} %)")
    print("reached but never caught: " + (", ".join(never) or "none"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
