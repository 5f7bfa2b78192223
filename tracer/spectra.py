"""Spectra to RGB, as Mitsuba 3.9.1's RGB variants reduce them.

A Mitsuba ``<spectrum>`` is either one number (``value="0.5"``) or wavelength:value
pairs in nanometres (``value="400:0.1, 500:0.2, 600:0.3"``, regular or irregular
spacing alike). An RGB variant never renders the spectrum: when a plugin reads the
property, ``Properties::get_texture_impl`` (``src/core/properties.cpp``) turns it into
a constant colour, in one of three ways according to how the plugin reads it:

* **reflectance** (``get_texture``: ``diffuse``'s ``reflectance``, ``plastic``'s and
  ``conductor``'s ``specular_reflectance``, a checkerboard's colours, ``blendbsdf``'s
  ``weight``, ...): pairs are integrated against the CIE 1931 colour matching
  functions *weighted by the D65 illuminant*, converted to linear sRGB and clamped
  to [0, 1]; one number is that grey;
* **illuminant** (``get_emissive_texture``: an emitter's ``radiance``, ``intensity``,
  ``irradiance``): pairs are integrated against the matching functions alone
  (no D65), converted and clamped below at 0; one number ``v`` is
  ``v * xyz_to_srgb(1, 1, 1)`` (a purple-ish colour: a flat spectrum is not white
  under sRGB's D65 white point);
* **unbounded** (``get_unbounded_texture``: ``conductor``'s ``eta`` and ``k``):
  pairs as reflectance (with D65) but only clamped below at 0; one number is that grey.

The integration (``spectrum_list_to_srgb``, ``src/core/spectrum.cpp``) takes 1000
wavelengths evenly from 360 to 830 nm, the spectrum linearly interpolated between its
pairs and zero outside them, the tables below linearly interpolated at each, the sum
scaled by 470 / 1000 / 106.7502593994140625 (so that a unit spectrum has luminance 1,
``MI_CIE_Y_NORMALIZATION``), then multiplied by ``xyz_to_srgb``'s matrix
(``include/mitsuba/core/spectrum.h``). It runs in double precision on the float32
tables; the colour is stored as float32. :func:`to_rgb` follows it step for step,
in float64 with numpy, and rounds to float32 at the same place
(``tests/tracer/test_spectra.py`` checks it against Mitsuba's own reading of random spectra
of each kind).

Data: ``cie1931_tbl`` of ``src/core/spectrum.cpp`` (the CIE 1931 2-degree observer,
95 samples from 360 to 830 nm every 5 nm) and ``d65_table`` of
``include/mitsuba/core/spectrum.h`` (CIE D65, relative to 100 at 560 nm), copied from
mitsuba-renderer/mitsuba3 at tag v3.9.1, commit
478e193a183c21723f4a8251afc3ad29a8da4c5e, as float32 values.
"""

from __future__ import annotations

import numpy as np

#: How a plugin reads the property (see the module docstring).
REFLECTANCE, ILLUMINANT, UNBOUNDED = "reflectance", "illuminant", "unbounded"
KINDS = (REFLECTANCE, ILLUMINANT, UNBOUNDED)

#: Mitsuba's MI_CIE_MIN, MI_CIE_MAX, MI_CIE_SAMPLES (nm, nm, samples).
CIE_MIN, CIE_MAX, CIE_SAMPLES = 360.0, 830.0, 95
#: MI_CIE_Y_NORMALIZATION: a unit spectrum integrates to luminance 1.
CIE_Y_NORMALIZATION = 1.0 / 106.7502593994140625
#: MI_CIE_D65_NORMALIZATION: D65 integrates to luminance 1.
CIE_D65_NORMALIZATION = 1.0 / 98.99741751876255
#: spectrum_list_to_srgb's number of integration steps.
STEPS = 1000
#: xyz_to_srgb's matrix (ITU-R BT.709 linear RGB from XYZ), as Mitsuba's float32 literals.
XYZ_TO_SRGB = ((3.240479, -1.537150, -0.498535),
               (-0.969256, 1.875991, 0.041556),
               (0.055648, -0.204043, 1.057311))

