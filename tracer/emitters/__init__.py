"""Light sources: one module per ``[[lights]]`` kind, a registry, and area emitters on shapes.

A kind's module (e.g. :mod:`tracer.emitters.point`) holds ``MODEL`` (its
scene-model dataclass, a :class:`~tracer.emitters.base.LightModel`),
``parse(table)`` (the ``[[lights]]`` table, read through a
:class:`~tracer.settings.Table`) and ``Emitter`` (a :class:`~tracer.emitters.base.Emitter`
built once per scene). Area emitters on shapes are :mod:`tracer.emitters.area`.
Adding a kind is one module and one line in :data:`LIGHTS` here, and one of
each in ``reference/emitters/`` for its Mitsuba conversion
(``docs/extending.md``). Lights that a material makes of the shape carrying
it (:meth:`~tracer.materials.base.MaterialModel.light_of`: Heckbert's light
spheres) are kinds too, registered in :data:`SHAPE_LIGHTS` because no
``[[lights]]`` table names them.
"""

from __future__ import annotations

from types import ModuleType

from whitted.tracer.emitters import (
    area,
    background,
    constant,
    directional,
    envmap,
    heckbert,
    point,
    projector,
    spot,
)
from whitted.tracer.emitters.base import Emitter, LightModel

#: ``[[lights]]`` TOML ``type`` -> the module of that kind (one line per kind).
LIGHTS: dict[str, ModuleType] = {
    "point": point,
    "directional": directional,
    "spot": spot,
    "background": background,
    "constant": constant,
    "envmap": envmap,
    "projector": projector,
}

#: Light kinds made by materials of the shapes carrying them (one line per kind).
SHAPE_LIGHTS: dict[str, ModuleType] = {
    "heckbert": heckbert,
}


def type_of(light: LightModel) -> str:
    """The TOML ``type`` of a light model (or its name in :data:`SHAPE_LIGHTS`)."""
    for name, module in (*LIGHTS.items(), *SHAPE_LIGHTS.items()):
        if type(light) is module.MODEL:
            return name
    raise TypeError(f"{type(light).__name__} is not a registered light kind")


def module_of(light: LightModel) -> ModuleType:
    """The module of a light model's kind."""
    name = type_of(light)
    return LIGHTS[name] if name in LIGHTS else SHAPE_LIGHTS[name]


def scene_emitters(lights: tuple, emitting_shapes: list,
                   shape_lights: tuple = ()) -> list[Emitter]:
    """Every light of a scene: the ``[[lights]]`` in order, the area emitters of shapes,
    then the lights materials make of shapes (``Scene.shape_lights()``).

    Lights that sample (not delta) are numbered in that order; the number
    chooses each one's random stream.
    """
    out: list[Emitter] = [LIGHTS[type_of(light)].Emitter(light) for light in lights]
    out += [area.Emitter(s) for s in emitting_shapes]
    out += [module_of(light).Emitter(light) for light in shape_lights]
    for i, e in enumerate(e for e in out if not e.delta):
        e.index = i
    return out


__all__ = ["LIGHTS", "SHAPE_LIGHTS", "Emitter", "LightModel", "area", "module_of",
           "scene_emitters", "type_of"]
