"""Mitsuba scenes as people have them: JPEG and Radiance HDR bitmaps, area emitters
declared at the top level and taken by ``<ref>``, the ``tent`` filter, and
``whitted import`` into a folder that does not exist yet.

The truth is what Mitsuba 3.9.1 does with the same file (``mi.Bitmap``,
``mi.load_file`` + ``mi.traverse``, ``mi.render``), not a reading of the XML.
"""

from __future__ import annotations

import dataclasses
import struct
import tomllib
from pathlib import Path

import numpy as np
import pytest

from whitted.tracer.errors import UserError
from whitted.tracer.mitsuba_xml import XMLImportError, read_xml
from whitted.tracer.scene import parse_scene

ROOT = Path(__file__).resolve().parents[4]
CBOX = ROOT / "tests" / "data" / "real_scenes" / "mitsuba-data" / "scenes" / "cbox"
#: A real scene the reader refuses (a rough dielectric).
REFUSED = (ROOT / "tests" / "data" / "real_scenes" / "mitsuba-data" / "tests" / "scenes" /
           "bsdf_spheres" / "test_roughdielectric_path.xml")


@pytest.fixture(scope="module")
def mi():
    from whitted.reference import mitsuba

    return mitsuba()


# ---------------------------------------------------------------- files written here


def _rle_channel(vals: list[int]) -> bytes:
    """One channel of a scanline in Radiance's run-length encoding (runs of 3 or more
    repeated, the rest as literals), as Radiance's ``fwritecolrs`` writes it."""
    out, i, n = bytearray(), 0, len(vals)
    while i < n:
        j = i
        while j < n and j - i < 127 and vals[j] == vals[i]:
            j += 1
        if j - i >= 3:
            out += bytes([128 + j - i, vals[i]])
            i = j
            continue
        lit: list[int] = []
        while i < n and len(lit) < 128 and not (
                i + 2 < n and vals[i] == vals[i + 1] == vals[i + 2]):
            lit.append(vals[i])
            i += 1
        out += bytes([len(lit)]) + bytes(lit)
    return bytes(out)


def write_hdr(path: Path, rgbe: np.ndarray, rle: bool) -> Path:
    """An H x W x 4 uint8 RGBE array as a Radiance HDR file, flat or run-length encoded."""
    h, w, _ = rgbe.shape
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode())
    for y in range(h):
        if rle:
            out += bytes([2, 2, w >> 8, w & 255])
            for c in range(4):
                out += _rle_channel([int(v) for v in rgbe[y, :, c]])
        else:
            out += rgbe[y].tobytes()
    path.write_bytes(bytes(out))
    return path


def _rgbe(rng, h: int, w: int, lo: int = 100, hi: int = 140) -> np.ndarray:
    a = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    a[..., 3] = rng.integers(lo, hi, (h, w))
    a[0, 0, 3] = 0            # E = 0: black whatever the mantissas
    a[1, 2:9] = a[1, 2]       # a run the encoder repeats
    return a


def write_jpeg(path: Path, rng, size=(37, 51), subsampling: int = 2) -> Path:
    from PIL import Image

    img = rng.integers(0, 256, (*size, 3), dtype=np.uint8)
    img[5:15] = (200, 120, 40)  # flat areas and edges, where upsampling differs
    Image.fromarray(img).save(path, quality=85, subsampling=subsampling)
    return path


# ---------------------------------------------------------------- decoding, as Mitsuba


@pytest.mark.parametrize("rle", [False, True], ids=["flat", "rle"])
def test_hdr_decodes_exactly_as_mitsubas_bitmap(mi, tmp_path, rle):
    """m 2^(E - 136) is exact in float32: the tracer's values are Mitsuba's, bit for bit."""
    from whitted.tracer.imageio import read_texture_file

    path = write_hdr(tmp_path / "t.hdr", _rgbe(np.random.default_rng(1), 7, 13), rle)
    ours = read_texture_file(path)
    theirs = np.asarray(mi.Bitmap(str(path)).convert(mi.Bitmap.PixelFormat.RGB,
                                                     mi.Struct.Type.Float32, False))
    assert ours.dtype == np.float32 and ours.shape == (7, 13, 3)
    assert np.array_equal(ours, theirs)