CIE_X = (
    0.000129900000, 0.000232100000, 0.000414900000, 0.000741600000, 0.001368000000,
    0.002236000000, 0.004243000000, 0.007650000000, 0.014310000000, 0.023190000000,
    0.043510000000, 0.077630000000, 0.134380000000, 0.214770000000, 0.283900000000,
    0.328500000000, 0.348280000000, 0.348060000000, 0.336200000000, 0.318700000000,
    0.290800000000, 0.251100000000, 0.195360000000, 0.142100000000, 0.095640000000,
    0.057950010000, 0.032010000000, 0.014700000000, 0.004900000000, 0.002400000000,
    0.009300000000, 0.029100000000, 0.063270000000, 0.109600000000, 0.165500000000,
    0.225749900000, 0.290400000000, 0.359700000000, 0.433449900000, 0.512050100000,
    0.594500000000, 0.678400000000, 0.762100000000, 0.842500000000, 0.916300000000,
    0.978600000000, 1.026300000000, 1.056700000000, 1.062200000000, 1.045600000000,
    1.002600000000, 0.938400000000, 0.854449900000, 0.751400000000, 0.642400000000,
    0.541900000000, 0.447900000000, 0.360800000000, 0.283500000000, 0.218700000000,
    0.164900000000, 0.121200000000, 0.087400000000, 0.063600000000, 0.046770000000,
    0.032900000000, 0.022700000000, 0.015840000000, 0.011359160000, 0.008110916000,
    0.005790346000, 0.004109457000, 0.002899327000, 0.002049190000, 0.001439971000,
    0.000999949300, 0.000690078600, 0.000476021300, 0.000332301100, 0.000234826100,
    0.000166150500, 0.000117413000, 0.000083075270, 0.000058706520, 0.000041509940,
    0.000029353260, 0.000020673830, 0.000014559770, 0.000010253980, 0.000007221456,
    0.000005085868, 0.000003581652, 0.000002522525, 0.000001776509, 0.000001251141,
)

CIE_Y = (
    0.000003917000, 0.000006965000, 0.000012390000, 0.000022020000, 0.000039000000,
    0.000064000000, 0.000120000000, 0.000217000000, 0.000396000000, 0.000640000000,
    0.001210000000, 0.002180000000, 0.004000000000, 0.007300000000, 0.011600000000,
    0.016840000000, 0.023000000000, 0.029800000000, 0.038000000000, 0.048000000000,
    0.060000000000, 0.073900000000, 0.090980000000, 0.112600000000, 0.139020000000,
    0.169300000000, 0.208020000000, 0.258600000000, 0.323000000000, 0.407300000000,
    0.503000000000, 0.608200000000, 0.710000000000, 0.793200000000, 0.862000000000,
    0.914850100000, 0.954000000000, 0.980300000000, 0.994950100000, 1.000000000000,
    0.995000000000, 0.978600000000, 0.952000000000, 0.915400000000, 0.870000000000,
    0.816300000000, 0.757000000000, 0.694900000000, 0.631000000000, 0.566800000000,
    0.503000000000, 0.441200000000, 0.381000000000, 0.321000000000, 0.265000000000,
    0.217000000000, 0.175000000000, 0.138200000000, 0.107000000000, 0.081600000000,
    0.061000000000, 0.044580000000, 0.032000000000, 0.023200000000, 0.017000000000,
    0.011920000000, 0.008210000000, 0.005723000000, 0.004102000000, 0.002929000000,
    0.002091000000, 0.001484000000, 0.001047000000, 0.000740000000, 0.000520000000,
    0.000361100000, 0.000249200000, 0.000171900000, 0.000120000000, 0.000084800000,
    0.000060000000, 0.000042400000, 0.000030000000, 0.000021200000, 0.000014990000,
    0.000010600000, 0.000007465700, 0.000005257800, 0.000003702900, 0.000002607800,
    0.000001836600, 0.000001293400, 0.000000910930, 0.000000641530, 0.000000451810,
)

