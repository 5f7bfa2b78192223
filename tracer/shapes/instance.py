"""``type = "instance"``: a group of shapes placed by ``to_world`` (lecture 2, "Instancing").

The group's shapes are in their own object space; the geometry takes each ray
there by the inverse of ``to_world``, asks the group's own geometry, and
brings the hit back, normals by the inverse transpose. That recursion into the
geometry is :class:`tracer.geometry.Geometry`'s own (:func:`pack` hands the
instances back to it), so this module is the model and its parsing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from whitted.tracer.settings import Matrix, Table, as_tuple
from whitted.tracer.shapes import base


@dataclass(frozen=True)
class Instance(base.ShapeModel):
    """A group of shapes placed by ``to_world`` (the group's own shapes are in object space)."""
    shape_type: ClassVar[str] = "instance"
    takes_material: ClassVar[bool] = False
    not_in_groups: ClassVar[str] = ("a group may not contain instances (nested instancing "
                                    "is not supported)")
    group: str
    to_world: Matrix
    material: str | None = None
    emitter: Any = None
    placement: base.Placement | None = base.placement_field()


MODEL = Instance


def parse(t: Table, ctx: base.Context) -> Instance:
    group = t.string("group")
    if group not in ctx.groups:
        known = ", ".join(sorted(ctx.groups)) or "none"
        t.fail("group", f'unknown group "{group}" (defined: {known})')
    return Instance(group, as_tuple(ctx.to_world()), placement=ctx.placement())


def pack(members: list, packing) -> list:
    """The geometry's own: one geometry a group, its instances in a hierarchy or one by one
    (:meth:`tracer.geometry.Packing.instances`)."""
    return packing.instances(members)
