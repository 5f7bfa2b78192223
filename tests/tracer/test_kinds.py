"""Material and light kinds: one module each, found through registries, dispatched per lane.

The built-in kinds are tested by the renders elsewhere; here the interface
itself: every registered kind is complete on both sides, parsing a scene
does not start Dr.Jit, and kinds registered at run time (defined in this
file, not in the package) are parsed, dispatched and rendered with the hooks
no built-in kind uses yet: a smooth part and a delta lobe in one kind, a
lobe that is no scattering event (letter ""), and a light at infinity.
"""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import ROOT, SCENES

from whitted.reference import emitters as ref_emitters
from whitted.reference import materials as ref_materials
from whitted.tracer import emitters, materials
from whitted.tracer.emitters import base as emitter_base
from whitted.tracer.materials import base
from whitted.tracer.scene import parse_scene


def test_every_kind_has_a_parser_a_tracer_behaviour_and_a_mitsuba_conversion():
    assert list(materials.REGISTRY) == list(ref_materials.REGISTRY)
    for name, module in materials.REGISTRY.items():
        assert issubclass(module.MODEL, base.MaterialModel), name
        assert issubclass(module.BSDF, base.BSDF), name
        assert callable(module.parse) and callable(ref_materials.REGISTRY[name].mitsuba), name
        bsdf = module.BSDF
        assert bsdf.smooth or bsdf.lobes, f"{name}: neither a smooth part nor delta lobes"
    assert list(emitters.LIGHTS) + list(emitters.SHAPE_LIGHTS) == list(ref_emitters.REGISTRY)
    for name, module in {**emitters.LIGHTS, **emitters.SHAPE_LIGHTS}.items():
        assert issubclass(module.MODEL, emitter_base.LightModel), name
        assert issubclass(module.Emitter, emitter_base.Emitter), name
        assert callable(ref_emitters.REGISTRY[name].mitsuba), name
        # [[lights]] kinds are parsed from their table; shape lights are made by materials
        assert callable(getattr(module, "parse", None)) == (name in emitters.LIGHTS), name


