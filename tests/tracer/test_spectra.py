"""Spectra to RGB as Mitsuba 3.9.1's RGB variants reduce them (tracer/spectra.py).

Mitsuba is the judge: each random spectrum is given to a Mitsuba plugin that reads it
the way in question (a ``diffuse`` reflectance, a ``point`` emitter's intensity, a
``conductor``'s eta) in ``llvm_ad_rgb``, and the colour read back with ``mi.traverse``
must be the tracer's reduction to float32 precision (the figures: bit for bit on every
spectrum tried). Then the real scenes the reduction unlocks agree with Mitsuba's
reading of the original, and fail with each reading's bug put back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from whitted.reference.renderers.mitsuba.original import compare_structure
from whitted.tracer import mitsuba_xml, spectra
from whitted.tracer.mitsuba_xml import XMLImportError, read_xml

ROOT = Path(__file__).resolve().parents[2]
CBOX = ROOT / "tests" / "data" / "real_scenes" / "mitsuba-data" / "scenes" / "cbox"
UNLOCKED = [CBOX / "cbox.xml", CBOX / "cbox-spectral.xml"]

#: kind -> (the XML of a plugin reading the spectrum that way, its traverse key)
PLUGINS = {
    spectra.REFLECTANCE: ('<bsdf version="3.0.0" type="diffuse">'
                          '<spectrum name="reflectance" value="{}"/></bsdf>',
                          "reflectance.value"),
    spectra.ILLUMINANT: ('<emitter version="3.0.0" type="point">'
                         '<spectrum name="intensity" value="{}"/></emitter>',
                         "intensity.value"),
    spectra.UNBOUNDED: ('<bsdf version="3.0.0" type="conductor">'
                        '<spectrum name="eta" value="{}"/><float name="k" value="1"/></bsdf>',
                        "eta.value"),
}
N = 60   # random spectra of each kind and shape (regular, irregular)


@pytest.fixture(scope="module")
def mi():
    from whitted.reference import mitsuba

    return mitsuba()


def mitsubas_reading(mi, kind: str, text: str) -> np.ndarray:
    xml, key = PLUGINS[kind]
    value = np.asarray(mi.traverse(mi.load_string(xml.format(text)))[key], np.float32)
    return np.broadcast_to(value.ravel(), (3,)) if value.size == 1 else value.ravel()


def random_spectrum(rng, kind: str, regular: bool) -> tuple[list, list]:
    n = int(rng.integers(2, 40))
    if regular:
        wl = rng.uniform(300, 560) + rng.uniform(1, 25) * np.arange(n)
    else:   # irregular, some of it outside 360-830 nm
        wl = np.unique(np.round(rng.uniform(300, 900, n), 3))
        if len(wl) < 2:
            wl = np.array([400.0, 700.0])
    hi = 1.3 if kind == spectra.REFLECTANCE else 25.0   # some out of gamut
    return [float(w) for w in wl], [float(v) for v in rng.uniform(0, hi, len(wl))]


def text_of(wl, values) -> str:
    return ", ".join(f"{w!r}:{v!r}" for w, v in zip(wl, values, strict=True))


def ulps(a, b) -> int:
    a, b = np.asarray(a, np.float32), np.asarray(b, np.float32)
    return int(np.abs(a.view(np.int32).astype(np.int64) - b.view(np.int32)).max())


@pytest.mark.parametrize("regular", [True, False], ids=["regular", "irregular"])
@pytest.mark.parametrize("kind", spectra.KINDS)
def test_spectrum_list_reduces_as_mitsubas_rgb_variant(mi, kind, regular):
    rng = np.random.default_rng(2 * spectra.KINDS.index(kind) + regular)
    worst, clamped = 0, 0
    for _ in range(N):
        wl, values = random_spectrum(rng, kind, regular)
        ours = spectra.to_rgb(wl, values, kind)
        theirs = mitsubas_reading(mi, kind, text_of(wl, values))
        worst = max(worst, ulps(ours, theirs))
        clamped += spectra.out_of_gamut(wl, values, kind)
    assert worst <= 1, f"{kind}: {worst} float32 ulps from Mitsuba's reading"
    if kind == spectra.REFLECTANCE:
        assert clamped > 0   # the clamp to [0, 1] was exercised


@pytest.mark.parametrize("kind", spectra.KINDS)
def test_single_value_spectrum_reduces_as_mitsubas_rgb_variant(mi, kind):
    rng = np.random.default_rng(7)
    for v in [0.0, 1.0, *rng.uniform(0, 10, 40)]:
        theirs = mitsubas_reading(mi, kind, repr(float(v)))
        assert ulps(spectra.uniform_to_rgb(float(v), kind), theirs) == 0, v


def test_a_flat_illuminant_is_not_white_in_srgb():
    """Mitsuba's RGB variants make a flat emission spectrum xyz_to_srgb(1, 1, 1) (purple-ish)."""
    r, g, b = spectra.uniform_to_rgb(1.0, spectra.ILLUMINANT)
    assert r > 1.2 > 0.95 > g > b > 0.9


