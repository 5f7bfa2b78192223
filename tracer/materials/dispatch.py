"""The one place that dispatches over material kinds, for whole wavefronts at once.

:class:`SceneMaterials` builds each kind's :class:`~tracer.materials.base.BSDF`
once per scene (only the kinds the scene has) and a table from material id
to (kind, row). At a wavefront of hits, :meth:`SceneMaterials.at` gathers
each lane's kind and row, and every present kind gathers its parameters under
its own mask; the returned :class:`Closure` answers the integrator's three
questions by evaluating each present kind under its mask and selecting per
lane. The integrator never asks which kind a lane holds.

Why masks and not Dr.Jit's ``dr.switch`` (an indirect call per lane): a scene
has a handful of kinds, each a few dozen instructions, and on the LLVM backend
the masked evaluation of every present kind inside the one kernel per level
was never slower than the symbolic calls on the built-in scenes, and up to
1.17 times faster (``benchmarks/bench_dispatch.py``; ``docs/extending.md``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import drjit as dr
import numpy as np

from whitted.tracer import faults
from whitted.tracer.backend import jit, upload
from whitted.tracer.materials import REGISTRY, type_of
from whitted.tracer.materials.base import MaterialModel, ShadingPoint
from whitted.tracer.materials.textures import TextureTable


@dataclass
class Slot:
    """One delta-lobe slot over a wavefront: the direction and weight per lane.

    ``letters`` and ``kinds`` map each lobe letter (``"S"``, ``""``) and each
    lobe kind (``"reflect"``, ``"transmit"``) to the mask of lanes that have it.
    """
    d: Any
    weight: Any
    letters: dict[str, Any] = field(default_factory=dict)
    kinds: dict[str, Any] = field(default_factory=dict)


def _or(masks: list, fallback):
    """The union of the masks that are not None (``fallback`` if none is)."""
    out = None
    for m in masks:
        if m is not None:
            out = m if out is None else out | m
    return fallback if out is None else out


class Closure:
    """The materials at one wavefront of hits (see the module docstring)."""

    def __init__(self, parts: list, si: ShadingPoint, valid, opacity=None):
        self.parts = parts          # (bsdf, mask, params) of each present kind
        self.si = si
        #: per lane, the material's opacity (None: every material is opaque)
        self.opacity = opacity
        no = dr.zeros(jit.Bool, dr.width(valid))
        #: lanes whose material has a smooth part (direct light is summed there)
        self.smooth = _or([mask for bsdf, mask, _ in parts if bsdf.smooth], no)

    def _opaque(self, value):
        """``value`` weighted by the opacity (Mitsuba's ``mask`` scales its material by it)."""
        return value if self.opacity is None else value * self.opacity

    def eval(self, wi):
        """f(wo, wi) of the smooth part of each lane's material (no cosine)."""
        f = None
        for bsdf, mask, prm in self.parts:
            if bsdf.smooth:
                fk = bsdf.eval(prm, self.si, wi)
                f = fk if f is None else dr.select(mask, fk, f)
        return None if f is None else self._opaque(f)

    def emission(self) -> list[tuple[Any, Any, str]]:
        """(lanes, radiance, light-path letters) of each kind that emits here."""
        out = []
        for bsdf, mask, prm in self.parts:
            if bsdf.emits:
                out += [(mask, self._opaque(value), letters)
                        for value, letters in bsdf.emission_terms(prm, self.si)]
        return out

    def delta_lobes(self, throughput) -> list[Slot]:
        """The lobe slots: per lane, the direction and ``throughput`` x the lobe's weight.

        Slot i holds lobe i of each lane's kind; lanes whose kind has fewer
        lobes get weight 0 there (and are dropped by the integrator).
        """
        slots: list[Slot] = []
        beta = throughput
        if self.opacity is not None:
            # Mitsuba's mask: the material's lobes weighted by the opacity, and one more
            # ray straight through with 1 - opacity (no scattering event: letter "").
            throughput = throughput * self.opacity
        for bsdf, mask, prm in self.parts:
            if not bsdf.lobes:
                continue
            lobes = bsdf.delta_lobes(prm, self.si)
            for i, ((d, w), lobe) in enumerate(zip(lobes, bsdf.lobes, strict=True)):
                if i == len(slots):
                    zero = dr.zeros(type(throughput), dr.width(throughput))
                    slots.append(Slot(d, dr.select(mask, throughput * w, zero)))
                else:
                    s = slots[i]
                    s.d = dr.select(mask, d, s.d)
                    s.weight = dr.select(mask, throughput * w, s.weight)
                s = slots[i]
                s.letters[lobe.letter] = _or([s.letters.get(lobe.letter), mask], None)
                s.kinds[lobe.kind] = _or([s.kinds.get(lobe.kind), mask], None)
        if self.opacity is not None:
            through = self.opacity < 1
            w_through = beta * (1 - self.opacity)
            w_through = faults.pick("mask-passthrough-unweighted", lambda: beta, w_through)
            slots.append(Slot(self.si.d, dr.select(through, w_through, 0),
                              {"": through}, {"transmit": through}))
        return slots


class SceneMaterials:
    """Every material of a scene as per-kind tables, and the dispatch over kinds."""

    def __init__(self, materials: list[MaterialModel]):
        by_kind: dict[str, list] = {}
        rows = []
        for m in materials:
            members = by_kind.setdefault(type_of(m), [])
            rows.append((type_of(m), len(members)))
            members.append(m)
        order = [name for name in REGISTRY if name in by_kind]
        #: one BSDF per kind present, in registry order
        self.kinds = [REGISTRY[name].BSDF(by_kind[name]) for name in order]
        # Material id len(materials) is "no material" (a pure emitter): no kind matches it.
        kind = [order.index(name) for name, _ in rows] + [len(order)]
        self.kind = upload(jit.UInt32, kind, np.uint32)
        self.row = upload(jit.UInt32, [r for _, r in rows] + [0], np.uint32)
        self.has_smooth = any(k.smooth for k in self.kinds)
        # Materials with ``two_sided = false`` are black where the ray arrives from behind
        # (the side the shading normal points away from), as a bare Mitsuba BSDF is.
        one_sided = [getattr(m, "two_sided", True) is False for m in materials]
        self.has_one_sided = any(one_sided)
        opacity = [m.mask_opacity for m in materials]
        #: some material is not opaque (``opacity`` < 1, Mitsuba's ``mask``)
        self.has_mask = any(o != 1 for o in opacity)
        #: some opacity is a texture, looked up at the hit's uv (else one float each)
        self.textured_opacity = any(not isinstance(o, (int, float)) for o in opacity)
        if self.textured_opacity:
            # One row a material id, the last (no material) opaque; the three channels
            # of every row are equal (textures.scalar_texture), so channel x is the value.
            self.opacity = TextureTable([o if not isinstance(o, (int, float)) else (o,) * 3
                                         for o in opacity] + [(1.0, 1.0, 1.0)])
        else:
            self.opacity = upload(jit.Float, opacity + [1.0], np.float32)
        self.one_sided = upload(jit.Bool, one_sided + [False], bool)
        self.has_delta = any(k.lobes for k in self.kinds) or self.has_mask
        #: the most delta-lobe slots :meth:`Closure.delta_lobes` returns (one per lobe of the
        #: kind with the most, and the mask's ray straight through)
        self.delta_slots = max((len(k.lobes) for k in self.kinds), default=0) + self.has_mask

    def at(self, mid, si: ShadingPoint, valid) -> Closure:
        """The materials of material ids ``mid`` at the hits ``si`` (lanes in ``valid``)."""
        kind = dr.gather(jit.UInt32, self.kind, mid, valid)
        row = dr.gather(jit.UInt32, self.row, mid, valid)
        parts = []
        opacity = None
        if self.has_mask:
            if self.textured_opacity:
                value = self.opacity.eval(mid, si.uv, valid).x
            else:
                value = dr.gather(jit.Float, self.opacity, mid, valid)
            opacity = dr.select(valid, value, 1.0)
        if self.has_one_sided:  # black from behind: no kind answers for those lanes
            valid = valid & ~(dr.gather(jit.Bool, self.one_sided, mid, valid) & (si.cos_i < 0))
        for i, bsdf in enumerate(self.kinds):
            mask = valid & (kind == i)
            parts.append((bsdf, mask, bsdf.params(row, si, mask)))
        return Closure(parts, si, valid, opacity)
