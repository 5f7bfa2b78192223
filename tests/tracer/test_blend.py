"""Mitsuba's ``blendbsdf`` of two smooth BSDFs (tracer/materials/blend.py), and
``twosided`` around the kinds the importer reads.

A blend imported from Mitsuba XML agrees with Mitsuba's reading of the original
(the structural check), renders as Mitsuba renders it (``whitted compare``,
exact-strata), and fails both with its bug put back; what the tracer cannot follow
is refused in one line, never written and then refused by Mitsuba.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from whitted.reference.commands import main
from whitted.reference.renderers.mitsuba.original import compare_structure
from whitted.tracer import mitsuba_xml
from whitted.tracer.materials import blend
from whitted.tracer.mitsuba_xml import XMLImportError, read_xml

HEAD = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world">
            <lookat origin="0, 0, 10" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <film type="hdrfilm">
            <integer name="width" value="40"/>
            <integer name="height" value="30"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <emitter type="point">
        <point name="position" x="1" y="4" z="6"/>
        <spectrum name="intensity" value="400:10, 550:60, 700:30"/>
    </emitter>
"""

BLENDS = HEAD + """
    <shape type="sphere">
        <float name="radius" value="1.5"/>
        <bsdf type="twosided">
            <bsdf type="blendbsdf">
                <float name="weight" value="0.3"/>
                <bsdf type="diffuse">
                    <spectrum name="reflectance" value="400:0.1, 500:0.7, 600:0.2, 700:0.4"/>
                </bsdf>
                <bsdf type="whitted_phong">
                    <rgb name="diffuse" value="0.3, 0.1, 0.5"/>
                    <rgb name="specular" value="0.4"/>
                    <float name="exponent" value="20"/>
                </bsdf>
            </bsdf>
        </bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="4"/><translate z="-2"/></transform>
        <bsdf type="blendbsdf">
            <float name="weight" value="0.75"/>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.9, 0.7, 0.1"/></bsdf>
        </bsdf>
    </shape>
</scene>
"""


@pytest.fixture
def scene(tmp_path) -> Path:
    p = tmp_path / "blends.xml"
    p.write_text(BLENDS)
    return p


def compare_xml(path, capsys, outdir) -> tuple[int, str]:
    rc = main(["compare", str(path), "--size", "40x30", "--spp", "4", "--no-second-opinion",
               "-o", str(outdir)])
    return rc, capsys.readouterr().out


def test_blends_import_and_agree_with_mitsubas_reading(scene):
    imp = read_xml(scene)
    mats = list(imp.data["materials"].values())
    assert [m["type"] for m in mats] == ["blend", "blend"]
    assert mats[0]["weight"] == 0.3 and "two_sided" not in mats[0]
    assert mats[1]["two_sided"] is False
    assert (mats[0]["first"]["type"], mats[0]["second"]["type"]) == ("diffuse", "phong")
    s = compare_structure(scene)
    assert s.agrees, "\n".join(s.lines())
    assert (s.shapes, s.bsdfs) == (2, 2)


def test_blends_render_as_mitsubas_blendbsdf(scene, capsys, tmp_path):
    rc, out = compare_xml(scene, capsys, tmp_path / "c")
    assert rc == 0, out
    assert "exact-strata" in out and "structure: agrees" in out


@pytest.mark.parametrize("bug", ["swapped parts", "weight of the first"])
def test_importer_blend_bugs_fail_the_structural_check(monkeypatch, scene, bug):
    original = mitsuba_xml._Importer._blendbsdf

    def broken(self, node, p, where, two_sided):
        out = original(self, node, p, where, two_sided)
        if bug == "swapped parts":
            out["first"], out["second"] = out["second"], out["first"]
        else:
            out["weight"] = 1 - out["weight"]
        return out

    monkeypatch.setattr(mitsuba_xml._Importer, "_blendbsdf", broken)
    s = compare_structure(scene)
    assert not s.agrees
    assert any("blendbsdf" in line or "bsdf_" in line or "weight" in line
               for line in s.lines()), s.lines()