@pytest.mark.parametrize("subsampling", [0, 1, 2], ids=["444", "422", "420"])
def test_jpeg_codes_are_mitsubas(mi, tmp_path, subsampling):
    """Pillow's libjpeg-turbo and Mitsuba's libjpeg give the same 8-bit codes (measured:
    a difference of 0 at 4:4:4, 4:2:2 and 4:2:0), both then decoded as sRGB."""
    from whitted.tracer.imageio import read_texture_file

    path = write_jpeg(tmp_path / "t.jpg", np.random.default_rng(subsampling),
                      subsampling=subsampling)
    bitmap = mi.Bitmap(str(path))
    assert bitmap.srgb_gamma() and bitmap.component_format() == mi.Struct.Type.UInt8
    ours = read_texture_file(path)
    assert ours.dtype == np.uint8
    assert np.array_equal(ours, np.asarray(bitmap))


def test_jpeg_and_hdr_sizes_are_checked_before_decoding(tmp_path, monkeypatch):
    """The JPEG frame header (after a large APP segment, skipped unread) and the HDR
    resolution line give the size; WHITTED_MAX_MEMORY refuses before Pillow runs."""
    from whitted.tracer.imageheader import ImageError, check_image_file, read_header
    from whitted.tracer.imageio import read_texture_file

    jpg = write_jpeg(tmp_path / "t.jpg", np.random.default_rng(3), size=(21, 34))
    data = jpg.read_bytes()
    app = b"\xff\xe1" + struct.pack(">H", 60002) + bytes(60000)  # an Exif-sized APP1
    big = tmp_path / "big.jpg"
    big.write_bytes(data[:2] + app + data[2:])
    for p in (jpg, big):
        h = read_header(p)
        assert (h.format, h.width, h.height, h.channels) == ("jpeg", 34, 21, 3)
    # a frame header claiming 60000 x 60000 pixels: refused from its header alone
    sof = data.index(b"\xff\xc0")
    bomb = tmp_path / "bomb.jpg"
    bomb.write_bytes(data[:sof + 5] + struct.pack(">HH", 60000, 60000) + data[sof + 9:])
    with pytest.raises(ImageError, match="WHITTED_MAX_MEMORY"):
        read_texture_file(bomb)
    hdr = write_hdr(tmp_path / "t.hdr", _rgbe(np.random.default_rng(2), 6, 9), rle=True)
    assert read_header(hdr).width == 9
    monkeypatch.setenv("WHITTED_MAX_MEMORY", "1000")
    with pytest.raises(ImageError, match="WHITTED_MAX_MEMORY"):
        read_texture_file(hdr)
    monkeypatch.delenv("WHITTED_MAX_MEMORY")
    # `whitted check`'s reader takes no JPEG: refused by name, not decoded
    with pytest.raises(ImageError, match="a JPEG file, expected"):
        check_image_file(jpg)


def test_broken_hdr_and_jpeg_are_one_line_errors(tmp_path):
    from whitted.tracer.imageheader import ImageError
    from whitted.tracer.imageio import read_texture_file

    hdr = write_hdr(tmp_path / "t.hdr", _rgbe(np.random.default_rng(2), 6, 9), rle=True)
    cut = tmp_path / "cut.hdr"
    cut.write_bytes(hdr.read_bytes()[:-20])
    with pytest.raises(ImageError, match="unreadable Radiance HDR file"):
        read_texture_file(cut)
    jpg = write_jpeg(tmp_path / "t.jpg", np.random.default_rng(3))
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(jpg.read_bytes()[:60])
    with pytest.raises(ImageError, match="JPEG"):
        read_texture_file(cut)
    swapped = tmp_path / "jpeg.hdr"
    swapped.write_bytes(jpg.read_bytes())
    with pytest.raises(ImageError, match="a JPEG file, expected Radiance HDR"):
        read_texture_file(swapped)


