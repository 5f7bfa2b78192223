"""Conversions of ``instance`` shapes: Mitsuba's ``instance`` of the group's ``shapegroup``.

LuxCore has no conversion here: its scene conversion expands each instance into
its group's meshes, transformed (:func:`reference.renderers.luxcore.scene.describe`).
"""

from __future__ import annotations

from whitted.reference.renderers.mitsuba import transforms
from whitted.tracer.shapes.instance import Instance


def mitsuba(shape: Instance, name: str) -> dict:
    return {"type": "instance", "to_world": transforms.tree(transforms.of(shape)),
            "shapegroup": {"type": "ref", "id": ("string", f"group_{shape.group}")}}