def test_tracer_blend_with_the_weights_swapped_fails_compare(monkeypatch, scene, capsys,
                                                              tmp_path):
    original = blend.BSDF.eval

    def swapped(self, prm, si, wi):
        w, parts = prm
        return original(self, (1 - w, parts), si, wi)

    monkeypatch.setattr(blend.BSDF, "eval", swapped)
    rc, out = compare_xml(scene, capsys, tmp_path / "c")
    assert rc == 1, out


# ---------------------------------------------------------------- refused in one line

REFUSED = {
    "delta lobes": ('<bsdf type="blendbsdf"><float name="weight" value="0.4"/>'
                    '<bsdf type="conductor"/><bsdf type="diffuse"/></bsdf>',
                    'a blend of "conductor"'),
    "textured weight": ('<bsdf type="blendbsdf"><texture name="weight" type="checkerboard"/>'
                        '<bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>',
                        "a weight given as <texture>"),
    "nested twosided": ('<bsdf type="blendbsdf"><float name="weight" value="0.4"/>'
                        '<bsdf type="twosided"><bsdf type="diffuse"/></bsdf>'
                        '<bsdf type="diffuse"/></bsdf>', 'a blend of "twosided"'),
    "twosided glass": ('<bsdf type="twosided"><bsdf type="dielectric"/></bsdf>',
                       'a twosided around "dielectric"'),
    "twosided mask": ('<bsdf type="twosided"><bsdf type="mask"><bsdf type="diffuse"/></bsdf>'
                      '</bsdf>', 'a twosided around "mask"'),
    "front and back": ('<bsdf type="twosided"><bsdf type="diffuse"/><bsdf type="conductor"/>'
                       '</bsdf>', "different front and back BSDFs"),
}


@pytest.mark.parametrize("case", REFUSED)
def test_what_the_tracer_cannot_follow_is_refused_in_one_line(tmp_path, case):
    bsdf, message = REFUSED[case]
    p = tmp_path / "r.xml"
    p.write_text(HEAD + f'<shape type="sphere">{bsdf}</shape></scene>')
    with pytest.raises(XMLImportError, match=message) as e:
        read_xml(p)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("inner", ["diffuse", "conductor", "plastic", "whitted_phong",
                                   "blendbsdf"])
def test_twosided_around_each_reflecting_kind_agrees_with_mitsuba(tmp_path, inner):
    body = {"blendbsdf": '<bsdf type="blendbsdf"><float name="weight" value="0.6"/>'
                         '<bsdf type="diffuse"/><bsdf type="whitted_phong"/></bsdf>',
            "conductor": '<bsdf type="conductor"><string name="material" value="Au"/></bsdf>',
            }.get(inner, f'<bsdf type="{inner}"/>')
    p = tmp_path / "t.xml"
    p.write_text(HEAD + f'<shape type="sphere"><bsdf type="twosided">{body}</bsdf></shape>'
                        "</scene>")
    s = compare_structure(p)
    assert s.agrees and s.unchecked is None, "\n".join(s.lines())


@pytest.mark.parametrize("part, words", [
    ('{ type = "diffuse", reflectance = 0.5, two_sided = true }', "give two_sided on the blend"),
    ('{ type = "phong", diffuse = 0.3, specular = 0.2, ambient = 0.1 }', "no ambient term")])
def test_a_blends_parts_refuse_what_the_blend_decides(tmp_path, part, words):
    """The parts of a TOML blend take neither two_sided (the blend as a whole is one- or
    two-sided, as Mitsuba's twosided around blendbsdf) nor a Phong ambient term."""
    from whitted.tracer import load_scene
    from whitted.tracer.errors import SceneError

    path = tmp_path / "b.toml"
    path.write_text(f"""
[film]
width = 8
height = 6

[camera]
origin = [0, 0, 5]
target = [0, 0, 0]

[materials.m]
type = "blend"
first = {part}
second = {{ type = "diffuse", reflectance = 0.2 }}

[[lights]]
type = "point"
position = [0, 3, 3]
intensity = 10

[[shapes]]
type = "sphere"
center = [0, 0, 0]
radius = 1
material = "m"
""")
    with pytest.raises(SceneError, match=words):
        load_scene(path)
