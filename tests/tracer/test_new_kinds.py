"""The material kinds of Mitsuba's BSDF set beyond the lectures': their data and formulas.

Each kind is also rendered against Mitsuba by the built-in scene that shows it
(``scenes/metals.toml``, ...: ``tests/e2e/test_cross_render.py`` at float
precision), and its formula bug is caught by ``whitted mutants``
(``tests/reference/test_mutants.py``); here the parts that are checked on their own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from whitted.reference import mutants  # noqa: F401  (declares the catalog's fault ids)
from whitted.tracer import faults
from whitted.tracer.ior import CONDUCTORS, DIELECTRICS
from whitted.tracer.scene import SceneError, parse_scene


def test_named_indices_are_mitsubas(mi):
    # The tables are Mitsuba's own values rounded to 6 decimals (docs/ior_tables.py), so
    # they agree to 5e-7 plus float32 rounding of the value (6e-8 relative).
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "ior_tables", Path(__file__).resolve().parents[2] / "docs" / "ior_tables.py")
    tables = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tables)
    for name in tables.DIELECTRIC_NAMES:
        assert DIELECTRICS[name] == pytest.approx(tables.dielectric_ior(mi, name), abs=6e-7)
    assert set(CONDUCTORS) - {"none"} == set(tables.conductor_names(mi))
    for name in CONDUCTORS:
        if name == "none":
            continue
        eta, k = tables.conductor_rgb(mi, name)
        np.testing.assert_allclose(CONDUCTORS[name][0], eta, atol=6e-7, rtol=6e-8)
        np.testing.assert_allclose(CONDUCTORS[name][1], k, atol=6e-7, rtol=6e-8)


def test_conductor_fresnel_matches_mitsuba_within_float32_rounding(mi):
    from whitted.reference.teaching.fresnel_curves import conductor_curves

    rows = conductor_curves(mi, step=1.0)
    assert rows and all(r["pass"] for r in rows), [r for r in rows if not r["pass"]]
    # The same check sees a conductor Fresnel term without k (the catalog's bug).
    with faults.active("conductor-k-ignored"):
        broken = conductor_curves(mi, names=("Au",), step=1.0)
    assert not all(r["pass"] for r in broken)


def _material(table: dict):
    scene = parse_scene({"film": {"width": 8, "height": 8},
                         "camera": {"origin": [0, 0, 5], "target": [0, 0, 0]},
                         "materials": {"m": table},
                         "lights": [{"type": "point", "position": [0, 1, 0], "intensity": 1}],
                         "shapes": [{"type": "sphere", "material": "m"}]})
    return scene.materials["m"]


def test_named_iors_and_conductors_are_read_and_unknown_names_refused():
    assert _material({"type": "dielectric", "ior": "bk7", "ext_ior": "air"}).eta == \
        pytest.approx(1.5046 / 1.000277)
    assert _material({"type": "conductor", "material": "Au"}).eta == CONDUCTORS["Au"][0]
    assert _material({"type": "conductor"}).k == (1.0, 1.0, 1.0)  # "none": a mirror
    with pytest.raises(SceneError, match="unknown index of refraction 'glas'"):
        _material({"type": "dielectric", "ior": "glas"})
    with pytest.raises(SceneError, match="unknown conductor 'Gold'"):
        _material({"type": "conductor", "material": "Gold"})
    with pytest.raises(SceneError, match="either material or eta and k"):
        _material({"type": "conductor", "material": "Au", "eta": 1, "k": 1})
    with pytest.raises(SceneError, match="two_sided"):
        _material({"type": "diffuse", "two_sided": 0})


def test_diffuse_fresnel_reflectance_fit_is_mitsubas(mi, jit):
    # Both evaluate the same two published fits in float32 (tracer.fresnel docstring):
    # a few ulps of F_dr <= 1 apart at most (8 ulp of 1 = 1e-6).
    from whitted.tracer import fresnel

    eta = np.linspace(0.2, 5, 400, dtype=np.float32)
    ours = np.asarray(fresnel.fresnel_diffuse_reflectance(jit.Float(eta)))
    theirs = np.asarray(mi.fresnel_diffuse_reflectance(mi.Float(eta)))
    assert np.abs(ours - theirs).max() <= 1e-6
    # F_dr grows from 0 at eta = 1 (no boundary) towards 1 (nearly all light trapped).
    at_one = np.asarray(fresnel.fresnel_diffuse_reflectance(jit.Float([1.0])))[0]
    assert at_one < 1e-3 and ours[0] > 0.9


def test_area_lights_on_a_mesh_a_cube_a_polygon_and_a_cylinder_agree_with_mitsuba(tmp_path):
    # Mitsuba samples these emitters its own way (no shared light samples), so the
    # one-lobe reference judges them by the z-test of reference.verdicts.compare (Sidak alpha
    # 0.01 per pixel, >= 99.75 % passing; regions within alpha 0.001), the tracer's
    # image the mean of 16 seeds.
    from whitted.reference.verdicts.compare import compare_scene
    from whitted.tracer import load_scene

    scene = load_scene(Path(__file__).resolve().parents[1] / "data" / "shape_lights.toml")
    result, tracer_img, _ = compare_scene(scene, tmp_path, second_opinion=False)
    assert result.reference == "onelobe" and result.test == "z-test"
    assert result.passed, result.checks
    assert tracer_img.max() > 0


BITMAP_SCENE = """
[film]
width = 64
height = 48
spp = 4
max_depth = 3
[camera]
origin = [0, 2.5, 4]
target = [0, 0.3, 0]
fov = 50
[materials.floor]
type = "diffuse"
reflectance = {{ bitmap = {{ filename = "tex.png" }} }}
[materials.ball]
type = "plastic"
diffuse_reflectance = {{ bitmap = {{ filename = "tex.png", filter_type = "nearest" }} }}
[materials.star]
type = "diffuse"
reflectance = {{ bitmap = {{ filename = "tex.exr", wrap_mode = "{wrap}", raw = true }} }}
[materials.raw]
type = "diffuse"
reflectance = {{ bitmap = {{ filename = "tex.png", raw = true, wrap_mode = "mirror" }} }}
[[lights]]
type = "point"
position = [1, 4, 3]
intensity = 30
[[shapes]]
type = "rectangle"
material = "floor"
to_world = [ {{ scale = 3 }}, {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }} ]
[[shapes]]
type = "sphere"
center = [-0.9, 0.5, 0]
radius = 0.5
material = "ball"
# Polygons' uvs are their plane's own coordinates, beyond [0, 1]: the wrap modes show.
[[shapes]]
type = "polygon"
material = "star"
vertices = [[0.2, 0.01, -1.0], [1.6, 0.01, -1.2], [1.9, 0.01, 0.4], [0.5, 0.01, 0.8]]
[[shapes]]
type = "polygon"
material = "raw"
vertices = [[-1.8, 0.01, 0.6], [-0.4, 0.01, 0.7], [-0.6, 0.01, 1.6], [-1.9, 0.01, 1.5]]
"""


def _bitmap_scene(tmp_path, wrap="repeat"):
    import tomllib

    from PIL import Image

    from whitted.tracer.imageio import write_exr

    rng = np.random.default_rng(7)
    # Odd sizes, so that rows and columns cannot be swapped unnoticed.
    Image.fromarray(rng.integers(0, 256, (5, 7, 3), dtype=np.uint8)).save(tmp_path / "tex.png")
    write_exr(tmp_path / "tex.exr", rng.uniform(0.05, 0.95, (3, 4, 3)).astype(np.float32))
    return parse_scene(tomllib.loads(BITMAP_SCENE.format(wrap=wrap)),
                       str(tmp_path / "scene.toml"))


@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
def test_bitmap_textures_agree_with_mitsuba_at_float_precision(tmp_path, wrap):
    from whitted.reference.verdicts.compare import compare_scene

    scene = _bitmap_scene(tmp_path, wrap)
    result, tracer_img, _ = compare_scene(scene, tmp_path / "out", second_opinion=False)
    assert result.reference == "deterministic" and result.test == "exact-strata"
    assert result.passed, result.checks
    assert result.metrics["median_rel"] < 1e-5


def test_bitmap_texture_rows_read_from_the_top_as_mitsuba_does(tmp_path):
    # The same comparison fails with v measured from the bottom (the catalog's bug).
    from whitted.reference.verdicts.compare import compare_scene

    scene = _bitmap_scene(tmp_path)
    with faults.active("bitmap-v-flipped"):
        result, _, _ = compare_scene(scene, tmp_path / "out", second_opinion=False)
    assert not result.passed


def test_bitmap_errors_are_one_line(tmp_path):
    import tomllib

    text = BITMAP_SCENE.format(wrap="repeat")
    with pytest.raises(SceneError, match="no such image file"):
        parse_scene(tomllib.loads(text), str(tmp_path / "scene.toml"))
    (tmp_path / "tex.png").write_bytes(b"not a png")
    with pytest.raises(SceneError, match="cannot read tex.png"):
        parse_scene(tomllib.loads(text), str(tmp_path / "scene.toml"))


# Textured opacity (Mitsuba's mask reads its opacity texture by eval_1): three veils
# before a plain wall, nothing else textured, so a wrong opacity lookup is all that
# can differ. The checkerboard's scale differs in u and v and the bitmap has odd sizes,
# so (u, v) swapped or rows flipped change the image.
MASK_SCENE = """
[film]
width = 64
height = 48
spp = 4
max_depth = 4
[camera]
origin = [0, 1, 4]
target = [0, 0.8, 0]
fov = 45
[materials.wall]
type = "diffuse"
reflectance = [0.2, 0.5, 0.8]
[materials.board]
type = "diffuse"
reflectance = [0.9, 0.6, 0.2]
opacity = { checkerboard = { color0 = 0.9, color1 = [0.1, 0.2, 0.3], scale = [2, 3] } }
[materials.image]
type = "conductor"
material = "Au"
opacity = { bitmap = { filename = "tex.png" } }
[materials.tint]
type = "plastic"
opacity = [0.2, 0.5, 0.9]
[[lights]]
type = "point"
position = [1, 3, 4]
intensity = 30
[[shapes]]
type = "rectangle"
material = "wall"
to_world = [ { scale = [3, 2, 1] }, { translate = [0, 1, -1.5] } ]
[[shapes]]
type = "rectangle"
material = "board"
to_world = [ { scale = [0.6, 0.6, 1] }, { translate = [-1.1, 1, 0] } ]
[[shapes]]
type = "rectangle"
material = "image"
to_world = [ { scale = [0.6, 0.6, 1] }, { rotate = { axis = [0, 1, 0], angle = -25 } },
             { translate = [0.2, 1, 0] } ]
