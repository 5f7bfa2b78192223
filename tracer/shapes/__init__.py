"""Shapes: one module per kind, and the registry that maps TOML ``type`` names to them.

A kind's module (e.g. :mod:`tracer.shapes.sphere`) holds its intersection
formulas (pure functions over Dr.Jit arrays) and

* ``MODEL``: its scene-model dataclass, a :class:`~tracer.shapes.base.ShapeModel`
  (re-exported by :mod:`tracer.scene`);
* ``parse(t, ctx)``: the ``[[shapes]]`` table into a ``MODEL``
  (:mod:`tracer.scene` reads ``type``, ``emitter``, ``material``, and refuses
  the keys nobody read);
* ``Block`` and optionally ``pack(members, packing)``: its shapes as the
  geometry's packed tables (:mod:`tracer.geometry` asks each kind);
* ``Sampler`` (optional): how an area emitter on it is sampled
  (:mod:`tracer.emitters.area`); ``bounds(shape)`` (optional): its box.

The interface is :mod:`tracer.shapes.base`. Adding a kind is one new module and
one line in :data:`REGISTRY`; its Mitsuba and LuxCore conversions are one
module in ``reference/shapes/`` and one line in that registry
(``docs/extending.md``). The order of :data:`REGISTRY` is the order of the
kinds in messages and in the scene format's schema.
"""

from __future__ import annotations

from types import ModuleType

from whitted.tracer.shapes import (
    cube,
    cylinder,
    disk,
    instance,
    mesh,
    paraboloid,
    polygon,
    rectangle,
    sphere,
    triangle,
)
from whitted.tracer.shapes.base import ShapeModel

#: TOML ``type`` -> the module of that kind (one line per kind).
REGISTRY: dict[str, ModuleType] = {
    "sphere": sphere,
    "rectangle": rectangle,
    "triangle": triangle,
    "disk": disk,
    "cylinder": cylinder,
    "paraboloid": paraboloid,
    "polygon": polygon,
    "mesh": mesh,
    "cube": cube,
    "instance": instance,
}

#: The order in which the message about area lights has always named the kinds that
#: carry them; a kind added later comes after these, in registry order.
_EMITTER_ORDER = ("sphere", "rectangle", "triangle", "disk", "mesh", "cube", "polygon",
                  "cylinder")


def type_of(shape: ShapeModel) -> str:
    """The TOML ``type`` of a shape model."""
    for name, module in REGISTRY.items():
        if type(shape) is module.MODEL:
            return name
    raise TypeError(f"{type(shape).__name__} is not a registered shape kind")


def module_of(shape: ShapeModel) -> ModuleType:
    """The module of a shape model's kind."""
    return REGISTRY[type_of(shape)]


def emitting() -> tuple[str, ...]:
    """The kinds that may carry an area emitter: those whose module has a ``Sampler``."""
    kinds = [k for k, m in REGISTRY.items() if getattr(m, "Sampler", None) is not None]
    rank = {k: i for i, k in enumerate(_EMITTER_ORDER)}
    return tuple(sorted(kinds, key=lambda k: rank.get(k, len(rank))))


__all__ = ["REGISTRY", "ShapeModel", "emitting", "module_of", "type_of"]
