"""The Phong and Blinn-Phong material (tracer.phong, Mitsuba plugin whitted_phong): one law a test.

Float32 tolerances. Two float32 evaluations of the lobe cosine c (a dot
product of unit vectors, possibly after a normalisation or a rotation) differ
by |dc| <= COS_ERR. The lobe N c^p then differs by at most
N (p c^(p-1) |dc| + a few ulp of pow) <= N (p + 1) COS_ERR for p >= 1, c <= 1
(``lobe_tol``); the diffuse term kd / pi by a few ulp.
"""

import math

import drjit as dr
import numpy as np
import pytest

from whitted.tracer import phong
from whitted.tracer.lights import coordinate_system

MODELS = ("phong", "blinn-phong")
COS_ERR = 2e-6      # ~32 ulp at 1: a dozen roundings in dots, norms and a rotation, with margin
ULP = 2.0 ** -23


def normalization(model, p):
    return (phong.phong_normalization(p) if model == "phong"
            else phong.blinn_phong_normalization(p))


def lobe_tol(model, p, ks):
    """Bound on |f1 - f2| from the lobe for two float32 evaluations (see the module docstring)."""
    return ks * normalization(model, p) * (p + 1) * COS_ERR


def v3(jit, a):
    a = np.asarray(a, dtype=np.float32).reshape(-1, 3)
    return jit.Array3f(a[:, 0], a[:, 1], a[:, 2])


def unit(rng, n):
    a = rng.normal(size=(n, 3))
    return a / np.linalg.norm(a, axis=1, keepdims=True)


def upper(rng, n, normal=(0, 0, 1)):
    """Unit vectors in the hemisphere around ``normal`` (uniform)."""
    a = unit(rng, n)
    return np.where((a @ np.asarray(normal, float))[:, None] < 0, -a, a)


def brdf(jit, n, wi, wo, kd, ks, p, model):
    """phong_brdf on numpy input; returns an (N, 3) float64 array."""
    m = len(n)
    f = phong.phong_brdf(v3(jit, n), v3(jit, wi), v3(jit, wo), v3(jit, [kd] * m),
                         v3(jit, [ks] * m), p, model)
    return np.asarray(f, dtype=np.float64).T