[[shapes]]
type = "sphere"
center = [1.3, 0.7, 0.2]
radius = 0.4
material = "tint"
"""


def _mask_scene(tmp_path):
    import tomllib

    from PIL import Image

    rng = np.random.default_rng(11)
    Image.fromarray(rng.integers(0, 256, (5, 7, 3), dtype=np.uint8)).save(tmp_path / "tex.png")
    return parse_scene(tomllib.loads(MASK_SCENE), str(tmp_path / "scene.toml"))


def test_colour_and_textured_opacity_read_as_mitsubas_eval_1(tmp_path):
    from whitted.tracer.materials.textures import LUMINANCE, Bitmap, Checkerboard

    scene = _mask_scene(tmp_path)
    m = {name: mat.mask_opacity for name, mat in scene.materials.items()}
    # A colour: Mitsuba's srgb eval_1, the channels' mean (3.9.1 answers 0.53333336).
    assert m["tint"] == pytest.approx((0.2 + 0.5 + 0.9) / 3, rel=1e-12)
    assert m["board"] == Checkerboard((0.9,) * 3, ((0.1 + 0.2 + 0.3) / 3,) * 3, (2.0, 3.0))
    assert isinstance(m["image"], Bitmap)
    from PIL import Image

    from whitted.tracer.materials.textures import srgb_decode

    rgb = srgb_decode(np.asarray(Image.open(tmp_path / "tex.png"), np.float64) / 255)
    np.testing.assert_allclose(m["image"].texels[..., 1], rgb @ np.asarray(LUMINANCE),
                               rtol=1e-6)  # float32 storage of the luminance


def test_textured_opacity_agrees_with_mitsuba_at_float_precision(tmp_path):
    # The deterministic reference follows the mask's null lobe with Mitsuba's own
    # BSDF.sample at the same uv: agreement to float32 rounding (the median relative
    # difference of the bitmap test above) is expected.
    from whitted.reference.verdicts.compare import compare_scene

    scene = _mask_scene(tmp_path)
    result, tracer_img, _ = compare_scene(scene, tmp_path / "out", second_opinion=False)
    assert result.reference == "deterministic" and result.test == "exact-strata"
    assert result.passed, result.checks
    assert result.metrics["median_rel"] < 1e-5


@pytest.mark.parametrize("fault", ["checkerboard-uv-swap", "bitmap-v-flipped"])
def test_textured_opacity_looked_up_wrongly_is_caught(tmp_path, fault):
    # The opacity is read through the same texture lookup as a reflectance: with the
    # checkerboard at (v, u) or the bitmap's rows from the bottom the comparison fails.
    from whitted.reference.verdicts.compare import compare_scene

    scene = _mask_scene(tmp_path)
    with faults.active(fault):
        result, _, _ = compare_scene(scene, tmp_path / "out", second_opinion=False)
    assert not result.passed


@pytest.mark.parametrize("colour", [(0.2, 0.5, 0.9), (1.0, 0.0, 0.25), (0.7, 0.7, 0.7)])
def test_colour_opacity_is_the_value_mitsubas_mask_reads(mi, colour):
    # The conversion hands Mitsuba the one value (a float), so the cross-render above
    # cannot tell a wrong reading of a colour: here Mitsuba's own mask is asked, by its
    # null transmission 1 - opacity, for the opacity of an rgb colour. Tolerance: four
    # float32 roundings on Mitsuba's side (the mean's sum and division, 1 - o, and
    # 1 - that here), each at most 2^-24 of a value up to 1.
    import drjit as dr

    from whitted.tracer.materials.textures import scalar_texture

    mask = mi.load_dict({"type": "mask", "opacity": {"type": "rgb", "value": colour},
                         "material": {"type": "diffuse"}})
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    through = mask.eval_null_transmission(si)
    assert abs((1 - through.x[0]) - scalar_texture(colour)) <= 4 * 2.0 ** -24
