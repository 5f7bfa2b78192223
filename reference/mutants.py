"""A catalog of plausible formula bugs, and the sweep that shows the harness catches each one.

A comparison that passes says little unless it would have failed on a wrong
formula. Each :class:`Mutant` below is a bug a student could plausibly write
into one formula of the lectures (lecture 1: "Ray tracing", TU Wien 186.101;
lecture 2: UCSD CSE 168, "Ray-surface intersection, shading"), named by an
id, with the formula as the bug computes it and as it should be, the slide
topic it belongs to, and the formula function of the tracer that carries its
switch (one ``faults.pick("id", ...)``, or ``if faults.on("id")``, there:
:mod:`tracer.faults`). Nothing is
edited: ``with faults.active("lambert-no-inv-pi"): ...`` renders the tracer
with that bug.

:func:`sweep` renders every built-in scene with the tracer as written and
with each bug, and judges each image as ``whitted compare`` does
(:mod:`reference.verdicts.compare`): against the deterministic reference at float
precision, against the harness's own model of a declared tracer-only part,
and, on area-lit scenes, by the one-lobe reference's statistical verdict. A
bug is *caught* by a scene whose verdict fails; the sweep passes when the
tracer as written passes every scene and every bug is caught by at least
one. Each catch records its margin: how many times its most violated check
exceeds its limit (1 is the limit itself).

Which reference can see which bug. The deterministic reference evaluates
Mitsuba's plugins along the tracer's ray tree, at the tracer's film positions
and area-light samples: it reads :func:`tracer.sampling.pixel_samples` and
:func:`tracer.sampling.light_sample` itself, so a bug there is in both images
alike and invisible to it (``shared``). Only the one-lobe reference, which
takes its pixel positions from Mitsuba's own sampler and its light samples
from its own stream, can see such a bug, and ``whitted compare`` runs it
only on scenes with area lights (the second opinion): the sweep judges shared
bugs by that verdict alone. Every other bug lives in code that only the
tracer runs and is judged by every verdict of the scene, as ``compare`` does.

Cost. Each reference is rendered once per scene and reused for every bug
(a bug changes the tracer, never Mitsuba); a bug is rendered only on the
scenes where its switch is reached (:func:`tracer.faults.recording` while the
tracer as written renders the scene: a switch never asked about cannot change
the image). The bugs decided by ``faults.pick`` are rendered with the bug's
number an input of the kernel (``faults.active(id, shared_kernel=True)``): one
kernel a scene serves all of them, compiled once (with the kernels' scopes of issue
33, a cold ``whitted report --quick`` went from 275-280 s to 144-151 s: ``python
benchmarks/bench_speed.py report --quick --cold --against e2c9ff4``); a bug decided
by ``faults.on`` (a scene read again, a spot's profile) still has kernels of its
own. Dr.Jit keeps every kernel in its cache on disk.

Adding a bug: one :class:`Mutant` entry in :data:`CATALOG` and one switch,
``faults.pick("id", ...)`` (or ``if faults.on("id")``), in the formula it breaks
(``docs/extending.md``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path

from whitted.tracer import faults

L1 = "lecture 1"
L2 = "lecture 2"


@dataclass(frozen=True)
class Mutant:
    """One plausible bug in one formula (see the module docstring)."""
    id: str
    #: what the bug does, in one sentence
    summary: str
    #: the formula as the bug computes it
    wrong: str
    #: the formula as it should be
    correct: str
    #: the lecture slide topic it belongs to, e.g. 'lecture 1, "Snell's law"'
    topic: str
    #: the tracer function whose ``faults.pick(id, ...)`` or ``faults.on(id)`` switches
    #: it, "path: function"
    where: str
    #: the deterministic reference reads the same code (tracer.sampling), so only the
    #: one-lobe reference can see the bug
    shared: bool = False
    #: when the switch is decided: "render" (while the tracer traces its kernels, or
    #: prepares the scene's tables); "parse" (while the scene file is read: a to_world
    #: composed, a sphere's radius scaled), for which the sweep reads the scene again
    #: with the bug on; "import" (while Mitsuba XML is imported: judged by Mitsuba's own
    #: reading of the file, the structure verdict); "output" (while an image file is
    #: written: judged against Mitsuba's own encoding, the files verdict)
    stage: str = "render"

    @property
    def seen_by(self) -> str:
        """Which verdicts can see the bug (:attr:`references`), in words."""
        return {("structure",): "structure", ("files",): "image file",
                ("onelobe",): "onelobe only"}.get(self.references, "both")

    @property
    def references(self) -> tuple[str, ...]:
        """The references that can see this bug."""
        if self.stage == "import":
            return ("structure",)
        if self.stage == "output":
            return ("files",)
        return ("onelobe",) if self.shared else ("deterministic", "onelobe")


def _m(id_, summary, wrong, correct, lecture, slide, where, shared=False,
       stage="render") -> Mutant:
    return Mutant(id_, summary, wrong, correct, f'{lecture}, "{slide}"', where, shared, stage)


#: The catalog: one entry per bug, in the order of the lectures' topics.
CATALOG: tuple[Mutant, ...] = (
    # --- Fresnel, Snell, total internal reflection (lecture 1) ---------------------------
    _m("schlick-for-exact",
       "Glass asked for the exact Fresnel equations gets Schlick's approximation.",
       "R = R0 + (1 - R0)(1 - cos)^5",
       "R = (r_s^2 + r_p^2) / 2, r_s = (n1 cos_i - n2 cos_t) / (n1 cos_i + n2 cos_t), "
       "r_p = (n2 cos_i - n1 cos_t) / (n2 cos_i + n1 cos_t)",
       L1, "The Fresnel equation", "tracer/fresnel.py: fresnel_exact"),
    _m("fresnel-average-amplitudes",
       "The two polarisations are averaged as amplitudes before squaring, not as "
       "reflectances.",
       "R = ((r_s + r_p) / 2)^2", "R = (r_s^2 + r_p^2) / 2",
       L1, "The Fresnel equation", "tracer/fresnel.py: fresnel_exact"),
    _m("schlick-dense-side-cosine",
       "Schlick's approximation takes the incident angle's cosine also when the ray "
       "leaves the denser medium.",
       "R = R0 + (1 - R0)(1 - cos theta_i)^5 on both sides",
       "R = R0 + (1 - R0)(1 - cos theta)^5 with theta the angle on the less dense side "
       "(theta_t when leaving glass), R = 1 beyond the critical angle",
       L1, "The Fresnel equation (simplified)", "tracer/fresnel.py: fresnel_schlick"),
    _m("conductor-k-ignored",
       "A metal's Fresnel term drops the extinction coefficient k, as if it were glass.",
       "R = R_dielectric(eta)", "R = (R_s + R_p) / 2 with the complex index eta + i k",
       L1, "The Fresnel equation", "tracer/fresnel.py: fresnel_conductor"),
    _m("thin-slab-single-reflection",
       "A thin pane reflects with one face's Fresnel R, forgetting its inner reflections.",
       "R' = R", "R' = R + T^2 R / (1 - R^2) = 2R / (1 + R)",
       L1, "The Fresnel equation", "tracer/fresnel.py: thin_slab_reflectance"),
    _m("snell-eta-inverted",
       "Snell's law with the ratio of the indices upside down.",
       "sin theta_t = (n2 / n1) sin theta_i", "n1 sin theta_i = n2 sin theta_t",
       L1, "Snell's law", "tracer/fresnel.py: refract"),
    _m("normal-not-flipped-inside",
       "A ray leaving a refracting surface is refracted about the outward normal, not "
       "the normal on its own side.",
       "t = d / rel + (cos_i / rel - cos_t) n, n always outward",
       "t = d / rel + (cos_i / rel - cos_t) n', n' = n turned to the side the ray "
       "comes from",
       L1, "Refraction", "tracer/fresnel.py: refract"),
    _m("tir-ignored",
       "No total internal reflection: beyond the critical angle the negative root is "
       "'fixed' with an absolute value, so light still leaves the glass.",
       "cos theta_t = sqrt(|1 - sin^2 theta_t|), no TIR",
       "sin^2 theta_t > 1: total internal reflection, R = 1, no refracted ray",
       L1, "Total internal reflection", "tracer/fresnel.py: _snell"),
    _m("reflect-sign",
       "The mirror direction with the wrong sign of the normal term.",
       "r = d + 2 (d . n) n", "r = d - 2 (d . n) n",
       L1, "Reflection", "tracer/fresnel.py: reflect"),
    _m("no-eta2-scaling",
       "Refracted radiance is not scaled by the squared ratio of the indices.",
       "L_t = (1 - R) L", "L_t = (1 - R) (n1 / n2)^2 L",
       L1, "Refraction", "tracer/materials/dielectric.py: BSDF.delta_lobes"),
    _m("inverted-eta2",
       "Refracted radiance is scaled by the squared ratio of the indices upside down.",
       "L_t = (1 - R) (n2 / n1)^2 L", "L_t = (1 - R) (n1 / n2)^2 L",
       L1, "Refraction", "tracer/materials/dielectric.py: BSDF.delta_lobes"),
    _m("no-fresnel-on-transmission",
       "The refracted ray is not weighted by the light the reflection takes.",
       "L_t = (n1 / n2)^2 L", "L_t = (1 - R) (n1 / n2)^2 L",
       L1, "The Fresnel equation", "tracer/materials/dielectric.py: BSDF.delta_lobes"),
    # --- Lambert, attenuation, lights ------------------------------------------------------
    _m("mask-passthrough-unweighted",
       "A partly transparent surface lets the ray through at full weight, on top of its own "
       "share.",
       "L = a L_surface + L_behind", "L = a L_surface + (1 - a) L_behind (a = opacity)",
       L1, "The Illumination Equation with recursion",
       "tracer/materials/dispatch.py: Closure.delta_lobes"),
    _m("plastic-no-internal-scattering",
       "A plastic's diffuse base forgets the light its coating reflects back inside.",
       "kd' = kd", "kd' = kd / (1 - F_dr), or kd / (1 - kd F_dr) when nonlinear",
       L1, "The illumination equation", "tracer/fresnel.py: plastic_diffuse"),
    _m("lambert-no-cosine",
       "Diffuse shading without Lambert's cosine.",
       "L = f E", "L = f E cos theta, cos theta = N . L",
       L1, "Light attenuation", "tracer/lights.py: lambert_cosine"),
    _m("lambert-abs-cosine",
       "Lambert's cosine taken as an absolute value: light from behind a surface lights it.",
       "cos theta = |N . L|", "cos theta = max(N . L, 0)",
       L2, "Diffuse term", "tracer/lights.py: lambert_cosine"),
    _m("lambert-no-inv-pi",
       "The Lambertian BRDF without its 1/pi, reflecting pi times the light it receives.",
       "f = kd", "f = kd / pi (energy conservation: integral of cos over the hemisphere is pi)",
       L1, "BRDF types (diffuse)", "tracer/materials/diffuse.py: BSDF.eval"),
    _m("point-light-no-falloff",
       "A point light without the inverse-square law.",
       "E = I", "E = I / r^2",
       L2, "Falloff, spot lights", "tracer/lights.py: inverse_square"),
    _m("point-light-linear-falloff",
       "A point light that falls off linearly with distance.",
       "E = I / r", "E = I / r^2",
       L2, "Falloff, spot lights", "tracer/lights.py: inverse_square"),
    _m("spot-linear-falloff",
       "The spot's ramp between beam_width and cutoff_angle is linear in cos theta, "
       "not in the angle theta.",
       "falloff = (cos theta - cos theta_c) / (cos theta_b - cos theta_c)",
       "falloff = (theta_c - theta) / (theta_c - theta_b) (Mitsuba's spot profile)",
       L2, "Falloff, spot lights", "tracer/lights.py: spot_falloff"),
    _m("spot-smoothstep-falloff",
       "The spot's ramp is a smoothstep of the cosine (pbrt-v4's profile), not "
       "Mitsuba's linear ramp in the angle.",
       "falloff = x^2 (3 - 2x), x = (cos theta - cos theta_c) / (cos theta_b - cos theta_c)",
       "falloff = (theta_c - theta) / (theta_c - theta_b)",
       L2, "Falloff, spot lights", "tracer/lights.py: spot_falloff"),
    _m("spot-uv-centred-at-zero",
       "A textured spot maps its axis to uv (0, 0) instead of the image's centre.",
       "uv = (x, y) / (2 z tan(cutoff))", "uv = 1/2 + (x, y) / (2 z tan(cutoff))",
       L2, "Falloff, spot lights", "tracer/lights.py: spot_uv"),
    _m("projector-distance-squared",
       "A projector's image falls off with the squared distance, as a point light's would, "
       "not with the camera's importance: off its axis the image is too bright.",
       "E = pi s tex / r^2", "E = pi s tex / (z^2 cos) = pi s tex / (r^2 cos^3)",
       L1, "Light attenuation", "tracer/emitters/projector.py: Emitter.sample"),
    _m("directional-light-reversed",
       "A directional light's travel direction is used as the direction towards it.",
       "wi = d", "wi = -d (d: the direction the light travels)",
       L2, "Point and directional lights", "tracer/lights.py: directional"),
    _m("heckbert-light-inverse-square",
       "Heckbert's light spheres given an inverse-square falloff his model does not have.",
       "kl colour (N . L) / r^2", "kl colour (N . L), at any distance",
       L1, "The illumination equation", "tracer/lights.py: sphere_centre"),
    # --- area lights -----------------------------------------------------------------------
    _m("area-pdf-rectangle",
       "A rectangle light's area taken from the unit square instead of Mitsuba's "
       "[-1, 1]^2.",
       "A = |u x v|", "A = 4 |u x v| (half-edges u, v)",
       L1, "Shadow computation", "tracer/shapes/rectangle.py: Sampler.local_area"),
    _m("area-pdf-disk",
       "A disk light's area taken as its bounding square's.",
       "A = 4 |u x v|", "A = pi |u x v|",
       L1, "Shadow computation", "tracer/shapes/disk.py: Sampler.local_area"),
    _m("area-pdf-sphere-cone",
       "The solid angle of the cone a sphere light subtends without the 2 of the "
       "azimuth's 2 pi.",
       "pdf = 1 / (pi (1 - cos theta_max))", "pdf = 1 / (2 pi (1 - cos theta_max))",
       L1, "Quick radiometry recap", "tracer/lights.py: sample_cone"),
    _m("sphere-direction-z-squared",
       "Directions towards a constant sky are drawn with z = 1 - 2 u^2, crowding them "
       "towards the zenith, but weighted as uniform.",
       "z = 1 - 2 u^2 (pdf still 1 / (4 pi))", "z = 1 - 2 u: uniform on the sphere, pdf 1 / (4 pi)",
       L1, "Quick radiometry recap", "tracer/lights.py: sample_uniform_direction"),
    _m("sphere-cone-disk-solid-angle",
       "The cone's solid angle approximated by the projected disk's, pi sin^2 theta_max.",
       "pdf = 1 / (pi sin^2 theta_max)", "pdf = 1 / (2 pi (1 - cos theta_max))",
       L1, "Quick radiometry recap", "tracer/lights.py: sample_cone"),
    _m("triangle-warp-no-sqrt",
       "Points on a triangle light drawn without the square root of the warp: not "
       "uniform in area, though the pdf says they are.",
       "p = p0 + (1 - u1) e1 + u2 u1 e2", "p = p0 + (1 - sqrt(u1)) e1 + u2 sqrt(u1) e2",
       L2, "Ray-triangle intersection", "tracer/lights.py: sample_triangle"),
    _m("light-sample-same-uv",
       "Both coordinates of an area light's sample come from one random number.",
       "u = (x, x)", "u = (x, y), independent",
       L1, "Shadow computation", "tracer/sampling.py: stratified_2d", shared=True),
    # --- shadows ---------------------------------------------------------------------------
    _m("shadow-acne",
       "Shadow rays start exactly on the surface, without an offset, and may hit it.",
       "o = p", "o = p + eps n (n on the light's side)",
       L1, "Shadow computation", "tracer/integrator.py: Integrator._shadow_ray"),
    _m("shadow-ray-past-light",
       "Shadow rays are not stopped at the light: anything beyond it casts a shadow.",
       "t_max = inf", "t_max = |light - p| (1 - eps)",
       L1, "Shadow computation", "tracer/integrator.py: Integrator._shadow_ray"),
    # --- intersections and normals ---------------------------------------------------------
    _m("sphere-near-root-from-inside",
       "The ray-sphere test always takes the smaller root, so a ray starting inside "
       "misses the sphere.",
       "t = t0", "t = t0 if t0 > 0 else t1",
       L1, "Ray-sphere intersection", "tracer/shapes/sphere.py: nearest_fraction"),
    _m("sphere-half-b-discriminant",
       "The discriminant of the half-b quadratic keeps the full form's 4.",
       "disc = b'^2 - 4 a c with b' = d . (o - c)", "disc = b'^2 - a c",
       L1, "Ray-sphere intersection", "tracer/shapes/sphere.py: quadratic"),
    _m("plane-hit-behind-ray",
       "The ray-plane test keeps intersections behind the ray's origin.",
       "hit = |a| <= 1 and |b| <= 1", "hit = t > 0 and |a| <= 1 and |b| <= 1",
       L2, "Ray-polygon intersection", "tracer/shapes/rectangle.py: intersect"),
    _m("unnormalized-normal",
       "The sphere's normal is the gradient p - c, not divided by the radius.",
       "n = p - c", "n = (p - c) / r",
       L1, "Surface normals", "tracer/shapes/sphere.py: Block.surface"),
    _m("normal-not-renormalized",
       "Interpolated vertex normals are used without normalising them again.",
       "n = b0 n0 + b1 n1 + b2 n2", "n = normalize(b0 n0 + b1 n1 + b2 n2)",
       L2, "Interpolating normals", "tracer/shapes/mesh.py: Block.surface"),
    _m("barycentrics-swapped",
       "Vertex attributes (normals, texture coordinates) interpolated with the "
       "barycentrics of the second and third vertex swapped.",
       "a = (1 - b - g) a0 + g a1 + b a2", "a = (1 - b - g) a0 + b a1 + g a2",
       L2, "Interpolating normals", "tracer/shapes/triangle.py: interpolate"),
    _m("instance-normal-by-matrix",
       "Normals of an instance are taken to world space by its matrix, not by the "
       "inverse transpose.",
       "n' = M n", "n' = (M^-1)^T n",
       L2, "Instancing", "tracer/geometry.py: instance_normal_matrix"),
    # --- transformed objects: to_world as the scene file gives it (lecture 2) ---------------
    # Decided while the file is read; the Mitsuba side composes the same steps itself
    # (reference/renderers/mitsuba/transforms.py), so each is a difference in the images.
    _m("rotation-sign-flipped",
       "A rotation turns the wrong way (the sine's sign flipped: the transpose of "
       "Rodrigues' matrix).",
       "R = cos I - sin [k]x + (1 - cos) k k^T", "R = cos I + sin [k]x + (1 - cos) k k^T",
       L2, "Intersecting transformed objects", "tracer/transform.py: rotate",
       stage="parse"),
    _m("steps-composed-in-reverse",
       "A list of to_world steps is applied last step first.",
       "[A, B, C] -> M = A B C", "[A, B, C] -> M = C B A (the first step applied first)",
       L2, "Intersecting transformed objects", "tracer/transform.py: compose",
       stage="parse"),
    _m("normals-by-matrix",
       "A mesh's vertex normals are taken to world space by to_world itself, not by its "
       "inverse transpose.",
       "n' = M n", "n' = (M^-1)^T n",
       L2, "Intersecting transformed objects", "tracer/shapes/mesh.py: parse",
       stage="parse"),
    _m("sphere-radius-unscaled",
       "A sphere placed by a scaling to_world keeps the radius written in the file.",
       "r' = r", "r' = s r (s: to_world's uniform scale)",
       L2, "Intersecting transformed objects", "tracer/shapes/sphere.py: parse",
       stage="parse"),
    _m("backface-not-flipped",
       "Two-sided shading forgets to turn the normal towards the side the ray comes "
       "from, so back faces go dark.",
       "N = n", "N = n if n . d < 0 else -n",
       L2, "Diffuse term", "tracer/integrator.py: Integrator._hit_point"),
    # --- cameras ---------------------------------------------------------------------------
    _m("fov-vertical-for-horizontal",
       "The horizontal field of view is used as the vertical one.",
       "d = f + (2u - 1) tan(fov/2) aspect r + (1 - 2v) tan(fov/2) up",
       "d = f + (2u - 1) tan(fov/2) r + (1 - 2v) tan(fov/2) / aspect up",
       L1, "Perspective camera construction", "tracer/camera.py: generate_rays"),
    _m("fov-y-divided",
       "A vertical field of view (fov_axis = \"y\") is made horizontal by dividing by the "
       "aspect ratio instead of multiplying.",
       "tan(fov_x / 2) = tan(fov_y / 2) / aspect", "tan(fov_x / 2) = aspect tan(fov_y / 2)",
       L1, "Perspective camera construction", "tracer/fov.py: horizontal"),
    _m("camera-y-not-flipped",
       "Image rows counted from the bottom: the picture is upside down.",
       "y_ndc = 2v - 1", "y_ndc = 1 - 2v (row 0 at the top)",
       L1, "Perspective camera construction", "tracer/camera.py: generate_rays"),
    _m("ortho-width-as-half",
       "The orthographic camera's width is taken as its half-width.",
       "o = eye + (2u - 1) width r + ...", "o = eye + (2u - 1) width / 2 r + ...",
       L1, "Orthographic camera", "tracer/camera.py: generate_rays"),
    _m("pixel-sample-corner",
       "Samples at the corners of their strata instead of their centres: the image "
       "moves by half a stratum.",
       "x = px + i / n", "x = px + (i + 1/2) / n",
       L1, "Perspective camera construction", "tracer/sampling.py: pixel_samples",
       shared=True),
    # --- Phong, textures, the classic model ------------------------------------------------
    _m("phong-no-normalization",
       "The Phong lobe without its normalisation, so highlights lose energy as the "
       "exponent grows.",
       "f_s = ks cos^p alpha", "f_s = ks (p + 2) / (2 pi) cos^p alpha",
       L2, "Specular highlights", "tracer/phong.py: phong_lobe"),
    _m("blinn-phong-with-phong-normalization",
       "The Blinn-Phong lobe normalised with Phong's factor.",
       "f_s = ks (p + 2) / (2 pi) cos^p theta_h",
       "f_s = ks (p + 2)(p + 4) / (8 pi (2^(-p/2) + p)) cos^p theta_h",
       L2, "Specular highlights", "tracer/phong.py: blinn_phong_lobe"),
    _m("half-vector-unnormalized",
       "The half vector is not normalised.",
       "h = wi + wo", "h = (wi + wo) / |wi + wo|",
       L2, "Specular highlights", "tracer/phong.py: blinn_phong_lobe"),
    _m("checkerboard-uv-swap",
       "The checkerboard is looked up at (v, u).",
       "(u', v') = (s_u v, s_v u)", "(u', v') = (s_u u, s_v v)",
       L2, "The BRDF", "tracer/texture.py: checkerboard"),
    _m("bitmap-v-flipped",
       "A bitmap texture's v is measured from the image's bottom row, as in OpenGL, not from "
       "its top row as Mitsuba does.",
       "row = (1 - v) height", "row = v height",
       L2, "The BRDF", "tracer/texture.py: bitmap"),
    _m("latlong-z-not-negated",
       "An environment map's longitude is measured from +z, not from -z as Mitsuba's "
       "lat-long maps are: the map turned half a revolution.",
       "u = atan2(d.x, d.z) / (2 pi)", "u = atan2(d.x, -d.z) / (2 pi)",
       L2, "Point and directional lights", "tracer/texture.py: latlong"),
    # --- Mitsuba XML read as Mitsuba reads it (the importer, tracer/mitsuba_xml.py) --------
    # Judged by the structure verdict: Mitsuba's own reading of the file against its
    # reading of the import (reference/renderers/mitsuba/original.py).
    _m("xml-steps-reversed",
       "The steps of a <transform> are composed last step first.",
       "<transform> A B C -> M = A B C", "M = C B A (Mitsuba applies the first step first)",
       L2, "Intersecting transformed objects", "tracer/mitsuba_xml.py: in_order",
       stage="import"),
    _m("xml-rotate-axis-normalised",
       "A <rotate> about an axis that is not unit is taken as a rotation about its "
       "direction, where Mitsuba 3.9.1 uses the axis as written (Rodrigues' formula with "
       "the raw vector: a rotation, a scale and a shear).",
       "R(a / |a|, angle)", "c I + (1 - c) a a^T + s [a]x with a as written",
       L2, "Intersecting transformed objects", "tracer/mitsuba_xml.py: _Importer.to_world",
       stage="import"),
    _m("xml-fov-axis-ignored",
       "A perspective sensor's fov_axis is dropped, so its fov is always the horizontal one.",
       "fov_x = fov", "fov_x from fov along fov_axis (x, y, diagonal, smaller, larger)",
       L1, "Perspective camera construction", "tracer/mitsuba_xml.py: _Importer.field_of_view",
       stage="import"),
    _m("xml-to-uv-dropped",
       "A bitmap texture's <transform name=\"to_uv\"> is dropped: the image is shown once "
       "instead of scaled and moved.",
       "uv' = uv", "uv' = to_uv (u, v, 1)",
       L2, "Interpolating normals", "tracer/mitsuba_xml.py: _Importer.texture",
       stage="import"),
    # --- image files (tracer/imageio.py) ----------------------------------------------------
    # Judged by the files verdict: the tracer's PNG against Mitsuba's own sRGB encoding.
    _m("png-gamma-2.2",
       "The PNG writer encodes with a plain gamma of 2.2 instead of the sRGB curve.",
       "code = round(255 x^(1/2.2))",
       "code = round(255 (12.92 x if x <= 0.0031308 else 1.055 x^(1/2.4) - 0.055)), "
       "IEC 61966-2-1", L1, "Quick radiometry recap", "tracer/imageio.py: to_srgb8",
       stage="output"),
    _m("png-truncated",
       "The PNG writer truncates to 8 bits instead of rounding: every code up to one low.",
       "code = floor(255 srgb(x))", "code = round(255 srgb(x))",
       L1, "Quick radiometry recap", "tracer/imageio.py: to_srgb8", stage="output"),
    _m("classic-reflection-tinted",
       "In Whitted's model the reflected ray is tinted by the surface colour.",
       "I = ... + ks colour S", "I = ... + ks S",
       L1, "The Illumination Equation with recursion",
       "tracer/materials/classic.py: BSDF.delta_lobes"),
)

BY_ID: dict[str, Mutant] = {m.id: m for m in CATALOG}
faults.declare(BY_ID)


def get(ids: Iterable[str]) -> list[Mutant]:
    """The catalog entries of ``ids`` (in catalog order); one-line ``UserError`` if unknown."""
    from whitted.tracer.errors import UserError

    ids = list(ids)
    unknown = [i for i in ids if i not in BY_ID]
    if unknown:
        raise UserError(f"unknown mutant {unknown[0]!r} (whitted mutants --list shows the "
                        f"{len(CATALOG)} ids)")
    wanted = set(ids)
    return [m for m in CATALOG if m.id in wanted]


# ------------------------------------------------------------------------------ margins


def margin(checks: dict) -> tuple[float, str]:
    """(how many times the most violated check exceeds its limit, that check's name).

    For a check "value < limit" the margin is value / limit; for the z-test's
    "fraction passing >= limit" it is the failing fraction over the allowed one,
    (1 - value) / (1 - limit). Above 1 the check fails; NaN (a render that
    produced NaN) counts as infinitely far.
    """
    worst, name = -math.inf, ""
    for k, c in checks.items():
        v, lim = c["value"], c["limit"]
        if v is None or (isinstance(v, float) and math.isnan(v)):
            m = math.inf
        elif k == "z_fraction_passed":
            m = (1 - v) / (1 - lim)
        else:
            m = v / lim if lim > 0 else (math.inf if v > 0 else 0.0)
        if not c["pass"]:
            m = max(m, 1.0)   # a failing check is at least at its limit
        if m > worst:
            worst, name = m, k
    return worst, name


# ------------------------------------------------------------------------------ the sweep

#: Sweep sizes: ``quick`` for the test suite and the quick report, ``full`` the scenes'
#: own sizes (as ``whitted compare``).
QUICK_WIDTH = 64
QUICK_SPP = 16


def sweep_size(scene, quick: bool):
    """The scene at the sweep's size: at most QUICK_WIDTH pixels wide and QUICK_SPP spp."""
    if not quick:
        return scene
    w, h = scene.film.width, scene.film.height
    if w > QUICK_WIDTH:
        h = max(8, round(h * QUICK_WIDTH / w))
        w = QUICK_WIDTH
    return scene.with_overrides(size=(w, h), spp=min(scene.film.spp, QUICK_SPP))


@dataclass
class Unit:
    """One verdict of a scene, as ``whitted compare`` judges it, with its reference kept.

    Besides the image verdicts, two that judge what no image comparison sees: the
    tracer's PNG file against Mitsuba's own sRGB encoding of the same image
    (``files``, :mod:`reference.verdicts.files`), and the scene written as Mitsuba XML
    (``whitted export``) and imported back, against Mitsuba's reading of that file
    (``structure``, :mod:`reference.renderers.mitsuba.original`)."""
    label: str          # "deterministic", "tracer-only model", "second opinion", ...
    reference: str      # "deterministic", "onelobe", "files" or "structure"
    test: str           # "exact-strata", "tessellated", "z-test", "png" or "structure"
    scene: object
    ref: object         # an image (deterministic) or a ReferenceResult (onelobe)
    reached: frozenset = frozenset()
    regions: dict | None = None
    clean_margin: float = 0.0
    clean_check: str = ""
    clean_passed: bool = True
    #: the tracer's clean image (deterministic units; the files unit's input)
    image: object = None
    #: the Mitsuba XML file the structure unit imports
    xml: Path | None = None

    def judge(self, tracer_image=None, scene=None) -> dict:
        """The verdict's checks for a tracer image (the tracer renders here for z-tests, of
        ``scene``, by default the unit's own)."""
        from whitted.reference.verdicts.compare import image_metrics, judge, statistical_verdict

        if self.reference == "structure":
            from whitted.reference.renderers.mitsuba.original import compare_structure

            s = compare_structure(self.xml)
            return {"structure": {"value": s.margin, "limit": 1.0, "pass": s.agrees}}
        if self.reference == "files":
            from whitted.reference import mitsuba
            from whitted.reference.verdicts.files import png_checks

            return png_checks(self.image, mitsuba())
        if self.reference == "onelobe":
            return statistical_verdict(scene or self.scene, self.ref, tracer_image,
                                       regions=self.regions, with_flip=False).verdict.checks
        metrics = image_metrics(tracer_image, self.ref, with_flip=False)
        verdict, _ = judge(self.test, metrics, tracer_image, self.ref, scene=scene or self.scene)
        return verdict.checks

    def judge_clean(self) -> None:
        """The tracer as written: its checks, and which switches the verdict asked about."""
        from whitted.reference.verdicts.compare import shared_tracer_image

        with faults.recording() as asked:
            image = shared_tracer_image(self.scene) if self.renders_tracer else None
            checks = self.judge(image)
        if image is not None:
            self.image = image
        self.reached = frozenset(asked)
        self.clean_margin, self.clean_check = margin(checks)
        self.clean_passed = all(c["pass"] for c in checks.values())

    @property
    def renders_tracer(self) -> bool:
        """Whether the verdict takes a tracer image rendered here (the deterministic
        reference's); the one-lobe verdict renders its own, the others none."""
        return self.reference == "deterministic"


def scene_units(scene, log: Callable[[str], None] | None = None,
                workdir: Path | None = None) -> list[Unit]:
    """The verdicts ``whitted compare`` gives ``scene``, each with its reference rendered once.

    As :func:`reference.verdicts.compare.compare_scene`: the scene with declared
    tracer-only parts replaced is judged against the deterministic reference;
    a declared part with a harness model (Schlick) is judged as it is against
    the deterministic reference with that model; an area-lit scene also gets
    the one-lobe reference's statistical verdict at the second opinion's size.
    Then the tracer's PNG of the deterministic verdict's image (``files``) and, with a
    ``workdir`` to write it in, the scene exported as Mitsuba XML and imported back
    (``structure``; a scene the importer refuses, such as the classic model's, has none).
    Each unit's clean verdict, and which switches its render reached, are recorded.
    """
    from whitted.reference.materials import has_tracer_only_models
    from whitted.reference.renderers.mitsuba.deterministic import shares_light_samples
    from whitted.reference.renderers.mitsuba.render import deterministic_image, render_reference
    from whitted.reference.verdicts.compare import (
        choose_test,
        comparable,
        regions_of,
        second_opinion_scene,
        ztest_passes,
    )
    from whitted.tracer.integrator import material_ids

    full = scene
    scene = comparable(scene)
    units = []
    if shares_light_samples(scene):
        units.append(Unit("deterministic", "deterministic", choose_test(scene),
                          scene, deterministic_image(scene)))
        if scene is not full and has_tracer_only_models(full):
            units.append(Unit("tracer-only model", "deterministic", choose_test(full), full,
                              deterministic_image(full, models=True)))
        second = scene.samples_lights()
    else:
        second = True   # no shared light samples: the one-lobe reference judges it alone
    if second:
        small = second_opinion_scene(scene)
        ref = render_reference(small, "whitted", moments=True,
                               passes=ztest_passes(small.film.strata ** 2))
        units.append(Unit("second opinion" if units else "onelobe", "onelobe", "z-test", small,
                          ref, regions=regions_of(material_ids(small), list(small.materials))))
    for u in units:
        u.judge_clean()
    extra = []
    if units[0].image is not None:
        extra.append(Unit("image file", "files", "png", scene, None, image=units[0].image))
    xml = _exported(full, workdir) if workdir is not None else None
    if xml is not None:
        extra.append(Unit("structure", "structure", "structure", full, None, xml=xml))
    for u in extra:
        u.judge_clean()
    return units + extra


def _exported(scene, workdir: Path) -> Path | None:
    """The scene written as Mitsuba XML into ``workdir`` (``whitted export``), or None where
    the importer refuses the file (it holds a kind only the harness's plugins know)."""
    from whitted.reference.renderers.mitsuba.scene import write_xml
    from whitted.tracer.errors import UserError
    from whitted.tracer.mitsuba_xml import read_xml

    folder = workdir / scene.name
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{scene.name}.xml"
    write_xml(scene, path, integrator="direct")
    try:
        read_xml(path)
    except UserError:
        return None
    return path


def xml_unit(name: str, path: Path) -> Unit:
    """The structure verdict of a Mitsuba XML file (the importer judged by Mitsuba's own
    reading of it), judged as the tracer's importer is written."""
    u = Unit("structure", "structure", "structure", name, None, xml=Path(path))
    u.judge_clean()
    return u


def structure_sources(pattern: str | None = None) -> list[tuple[str, Path]]:
    """Mitsuba's own scenes (package data, :mod:`whitted.scenes`) whose import the sweep
    judges by Mitsuba's reading of the file: the report's imported group, a bitmap under
    ``to_uv`` (``texture_interp``) and a rotation about an unnormalised axis (``hello``);
    with a glob ``pattern``, those whose file name matches it."""
    import fnmatch

    from whitted.reference.renderers.mitsuba.importer import (
        MITSUBA_DATA,
        MITSUBA_DATA_DIR,
        imported_cases,
    )

    out = [(f"{c.xml.stem}.xml", c.xml) for c in imported_cases(True) if c.xml is not None]
    out.append(("test_texture_interp_direct.xml",
                MITSUBA_DATA / "texture_interp" / "test_texture_interp_direct.xml"))
    out.append(("hello.xml", MITSUBA_DATA_DIR / "scenes" / "hello.xml"))
    if pattern:
        out = [(n, p) for n, p in out if fnmatch.fnmatch(n, pattern)
               or fnmatch.fnmatch(p.stem, pattern)]
    return out


@dataclass
class Catch:
    """A scene whose verdict fails with a bug switched on."""
    scene: str
    verdict: str        # the unit that failed: "deterministic", "second opinion", ...
    margin: float       # how many times the most violated check exceeds its limit
    check: str


@dataclass
class MutantResult:
    id: str
    summary: str
    topic: str
    references: list[str]
    caught_by: list[Catch] = field(default_factory=list)
    #: scenes whose render reaches the switch but whose verdict passes
    passed: list[str] = field(default_factory=list)
    #: scenes where the switch is reached only by verdicts blind to it (shared code)
    blind: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def caught(self) -> bool:
        return bool(self.caught_by)

    @property
    def strongest(self) -> Catch | None:
        return max(self.caught_by, key=lambda c: c.margin, default=None)

    @property
    def weakest(self) -> Catch | None:
        return min(self.caught_by, key=lambda c: c.margin, default=None)


@dataclass
class SceneResult:
    name: str
    size: tuple[int, int]
    spp: int
    verdicts: list[dict]        # label, reference, test, clean pass, clean margin
    passed: bool
    seconds: float = 0.0


@dataclass
class SweepResult:
    quick: bool
    scenes: list[SceneResult]
    mutants: list[MutantResult]
    seconds: float = 0.0

    @property
    def clean_passed(self) -> bool:
        return all(s.passed for s in self.scenes)

    @property
    def all_caught(self) -> bool:
        return all(m.caught for m in self.mutants)

    @property
    def passed(self) -> bool:
        return self.clean_passed and self.all_caught

    def to_json(self) -> dict:
        out = {"pass": self.passed, "quick": self.quick, "seconds": self.seconds,
               "clean_passed": self.clean_passed, "all_caught": self.all_caught,
               "scenes": [asdict(s) for s in self.scenes], "mutants": []}
        for m in self.mutants:
            d = asdict(m)
            d["caught"] = m.caught
            d["strongest"] = None if m.strongest is None else asdict(m.strongest)
            d["weakest"] = None if m.weakest is None else asdict(m.weakest)
            d["shared"] = BY_ID[m.id].shared if m.id in BY_ID else False
            out["mutants"].append(d)
        return out


def sweep(scene_paths: list[Path], mutants: list[Mutant] | None = None, quick: bool = True,
          log: Callable[[str], None] = print,
          between: Callable[[], None] | None = None,
          xml_sources: list[tuple[str, Path]] = (), last_first: bool = False) -> SweepResult:
    """Judge the tracer as written and with each bug on every scene (module docstring).

    ``xml_sources``: (name, path) of Mitsuba XML files judged by the structure verdict
    alone (:func:`structure_sources`), after the scenes. ``between()``, when given, is
    called before each scene and each bug's judgement (``whitted report``:
    reference.renderers.luxcore.render.SharedCores.poll). ``last_first``: judge the
    scenes from the last to the first (the quick report's worker, beside the comparisons,
    which go from the first: reference.report.sweep_worker); the result is the same, its
    lists in the given order."""
    import shutil
    import tempfile

    from whitted.reference.verdicts.compare import at_strata_centres
    from whitted.tracer import load_scene

    def read(p):
        """The scene as compare judges it: at the sweep's size, its samples at the strata
        centres with the box filter (a scene's jitter or wider filter moves and weighs the
        same samples alike on both sides, :func:`~reference.verdicts.compare.at_strata_centres`)."""
        return at_strata_centres(sweep_size(load_scene(p), quick))

    start = time.perf_counter()
    mutants = list(CATALOG if mutants is None else mutants)
    results = {m.id: MutantResult(m.id, m.summary, m.topic, list(m.references))
               for m in mutants}
    scenes_out = []
    scenes = []
    for p in scene_paths:   # validated first; the switches asked while each file is read
        with faults.recording() as asked:
            scenes.append((p, read(p), frozenset(asked)))
    total = len(scenes) + len(xml_sources)
    workdir = Path(tempfile.mkdtemp(prefix="whitted-sweep-"))
    try:
        jobs = [(scene.name, (scene.film.width, scene.film.height), scene.film.strata ** 2,
                 lambda scene=scene: scene_units(scene, workdir=workdir), read_asked,
                 lambda p=path: read(p))
                for path, scene, read_asked in scenes]
        jobs += [(name, (0, 0), 0, lambda n=name, x=xml: [xml_unit(n, x)], frozenset(), None)
                 for name, xml in xml_sources]
        outcomes: dict[int, list] = {}   # job index -> (bug id, outcome) in judging order
        order = range(len(jobs) - 1, -1, -1) if last_first else range(len(jobs))
        for done, j in enumerate(order, 1):
            name, size, spp, make_units, read_asked, reread = jobs[j]
            outcomes[j] = []
            t0 = time.perf_counter()
            if between is not None:
                between()
            units = make_units()
            clean = all(u.clean_passed for u in units)
            reached = frozenset().union(*(u.reached for u in units), read_asked)
            todo = [m for m in mutants if m.id in reached]
            for m in todo:
                if between is not None:
                    between()
                t1 = time.perf_counter()
                outcome = _judge_mutant(m, units, reread)
                results[m.id].seconds += time.perf_counter() - t1
                if isinstance(outcome, Catch):
                    outcome.scene = name
                outcomes[j].append((m.id, outcome))
            seconds = time.perf_counter() - t0
            scenes_out.append((j, SceneResult(
                name, size, spp,
                [{"verdict": u.label, "reference": u.reference, "test": u.test,
                  "pass": u.clean_passed, "margin": u.clean_margin, "check": u.clean_check}
                 for u in units], clean, seconds)))
            caught = sum(1 for _, o in outcomes[j] if isinstance(o, Catch))
            log(f"[{done}/{total}] {name:<22} tracer as written: "
                f"{'pass' if clean else 'FAIL'} "
                f"(margin {max(u.clean_margin for u in units):.2f}); "
                f"{len(todo)} mutants reach it, {caught} caught ({seconds:.1f} s)")
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    for j in sorted(outcomes):   # each bug's scenes in the given order, however judged
        name = jobs[j][0]
        for mid, outcome in outcomes[j]:
            r = results[mid]
            if isinstance(outcome, Catch):
                r.caught_by.append(outcome)
            elif outcome == "blind":
                r.blind.append(name)
            elif outcome.startswith("error"):
                r.errors.append(f"{name}: {outcome}")
            else:
                r.passed.append(name)
    return SweepResult(quick, [s for _, s in sorted(scenes_out, key=lambda js: js[0])],
                       list(results.values()), time.perf_counter() - start)


def _judge_mutant(m: Mutant, units: list[Unit], reread: Callable | None = None):
    """A Catch from the first of the scene's verdicts that fails with ``m`` on, else why not.

    A bug decided while the file is read (``stage == "parse"``) is judged on the scene
    read again with it on (``reread()``): its camera, lights and shapes replace those of
    each image verdict's scene, whose film and materials stay the verdict's own. The
    files and structure verdicts judge the bugs whose switches they asked about (the
    image writer's, the importer's and what the import reads of the tracer)."""
    from dataclasses import replace

    from whitted.reference.verdicts.compare import (
        shared_tracer_image,  # a new render with the bug on
    )

    fresh = None
    images = [u for u in units if u.reference in ("deterministic", "onelobe")]
    if m.stage == "parse" and reread is not None and images:
        try:
            with faults.active(m.id):
                fresh = reread()
        except Exception as e:  # the bug made the file unreadable: not the harness's catch
            return f"error: {type(e).__name__}: {e}"
    seen_by_any = False
    for u in units:
        scene = u.scene
        if fresh is not None and u in images:
            scene = replace(u.scene, camera=fresh.camera, lights=fresh.lights,
                            shapes=fresh.shapes, groups=fresh.groups)
        elif m.id not in u.reached:
            continue          # this verdict never asks for the switch
        if m.shared and u.reference == "deterministic":
            continue          # the reference reads the same code: blind by construction
        seen_by_any = True
        try:
            # the bug's number an input of the kernel: one kernel a scene serves every bug
            # decided by faults.pick (issue 33), the same images
            with faults.active(m.id, shared_kernel=True):
                image = shared_tracer_image(scene) if u.renders_tracer else None
                checks = u.judge(image, scene)
        except Exception as e:  # a bug that crashes the tracer is not a catch of the harness
            return f"error: {type(e).__name__}: {e}"
        if not all(c["pass"] for c in checks.values()):
            value, check = margin(checks)
            return Catch("", u.label, value, check)
    return "passed" if seen_by_any else "blind"


# ------------------------------------------------------------------------------ output


def format_margin(x: float) -> str:
    if math.isinf(x):   # a NaN image, or a structure that differs in kind or size
        return "inf"
    return f"{x:.3g}"


def format_table(result: SweepResult) -> str:
    """The sweep as text: the tracer as written per scene, then one row per bug."""
    lines = [f"tracer as written: {sum(s.passed for s in result.scenes)}/{len(result.scenes)} "
             "scenes pass"]
    for s in result.scenes:
        if not s.passed:
            bad = [v for v in s.verdicts if not v["pass"]]
            lines.append(f"  FAIL {s.name}: " + ", ".join(
                f"{v['verdict']} {v['check']} x{format_margin(v['margin'])}" for v in bad))
    width = max((len(m.id) for m in result.mutants), default=10)
    lines.append("")
    lines.append(f"{'mutant':<{width}}  {'reference':<13} {'caught':>6}  "
                 f"{'strongest (margin)':<34} scenes whose verdict fails (margin)")
    for m in result.mutants:
        ref = BY_ID[m.id].seen_by if m.id in BY_ID else "both"
        best = m.strongest
        strongest = (f"{best.scene} ({format_margin(best.margin)}, {best.check})"
                     if best else "NOT CAUGHT")
        scenes = ", ".join(f"{c.scene} {format_margin(c.margin)}"
                           for c in sorted(m.caught_by, key=lambda c: -c.margin))
        lines.append(f"{m.id:<{width}}  {ref:<13} {len(m.caught_by):>6}  {strongest:<34} "
                     f"{scenes}")
        if m.errors:
            lines.append(f"{'':<{width}}  errors: {'; '.join(m.errors)}")
    missed = [m.id for m in result.mutants if not m.caught]
    barely = [m.id for m in result.mutants if m.caught and m.strongest.margin < 2]
    lines.append("")
    lines.append(f"{sum(m.caught for m in result.mutants)}/{len(result.mutants)} mutants "
                 f"caught" + (f"; NOT CAUGHT: {', '.join(missed)}" if missed else "")
                 + (f"; caught by less than twice a limit: {', '.join(barely)}"
                    if barely else ""))
    lines.append(("PASS" if result.passed else "FAIL") +
                 f" ({'quick' if result.quick else 'full'} sizes, {result.seconds:.0f} s)")
    return "\n".join(lines)


def catalog_table() -> str:
    """The catalog as text (``whitted mutants --list``)."""
    lines = []
    for m in CATALOG:
        lines.append(f"{m.id}  [{m.topic}; {m.where}"
                     f"{'; shared with the deterministic reference' if m.shared else ''}]")
        lines.append(f"    {m.summary}")
        lines.append(f"    wrong:   {m.wrong}")
        lines.append(f"    correct: {m.correct}")
    return "\n".join(lines)


def matrix(result: SweepResult) -> tuple[list[str], list[list[str]]]:
    """(scene names, rows): per bug and scene the margin of a catch, '.' where the verdict
    passes although the switch is reached, 'b' where only blind verdicts reach it, '' where
    the scene never reaches it."""
    names = [s.name for s in result.scenes]
    rows = []
    for m in result.mutants:
        by = {c.scene: c for c in m.caught_by}
        row = []
        for n in names:
            if n in by:
                row.append(format_margin(by[n].margin))
            elif n in m.passed:
                row.append(".")
            elif n in m.blind:
                row.append("b")
            else:
                row.append("")
        rows.append(row)
    return names, rows


def markdown(result: SweepResult) -> str:
    """The sweep as Markdown: the tracer as written per scene, then one row per bug."""
    lines = [f"# whitted mutants: {'PASS' if result.passed else 'FAIL'}", "",
             f"{len(result.mutants)} formula bugs (`reference/mutants.py`) against "
             f"{len(result.scenes)} scenes at {'quick' if result.quick else 'full'} sizes, "
             f"{result.seconds:.0f} s. Margin: how many times the most violated check of a "
             "failing verdict exceeds its limit.", "",
             "| scene | size, spp | verdicts of the tracer as written (largest check / limit) "
             "| result |", "|---|---|---|---|"]
    for s in result.scenes:
        v = "; ".join(f"{x['verdict']} ({x['test']}) {x['margin']:.2f} {x['check']}"
                      for x in s.verdicts)
        lines.append(f"| {s.name} | {s.size[0]}x{s.size[1]}, {s.spp} | {v} | "
                     f"{'pass' if s.passed else '**FAIL**'} |")
    lines += ["", "| mutant | lecture topic | seen by | caught by | strongest (margin) | "
              "weakest (margin) | scenes whose verdict fails (margin) |",
              "|---|---|---|---|---|---|---|"]
    for m in result.mutants:
        best, worst = m.strongest, m.weakest
        scenes = ", ".join(f"{c.scene} {format_margin(c.margin)}"
                           for c in sorted(m.caught_by, key=lambda c: -c.margin))
        lines.append(
            f"| `{m.id}` | {m.topic} | {', '.join(m.references)} | {len(m.caught_by)} | "
            + (f"{best.scene} ({format_margin(best.margin)}, {best.check}) | "
               f"{worst.scene} ({format_margin(worst.margin)}, {worst.check})"
               if best else "**NOT CAUGHT** | ") + f" | {scenes} |")
    lines.append("")
    return "\n".join(lines)