def test_reflectance_weighs_by_d65_and_illuminant_does_not():
    flat = ([360.0, 830.0], [1.0, 1.0])
    assert np.allclose(spectra.to_rgb(*flat, spectra.REFLECTANCE), 1, atol=6e-3)
    assert not np.allclose(spectra.to_rgb(*flat, spectra.ILLUMINANT), 1, atol=0.05)


@pytest.mark.parametrize("text,message", [
    ("400:0.5", "at least two pairs"),
    ("500:0.1, 400:0.2", "increasing order"),
    ("0.1 0.2 0.3", "wavelength:value pairs"),
    ("400:0.1, 500", "wavelength:value pairs"),
    ("400:nan, 500:1", "float32's range"),
])
def test_malformed_spectra_are_refused_as_mitsuba_refuses_them(text, message):
    with pytest.raises(ValueError, match=message):
        spectra.parse(text)


def test_spectrum_from_file_is_refused_in_one_line(tmp_path):
    p = tmp_path / "s.xml"
    p.write_text('<scene version="3.0.0"><sensor type="perspective"/><shape type="sphere">'
                 '<bsdf type="diffuse"><spectrum name="reflectance" filename="x.spd"/>'
                 '</bsdf></shape></scene>')
    with pytest.raises(XMLImportError, match="a spectrum from a file"):
        read_xml(p)


# ---------------------------------------------------------------- the real scenes


@pytest.mark.parametrize("path", UNLOCKED, ids=lambda p: p.name)
def test_spectral_cbox_imports_as_it_stands_and_agrees_with_the_original(path):
    imp = read_xml(path)
    assert not imp.approximate and not imp.warnings
    s = compare_structure(path)
    assert s.agrees, "\n".join(s.lines())
    assert (s.shapes, s.bsdfs, s.emitters) == (8, 5, 1)


def _break(monkeypatch, bug: str) -> None:
    if bug == "grey mean":          # the old approximation
        monkeypatch.setattr(spectra, "to_rgb",
                            lambda wl, v, kind: (float(np.mean(v)),) * 3)
    elif bug == "no d65":           # every spectrum read as an illuminant
        original = spectra.to_rgb
        monkeypatch.setattr(spectra, "to_rgb",
                            lambda wl, v, kind: original(wl, v, spectra.ILLUMINANT))
    elif bug == "emitter as reflectance":   # D65 and the clamp to 1 for radiance too
        monkeypatch.setattr(mitsuba_xml, "SPECTRUM_KINDS", {})


@pytest.mark.parametrize("bug", ["grey mean", "no d65", "emitter as reflectance"])
def test_each_spectrum_bug_fails_the_structural_check(monkeypatch, bug):
    _break(monkeypatch, bug)
    s = compare_structure(CBOX / "cbox.xml")
    assert not s.agrees
    expect = "radiance" if bug == "emitter as reflectance" else "reflectance"
    assert any(expect in line for line in s.lines()), s.lines()
