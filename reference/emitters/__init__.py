"""Conversions of the light kinds to other renderers: one module per kind, beside the tracer's.

``reference/emitters/<kind>.py`` sits beside ``tracer/emitters/<kind>.py`` and
holds ``mitsuba(light) -> dict`` (the Mitsuba 3 emitter as a plugin tree,
:mod:`reference.renderers.mitsuba.tree`) and ``luxcore(light) -> dict`` (LuxCore's light
properties, :mod:`reference.renderers.luxcore.scene`; a kind without one is refused in
one line, "<kind>: no LuxCore equivalent"); :mod:`reference.emitters.area` converts area
emitters on shapes. Adding a ``[[lights]]`` kind is one module here and one
line in :data:`REGISTRY` (``docs/extending.md``).
"""

from __future__ import annotations

from types import ModuleType

from whitted.reference.emitters import (
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
from whitted.tracer.emitters import type_of
from whitted.tracer.errors import UserError

#: ``[[lights]]`` TOML ``type`` -> the module of that kind's conversions (one line per kind).
REGISTRY: dict[str, ModuleType] = {
    "point": point,
    "directional": directional,
    "spot": spot,
    "background": background,
    "constant": constant,
    "envmap": envmap,
    "projector": projector,
    # made by materials of their shapes (tracer.emitters.SHAPE_LIGHTS), attached to the shape
    "heckbert": heckbert,
}


def convert(light, renderer: str = "mitsuba"):
    """The light in ``renderer``'s terms; one-line :class:`UserError` if its kind has none."""
    kind = type_of(light)
    fn = getattr(REGISTRY.get(kind), renderer, None)
    if fn is None and renderer == "luxcore":
        # the default for kinds without a LuxCore conversion, added later ones included
        raise UserError(f"{kind}: no LuxCore equivalent (light)")
    if fn is None:
        raise UserError(f"no {renderer} conversion for lights of type = {kind!r}")
    return fn(light)


def emitter_tree(light) -> dict:
    """The Mitsuba emitter of a ``[[lights]]`` entry."""
    return convert(light, "mitsuba")


def area_tree(emitter) -> dict:
    """The Mitsuba emitter of a shape's area emitter."""
    return area.mitsuba(emitter)


def plugin_names() -> tuple[str, ...]:
    """The names of the emitters :func:`register_plugins` registers."""
    return tuple(name for m in REGISTRY.values() for name in getattr(m, "PLUGINS", ()))


def register_plugins(mi) -> None:
    """Register every emitter written on Mitsuba's API (Mitsuba's variant must be set)."""
    for module in REGISTRY.values():
        if hasattr(module, "register"):
            module.register(mi)
