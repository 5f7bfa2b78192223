"""Conversion of ``projector`` lights (tracer/emitters/projector.py): Mitsuba's ``projector``.

Its ``irradiance`` texture, ``scale``, ``fov`` and ``fov_axis`` as the file gives them
(Mitsuba converts the field of view from the texture's resolution itself), and its
``to_world`` as the file's steps, composed by Mitsuba
(:mod:`reference.renderers.mitsuba.transforms`). LuxCore has no equivalent here: the
conversion is refused in one line (:func:`reference.emitters.convert`).
"""

from __future__ import annotations

from whitted.reference.materials.textures import texture_tree
from whitted.reference.renderers.mitsuba import transforms
from whitted.tracer.emitters.projector import Projector


def mitsuba(light: Projector) -> dict:
    return {"type": "projector", "irradiance": texture_tree(light.irradiance),
            "scale": ("float", light.scale), "fov": ("float", light.fov),
            "fov_axis": ("string", light.fov_axis),
            "to_world": transforms.tree(transforms.of(light))}
