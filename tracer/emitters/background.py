"""``type = "background"``: the radiance a ray that hits nothing brings back, and nothing else.

A backdrop, L = ``radiance`` for a ray that hits nothing: in the classic
model's recursion (Whitted 1980; Heckbert's minray returns its ambient
colour for a ray that misses every sphere) a trace call whose ray leaves the
scene returns the background colour. It lights nothing (shading points do
not sample it: that would be Mitsuba's ``constant`` environment) and, like
everything else a trace call returns, it is a hit term: counted for rays the
tracer still shades, depth < max_depth (:mod:`tracer.emitters.base`), so
that max_depth = DEPTH + 1 reproduces Heckbert's DEPTH. Its Mitsuba
counterpart is the ``whitted_background`` emitter of
``reference/emitters/background.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.emitters import base
from whitted.tracer.settings import Table

Color = tuple[float, float, float]


@dataclass(frozen=True)
class Background(base.LightModel):
    radiance: Color  # brought back by rays that hit nothing


MODEL = Background


def parse(t: Table) -> Background:
    return Background(t.color("radiance"))


class Emitter(base.Emitter):
    infinite = True
    illuminates = False
    hit_term = True

    def __init__(self, light: Background):
        self.radiance = base.color(light.radiance)

    def sample(self, p, origin, u):
        raise NotImplementedError("a background lights nothing (illuminates = False)")

    def background(self, d):
        return self.radiance
