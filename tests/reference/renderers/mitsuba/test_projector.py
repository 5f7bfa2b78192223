"""Mitsuba's ``projector`` emitter as a light kind (tracer/emitters/projector.py): the two
projector scenes of mitsuba-data import as they stand and agree with Mitsuba at float
precision, against the import's conversion and against Mitsuba's own reading of the
file; what the kind cannot follow is refused in one line."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import write_scene

from whitted.reference.commands import main
from whitted.tracer.errors import UserError
from whitted.tracer.mitsuba_xml import XMLImportError, read_xml
from whitted.tracer.scene import load_scene

REAL = Path(__file__).resolve().parents[3] / "data" / "real_scenes" / "mitsuba-data"
PROJECTORS = sorted((REAL / "tests" / "scenes" / "projector").glob("*.xml"))


@pytest.mark.parametrize("path", PROJECTORS, ids=lambda p: p.stem)
def test_mitsubas_projector_scenes_import_and_agree(path, tmp_path, capsys):
    assert len(PROJECTORS) == 2
    imp = read_xml(path)          # as it stands: nothing approximated
    assert not imp.approximate
    assert [x["type"] for x in imp.data["lights"]] == ["projector"]
    # at the file's own 48 x 48, so that Mitsuba's reading of the original is rendered too
    rc = main(["compare", str(path), "--spp", "4", "--no-second-opinion",
               "-o", str(tmp_path / "c")])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "structure: agrees" in out
    assert "original file, test exact-strata: pass" in out


XML = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
        </film>
    </sensor>
    <emitter type="projector">
        {fov}
        <rgb name="irradiance" value="1"/>
    </emitter>
</scene>
"""


def test_fov_and_focal_length_together_or_a_bad_focal_length_are_refused(tmp_path):
    both = tmp_path / "both.xml"
    both.write_text(XML.format(fov='<float name="fov" value="30"/>'
                               '<string name="focal_length" value="35mm"/>'))
    with pytest.raises(XMLImportError, match="give fov or focal_length, not both"):
        read_xml(both)
    bad = tmp_path / "bad.xml"
    bad.write_text(XML.format(fov='<string name="focal_length" value="-5mm"/>'))
    with pytest.raises(XMLImportError, match="expected a positive focal_length"):
        read_xml(bad)
    lens = tmp_path / "lens.xml"     # a focal length alone: the diagonal of a 35 mm film
    lens.write_text(XML.format(fov='<string name="focal_length" value="50mm"/>'))
    light = read_xml(lens).data["lights"][0]
    assert light["fov_axis"] == "diagonal" and light["fov"] == pytest.approx(46.793, abs=1e-3)


def test_a_checkerboard_projected_is_refused_in_one_line(tmp_path):
    scene = """
[camera]
origin = [0, 0, 5]
target = [0, 0, 0]

[[lights]]
type = "projector"
irradiance = { checkerboard = { color0 = 1, color1 = 0 } }
"""
    with pytest.raises(UserError, match="expected a colour or a bitmap") as e:
        load_scene(write_scene(tmp_path, scene))
    assert "\n" not in str(e.value)
