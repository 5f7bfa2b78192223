"""Fresnel, Snell and the law of reflection (lecture 1), one law per test."""

import math

import numpy as np
import pytest

from whitted.reference.teaching.fresnel_curves import exact64, float32_tolerance
from whitted.tracer import fresnel


def F(jit, x):
    return jit.Float(np.asarray(x, dtype=np.float32))


def v3(jit, a):
    a = np.asarray(a, dtype=np.float32).reshape(-1, 3)
    return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])


@pytest.mark.parametrize("n1,n2", [(1.0, 1.5), (1.0, 1.33), (1.0, 2.42), (1.5, 1.0)])
def test_normal_incidence_reflectance_is_r0(jit, n1, n2):
    # R0 = ((n1 - n2) / (n1 + n2))^2, the same from either side.
    eta = max(n1, n2) / min(n1, n2)
    cos_i = 1.0 if n1 < n2 else -1.0
    r = fresnel.fresnel_exact(F(jit, [cos_i]), F(jit, [eta]))[0]
    assert r == pytest.approx(((n1 - n2) / (n1 + n2)) ** 2, rel=1e-6)


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.42])
def test_reflectance_tends_to_one_at_grazing_incidence(jit, eta):
    cos = np.array([1e-2, 1e-3, 1e-4])
    r = np.asarray(fresnel.fresnel_exact(F(jit, cos), F(jit, [eta] * 3)))
    assert np.all(np.diff(r) > 0) and r[-1] > 0.999


def test_equal_indices_reflect_nothing(jit):
    cos = np.linspace(-1, 1, 201)
    r = np.asarray(fresnel.fresnel_exact(F(jit, cos), F(jit, np.ones_like(cos))))
    assert np.all(r == 0)


@pytest.mark.parametrize("n", [1.33, 1.5, 2.42])
def test_critical_angle_is_asin_n2_over_n1(jit, n):
    # From inside (n1 = n) towards n2 = 1: total reflection starts at asin(1 / n).
    crit = math.asin(1 / n)
    below, above = crit - 1e-3, crit + 1e-3
    cos = -np.cos([below, above])
    r = np.asarray(fresnel.fresnel_exact(F(jit, cos), F(jit, [n, n])))
    _, tir = fresnel.snell_cos_t(F(jit, cos), F(jit, [n, n]))
    assert r[0] < 1 and r[1] == 1
    assert list(np.asarray(tir)) == [False, True]


