"""``type = "blend"``: a constant mix of two smooth materials (Mitsuba 3's ``blendbsdf``).

    f(wi, wo) = (1 - weight) f_first(wi, wo) + weight f_second(wi, wo),

the linear blend of Mitsuba 3's ``blendbsdf`` plugin (``src/bsdfs/blendbsdf.cpp``,
``eval``: ``bsdf_0 * (1 - weight) + bsdf_1 * weight``; weight 0 is the first material
alone, 1 the second), and pbrt-v3's ``MixMaterial`` (``src/materials/mixmat.cpp``, with
its ``amount`` the weight of the second). A convex combination of two BRDFs is a BRDF:
reciprocal, and energy-conserving when both are.

``first`` and ``second`` are inline tables of a smooth kind (:data:`SMOOTH`: ``diffuse``,
``phong`` without an ambient term), without ``two_sided`` of their own: the blend is
one-sided (``two_sided = false``) or two-sided as a whole, as Mitsuba's ``twosided``
around ``blendbsdf`` makes it. The smooth part is the weighted sum (the tracer sums it
over the lights with one shadow ray each). Blends of kinds with delta lobes (mirrors,
glass, conductors, plastic) are refused: Whitted's recursion would follow each lobe
with its weight, but the harness does not yet check that Mitsuba's reference follows
a blend's lobes deterministically. The weight is a number in [0, 1] (Mitsuba's
``blendbsdf`` clips its weight texture to that range); a textured weight is refused.
Mitsuba's counterpart is ``blendbsdf`` (``reference/materials/blend.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from whitted.tracer.backend import deferred, jit, upload
from whitted.tracer.materials import base, diffuse, phong
from whitted.tracer.settings import Table

dr = deferred("drjit")

#: The kinds a blend may mix: smooth only (no delta lobes), by TOML ``type``.
SMOOTH = {"diffuse": diffuse, "phong": phong}
#: The keys naming the two materials, in Mitsuba's order (bsdf_0, bsdf_1).
PARTS = ("first", "second")


@dataclass(frozen=True)
class Blend(base.MaterialModel):
    """(1 - weight) first + weight second."""
    first: base.MaterialModel = None
    second: base.MaterialModel = None
    weight: float = 0.5
    two_sided: bool = True

    def textures(self) -> tuple:
        return self.first.textures() + self.second.textures()


MODEL = Blend


def kind_of(material: base.MaterialModel) -> str:
    """The TOML ``type`` of a blended material."""
    return next(k for k, module in SMOOTH.items() if type(material) is module.MODEL)


def _part(t: Table, name: str) -> base.MaterialModel:
    kind = t.string("type", choices=tuple(SMOOTH))
    if t.has("two_sided"):
        t.fail("two_sided", "give two_sided on the blend, not on the materials it mixes")
    m = SMOOTH[kind].parse(t, name)
    if kind == "phong" and any(m.ambient):
        t.fail("ambient", "a blended phong has no ambient term (the blend mixes only "
                          "smooth parts)")
    t.finish()
    # the blend decides the sides; the parts' own flag is only what their parse defaults to
    return replace(m, two_sided=False) if hasattr(m, "two_sided") else m


def parse(t: Table, name: str) -> Blend:
    first = t.table("first", parse=lambda s: _part(s, f"{name}.first"))
    second = t.table("second", parse=lambda s: _part(s, f"{name}.second"))
    return Blend(name, first, second, weight=t.number("weight", 0.5, lo=0, hi=1),
                 two_sided=base.parse_two_sided(t))


class BSDF(base.BSDF):
    smooth = True

    def __init__(self, materials: list[Blend]):
        super().__init__(materials)
        parts = [(m.first, m.second) for m in materials]
        by_kind: dict[str, list] = {}
        where = []   # per slot: (kind index, row in that kind's table), one list a slot
        for pair in parts:
            for m in pair:
                members = by_kind.setdefault(kind_of(m), [])
                where.append((kind_of(m), len(members)))
                members.append(m)
        order = [k for k in SMOOTH if k in by_kind]
        #: one BSDF per mixed kind present
        self.inner = [SMOOTH[k].BSDF(by_kind[k]) for k in order]
        self.kind = [upload(jit.UInt32, [order.index(k) for k, _ in where[s::2]], np.uint32)
                     for s in range(2)]
        self.row = [upload(jit.UInt32, [r for _, r in where[s::2]], np.uint32)
                    for s in range(2)]
        self.weight = base.floats([m.weight for m in materials])

    def params(self, row, si, active):
        w = base.gather(self.weight, row, active)
        parts = []
        for s in range(2):
            kind = base.gather(self.kind[s], row, active)
            inner_row = base.gather(self.row[s], row, active)
            for i, bsdf in enumerate(self.inner):
                mask = active & (kind == i)
                parts.append((s, bsdf, mask, bsdf.params(inner_row, si, mask)))
        return w, parts

    def eval(self, prm, si, wi):
        w, parts = prm
        f = dr.zeros(jit.Array3f, dr.width(w))
        for s, bsdf, mask, p in parts:
            share = (1 - w) if s == 0 else w
            f = dr.select(mask, f + bsdf.eval(p, si, wi) * share, f)
        return f
