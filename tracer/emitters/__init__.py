"""Light sources: one module per ``[[lights]]`` kind, a registry, and area emitters on shapes.

A kind's module (e.g. :mod:`tracer.emitters.point`) holds ``MODEL`` (its
scene-model dataclass, a :class:`~tracer.emitters.base.LightModel`),
``parse(table)`` (the ``[[lights]]`` table, read with the ``_Table`` helpers
of :mod:`tracer.scene`) and ``Emitter`` (a :class:`~tracer.emitters.base.Emitter`
built once per scene). Area emitters on shapes are :mod:`tracer.emitters.area`.
Adding a kind is one module and one line in :data:`LIGHTS` here, and one of
each in ``reference/emitters/`` for its Mitsuba conversion
(``docs/extending.md``).
"""

from __future__ import annotations

from types import ModuleType

from tracer.emitters import area, directional, point, spot
from tracer.emitters.base import Emitter, LightModel

#: ``[[lights]]`` TOML ``type`` -> the module of that kind (one line per kind).
LIGHTS: dict[str, ModuleType] = {
    "point": point,
    "directional": directional,
    "spot": spot,
}


def type_of(light: LightModel) -> str:
    """The TOML ``type`` of a light model."""
    for name, module in LIGHTS.items():
        if type(light) is module.MODEL:
            return name
    raise TypeError(f"{type(light).__name__} is not a registered light kind")


def scene_emitters(lights: tuple, emitting_shapes: list) -> list[Emitter]:
    """Every light of a scene: the ``[[lights]]`` in order, then the area emitters of shapes.

    Lights that sample (not delta) are numbered in that order; the number
    chooses each one's random stream.
    """
    out: list[Emitter] = [LIGHTS[type_of(light)].Emitter(light) for light in lights]
    out += [area.Emitter(s) for s in emitting_shapes]
    for i, e in enumerate(e for e in out if not e.delta):
        e.index = i
    return out


__all__ = ["LIGHTS", "Emitter", "LightModel", "area", "scene_emitters", "type_of"]