CIE_Z = (
    0.000606100000, 0.001086000000, 0.001946000000, 0.003486000000, 0.006450001000,
    0.010549990000, 0.020050010000, 0.036210000000, 0.067850010000, 0.110200000000,
    0.207400000000, 0.371300000000, 0.645600000000, 1.039050100000, 1.385600000000,
    1.622960000000, 1.747060000000, 1.782600000000, 1.772110000000, 1.744100000000,
    1.669200000000, 1.528100000000, 1.287640000000, 1.041900000000, 0.812950100000,
    0.616200000000, 0.465180000000, 0.353300000000, 0.272000000000, 0.212300000000,
    0.158200000000, 0.111700000000, 0.078249990000, 0.057250010000, 0.042160000000,
    0.029840000000, 0.020300000000, 0.013400000000, 0.008749999000, 0.005749999000,
    0.003900000000, 0.002749999000, 0.002100000000, 0.001800000000, 0.001650001000,
    0.001400000000, 0.001100000000, 0.001000000000, 0.000800000000, 0.000600000000,
    0.000340000000, 0.000240000000, 0.000190000000, 0.000100000000, 0.000049999990,
    0.000030000000, 0.000020000000, 0.000010000000, 0.000000000000, 0.000000000000,
    0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000,
    0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000,
    0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000,
    0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000,
    0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000,
    0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000,
    0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000, 0.000000000000,
)

D65 = (
    46.6383, 49.3637, 52.0891, 51.0323, 49.9755, 52.3118, 54.6482, 68.7015,
    82.7549, 87.1204, 91.486, 92.4589, 93.4318, 90.057, 86.6823, 95.7736,
    104.865, 110.936, 117.008, 117.41, 117.812, 116.336, 114.861, 115.392,
    115.923, 112.367, 108.811, 109.082, 109.354, 108.578, 107.802, 106.296,
    104.79, 106.239, 107.689, 106.047, 104.405, 104.225, 104.046, 102.023,
    100.0, 98.1671, 96.3342, 96.0611, 95.788, 92.2368, 88.6856, 89.3459,
    90.0062, 89.8026, 89.5991, 88.6489, 87.6987, 85.4936, 83.2886, 83.4939,
    83.6992, 81.863, 80.0268, 80.1207, 80.2146, 81.2462, 82.2778, 80.281,
    78.2842, 74.0027, 69.7213, 70.6652, 71.6091, 72.979, 74.349, 67.9765,
    61.604, 65.7448, 69.8856, 72.4863, 75.087, 69.3398, 63.5927, 55.0054,
    46.4182, 56.6118, 66.8054, 65.0941, 63.3828, 63.8434, 64.304, 61.8779,
    59.4519, 55.7054, 51.959, 54.6998, 57.4406, 58.8765, 60.3125,
)

_F32 = np.float32


def _table(values) -> np.ndarray:
    """A table as Mitsuba holds it (float32), in float64 for the double-precision sums."""
    return np.asarray(values, dtype=_F32).astype(np.float64)


_XYZ = np.stack([_table(CIE_X), _table(CIE_Y), _table(CIE_Z)], axis=1)   # (95, 3)
_D65 = _table(D65)
_M = np.asarray(XYZ_TO_SRGB, dtype=_F32).astype(np.float64)


def parse(text: str) -> tuple[list[float], list[float]] | float:
    """A ``<spectrum value=...>`` as Mitsuba's ``Properties::Spectrum`` reads it: one
    number (returned as a float), or wavelength:value pairs (two lists, at least two
    pairs, wavelengths strictly increasing). Tokens are split at commas and spaces.

    Raises ``ValueError`` with a one-line reason where Mitsuba refuses the text.
    """
    tokens = [t for t in text.replace(",", " ").split(" ") if t.strip()]
    if len(tokens) == 1 and ":" not in tokens[0]:
        return _finite(tokens[0], "a spectrum value")
    wavelengths, values = [], []
    for token in tokens:
        pair = [p for p in token.split(":") if p]
        if len(pair) != 2:
            raise ValueError(f"expected wavelength:value pairs, got {token.strip()!r}")
        wavelengths.append(_finite(pair[0], "a wavelength"))
        values.append(_finite(pair[1], "a spectrum value"))
    if len(wavelengths) < 2:
        raise ValueError("a spectrum given per wavelength needs at least two pairs")
    if any(b <= a for a, b in zip(wavelengths, wavelengths[1:], strict=False)):
        raise ValueError("wavelengths must be given in increasing order")
    return wavelengths, values


