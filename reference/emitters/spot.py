"""Mitsuba conversion of ``spot`` lights (tracer/emitters/spot.py).

Mitsuba's ``spot`` points along +z of its ``to_world``: a look-at frame from
the position to the target; ``cutoff_angle`` and ``beam_width`` mean the same.

LuxCore's ``spot`` (:func:`luxcore`): ``coneangle`` = cutoff_angle,
``conedeltaangle`` = cutoff_angle - beam_width, intensity gain * color W/sr on the
axis (no 1 / (4 pi), unlike its point light; measured: 4 pi too bright with
the point light's gain). Inside the beam and
beyond the cutoff it is the same light. Between them its profile is not
Mitsuba's: pbrt-v1's smooth step, ((cos theta - cos cutoff) / (cos beam -
cos cutoff))^4, where Mitsuba's and the tracer's fall linearly in the angle
(lecture 1, "Spot lights"). The comparison shows that ring as LuxCore's
difference (README, "LuxCore").
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


def luxcore(light: SpotLight) -> dict:
    return {"type": "spot", "position": tuple(light.position), "target": tuple(light.target),
            "color": tuple(light.intensity), "gain": (1.0, 1.0, 1.0), "power": 0.0,
            "efficiency": 0.0, "coneangle": light.cutoff_angle,
            "conedeltaangle": light.cutoff_angle - light.beam_width}
