"""Print the tables of ``tracer/ior.py`` from Mitsuba 3's own data (run with Mitsuba installed).

Mitsuba 3 ships the complex refractive indices of its named conductors as
spectra, ``data/ior/<name>.eta.spd`` and ``<name>.k.spd`` (from the luxpop.com
database and Palik's "Handbook of Optical Constants of Solids"). Its RGB
variants reduce each spectrum to one linear sRGB triple when the ``conductor``
plugin is built (``spectrum_list_to_srgb``, unbounded, no illuminant: the
spectrum is integrated against the CIE 1931 colour-matching functions and the
XYZ result converted to linear sRGB). This script reads those triples back from
the plugin (``mi.traverse``), so the tracer uses exactly the values Mitsuba
renders with, and prints the named dielectric indices of Mitsuba's table the
same way (``int_ior`` of a ``dielectric`` with ``ext_ior = 1``).

    python docs/ior_tables.py > /tmp/ior.txt    # paste into tracer/ior.py
"""

from __future__ import annotations

import glob
import os

import numpy as np

DIELECTRIC_NAMES = ("vacuum", "helium", "hydrogen", "air", "carbon dioxide", "water",
                    "acetone", "ethanol", "carbon tetrachloride", "glycerol", "benzene",
                    "silicone oil", "bromine", "water ice", "fused quartz", "pyrex",
                    "acrylic glass", "polypropylene", "bk7", "sodium chloride", "amber",
                    "pet", "diamond")


def conductor_names(mi) -> list[str]:
    d = os.path.join(os.path.dirname(mi.__file__), "data", "ior")
    files = glob.glob(os.path.join(d, "*.k.spd"))
    return sorted({os.path.basename(f).split(".")[0] for f in files})


def conductor_rgb(mi, name: str):
    p = mi.traverse(mi.load_dict({"type": "conductor", "material": name}))
    return (tuple(round(float(x), 6) for x in np.ravel(p["eta.value"])),
            tuple(round(float(x), 6) for x in np.ravel(p["k.value"])))


def dielectric_ior(mi, name: str) -> float:
    p = mi.traverse(mi.load_dict({"type": "dielectric", "int_ior": name, "ext_ior": 1.0}))
    return round(float(np.ravel(p["eta"])[0]), 6)


def main() -> None:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    print(f"# Mitsuba {mi.__version__}")
    print("DIELECTRICS = {")
    for n in DIELECTRIC_NAMES:
        print(f"    {n!r}: {dielectric_ior(mi, n)!r},")
    print("}")
    print("CONDUCTORS = {")
    for n in conductor_names(mi):
        eta, k = conductor_rgb(mi, n)
        print(f"    {n!r}: ({eta!r}, {k!r}),")
    print("}")


if __name__ == "__main__":
    main()
