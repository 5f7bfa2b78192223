"""Mitsuba 3's named indices of refraction, as data.

The names a Mitsuba ``dielectric`` (``int_ior``/``ext_ior``) accepts instead of a
number, with Mitsuba's values (at 589 nm, 20 degrees C). Source: the table of
the ``dielectric`` plugin in Mitsuba 3's documentation ("Smooth dielectric
material"; ``include/mitsuba/render/ior.h``), which takes them from Mitsuba
0.5's ``ior.h``; tests/reference/renderers/mitsuba/test_import.py checks every entry against
``mi.load_dict`` of a dielectric with that name.
"""

from __future__ import annotations

#: name -> index of refraction
IOR: dict[str, float] = {
    "vacuum": 1.0,
    "helium": 1.000036,
    "hydrogen": 1.000132,
    "air": 1.000277,
    "carbon dioxide": 1.00045,
    "water": 1.333,
    "acetone": 1.36,
    "ethanol": 1.361,
    "carbon tetrachloride": 1.461,
    "glycerol": 1.4729,
    "benzene": 1.501,
    "silicone oil": 1.52045,
    "bromine": 1.661,
    "water ice": 1.31,
    "fused quartz": 1.458,
    "pyrex": 1.47,
    "acrylic glass": 1.49,
    "polypropylene": 1.49,
    "bk7": 1.5046,
    "sodium chloride": 1.544,
    "amber": 1.55,
    "pet": 1.575,
    "diamond": 2.419,
}
