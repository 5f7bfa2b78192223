"""Mitsuba conversion of ``conductor`` (tracer/materials/conductor.py): Mitsuba's ``conductor``.

The indices are passed as ``eta`` and ``k`` colours (a named conductor's
values are those Mitsuba's RGB variants compute for that name,
:mod:`tracer.ior`), wrapped in ``twosided`` unless ``two_sided = false``.
"""

from __future__ import annotations

from whitted.reference.materials.textures import texture_tree
from whitted.reference.renderers.mitsuba.tree import rgb
from whitted.tracer.materials.conductor import Conductor


def one_sided(m: Conductor) -> dict:
    return {"type": "conductor", "eta": rgb(m.eta), "k": rgb(m.k),
            "specular_reflectance": texture_tree(m.specular_reflectance)}


def mitsuba(m: Conductor) -> dict:
    bsdf = one_sided(m)
    return {"type": "twosided", "material": bsdf} if m.two_sided else bsdf
