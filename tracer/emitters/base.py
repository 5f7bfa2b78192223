"""The emitter interface: what the tracer asks of a light source.

Modelled on Mitsuba 3's emitter plugins (``src/emitters/*.cpp``, one
interface: ``sample_direction``, ``eval``) and pbrt-v4's lights
(``src/pbrt/lights.h``: ``SampleLi``, ``L``, ``Le``), cut to what a Whitted
tracer needs:

* :meth:`Emitter.sample`: for shading points p, the unit direction wi
  towards the light, the length of the shadow ray from its origin to the
  light, and the incident quantity that multiplies f cos (lecture 1,
  "Light attenuation"; for area lights an estimator of integral L d(omega));
  :meth:`Emitter.shadow_ray` turns that into the shadow ray itself;
* :meth:`Emitter.background`: for a light at infinity (``infinite``), the
  radiance a ray that escapes the scene brings back;
* :attr:`Emitter.illuminates`: whether shading points sample it at all (a
  backdrop that is only seen does not);
* :attr:`Emitter.hit_term`: whether what it adds where a ray meets it is
  counted as a hit term (see below);
* area emitters on shapes also emit where a ray hits their front side
  (:func:`tracer.emitters.area.emitted`).

**Hit terms and depth.** ``max_depth`` counts path segments as Mitsuba does:
light seen by the ray of segment k (an area light hit, an environment an
escaping ray sees) counts while k <= max_depth, light arriving at its hit
through a shadow ray only while k < max_depth. The classic model (Whitted
1980, Heckbert's minray 1987) counts trace calls instead: everything a trace
call returns is decided at its ray's hit (emission, ambient, direct light)
or, for a ray that hits nothing, is the background. Such *hit terms* are
counted like direct light, for rays with k < max_depth: a material's
emission (:meth:`tracer.materials.base.BSDF.emission_terms`) always is, and a
background is when its emitter sets ``hit_term``. Then max_depth = DEPTH + 1
is exactly Heckbert's DEPTH.

**Lights made by materials.** A material may make a light of a shape that
carries it (:meth:`tracer.materials.base.MaterialModel.light_of`: the classic
model's spheres with kl > 0 are Heckbert's light spheres); such light kinds
are registered in :data:`tracer.emitters.SHAPE_LIGHTS` rather than as
``[[lights]]`` kinds.

A ``[[lights]]`` kind is one module of :mod:`tracer.emitters` holding its
scene-model dataclass (a :class:`LightModel`), ``parse(table)`` and
``Emitter``; area emitters on shapes are :mod:`tracer.emitters.area`, with
one sampler per emitting shape kind. The formulas stay in :mod:`tracer.lights`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from whitted.tracer import faults
from whitted.tracer.backend import jit


@dataclass(frozen=True)
class LightModel:
    """A ``[[lights]]`` entry of the scene model (one dataclass per kind)."""


class Emitter:
    """A light source of a scene, built once per scene (see the module docstring)."""
    #: One direction per shading point: :meth:`sample` ignores ``u``.
    delta: ClassVar[bool] = True
    #: At infinity: rays that escape the scene bring back :meth:`background`.
    infinite: ClassVar[bool] = False
    #: Shading points sample it (:meth:`sample`); False for a backdrop that is only seen.
    illuminates: ClassVar[bool] = True
    #: What it adds where a ray meets it (its :meth:`background`) is a hit term, counted
    #: only for rays that are still shaded (depth < max_depth; see the module docstring).
    hit_term: ClassVar[bool] = False
    #: The sample ``u`` that lands in the middle of the light (the ray trees aim there).
    aim: tuple[float, float] = (0.5, 0.5)
    #: Place among the scene's sampled (not delta) lights: chooses its random stream.
    index: int = 0

    def sample(self, p, origin, u) -> tuple[Any, Any, Any]:
        """(wi, distance, value) for shading points ``p`` (Array3f).

        ``wi``: unit direction from p towards the light (its sampled point);
        ``distance``: from the shadow ray's ``origin`` (p moved off the
        surface) to that point, inf for a light at infinity; ``value``: the
        incident quantity multiplying f(wo, wi) cos(theta_i) (Array3f);
        ``u``: a 2D sample in [0, 1)^2 (Array2f), unused by delta lights.
        """
        raise NotImplementedError

    def shadow_ray(self, p, origin, wi, dist) -> tuple[Any, Any]:
        """(unit direction, length) of the shadow ray from ``origin`` for a :meth:`sample`.

        By default along ``wi``, ``dist`` long: right for a light whose point no
        surface occupies (a point light's position, a direction at infinity). A
        light sampled at points of its own surface aims at the point instead
        (:mod:`tracer.emitters.area`).
        """
        return wi, dist

    def background(self, d):
        """Radiance (Array3f) brought back by rays escaping along the unit ``d`` (``infinite``)."""
        raise NotImplementedError(f"{type(self).__module__} is not at infinity")


def vec(v) -> Any:
    """A constant 3-vector (position, direction) written into the kernel (an input of it
    in the formula-bug sweep: :func:`tracer.faults.number`)."""
    return jit.Array3f(*(faults.number(v[k]) for k in range(3)))


def color(c) -> Any:
    """A constant RGB value written into the kernel."""
    return jit.Array3f(float(c[0]), float(c[1]), float(c[2]))
