"""Conversions of the shape kinds to other renderers: one module per kind, beside the tracer's.

``reference/shapes/<kind>.py`` sits beside ``tracer/shapes/<kind>.py`` and holds

* ``mitsuba(shape, name) -> dict``: the Mitsuba 3 shape as a plugin tree
  (:mod:`reference.renderers.mitsuba.tree`), or an in-memory mesh node
  (:func:`reference.shapes.meshes.mesh_node`, written as an ``obj`` file beside
  the XML, named ``name``); :mod:`reference.renderers.mitsuba.scene` adds its BSDF
  and emitter. Its placement is built by Mitsuba from the values the file gives
  (the model's :class:`tracer.shapes.base.Placement`: ``to_world``'s steps, a
  sphere's centre and radius, a triangle's or a polygon's own vertices), never taken
  from the tracer's composed matrices (:mod:`reference.renderers.mitsuba.transforms`);
* ``luxcore(shape) -> (vertices, faces, normals or None)``: the shape as a
  world-space triangle mesh for LuxCore (:mod:`reference.renderers.luxcore.scene`),
  only where it means the same; a kind without one is refused in one line,
  "<kind>: no LuxCore equivalent".

Adding a kind is one module here and one line in :data:`REGISTRY`
(``docs/extending.md``).
"""

from __future__ import annotations

from types import ModuleType

from whitted.reference.shapes import (
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
from whitted.tracer.errors import UserError
from whitted.tracer.shapes import type_of

#: TOML ``type`` -> the module of that kind's conversions (one line per kind).
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


def _kind(shape) -> str:
    """The shape's registered kind, or its class name in lower case."""
    try:
        return type_of(shape)
    except TypeError:
        return type(shape).__name__.lower()


def mitsuba_tree(shape, name: str) -> dict:
    """The shape's Mitsuba plugin tree, without its BSDF and emitter."""
    fn = getattr(REGISTRY.get(_kind(shape)), "mitsuba", None)
    if fn is None:
        raise TypeError(f"no Mitsuba conversion for {type(shape).__name__}")
    return fn(shape, name)


def luxcore_mesh(shape):
    """(vertices, faces, normals or None) of the shape in world space, for LuxCore;
    one-line :class:`UserError` if its kind has no LuxCore conversion."""
    kind = _kind(shape)
    fn = getattr(REGISTRY.get(kind), "luxcore", None)
    if fn is None:
        raise UserError(f"{kind}: no LuxCore equivalent")
    return fn(shape)


__all__ = ["REGISTRY", "luxcore_mesh", "mitsuba_tree"]