# ---------------------------------------------------------------------------------------
# The formula (tracer.phong)
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("model", MODELS)
def test_helmholtz_reciprocity_f_wi_wo_equals_f_wo_wi(jit, model):
    rng = np.random.default_rng(7)
    m = 20000
    n, wi, wo = unit(rng, m), unit(rng, m), unit(rng, m)
    # Half the pairs close to the mirror configuration, where the lobe is large.
    mirror = 2 * np.sum(n * wi, axis=1, keepdims=True) * n - wi
    wo[: m // 2] = mirror[: m // 2] + 0.05 * rng.normal(size=(m // 2, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    p = rng.uniform(1, 1000, m).astype(np.float32)      # a Float exponent, one per lane
    kd, ks = (0.3, 0.5, 0.1), (0.7, 0.5, 0.9)
    pf = jit.Float(p)
    a = np.asarray(phong.phong_brdf(v3(jit, n), v3(jit, wi), v3(jit, wo), v3(jit, [kd] * m),
                                    v3(jit, [ks] * m), pf, model), dtype=np.float64).T
    b = np.asarray(phong.phong_brdf(v3(jit, n), v3(jit, wo), v3(jit, wi), v3(jit, [kd] * m),
                                    v3(jit, [ks] * m), pf, model), dtype=np.float64).T
    tol = 4 * ULP * np.maximum(a, b) + lobe_tol(model, p.astype(np.float64), 1.0)[:, None]
    assert np.count_nonzero(a[:, 2] > 1) > 100          # the lobe was actually probed
    assert np.all(np.abs(a - b) <= tol)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("p", [0.0, 0.5, 1.0, 20.0, 1000.0])
def test_positivity_f_is_finite_and_non_negative(jit, model, p):
    rng = np.random.default_rng(3)
    m = 5000
    n, wi, wo = unit(rng, m), unit(rng, m), unit(rng, m)
    f = brdf(jit, n, wi, wo, (0.2, 0.0, 0.5), (0.8, 1.0, 0.0), p, model)
    assert np.all(np.isfinite(f)) and np.all(f >= 0)


@pytest.mark.parametrize("model", MODELS)
def test_f_is_zero_when_either_direction_is_below_the_surface(jit, model):
    rng = np.random.default_rng(4)
    m = 4000
    n, wi, wo = unit(rng, m), unit(rng, m), unit(rng, m)
    f = brdf(jit, n, wi, wo, (0.5, 0.5, 0.5), (0.5, 0.5, 0.5), 10.0, model)
    below = (np.sum(n * wi, axis=1) <= 0) | (np.sum(n * wo, axis=1) <= 0)
    assert np.all(f[below] == 0) and np.all(f[~below] > 0)


def test_unknown_model_is_refused(jit):
    z = [[0, 0, 1]]
    with pytest.raises(ValueError, match="blinn-phong"):
        phong.phong_brdf(v3(jit, z), v3(jit, z), v3(jit, z), v3(jit, z), v3(jit, z), 1.0, "ward")


def test_zero_exponent_blinn_phong_is_lambertian(jit):
    # N(0) = 2 * 4 / (8 pi (1 + 0)) = 1 / pi and cos^0 = 1: ks acts like a second kd.
    assert phong.blinn_phong_normalization(0.0) == pytest.approx(1 / math.pi, rel=1e-15)
    rng = np.random.default_rng(5)
    wi, wo = upper(rng, 1000), upper(rng, 1000)
    n = np.tile([0.0, 0.0, 1.0], (1000, 1))
    f = brdf(jit, n, wi, wo, (0, 0, 0), (0.5, 0.5, 0.5), 0.0, "blinn-phong")
    assert np.allclose(f, 0.5 / math.pi, rtol=4 * ULP, atol=0)


def test_normalizations_accept_floats_and_float_arrays(jit):
    p = [0.0, 1.0, 10.0, 100.0]
    for fn in (phong.phong_normalization, phong.blinn_phong_normalization):
        a = np.asarray(fn(jit.Float(np.asarray(p, np.float32))))
        assert np.allclose(a, [fn(x) for x in p], rtol=4 * ULP)


# ---------------------------------------------------------------------------------------
# Energy: the directional albedo a(wo) = integral f(wi, wo) cos(theta_i) d(wi)
# ---------------------------------------------------------------------------------------


def lobe_bound(model, p):
    """sup of (ks-lobe f cos(theta_i)) / (lobe sampling pdf) for ks = 1.

    Phong: N cos^p(a) cos(theta_i) / ((p + 1) / (2 pi) cos^p(a)) <= (p + 2) / (p + 1).
    Blinn-Phong: the pdf in wi is (p + 1) / (2 pi) cos^p(theta_h) / (4 wi . h), so the
    ratio is 8 pi N (wi . h) cos(theta_i) / (p + 1) <= 8 pi N / (p + 1).
    """
    if model == "phong":
        return (p + 2) / (p + 1)
    return 8 * math.pi * phong.blinn_phong_normalization(p) / (p + 1)


def albedo(jit, model, p, kd, ks, theta_o, strata=512, seed=0):
    """Stratified, multiple-importance-sampled estimates of a(wo), RGB, and their error bound.

    For each outgoing direction (polar angle ``theta_o`` about a random normal, random
    azimuth) two techniques draw one direction in each of strata^2 cells of [0, 1)^2:
    D, cosine-weighted about n; S, the glossy lobe (cos = u^(1 / (p + 1)) about the
    mirror direction of wo for Phong, about n for Blinn-Phong's half vector). With the
    balance heuristic for equal counts the estimate is
    sum over both techniques' samples of f cos(theta_i) / (p_D + p_S), divided by the
    count K = strata^2, and its expectation is a(wo).

    Error bound (Hoeffding). Each of the 2K terms is independent (one per cell and
    technique) and lies in [0, M], M = kd + ks sup(f_s cos / p_S) (see lobe_bound),
    since (f_d + f_s) cos / (p_D + p_S) <= f_d cos / p_D + f_s cos / p_S and
    f_d cos / p_D = kd. So P(estimate - a >= t) <= exp(-K t^2 / M^2), and with
    t = M sqrt(ln(1 / delta) / K) an estimate exceeds a by t with probability at most
    delta. Returns (estimates (n_wo, 3), t (3,)).
    """
    theta_o = np.asarray(theta_o, dtype=np.float64)
    n_wo, k = len(theta_o), strata * strata
    rng = np.random.default_rng(seed)
    normals = unit(rng, n_wo)
    phi = rng.uniform(0, 2 * math.pi, n_wo)
    local = np.stack([np.sin(theta_o) * np.cos(phi), np.sin(theta_o) * np.sin(phi),
                      np.cos(theta_o)], axis=1)

    total = n_wo * k
    idx = dr.arange(jit.UInt32, total)
    which = idx // k                                       # outgoing direction
    cell = idx - which * k
    n = dr.gather(jit.Array3f, v3(jit, normals), which)
    t1, t2 = coordinate_system(n)
    lo = dr.gather(jit.Array3f, v3(jit, local), which)
    wo = dr.normalize(t1 * lo.x + t2 * lo.y + n * lo.z)
    kd_a, ks_a = jit.Array3f(*kd), jit.Array3f(*ks)
    norm_sampling = (p + 1) / (2 * math.pi)

    def pdfs(wi):
        cos_i = dr.dot(n, wi)
        p_d = dr.maximum(cos_i, 0) / math.pi
        if model == "phong":
            c = dr.dot(phong.reflect_about(n, wo), wi)
            p_s = norm_sampling * dr.select(c > 0, dr.power(dr.maximum(c, 1e-30), p), 0)
        else:
            h = dr.normalize(wi + wo)
            c = dr.dot(n, h)
            p_s = norm_sampling * dr.select(c > 0, dr.power(dr.maximum(c, 1e-30), p), 0)
            p_s = p_s / (4 * dr.maximum(dr.dot(wi, h), 1e-30))
        return cos_i, p_d, p_s

    sums = np.zeros((n_wo, 3))
    for tech, stream in (("D", 1), ("S", 2)):
        pcg = jit.PCG32(total, stream)
        cy = cell // strata
        u1 = (jit.Float(cell - cy * strata) + pcg.next_float32()) / strata
        u2 = (jit.Float(cy) + pcg.next_float32()) / strata
        s, c = dr.sincos(2 * math.pi * u2)
        if tech == "D":
            cos_t = dr.sqrt(u1)
            axis = n
        else:
            cos_t = dr.power(u1, 1 / (p + 1))
            # Phong's lobe is about the mirror direction; Blinn-Phong's half vector about n.
            axis = phong.reflect_about(n, wo) if model == "phong" else n
        sin_t = dr.safe_sqrt(1 - cos_t * cos_t)
        a1, a2 = coordinate_system(axis)
        d = a1 * (c * sin_t) + a2 * (s * sin_t) + axis * cos_t
        wi = d if (tech == "D" or model == "phong") else phong.reflect_about(d, wo)
        cos_i, p_d, p_s = pdfs(wi)
        f = phong.phong_brdf(n, wi, wo, kd_a, ks_a, p, model)
        w = dr.select((cos_i > 0) & (p_d + p_s > 0), cos_i / (p_d + p_s), 0)
        g = np.asarray(f * w, dtype=np.float64)            # (3, total), summed in float64
        sums += g.reshape(3, n_wo, k).sum(axis=2).T
    estimate = sums / k

    delta = 1e-9            # per check; a few hundred checks in all keep the total below 1e-6
    m = np.asarray(kd) + np.asarray(ks) * lobe_bound(model, p)
    # float32 terms: each within (4 p + 16) ulp (the pow magnifies the cosine's rounding).
    t = m * math.sqrt(math.log(1 / delta) / k) + (4 * p + 16) * ULP * m
    return estimate, t


THETA_O = np.radians([0, 5, 15, 25, 35, 45, 55, 65, 72, 78, 83, 86, 88, 89, 89.7, 89.95])


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("p", [1.0, 4.0, 30.0, 1000.0])
def test_energy_conservation_glossy_lobe_albedo_at_most_one(jit, model, p):
    # ks = 1, kd = 0: the lobe alone reflects at most what arrives, at every outgoing angle.
    est, t = albedo(jit, model, p, (0, 0, 0), (1, 1, 1), THETA_O)
    assert np.all(est <= 1 + t), (est[:, 0], t)
    # Normal incidence, where both normalisations are exact: the estimate is near 1 too.
    assert est[0, 0] >= 1 - t[0]


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("p", [2.0, 50.0])
def test_energy_conservation_white_furnace_rgb_at_most_kd_plus_ks(jit, model, p):
    # kd + ks = (1, 1, 0.9): red mostly diffuse, green mostly glossy, blue all glossy.
    kd, ks = (0.7, 0.2, 0.0), (0.3, 0.8, 0.9)
    est, t = albedo(jit, model, p, kd, ks, THETA_O, strata=384, seed=1)
    assert np.all(est <= np.add(kd, ks) + t), (est, t)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("p", [1.0, 10.0, 100.0])
def test_albedo_at_normal_incidence_is_exactly_one_for_ks_one(jit, model, p):
    """Both normalisations are exact at wo = n (Lafortune-Willems for Phong, Giesen for Blinn).

    By symmetry about n, a = 2 pi integral_0^1 f(mu) mu d(mu), mu = cos(theta_i). The midpoint
    rule with K cells errs by at most max|g''| / (24 K^2) for g(mu) = 2 pi f(mu) mu:
    Phong, g = (p + 2) mu^(p+1), |g''| <= (p + 2)(p + 1) p; Blinn-Phong,
    g = 2 pi N mu q^(p/2) with q = (1 + mu) / 2 in [1/2, 1], |g''| <= 2 pi N (p + p |p - 2| / 4)
    (q^(-1) <= 2, q^(-2) <= 4). The float32 values of f each err by (4 p + 16) ulp at most.
    """
    k = 1 << 16
    mu = (np.arange(k) + 0.5) / k
    z = np.zeros(k)
    wi = np.stack([np.sqrt(1 - mu * mu), z, mu], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (k, 1))
    f = brdf(jit, n, wi, n, (0, 0, 0), (1, 1, 1), p, model)[:, 0]
    a = 2 * math.pi * np.sum(f * mu) / k
    if model == "phong":
        g2 = (p + 2) * (p + 1) * p
    else:
        g2 = 2 * math.pi * phong.blinn_phong_normalization(p) * (p + p * abs(p - 2) / 4)
    tol = g2 / (24 * k * k) + (4 * p + 16) * ULP
    assert abs(a - 1) <= tol, (a, tol)


def test_phong_factor_on_blinn_phong_would_not_conserve_energy(jit):
    # Why Blinn-Phong needs its own factor: with (p + 2) / (2 pi) its albedo at normal
    # incidence is 4 (2^(-p/2) + p) / (p + 4) (2.87 at p = 10), not 1.
    p = 10.0
    ratio = phong.phong_normalization(p) / phong.blinn_phong_normalization(p)
    assert ratio == pytest.approx(4 * (2 ** (-p / 2) + p) / (p + 4), rel=1e-12)
    assert ratio > 2.8


# ---------------------------------------------------------------------------------------
# The Mitsuba plugin (reference/materials/phong.py)
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def mip(mi):
    """Mitsuba with ``whitted_phong`` registered (reference.mitsuba() registers it)."""
    return mi


def load(mi, model, p, kd=(0.3, 0.2, 0.1), ks=(0.5, 0.6, 0.7)):
    return mi.load_dict({"type": "whitted_phong", "diffuse": list(kd), "specular": list(ks),
                         "exponent": p, "model": model})


def mvec(mi, a):
    a = np.asarray(a, dtype=np.float32).reshape(-1, 3)
    return mi.Vector3f(a[:, 0], a[:, 1], a[:, 2])


def interaction(mi, wi):
    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = mvec(mi, wi)
    return si


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("p", [1.0, 40.0, 500.0])
def test_tracer_formula_equals_plugin_eval_over_cos_theta_o(jit, mip, model, p):
    mi = mip
    rng = np.random.default_rng(11)
    m = 20000
    wi_m = unit(rng, m)                          # Mitsuba's si.wi: towards the viewer
    wo_m = unit(rng, m)                          # Mitsuba's wo: towards the light
    mirror = wi_m * [-1, -1, 1]
    wo_m[: m // 2] = mirror[: m // 2] + 0.1 * rng.normal(size=(m // 2, 3)) / math.sqrt(p)
    wo_m /= np.linalg.norm(wo_m, axis=1, keepdims=True)
    kd, ks = (0.3, 0.2, 0.1), (0.5, 0.6, 0.7)
    bsdf = load(mi, model, p, kd, ks)
    value = np.asarray(bsdf.eval(mi.BSDFContext(), interaction(mi, wi_m), mvec(mi, wo_m)),
                       dtype=np.float64).T
    cos_o = wo_m[:, 2]
    up = cos_o > 0
    assert np.all(value[~up] == 0)
    f_plugin = value[up] / cos_o[up, None]

    # The tracer in a random world frame: its wi (towards the light) is Mitsuba's wo.
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    f_tracer = brdf(jit, np.tile(q[:, 2], (m, 1))[up], wo_m[up] @ q.T, wi_m[up] @ q.T,
                    kd, ks, p, model)
    # value / cos_o adds 2 ulp; the rotation is within COS_ERR.
    tol = 6 * ULP * np.maximum(f_plugin, f_tracer) + lobe_tol(model, p, max(ks))
    assert np.count_nonzero(f_tracer[:, 0] > 2 * kd[0] / math.pi) > 100
    assert np.all(np.abs(f_plugin - f_tracer) <= tol)


@pytest.mark.parametrize("model", MODELS)
def test_plugin_eval_pdf_equals_eval_and_pdf(mip, model):
    mi = mip
    rng = np.random.default_rng(12)
    m = 5000
    bsdf = load(mi, model, 25.0)
    ctx, si, wo = mi.BSDFContext(), interaction(mi, unit(rng, m)), mvec(mi, unit(rng, m))
    v, pdf = bsdf.eval_pdf(ctx, si, wo)
    assert np.allclose(np.asarray(v), np.asarray(bsdf.eval(ctx, si, wo)), rtol=2 * ULP, atol=0)
    assert np.allclose(np.asarray(pdf), np.asarray(bsdf.pdf(ctx, si, wo)), rtol=2 * ULP, atol=0)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("p", [3.0, 100.0])
def test_plugin_sample_weight_equals_eval_over_pdf(mip, model, p):
    mi = mip
    rng = np.random.default_rng(13)
    m = 20000
    bsdf = load(mi, model, p)
    wi = unit(rng, m)
    ctx, si = mi.BSDFContext(), interaction(mi, wi)
    u = rng.random((3, m)).astype(np.float32)
    bs, weight = bsdf.sample(ctx, si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    v, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
    weight, v = np.asarray(weight, np.float64).T, np.asarray(v, np.float64).T
    pdf, bs_pdf = np.asarray(pdf, np.float64), np.asarray(bs.pdf, np.float64)
    ok = pdf > 0
    assert np.all(np.isfinite(weight)) and np.all(weight >= 0)
    assert np.all(weight[wi[:, 2] <= 0] == 0)                  # one-sided: nothing from below
    assert np.allclose(bs_pdf[ok], pdf[ok], rtol=2 * ULP, atol=0)
    assert np.allclose(weight[ok], v[ok] / pdf[ok, None], rtol=4 * ULP, atol=0)
    assert np.count_nonzero(ok) > m // 4


def chi2_test(mi, model, p, theta_i_deg, pdf_exponent=None):
    """Mitsuba's chi-square test of ``sample`` against ``pdf`` (src/python/python/chi2.py)."""
    from mitsuba import chi2

    a = math.radians(theta_i_deg)
    wi = [math.sin(a), 0.0, math.cos(a)]
    spec = {"type": "whitted_phong", "diffuse": [0.3, 0.3, 0.3], "specular": [0.6, 0.6, 0.6],
            "exponent": p, "model": model}
    sample_func, pdf_func = chi2.BSDFAdapter("whitted_phong", spec, wi=wi)
    if pdf_exponent is not None:
        _, pdf_func = chi2.BSDFAdapter("whitted_phong", dict(spec, exponent=pdf_exponent), wi=wi)
    # ires = 16 integration points per cell side: narrow lobes need more than the default 4.
    test = chi2.ChiSquareTest(domain=chi2.SphericalDomain(), sample_func=sample_func,
                              pdf_func=pdf_func, sample_dim=3, sample_count=1_000_000,
                              res=101, ires=16, seed=3)
    return test


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("p,theta_i", [(5.0, 0.0), (5.0, 70.0), (60.0, 30.0), (60.0, 80.0)])
def test_plugin_sampling_matches_its_pdf_chi2(mip, model, p, theta_i, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)          # a rejected test writes chi2_data.py to the cwd
    test = chi2_test(mip, model, p, theta_i)
    assert test.run(significance_level=0.01), test.messages


@pytest.mark.parametrize("model", MODELS)
def test_chi2_rejects_a_pdf_with_the_wrong_exponent(mip, model, tmp_path, monkeypatch):
    # The test has power: sampling with p = 20 against the pdf of p = 24 is rejected.
    monkeypatch.chdir(tmp_path)
    test = chi2_test(mip, model, 20.0, 30.0, pdf_exponent=24.0)
    assert not test.run(significance_level=0.01, quiet=True)


@pytest.mark.parametrize("value", [[0.2, 0.3, 0.4], "color", "rgb", 0.3])
def test_plugin_reads_colors_as_lists_colors_textures_and_floats(mip, value):
    mi = mip
    expected = [0.3] * 3 if value == 0.3 else [0.2, 0.3, 0.4]
    if value == "color":
        value = mi.ScalarColor3f(0.2, 0.3, 0.4)
    elif value == "rgb":
        value = {"type": "rgb", "value": [0.2, 0.3, 0.4]}
    bsdf = mi.load_dict({"type": "whitted_phong", "diffuse": value, "specular": 0.0,
                         "exponent": 10.0, "model": "phong"})
    si = interaction(mi, [[0, 0, 1]])
    v = np.asarray(bsdf.eval(mi.BSDFContext(), si, mvec(mi, [[0, 0, 1]]))).ravel()
    assert np.allclose(v, np.asarray(expected) / math.pi, rtol=4 * ULP)
    assert bsdf.flags() & int(mi.BSDFFlags.GlossyReflection)
    assert bsdf.flags() & int(mi.BSDFFlags.DiffuseReflection)


def test_plugin_refuses_an_unknown_model(mip):
    with pytest.raises(RuntimeError, match="unknown model"):
        mip.load_dict({"type": "whitted_phong", "model": "ward"})


@pytest.mark.parametrize("model", MODELS)
def test_twosided_plugin_reflects_the_same_on_both_sides(mip, model):
    mi = mip
    rng = np.random.default_rng(14)
    m = 1000
    wi, wo = upper(rng, m), upper(rng, m)
    spec = {"type": "whitted_phong", "exponent": 15.0, "model": model}
    two = mi.load_dict({"type": "twosided", "material": spec})
    one = mi.load_dict(spec)
    ctx = mi.BSDFContext()
    front = np.asarray(one.eval(ctx, interaction(mi, wi), mvec(mi, wo)))
    back = np.asarray(two.eval(ctx, interaction(mi, -wi), mvec(mi, -wo)))
    assert np.allclose(front, back, rtol=2 * ULP, atol=0)
