"""Mitsuba conversion of ``spot`` lights (tracer/emitters/spot.py).

Mitsuba's ``spot`` points along +z of its ``to_world``: a look-at frame from
the position to the target (:meth:`SpotLight.frame`); ``cutoff_angle``,
``beam_width`` and ``texture`` mean the same.
"""

from __future__ import annotations

from reference.materials.textures import texture_tree
from reference.mitsuba_tree import matrix, rgb
from tracer.emitters.spot import SpotLight


def mitsuba(light: SpotLight) -> dict:
    tree = {"type": "spot",
            "to_world": matrix(light.frame()),
            "intensity": rgb(light.intensity),
            "cutoff_angle": ("float", light.cutoff_angle),
            "beam_width": ("float", light.beam_width)}
    if light.texture is not None:
        tree["texture"] = texture_tree(light.texture)
    return tree
