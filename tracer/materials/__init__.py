"""Materials: one module per kind, and the registry that maps TOML ``type`` names to them.

A kind's module (e.g. :mod:`tracer.materials.diffuse`) holds

* ``MODEL``: its scene-model dataclass, a :class:`~tracer.materials.base.MaterialModel`
  (re-exported by :mod:`tracer.scene` for the kinds that were there before);
* ``parse(table, name)``: the ``[materials.NAME]`` table into a ``MODEL``,
  read through a :class:`~tracer.settings.Table` (:mod:`tracer.scene` reads
  the ``type`` key and refuses the keys the kind did not read);
* ``BSDF``: its behaviour in the tracer, a :class:`~tracer.materials.base.BSDF`.

Adding a kind is one new module and one line in :data:`REGISTRY`; its
Mitsuba conversion is one module in ``reference/materials/`` and one line in
that registry (``docs/extending.md``). The order of :data:`REGISTRY` is the
order of the kinds in messages and in the dispatch
(:mod:`tracer.materials.dispatch`).
"""

from __future__ import annotations

from types import ModuleType

from whitted.tracer.materials import (
    blend,
    classic,
    conductor,
    dielectric,
    diffuse,
    mirror,
    phong,
    plastic,
    thindielectric,
)
from whitted.tracer.materials.base import MaterialModel

#: TOML ``type`` -> the module of that kind (one line per kind).
REGISTRY: dict[str, ModuleType] = {
    "diffuse": diffuse,
    "mirror": mirror,
    "conductor": conductor,
    "dielectric": dielectric,
    "thindielectric": thindielectric,
    "plastic": plastic,
    "phong": phong,
    "classic": classic,
    "blend": blend,
}


def type_of(material: MaterialModel) -> str:
    """The TOML ``type`` of a material model."""
    for name, module in REGISTRY.items():
        if type(material) is module.MODEL:
            return name
    raise TypeError(f"{type(material).__name__} is not a registered material kind")


def module_of(material: MaterialModel) -> ModuleType:
    """The module of a material model's kind."""
    return REGISTRY[type_of(material)]


def tracer_only_parts() -> tuple[str, ...]:
    """Every part a scene may declare tracer-only, in registry order."""
    parts: list[str] = []
    for module in REGISTRY.values():
        parts += [p for p in module.MODEL.tracer_only_parts if p not in parts]
    return tuple(parts)


__all__ = ["REGISTRY", "MaterialModel", "module_of", "tracer_only_parts", "type_of"]