def test_no_refracted_ray_beyond_the_critical_angle(jit):
    n = 1.5
    theta = np.radians([45, 60, 89])           # all beyond asin(1/1.5) = 41.8 degrees
    # Inside the glass, travelling outwards through the boundary z = 0 (normal +z).
    d = np.stack([np.sin(theta), np.zeros(3), np.cos(theta)], axis=1)
    t, tir = fresnel.refract(v3(jit, d), v3(jit, [[0, 0, 1]] * 3), F(jit, [n] * 3))
    assert np.all(np.asarray(tir))
    r = np.asarray(fresnel.fresnel_exact(F(jit, -np.cos(theta)), F(jit, [n] * 3)))
    assert np.all(r == 1)


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.42, 1 / 1.5])
def test_refracted_directions_obey_snells_law(jit, eta):
    rng = np.random.default_rng(1)
    n = rng.normal(size=(64, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = rng.normal(size=(64, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, tir = fresnel.refract(v3(jit, d), v3(jit, n), F(jit, [eta] * 64))
    t, tir = np.asarray(t).T, np.asarray(tir)
    cos_i = -np.sum(d * n, axis=1)
    n_i = np.where(cos_i >= 0, 1.0, eta)        # outside (normal side) has index 1
    n_t = np.where(cos_i >= 0, eta, 1.0)
    sin_i = np.linalg.norm(np.cross(d, n), axis=1)
    sin_t = np.linalg.norm(np.cross(t, n), axis=1)
    ok = ~tir
    assert ok.sum() > 10
    assert np.allclose(n_i[ok] * sin_i[ok], n_t[ok] * sin_t[ok], atol=2e-6)
    assert np.allclose(np.linalg.norm(t[ok], axis=1), 1, atol=1e-6)
    # The refracted ray continues to the other side, in the plane of d and n.
    assert np.all(np.sign(np.sum(t[ok] * n[ok], axis=1)) == np.sign(np.sum(d[ok] * n[ok], axis=1)))
    assert np.allclose(np.sum(np.cross(d[ok], n[ok]) * t[ok], axis=1), 0, atol=2e-6)
    # Total internal reflection exactly where sin_t would exceed 1.
    assert np.array_equal(tir, n_i / n_t * sin_i > 1)


def test_law_of_reflection(jit):
    rng = np.random.default_rng(2)
    n = rng.normal(size=(32, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = rng.normal(size=(32, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.asarray(fresnel.reflect(v3(jit, d), v3(jit, n))).T
    # Angle of incidence equals angle of reflection, mirrored about the normal,
    # in the plane of incidence, and the length is kept.
    assert np.allclose(np.sum(r * n, axis=1), -np.sum(d * n, axis=1), atol=1e-6)
    assert np.allclose(np.cross(r, n), np.cross(d, n), atol=1e-6)
    assert np.allclose(np.linalg.norm(r, axis=1), 1, atol=1e-6)


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.42])
def test_reflectance_and_transmittance_sum_to_one(jit, eta):
    # T from the transmission amplitudes t_s = 2 n_i c_i / (n_i c_i + n_t c_t),
    # t_p = 2 n_i c_i / (n_t c_i + n_i c_t): T = n_t c_t / (n_i c_i) (t_s^2 + t_p^2) / 2.
    for sign in (1, -1):
        theta = np.radians(np.linspace(0, 89, 90))
        c = np.cos(theta)
        n_i, n_t = (1.0, eta) if sign > 0 else (eta, 1.0)
        sin_t = n_i / n_t * np.sin(theta)
        ok = sin_t < 1
        ct = np.sqrt(1 - sin_t[ok] ** 2)
        ci = c[ok]
        ts = 2 * n_i * ci / (n_i * ci + n_t * ct)
        tp = 2 * n_i * ci / (n_t * ci + n_i * ct)
        T = n_t * ct / (n_i * ci) * (ts ** 2 + tp ** 2) / 2
        R = np.asarray(fresnel.fresnel_exact(F(jit, sign * ci), F(jit, [eta] * int(ok.sum()))))
        assert np.allclose(R + T, 1, atol=2e-6)


@pytest.mark.parametrize("eta", [1.0, 1.33, 1.5, 2.42])
def test_schlick_equals_exact_at_normal_incidence(jit, eta):
    e = fresnel.fresnel_exact(F(jit, [1.0, -1.0]), F(jit, [eta, eta]))
    s = fresnel.fresnel_schlick(F(jit, [1.0, -1.0]), F(jit, [eta, eta]))
    assert np.allclose(np.asarray(e), np.asarray(s), atol=1e-7)


def test_schlicks_largest_error_for_glass_is_computed_and_bounded(jit):
    # Search 0..90 degrees on a fine grid, refine around the worst angle, and compare
    # with the same search on an independent float64 evaluation.
    eta = 1.5

    def worst(f_exact, f_schlick):
        th = np.radians(np.linspace(0, 90, 9001))
        err = np.abs(f_schlick(np.cos(th)) - f_exact(np.cos(th)))
        i = int(np.argmax(err))
        fine = np.radians(np.linspace(np.degrees(th[max(i - 1, 0)]),
                                      np.degrees(th[min(i + 1, len(th) - 1)]), 2001))
        e2 = np.abs(f_schlick(np.cos(fine)) - f_exact(np.cos(fine)))
        j = int(np.argmax(e2))
        return e2[j], np.degrees(fine[j])

    def ours_exact(c):
        return np.asarray(fresnel.fresnel_exact(F(jit, c), F(jit, np.full(len(c), eta))))

    def ours_schlick(c):
        return np.asarray(fresnel.fresnel_schlick(F(jit, c), F(jit, np.full(len(c), eta))))

    r0 = ((eta - 1) / (eta + 1)) ** 2

    def schlick64(c):
        return r0 + (1 - r0) * (1 - c) ** 5

    err32, at32 = worst(ours_exact, ours_schlick)
    err64, at64 = worst(lambda c: exact64(c, eta), schlick64)
    assert err32 == pytest.approx(err64, abs=1e-5) and at32 == pytest.approx(at64, abs=0.1)
    # Where it is worst, and how bad: below R0 itself, at a grazing angle.
    assert 80 < at64 < 90
    assert err64 < r0


def test_schlick_reaches_one_at_the_critical_angle_from_the_dense_side(jit):
    # With the cosine taken on the less dense side, Schlick's curve is continuous
    # at the critical angle instead of jumping to 1 there.
    eta = 1.5
    crit = math.asin(1 / eta)
    # Near theta_c, cos_t ~ sqrt(theta_c - theta): R climbs to 1 like a square root.
    d = np.array([1e-2, 1e-4, 1e-6])
    s = np.asarray(fresnel.fresnel_schlick(F(jit, -np.cos(crit - d)), F(jit, [eta] * 3)))
    assert np.all(np.diff(s) > 0) and s[-1] > 0.99


def test_float32_tolerance_grows_near_the_critical_angle():
    eta = 1.5
    crit = math.asin(1 / eta)
    tol = float32_tolerance(-np.cos(np.array([0.2, crit - 1e-5])), eta)
    assert tol[1] > 100 * tol[0]


def test_plugin_curve_check_passes_mitsubas_dielectric_and_fails_a_shifted_ior(monkeypatch):
    """The Fresnel table's plugin check: the reflection fraction of Mitsuba's dielectric,
    k of N binomial draws per angle, must hold the exact R in its Wilson interval at
    1 - 0.01 / M (Bonferroni over the M angles; a correct plugin fails with probability
    below 1 %, at the fixed seed: not at all). A plugin 2 % off in ior moves the critical
    angle inside the glass by about a degree, where R jumps from below 1 to 1, far
    outside any interval (at ior 1, where R = 0, any reflection at all fails); at the quick
    table's 20,000 draws each ior must fail."""
    from whitted.reference.teaching import fresnel_curves as fc

    table = fc.fresnel_table(fc.DEFAULT_IORS, step=1.0, samples=20_000)
    assert table.passed
    assert all(r["exact_within_plugin_interval"] for r in table.summary)
    counted = fc._plugin_reflect_fraction
    monkeypatch.setattr(fc, "_plugin_reflect_fraction",
                        lambda mi, ior, *a: counted(mi, ior * 1.02, *a))
    shifted = fc.fresnel_table(fc.DEFAULT_IORS, step=1.0, samples=20_000)
    assert not shifted.passed
    assert {r["ior"] for r in shifted.summary if not r["exact_within_plugin_interval"]} == set(
        fc.DEFAULT_IORS)