def test_parsing_a_scene_does_not_start_drjit():
    # The backend and its libLLVM are chosen after a scene is validated, so parsing
    # (which imports every kind) must not import Dr.Jit. Polygon validation is the
    # one exception (tracer/shapes/polygon.py), so scenes with polygons are left out.
    paths = [str(p) for p in sorted(SCENES.glob("*.toml"))
             if 'type = "polygon"' not in p.read_text()]
    code = ("import sys, tracer\n"
            f"for p in {paths!r}: tracer.load_scene(p)\n"
            "print(sorted(m for m in sys.modules if m == 'drjit' or m.startswith('drjit.')))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]", r.stdout


# ---------------------------------------------------------------------------------------
# Kinds registered at run time
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Veil(base.MaterialModel):
    """Lambertian with probability ``opacity``, else the ray passes straight through."""
    opacity: float = 0.0
    color: tuple = (0.5, 0.5, 0.5)


class VeilBSDF(base.BSDF):
    smooth = True
    lobes = (base.Lobe("transmit", ""),)  # passing through is no scattering event

    def __init__(self, ms):
        super().__init__(ms)
        self.opacity = base.floats([m.opacity for m in ms])
        self.color = base.colors([m.color for m in ms])

    def params(self, row, si, active):
        return base.gather(self.opacity, row, active), base.gather(self.color, row, active)

    def eval(self, prm, si, wi):
        opacity, color = prm
        return color * (opacity / math.pi)

    def delta_lobes(self, prm, si):
        return [(si.d, 1 - prm[0])]


VEIL = SimpleNamespace(
    MODEL=Veil, BSDF=VeilBSDF,
    parse=lambda t, name: Veil(name, t.number("opacity", 0.0, lo=0, hi=1),
                               t.color("color", 0.5, hi=1)))


@dataclass(frozen=True)
class Sky(emitter_base.LightModel):
    """Uniform radiance from every direction at infinity (Mitsuba's ``constant``)."""
    radiance: tuple


class SkyEmitter(emitter_base.Emitter):
    delta = False
    infinite = True

    def __init__(self, light):
        self.radiance = emitter_base.color(light.radiance)

    def sample(self, p, origin, u):
        import drjit as dr

        from whitted.tracer import lights

        # A direction uniform on the sphere: pdf 1 / (4 pi), so L / pdf = 4 pi L.
        _, wi = lights.sample_sphere_uniform(u, p * 0, 1.0)
        return wi, dr.full(type(p.x), dr.inf, dr.width(p)), self.radiance * (4 * math.pi)

    def background(self, d):
        return self.radiance


SKY = SimpleNamespace(MODEL=Sky, Emitter=SkyEmitter,
                      parse=lambda t: Sky(t.color("radiance")))

SCENE = """
[film]
width = 48
height = 36
spp = {spp}
max_depth = {depth}
[camera]
origin = [0, 1.5, 5]
target = [0, 0.5, 0]
fov = 40
[materials.white]
type = "diffuse"
reflectance = 0.5
[materials.veil]
type = "veil"
opacity = {opacity}
color = [0.9, 0.2, 0.1]
{lights}
[[shapes]]
type = "rectangle"
material = "white"
to_world = [ {{ scale = 3 }}, {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }} ]
{shapes}
"""
POINT = '[[lights]]\ntype = "point"\nposition = [2, 5, 6]\nintensity = 20'
# A sphere on the floor, and a veil facing the camera in front of it, lit from the front.
SHAPES = """[[shapes]]
type = "sphere"
center = [0, 0.6, 0]
radius = 0.6
material = "white"
[[shapes]]
type = "rectangle"
material = "veil"
to_world = [ { scale = [0.3, 0.25, 1] }, { translate = [0, 0.8, 3.5] } ]"""


def _veiled(opacity, spp=4):
    return SCENE.format(spp=spp, depth=3, opacity=opacity, lights=POINT, shapes=SHAPES)


@pytest.fixture
def registered(monkeypatch):
    monkeypatch.setitem(materials.REGISTRY, "veil", VEIL)
    monkeypatch.setitem(emitters.LIGHTS, "sky", SKY)


def _render(text, lpe=None, seed=0):
    import tomllib

    from whitted.tracer.integrator import Integrator

    return Integrator(parse_scene(tomllib.loads(text)), seed=seed, lpe=lpe).render()


def test_a_lobe_without_a_letter_is_no_vertex_of_the_light_path(jit, registered):
    # The pass-through lobe adds no letter: light seen through a fully transparent
    # veil is still LDE (the whole image), and no path through it is LDSE.
    full = _render(_veiled(0.0)).image
    assert np.array_equal(_render(_veiled(0.0), "LDE").image, full)
    assert not _render(_veiled(0.0), "LDS+E").image.any()
    # What the veil covers is seen through it, not black.
    covered = np.abs(_render(_veiled(1.0)).image - full).sum(-1) > 1e-3
    assert covered.mean() > 0.02 and full[covered].mean() > 0.02


def test_a_kind_with_a_smooth_part_and_a_lobe_mixes_their_images_linearly(jit, registered):
    # f = opacity color / pi and a pass-through of weight 1 - opacity: the image at
    # opacity 1/2 is the mean of the images at 0 (all through) and 1 (all diffuse),
    # to float32 rounding of the sums (a few ulp of the pixel values).
    clear, half = (_render(_veiled(a)).image.astype(np.float64) for a in (0.0, 0.5))
    opaque_run = _render(_veiled(1.0))
    opaque = opaque_run.image.astype(np.float64)
    covered = np.abs(opaque - clear).sum(-1) > 1e-3
    assert covered.mean() > 0.02 and opaque[covered].max() > 0.02  # lit from the front
    assert np.allclose(half, 0.5 * (clear + opaque), rtol=1e-5, atol=1e-7)
    # An opaque veil spawns no rays through it: every ray ends at level 1.
    assert len(opaque_run.rays_per_level) == 1


def test_a_light_at_infinity_is_seen_by_escaping_rays_and_sampled_at_surfaces(jit, registered):
    L, rho, spp = 0.8, 0.5, 256
    sky = f'[[lights]]\ntype = "sky"\nradiance = {L}'
    text = SCENE.format(spp=spp, depth=2, opacity=0.0, lights=sky, shapes="")
    image = _render(text).image.astype(np.float64)
    # Camera rays that miss bring back L exactly (one sample per pixel: no averaging).
    one = _render(SCENE.format(spp=1, depth=2, opacity=0.0, lights=sky, shapes="")).image
    seen = _render(SCENE.format(spp=1, depth=2, opacity=0.0, lights=sky, shapes=""), "LE").image
    assert 0.1 < (seen.sum(-1) > 0).mean() < 0.9
    assert np.all((seen == 0) | (seen == np.float32(L)))
    assert np.array_equal(one[seen.sum(-1) > 0], seen[seen.sum(-1) > 0])
    lpe_le = _render(text, "LE").image
    missed = lpe_le.sum(-1) > 0
    # The floor under the open sky: L_o = rho / pi * pi L = rho L. Each sample's
    # estimate 4 rho L cos+ (cos+ = max(z, 0), z uniform in [-1, 1]) has variance
    # (8/3 - 1)(rho L)^2, so the mean over the N samples of the pixels that see only
    # the floor lies within 5 sigma of rho L (false alarm 6e-7; the strata only
    # lower the variance).
    floor = image[~missed]
    sigma = math.sqrt(5 / 3) * rho * L / math.sqrt(floor.shape[0] * spp)
    assert 5 * sigma < 0.02 * rho * L  # the test sees a 2 % bias
    assert abs(floor.mean() - rho * L) < 5 * sigma, (floor.mean(), rho * L, sigma)
    # Every path here is LE or LDE.
    assert np.allclose(_render(text, "LDE").image + lpe_le, image, rtol=1e-6, atol=0)

    # The tracer samples it, so its image has variance: compared by the z-test with
    # its seeds pooled, unlike a scene lit by delta lights only.
    import tomllib

    from whitted.reference.renderers.mitsuba.deterministic import shares_light_samples
    from whitted.reference.verdicts.compare import choose_test

    assert parse_scene(tomllib.loads(text)).samples_lights()
    # No shared sample points for it: the one-lobe reference and its z-test judge it.
    assert not shares_light_samples(parse_scene(tomllib.loads(text)))
    assert choose_test(parse_scene(tomllib.loads(text)), "onelobe") == "z-test"
    assert not parse_scene(tomllib.loads(_veiled(1.0))).samples_lights()