TEXTURED = """
[film]
width = 48
height = 36
spp = 4
max_depth = 2
[camera]
origin = [0, 2.5, 4]
target = [0, 0.3, 0]
fov = 50
[materials.floor]
type = "diffuse"
reflectance = { bitmap = { filename = "tex.jpg" } }
[materials.ball]
type = "diffuse"
reflectance = { bitmap = { filename = "tex.hdr", filter_type = "nearest" } }
[materials.wall]
type = "diffuse"
reflectance = { bitmap = { filename = "grey.jpg", raw = true } }
[[lights]]
type = "point"
position = [1, 4, 3]
intensity = 30
[[shapes]]
type = "rectangle"
material = "floor"
to_world = [ { scale = 3 }, { rotate = { axis = [1, 0, 0], angle = -90 } } ]
[[shapes]]
type = "sphere"
center = [-0.6, 0.6, 0]
radius = 0.6
material = "ball"
[[shapes]]
type = "rectangle"
material = "wall"
to_world = [ { scale = 0.8 }, { translate = [1.2, 0.8, -0.5] } ]
"""


def _textured_scene(tmp_path):
    from PIL import Image

    rng = np.random.default_rng(5)
    write_jpeg(tmp_path / "tex.jpg", rng, size=(9, 13))
    Image.fromarray(rng.integers(0, 256, (5, 7), dtype=np.uint8)).save(tmp_path / "grey.jpg")
    write_hdr(tmp_path / "tex.hdr", _rgbe(rng, 5, 11, 120, 129), rle=True)  # values < 1
    return parse_scene(tomllib.loads(TEXTURED), str(tmp_path / "scene.toml"))


def test_jpeg_and_hdr_textures_agree_with_mitsuba_at_float_precision(tmp_path):
    """A JPEG (sRGB), a grey JPEG read raw and an HDR (linear) texture, rendered by the
    tracer and by Mitsuba's bitmap plugin from the same files: the exact-strata test."""
    from whitted.reference.verdicts.compare import compare_scene

    scene = _textured_scene(tmp_path)
    result, _, _ = compare_scene(scene, tmp_path / "out", second_opinion=False)
    assert result.reference == "deterministic" and result.test == "exact-strata"
    assert result.passed, result.checks
    assert result.metrics["median_rel"] < 1e-5


def test_hdr_envmap_reads_the_values_of_the_same_exr(tmp_path):
    """An envmap from an .hdr file holds the texels an .exr of the same values gives (the
    envmap's agreement with Mitsuba is tested on EXR maps)."""
    from whitted.tracer.imageio import read_texture_file, write_exr

    rgbe = _rgbe(np.random.default_rng(4), 6, 12, 120, 140)
    write_hdr(tmp_path / "sky.hdr", rgbe, rle=True)
    write_exr(tmp_path / "sky.exr", read_texture_file(tmp_path / "sky.hdr"))
    doc = {"film": {"width": 8, "height": 6}, "camera": {"origin": [0, 0, 0],
                                                          "target": [0, 0, 1]},
           "lights": [{"type": "envmap", "filename": "sky.hdr"}]}
    a = parse_scene(doc, str(tmp_path / "s.toml")).lights[0]
    doc["lights"][0]["filename"] = "sky.exr"
    b = parse_scene(doc, str(tmp_path / "s.toml")).lights[0]
    assert np.array_equal(np.asarray(a.texels), np.asarray(b.texels))


def test_import_reads_jpeg_and_hdr_bitmaps(tmp_path):
    _textured_scene(tmp_path)
    (tmp_path / "s.xml").write_text("""<scene version="3.0.0">
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>
    <integer name="height" value="6"/></film></sensor>
  <emitter type="envmap"><string name="filename" value="tex.hdr"/></emitter>
  <shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">
    <string name="filename" value="tex.jpg"/></texture></bsdf></shape>
</scene>""")
    imp = read_xml(tmp_path / "s.xml")
    scene = parse_scene(imp.data, str(tmp_path / "s.toml"))
    assert scene.lights[0].filename.endswith("tex.hdr")


# ---------------------------------------------------------------- area emitters by reference


