"""Mitsuba conversion of ``background`` (tracer/emitters/background.py): ``whitted_background``.

Mitsuba's ``constant`` emitter is seen by escaping rays and also lights
every shading point (its integrators sample it); the classic model's
backdrop is only seen. So this emitter is written on Mitsuba's API: an
infinite emitter (Mitsuba makes it the scene's environment, which rays that
hit nothing evaluate) whose ``eval`` is the radiance and whose
``sample_direction`` returns weight 0 with pdf 0, so no integrator lights a
point with it. It is a hit term (``hit_term = True``, see
:mod:`tracer.emitters.base`): both of the harness's references count it
only for rays that would still be shaded (:mod:`reference.renderers.mitsuba.shading`), as
minray's trace returns its
ambient colour for a ray that misses, at DEPTH calls and no deeper.
"""

from __future__ import annotations

import drjit as dr

from whitted.reference.emitters.heckbert import constant_color
from whitted.reference.renderers.mitsuba.tree import per_variant, rgb
from whitted.tracer.emitters.background import Background

#: the Mitsuba plugins this module registers
PLUGINS = ("whitted_background",)


def mitsuba(light: Background) -> dict:
    return {"type": "whitted_background", "radiance": rgb(light.radiance)}


def register(mi) -> None:
    """Register ``whitted_background`` with Mitsuba, whose variant must be set."""
    cls = plugin_class(mi)
    mi.register_emitter("whitted_background", lambda props: cls(props))


plugin_class = per_variant(lambda mi: _define(mi))


def _define(mi):
    class BackgroundEmitter(mi.Emitter):
        """Radiance for rays that hit nothing; lights nothing (module docstring)."""

        hit_term = True

        def __init__(self, props: mi.Properties):
            super().__init__(props)
            self.radiance = constant_color(mi, props, "radiance")
            self.m_flags = mi.EmitterFlags.Infinite

        def sample_direction(self, it, sample, active=True):
            return dr.zeros(mi.DirectionSample3f), mi.Color3f(0.0)

        def eval(self, si, active=True):
            return dr.select(mi.Bool(active), self.radiance, 0.0)

        def pdf_direction(self, it, ds, active=True):
            return mi.Float(0.0)

        def eval_direction(self, it, ds, active=True):
            return dr.select(mi.Bool(active), self.radiance, 0.0)

        def set_scene(self, scene):
            pass

        def traverse(self, cb):
            pass

        def to_string(self):
            return f"BackgroundEmitter[radiance = {self.radiance}]"

    return BackgroundEmitter
