"""The material interface: what Whitted's recursion asks of a surface.

Modelled on Mitsuba 3's BSDF plugins (``src/bsdfs/*.cpp``: one interface,
``eval`` / ``sample`` / ``pdf``, a plugin registered by name; the integrator
never asks which BSDF it holds) and on pbrt-v4's BxDFs (``src/pbrt/bxdfs.h``:
``DiffuseBxDF``, ``DielectricBxDF``, ... with one set of methods, dispatched
through a tagged pointer), cut down to what a Whitted tracer needs (Whitted,
"An Improved Illumination Model for Shaded Display", CACM 23(6), 1980;
lecture 1, "The illumination equation with recursion"). A material answers
three questions at a hit:

(a) the **smooth part**: f(wo, wi), its BRDF for a light direction wi without
    the cosine, which the integrator sums over the lights with one shadow ray
    each (Lambert, Phong: the D of Heckbert's light-path notation);
(b) the **delta lobes**: directions with weights, which the integrator follows
    recursively (a mirror's reflection; glass's reflection with Fresnel R and
    refraction with (1 - R)(n1 / n2)^2: the S of the notation);
(c) **emission**: radiance added at the hit without any light sample (the
    lecture's ambient term of the Phong model; the classic model's ambient
    term and the glow kl x colour of its light spheres). Emission is a *hit
    term*: it is counted with the shading of the hit, for rays with
    depth < max_depth (see :mod:`tracer.emitters.base`).

A material may also make a light source of a shape that carries it
(:meth:`MaterialModel.light_of`), as the classic model's spheres with
kl > 0 are Heckbert's light spheres.

A kind is one module of :mod:`tracer.materials` holding three things: its
scene-model dataclass (a :class:`MaterialModel`), ``parse(table, name)``
(the TOML ``[materials.NAME]`` table, read with a :class:`~tracer.settings.Table`,
:mod:`tracer.settings`), and ``BSDF``, a subclass of :class:`BSDF` built once per
scene from that kind's materials. It packs their parameters into Dr.Jit
tables (row ``i`` = the kind's ``i``-th material), gathers a row per lane
(:meth:`BSDF.params`) and evaluates (a), (b) and (c) on whole wavefronts. The
formulas themselves stay in the pure formula modules (:mod:`tracer.fresnel`,
:mod:`tracer.phong`, :mod:`tracer.texture`); a kind only calls them.
:class:`tracer.materials.dispatch.SceneMaterials` is the one place that
dispatches over kinds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from whitted.tracer.backend import deferred, jit, upload, upload_rows
from whitted.tracer.settings import check_number, number_schema, range_text

dr = deferred("drjit")


@dataclass(frozen=True)
class MaterialModel:
    """A material of the scene model, the parsed ``[materials.NAME]`` table (a dataclass a kind)."""
    name: str
    #: The TOML key ``opacity`` of every kind (Mitsuba's ``mask``): the material counts
    #: with this weight, and the ray continues straight through with 1 - opacity (read
    #: by the scene parser for every kind that does not read ``opacity`` itself, applied
    #: by :mod:`tracer.materials.dispatch`): a float, or a texture model whose three
    #: channels are equal (:func:`tracer.materials.textures.scalar_texture`)
    mask_opacity: Any = field(default=1.0, kw_only=True)

    #: Parts of this kind that only the tracer models, which a scene may declare in
    #: ``[compare] tracer_only`` (e.g. ``"schlick"``).
    tracer_only_parts: ClassVar[tuple[str, ...]] = ()

    def tracer_only_used(self) -> frozenset[str]:
        """The tracer-only parts (from :attr:`tracer_only_parts`) this material uses."""
        return frozenset()

    def comparable(self, declared: tuple[str, ...]) -> MaterialModel:
        """This material with the ``declared`` tracer-only parts replaced by what Mitsuba models."""
        return self

    def textures(self) -> tuple:
        """The textures among its parameters (colours or texture models)."""
        return ()

    def light_of(self, shape) -> Any:
        """The light source this material makes of ``shape``, which carries it, or None.

        Most kinds make none. A kind that does returns the model of a light kind
        registered in :data:`tracer.emitters.SHAPE_LIGHTS` (the classic model's
        spheres with kl > 0: Heckbert's light spheres), and raises ``ValueError``
        with a one-line reason for a shape it cannot make a light of; the scene
        is then refused.
        """
        return None


@dataclass
class ShadingPoint:
    """A hit as a material sees it (Mitsuba's SurfaceInteraction, pbrt's SurfaceInteraction).

    All vectors are unit Array3f of one wavefront. Normals point outwards as
    the shape defines them; ``nl`` and ``ng`` are turned to the side the ray
    arrives from (the two-sided shading of the tracer, judged as Mitsuba's
    ``twosided`` BSDF judges it: by the shading normal).
    """
    p: Any       # position
    n: Any       # geometric normal
    ns: Any      # shading normal (interpolated on smooth meshes, else n)
    uv: Any      # texture coordinates (Mitsuba's for each shape)
    d: Any       # direction of the arriving ray, towards the surface
    nl: Any      # ns turned towards the side the ray arrives from
    ng: Any      # n turned towards the side the ray arrives from
    cos_i: Any   # -d . ns: > 0 when the ray arrives on the outside

    @property
    def wo(self):
        """The direction towards the viewer (pointing away from the surface)."""
        return -self.d


@dataclass(frozen=True)
class Lobe:
    """One delta lobe a kind may return, as a slot of :meth:`BSDF.delta_lobes`.

    ``kind`` is ``"reflect"`` or ``"transmit"`` (what the ray trees draw);
    ``letter`` is the vertex's letter in light-path expressions: ``"S"``
    (Heckbert's specular), or ``""`` for a lobe that is no scattering event at
    all (a ray passing straight through).
    """
    kind: str = "reflect"
    letter: str = "S"


REFLECT = Lobe("reflect")
TRANSMIT = Lobe("transmit")


class BSDF:
    """One kind's behaviour over all the scene's materials of that kind (see the module docstring).

    Subclasses set the class attributes and override what applies:
    :meth:`params` (gather a row per lane), :meth:`eval` (smooth kinds),
    :meth:`delta_lobes` (kinds with lobes), :meth:`emission` (kinds that emit).
    """
    #: The kind has a smooth part: the integrator sums direct light through :meth:`eval`
    #: (a D vertex in light-path expressions).
    smooth: ClassVar[bool] = False
    #: The delta lobes :meth:`delta_lobes` returns, in slot order.
    lobes: ClassVar[tuple[Lobe, ...]] = ()
    #: Letters of the light path that :meth:`emission` adds, read from the hit towards
    #: the light: ``"DL"`` is light reaching the eye through the smooth part (ambient).
    emission_letters: ClassVar[str] = "DL"

    def __init__(self, materials: list):
        self.materials = materials
        #: :meth:`emission` returns radiance for some material of this scene
        self.emits = False

    def params(self, row, si: ShadingPoint, active) -> Any:
        """Per-lane parameters of the materials at ``row`` (textures looked up at ``si.uv``)."""
        return None

    def eval(self, prm, si: ShadingPoint, wi):
        """f(wo, wi) of the smooth part, without the cosine (Array3f); wi points to the light."""
        raise NotImplementedError(f"{type(self).__module__} has no smooth part")

    def delta_lobes(self, prm, si: ShadingPoint) -> list[tuple[Any, Any]]:
        """(direction, weight) of each lobe in :attr:`lobes`, the weight a Float or Array3f.

        The weight multiplies the radiance the lobe's ray brings back; zero drops
        the ray (e.g. the refraction under total internal reflection).
        """
        return []

    def emission(self, prm, si: ShadingPoint):
        """Radiance added at the hit (Array3f), or None."""
        return None

    def emission_terms(self, prm, si: ShadingPoint) -> list[tuple[Any, str]]:
        """Each term of radiance added at the hit: (Array3f, light-path letters).

        By default the one term of :meth:`emission` with :attr:`emission_letters`.
        A kind that adds terms of different origin overrides this (the classic
        model: its ambient term, ``"DL"``, and the glow of a light sphere, ``"L"``).
        """
        value = self.emission(prm, si)
        return [] if value is None else [(value, self.emission_letters)]


# --------------------------------------------------------------------------- parsing


def parse_ior(t, key: str, default: float) -> float:
    """An index of refraction: a positive number or one of Mitsuba's names (``tracer.ior``)."""
    from whitted.tracer.ior import DIELECTRICS

    number = range_text("a number", 0, None, True, False)
    v = t.raw(key, default, f"{number} or an IOR name",
              {"anyOf": [number_schema(0, None, True, False), {"enum": list(DIELECTRICS)}]})
    if isinstance(v, str):
        if v not in DIELECTRICS:
            t.fail(key, f"unknown index of refraction {v!r} (a number, or one of "
                        f"{', '.join(DIELECTRICS)})")
        return DIELECTRICS[v]
    return check_number(t, key, v, number, 0, None, True, False)


def parse_two_sided(t) -> bool:
    """``two_sided`` (default true): false makes the surface black from behind, as a bare
    Mitsuba BSDF is (behind: the side the shading normal points away from)."""
    return t.boolean("two_sided", True)


# --------------------------------------------------------------------------- tables


def colors(values) -> Any:
    """A table of RGB colours, one row per material."""
    return upload_rows(jit.Array3f, values)


def floats(values) -> Any:
    """A table of numbers, one row per material."""
    return upload(jit.Float, values, np.float32)


def flags(values) -> Any:
    """A table of booleans, one row per material."""
    return upload(jit.Bool, values, bool)


def gather(table, row, active):
    """The rows ``row`` of a table, per lane (zero where not ``active``)."""
    return dr.gather(type(table), table, row, active)
