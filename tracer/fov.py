"""The horizontal field of view of a perspective camera or projector, from ``fov`` along
``fov_axis``.

Mitsuba's conversion (``parse_fov`` in its ``include/mitsuba/render/sensor.h``, which its
``perspective`` sensor and ``projector`` emitter share): the image plane at distance 1
spans 2 tan(fov_x / 2) across and 2 tan(fov_x / 2) / aspect down, so a vertical fov_y
gives tan(fov_x / 2) = aspect tan(fov_y / 2), and a diagonal one tan(fov_x / 2) =
tan(fov_d / 2) / sqrt(1 + 1 / aspect^2); "smaller" and "larger" name the film's smaller
or larger side.
"""

from __future__ import annotations

import math

from whitted.tracer import faults

#: The values of ``fov_axis``.
FOV_AXES = ("x", "y", "diagonal", "smaller", "larger")


def horizontal(fov: float, axis: str, aspect: float) -> float:
    """The horizontal field of view in degrees of ``fov`` degrees along ``axis`` for a
    film (or a projected image) of ``aspect`` = width / height."""
    if axis == "smaller":
        axis = "y" if aspect > 1 else "x"
    elif axis == "larger":
        axis = "x" if aspect > 1 else "y"
    t = math.tan(math.radians(fov) / 2)
    if axis == "y":
        t = t / aspect if faults.on("fov-y-divided") else t * aspect
    elif axis == "diagonal":
        t /= math.sqrt(1 + 1 / (aspect * aspect))
    return math.degrees(2 * math.atan(t))
