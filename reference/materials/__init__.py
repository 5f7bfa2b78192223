"""Conversions of the material kinds to other renderers: one module per kind, beside the tracer's.

``reference/materials/<kind>.py`` sits beside ``tracer/materials/<kind>.py``
and holds

* ``mitsuba(material) -> dict``: the Mitsuba 3 BSDF as a plugin tree
  (:mod:`reference.renderers.mitsuba.tree`), with the same meaning as the tracer's
  (Mitsuba's defaults that differ from a Whitted set-up overridden);
* optionally ``register(mi)`` and ``PLUGINS``: BSDFs written on Mitsuba's API
  (``whitted_phong``), registered by :func:`reference.mitsuba`.

A second renderer's conversion is one more function per module:
``luxcore(material) -> dict``, LuxCore's material properties
(:mod:`reference.renderers.luxcore.scene`), reached through :func:`convert`; a kind
without one is refused in one line, "<kind>: no LuxCore equivalent". Adding a kind is one
module here and one line in :data:`REGISTRY` (``docs/extending.md``).
"""

from __future__ import annotations

from dataclasses import replace
from types import ModuleType

from whitted.reference.materials import (
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
from whitted.reference.materials.textures import texture_tree
from whitted.reference.renderers.mitsuba.tree import rgb
from whitted.tracer.errors import UserError
from whitted.tracer.materials import type_of
from whitted.tracer.materials.textures import Checkerboard

#: TOML ``type`` -> the module of that kind's conversions (one line per kind).
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

#: "No material" (a shape that only emits): black from both sides.
BLACK = {"type": "twosided", "material": {"type": "diffuse", "reflectance": rgb((0, 0, 0))}}


def convert(material, renderer: str = "mitsuba"):
    """The material in ``renderer``'s terms; one-line :class:`UserError` if its kind has none."""
    kind = type_of(material)
    module = REGISTRY.get(kind)
    fn = getattr(module, renderer, None)
    if fn is None and renderer == "luxcore":
        # the default for kinds without a LuxCore conversion, added later ones included
        raise UserError(f"{kind}: no LuxCore equivalent (material {material.name!r})")
    if renderer == "luxcore" and material.mask_opacity != 1:
        raise UserError(f"material {material.name!r}: opacity (a mask) has no LuxCore "
                        "equivalent here")
    if fn is None:
        raise UserError(f"material {material.name!r}: no {renderer} conversion for "
                        f"type = {kind!r}")
    return fn(material)


def bsdf_tree(material, models: bool = False) -> dict:
    """The Mitsuba BSDF of a material (None: a pure emitter, black).

    ``models``: where the material's kind has a model of its own for a
    tracer-only part the material uses (:func:`tracer_only_model`), that model
    instead of Mitsuba's equivalent.
    """
    if material is None:
        return BLACK
    model = tracer_only_model(material) if models else None
    tree = model if model is not None else convert(material, "mitsuba")
    if material.mask_opacity != 1:  # every kind: Mitsuba's mask around its BSDF
        tree = {"type": "mask", "opacity": opacity_tree(material.mask_opacity),
                "material": tree}
    return tree


def opacity_tree(opacity) -> tuple | dict:
    """Mitsuba's ``opacity`` of a mask: a float, or the texture the material reads
    (tracer.materials.textures.scalar_texture: a bitmap's file, which Mitsuba reads by
    luminance as the tracer does).

    A checkerboard goes with its two colours swapped: Mitsuba 3's checkerboard picks
    ``color0`` where frac(u) > 1/2 equals frac(v) > 1/2 in ``eval`` but where they
    differ in ``eval_1``, the one-value lookup the mask uses (src/textures/
    checkerboard.cpp; Mitsuba 3.9.1 answers eval_1 = 0.3 and eval = color0 = 0.2 at
    uv = (0.1, 0.1) for color0 = 0.2, color1 = 0.3), so the swap makes its opacity
    the scene's checkerboard, color0 where the format says.
    """
    if isinstance(opacity, (int, float)):
        return ("float", float(opacity))
    if isinstance(opacity, Checkerboard):
        opacity = replace(opacity, color0=opacity.color1, color1=opacity.color0)
    return texture_tree(opacity)


def tracer_only_model(material) -> dict | None:
    """The harness's own Mitsuba model of the material's tracer-only part, or None.

    A kind's module may define ``mitsuba_model(material)``: a BSDF written on
    Mitsuba's API that models what Mitsuba lacks (``dielectric``: Schlick's
    approximation, ``whitted_schlick``), so that the tracer's rendering of that
    part is judged too, not only shown as an expected deviation.
    """
    fn = getattr(REGISTRY.get(type_of(material)), "mitsuba_model", None)
    return None if fn is None else fn(material)


def has_tracer_only_models(scene) -> bool:
    """Whether a declared tracer-only part of ``scene`` has a harness model."""
    return any(m.tracer_only_used() & set(scene.tracer_only) and
               tracer_only_model(m) is not None for m in scene.used_materials())


def register_plugins(mi) -> None:
    """Register every BSDF written on Mitsuba's API (Mitsuba's variant must be set)."""
    for module in REGISTRY.values():
        if hasattr(module, "register"):
            module.register(mi)


def plugin_names() -> tuple[str, ...]:
    """The names of the BSDFs :func:`register_plugins` registers."""
    return tuple(name for m in REGISTRY.values() for name in getattr(m, "PLUGINS", ()))
