"""Mitsuba conversion of ``spot`` lights (tracer/emitters/spot.py).

Mitsuba's ``spot`` points along +z of its ``to_world``: a look-at frame from
the position to the target; ``cutoff_angle`` and ``beam_width`` mean the same.
"""

from __future__ import annotations

from reference.mitsuba_tree import any_up, matrix, rgb
from tracer import transform as tf
from tracer.emitters.spot import SpotLight


def mitsuba(light: SpotLight) -> dict:
    return {"type": "spot",
            "to_world": matrix(tf.look_at(light.position, light.target, any_up(light.axis))),
            "intensity": rgb(light.intensity),
            "cutoff_angle": ("float", light.cutoff_angle),
            "beam_width": ("float", light.beam_width)}