def _finite(text: str, what: str) -> float:
    try:
        v = float(text.strip())
    except ValueError:
        raise ValueError(f"expected {what}, got {text.strip()!r}") from None
    if not np.isfinite(v) or abs(v) > np.finfo(_F32).max:
        raise ValueError(f"expected {what} within float32's range, got {text.strip()!r}")
    return v


def uniform_to_rgb(value: float, kind: str) -> tuple[float, float, float]:
    """One number as a colour: a grey, or for an illuminant ``value * xyz_to_srgb(1, 1, 1)``
    (the matrix's float32 rows summed and multiplied in double, rounded once: what
    Mitsuba 3.9.1 stores, bit for bit on 300 random values)."""
    _check_kind(kind)
    if kind != ILLUMINANT:
        v = float(_F32(value))
        return (v, v, v)
    return tuple(float(x) for x in (value * _M.sum(axis=1)).astype(_F32))


def to_rgb(wavelengths, values, kind: str) -> tuple[float, float, float]:
    """Wavelength:value pairs as Mitsuba 3.9.1's RGB variants reduce them
    (``spectrum_list_to_srgb(wavelengths, values, bounded, d65)`` with
    bounded = reflectance, d65 = not an illuminant), as float32 values.

    >>> [round(c, 4) for c in to_rgb([400, 700], [1.0, 1.0], "reflectance")]
    [0.9953, 0.9998, 0.9949]
    """
    rgb = integrate(wavelengths, values, kind)
    rgb = np.clip(rgb, 0.0, 1.0) if kind == REFLECTANCE else np.maximum(rgb, 0.0)
    return tuple(float(x) for x in rgb.astype(_F32))


def out_of_gamut(wavelengths, values, kind: str) -> bool:
    """Whether Mitsuba clamps the colour (it warns "Spectrum: clamping out-of-gamut color")."""
    rgb = integrate(wavelengths, values, kind)
    return bool(np.any(rgb < 0) or (kind == REFLECTANCE and np.any(rgb > 1)))


def integrate(wavelengths, values, kind: str) -> np.ndarray:
    """The linear sRGB colour of the pairs before Mitsuba's clamping (float64)."""
    _check_kind(kind)
    wl = np.asarray(wavelengths, dtype=np.float64)
    val = np.asarray(values, dtype=np.float64)
    i = np.arange(STEPS, dtype=np.float64)
    w = CIE_MIN + (i / (STEPS - 1)) * (CIE_MAX - CIE_MIN)
    w = w[(w >= wl[0]) & (w <= wl[-1])]          # zero outside the given pairs
    # math::find_interval: the last pair at or below w, at most the last but one
    k = np.clip(np.searchsorted(wl, w, side="right") - 1, 0, len(wl) - 2)
    w0, w1, v0, v1 = wl[k], wl[k + 1], val[k], val[k + 1]
    v = ((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1)
    # cie1931_xyz / cie_d65: the tables linearly interpolated (0.2 samples a nanometre)
    t = (w - CIE_MIN) * ((CIE_SAMPLES - 1) / (CIE_MAX - CIE_MIN))
    j = np.clip(t.astype(np.uint32), 0, CIE_SAMPLES - 2)
    b = t - j
    a = 1.0 - b
    term = (a[:, None] * _XYZ[j] + b[:, None] * _XYZ[j + 1]) * v[:, None]
    if kind != ILLUMINANT:
        d65 = (a * _D65[j] + b * _D65[j + 1]) * CIE_D65_NORMALIZATION
        term = term * d65[:, None]
    # summed in the loop's order (cumsum adds one term at a time)
    total = np.cumsum(np.vstack([np.zeros((1, 3)), term]), axis=0)[-1]
    total = total * ((CIE_MAX - CIE_MIN) * CIE_Y_NORMALIZATION / STEPS)
    return _M @ total


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"spectrum kind {kind!r}: expected one of {', '.join(KINDS)}")
