"""Mitsuba conversion of ``spot`` lights (tracer/emitters/spot.py).

Mitsuba's ``spot`` points along +z of its ``to_world``: a look-at frame from
the position to the target (:meth:`SpotLight.frame`); ``cutoff_angle``,
``beam_width`` and ``texture`` mean the same.

LuxCore's ``spot`` (:func:`luxcore`): ``coneangle`` = cutoff_angle,
``conedeltaangle`` = cutoff_angle - beam_width, intensity gain * color W/sr on the
axis (no 1 / (4 pi), unlike its point light; measured: 4 pi too bright with
the point light's gain). Beyond the cutoff both are dark; inside the beam
LuxCore's is brighter by 1 / cos theta (measured with
tests/data/luxcore/spot_probe.toml: 1.0127 at 9.1 degrees). Between them its profile is not
Mitsuba's: pbrt-v1's smooth step, ((cos theta - cos cutoff) / (cos beam -
cos cutoff))^4, where Mitsuba's and the tracer's fall linearly in the angle
(lecture 1, "Spot lights"). The comparison shows that ring as LuxCore's
difference (README, "LuxCore"). A textured spot is refused.
"""

from __future__ import annotations

import numpy as np

from whitted.reference.materials.textures import texture_tree
from whitted.reference.renderers.mitsuba import transforms
from whitted.reference.renderers.mitsuba.tree import any_up, rgb
from whitted.tracer.emitters.spot import SpotLight
from whitted.tracer.errors import UserError


def mitsuba(light: SpotLight) -> dict:
    tree = {"type": "spot",
            # Mitsuba's look_at from the position to the target, as the file gives them
            "to_world": transforms.tree(transforms.lookat_step(
                light.position, light.target,
                any_up(np.subtract(light.target, light.position)))),
            "intensity": rgb(light.intensity),
            "cutoff_angle": ("float", light.cutoff_angle),
            "beam_width": ("float", light.beam_width)}
    if light.texture is not None:
        tree["texture"] = texture_tree(light.texture)
    return tree


def luxcore(light: SpotLight) -> dict:
    if light.texture is not None:
        raise UserError("a textured spot light has no LuxCore equivalent here")
    return {"type": "spot", "position": tuple(light.position), "target": tuple(light.target),
            "color": tuple(light.intensity), "gain": (1.0, 1.0, 1.0), "power": 0.0,
            "efficiency": 0.0, "coneangle": light.cutoff_angle,
            "conedeltaangle": light.cutoff_angle - light.beam_width}