def test_cbox_rgb_area_emitter_taken_by_ref_is_mitsubas(mi, tmp_path):
    """Mitsuba's own Cornell box declares its area emitter at the top level (after the
    shape that takes it by <ref>): the imported light is the shape Mitsuba attaches it
    to, with the radiance mi.traverse reports."""
    xml = CBOX / "cbox-rgb.xml"
    scene = parse_scene(read_xml(xml).data, str(tmp_path / "c.toml"))
    lit = [s for s in scene.shapes if getattr(s, "emitter", None) is not None]
    assert len(lit) == 1
    m = mi.load_file(str(xml))
    theirs = [s for s in m.shapes() if s.emitter() is not None]
    assert len(theirs) == 1
    params = mi.traverse(theirs[0].emitter())
    key = next(k for k in params.keys() if k.endswith("radiance.value"))
    assert np.allclose(lit[0].emitter.radiance, np.asarray(params[key]).ravel(), rtol=1e-6)
    # the same shape: the luminaire's vertices, as Mitsuba placed them
    verts = np.asarray(mi.traverse(theirs[0])["vertex_positions"]).reshape(-1, 3)
    ours = np.asarray(lit[0].vertices if hasattr(lit[0], "vertices") else
                      lit[0].world_vertices()).reshape(-1, 3)
    assert np.allclose(np.sort(ours, axis=0), np.sort(verts, axis=0), atol=1e-3)


REFS = """<scene version="3.0.0">
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>
    <integer name="height" value="6"/></film></sensor>
  {body}
</scene>"""


def test_emitter_and_bsdf_refs_load_as_mitsuba_loads_them(mi, tmp_path):
    """A forward <ref> to an emitter and a bsdf, an area emitter no shape takes (Mitsuba
    loads and ignores it), and one taken by two shapes (Mitsuba refuses it)."""
    body = """<shape type="sphere"><ref id="m"/><ref id="e"/></shape>
  <shape type="rectangle"><ref id="m"/></shape>
  <bsdf type="diffuse" id="m"><rgb name="reflectance" value="0.1, 0.2, 0.3"/></bsdf>
  <emitter type="area" id="e"><rgb name="radiance" value="1, 2, 3"/></emitter>
  <emitter type="area" id="unused"><rgb name="radiance" value="5, 5, 5"/></emitter>"""
    path = tmp_path / "ok.xml"
    path.write_text(REFS.format(body=body))
    m = mi.load_file(str(path))
    assert [s.emitter() is not None for s in m.shapes()] == [True, False]
    assert len(m.emitters()) == 1
    imp = read_xml(path)
    scene = parse_scene(imp.data, str(tmp_path / "ok.toml"))
    assert scene.shapes[0].emitter.radiance == (1.0, 2.0, 3.0)
    assert scene.shapes[1].emitter is None
    assert scene.shapes[0].material == scene.shapes[1].material
    assert len(scene.lights) == 0
    assert any("belongs to no shape" in n for n in imp.notes["lights"])

    twice = tmp_path / "twice.xml"
    twice.write_text(REFS.format(body="""<emitter type="area" id="e"/>
  <shape type="sphere"><ref id="e"/></shape>
  <shape type="rectangle"><ref id="e"/></shape>"""))
    with pytest.raises(RuntimeError, match="single shape"):
        mi.load_file(str(twice))
    with pytest.raises(XMLImportError, match="twice.xml:6: .*line 4 .*one shape only"):
        read_xml(twice)


# ---------------------------------------------------------------- the tent filter


@pytest.mark.parametrize("radius", [1.0, 1.7])
def test_tent_filter_matches_mitsubas_at_the_strata_centres(mi, radius):
    """Both sides take the same samples (strata centres, a point light: nothing random)
    and weigh them with the tent 1 - |d| / radius per axis: the images agree but for
    float32 rounding (measured 3e-7 of the brightest pixel; a box or gaussian filter in
    its place differs by 1e-1 and 3e-2)."""
    from whitted.reference.renderers.mitsuba.scene import load
    from whitted.tracer import load_scene
    from whitted.tracer.integrator import render

    scene = load_scene(ROOT / "scenes" / "sphere_point.toml").with_overrides(size=(48, 36),
                                                                               spp=4)
    t = dataclasses.replace(scene, film=dataclasses.replace(scene.film, filter="tent",
                                                            radius=radius))
    ours = render(t).image
    theirs = np.asarray(mi.render(load(t, mi, "direct"), spp=4))[..., :3]
    assert np.abs(ours - theirs).max() <= 1e-5 * theirs.max()


