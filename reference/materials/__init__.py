"""Conversions of the material kinds to other renderers: one module per kind, beside the tracer's.

``reference/materials/<kind>.py`` sits beside ``tracer/materials/<kind>.py``
and holds

* ``mitsuba(material) -> dict``: the Mitsuba 3 BSDF as a plugin tree
  (:mod:`reference.mitsuba_tree`), with the same meaning as the tracer's
  (Mitsuba's defaults that differ from a Whitted set-up overridden);
* optionally ``register(mi)`` and ``PLUGINS``: BSDFs written on Mitsuba's API
  (``whitted_phong``), registered by :func:`reference.mitsuba`.

A second renderer's conversion is one more function per module (e.g.
``luxcore(material)``), reached through :func:`convert`. Adding a kind is one
module here and one line in :data:`REGISTRY` (``docs/extending.md``).
"""

from __future__ import annotations

from types import ModuleType

from reference.materials import classic, dielectric, diffuse, mirror, phong
from reference.mitsuba_tree import rgb
from tracer.errors import UserError
from tracer.materials import type_of

#: TOML ``type`` -> the module of that kind's conversions (one line per kind).
REGISTRY: dict[str, ModuleType] = {
    "diffuse": diffuse,
    "mirror": mirror,
    "dielectric": dielectric,
    "phong": phong,
    "classic": classic,
}

#: "No material" (a shape that only emits): black from both sides.
BLACK = {"type": "twosided", "material": {"type": "diffuse", "reflectance": rgb((0, 0, 0))}}


def convert(material, renderer: str = "mitsuba"):
    """The material in ``renderer``'s terms; one-line :class:`UserError` if its kind has none."""
    kind = type_of(material)
    module = REGISTRY.get(kind)
    fn = getattr(module, renderer, None)
    if fn is None:
        raise UserError(f"material {material.name!r}: no {renderer} conversion for "
                        f"type = {kind!r}")
    return fn(material)


def bsdf_tree(material) -> dict:
    """The Mitsuba BSDF of a material (None: a pure emitter, black)."""
    return BLACK if material is None else convert(material, "mitsuba")


def register_plugins(mi) -> None:
    """Register every BSDF written on Mitsuba's API (Mitsuba's variant must be set)."""
    for module in REGISTRY.values():
        if hasattr(module, "register"):
            module.register(mi)


def plugin_names() -> tuple[str, ...]:
    """The names of the BSDFs :func:`register_plugins` registers."""
    return tuple(name for m in REGISTRY.values() for name in getattr(m, "PLUGINS", ()))