def test_tent_filter_is_imported_and_validated(tmp_path):
    path = tmp_path / "t.xml"
    path.write_text(REFS.format(body="").replace(
        '<integer name="height" value="6"/>',
        '<integer name="height" value="6"/><rfilter type="tent"/>'))
    film = read_xml(path).data["film"]
    assert film["filter"] == "tent" and "radius" not in film
    path.write_text(path.read_text().replace('<rfilter type="tent"/>',
                                             '<rfilter type="tent"><float name="radius" '
                                             'value="2"/></rfilter>'))
    data = read_xml(path).data
    assert data["film"]["radius"] == 2.0
    assert parse_scene(data, str(tmp_path / "t.toml")).film.filter_radius == 2.0
    from whitted.tracer.errors import SceneError

    with pytest.raises(SceneError, match="radius is for filter"):
        parse_scene({"film": {"radius": 2.0}}, str(tmp_path / "t.toml"))


# ---------------------------------------------------------------- import into a new folder


def test_import_makes_the_output_folder(tmp_path):
    from whitted.reference.renderers.mitsuba.importer import check_output, write_import
    from whitted.tracer import load_scene

    out = check_output(tmp_path / "new" / "deeper" / "cbox.toml")
    assert not (tmp_path / "new").exists()  # checking makes nothing
    write_import(CBOX / "cbox-rgb.xml", out)
    assert load_scene(out).shapes


def test_import_command_makes_the_output_folder_and_leaves_none_when_refused(tmp_path):
    from conftest import run_cli

    out = tmp_path / "new_folder" / "cbox.toml"
    r = run_cli("import", CBOX / "cbox-rgb.xml", "-o", out)
    assert r.returncode == 0, r.stderr
    assert out.is_file()
    r = run_cli("import", REFUSED, "-o", tmp_path / "other" / "x.toml")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert not (tmp_path / "other").exists()


def test_a_failed_import_leaves_no_folder_behind(tmp_path):
    """Refused by the reader, or by the tracer's loading of the TOML: no folder made."""
    from whitted.reference.renderers.mitsuba.importer import write_import

    with pytest.raises(XMLImportError):
        write_import(REFUSED, tmp_path / "a" / "b" / "x.toml")
    bad = tmp_path / "bad.xml"   # a texture file that is no image: the tracer refuses it
    (tmp_path / "tex.jpg").write_text("not a jpeg")
    bad.write_text(REFS.format(body="""<shape type="sphere"><bsdf type="diffuse">
      <texture type="bitmap" name="reflectance"><string name="filename" value="tex.jpg"/>
      </texture></bsdf></shape>"""))
    with pytest.raises(UserError, match="nothing was written"):
        write_import(bad, tmp_path / "c" / "d" / "x.toml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.xml", "tex.jpg"]


def test_import_output_checks_refuse_before_any_work(tmp_path):
    from whitted.reference.renderers.mitsuba.importer import check_output

    (tmp_path / "file").write_text("")
    with pytest.raises(UserError, match="is a file, not a folder"):
        check_output(tmp_path / "file" / "sub" / "x.toml")
    with pytest.raises(UserError, match="unknown file type"):
        check_output(tmp_path / "new" / "x.txt")
    (tmp_path / "dir.toml").mkdir()
    with pytest.raises(UserError, match="is a folder"):
        check_output(tmp_path / "dir.toml")


def test_folders_made_for_an_import_are_removed_when_its_writing_fails(tmp_path, monkeypatch):
    """The folder is made only after every check; a write that fails then (a full disk)
    takes the folders it made with it."""
    import whitted.tracer.imageio as imageio
    from whitted.reference.renderers.mitsuba.importer import write_import

    def full(path, write):
        raise UserError(f"{path}: cannot write: No space left on device")

    monkeypatch.setattr(imageio, "_atomic_write", full)
    with pytest.raises(UserError, match="No space left"):
        write_import(CBOX / "cbox-rgb.xml", tmp_path / "a" / "b" / "x.toml")
    assert list(tmp_path.iterdir()) == []
