"""Heitz, Hanika, d'Eon & Dachsbacher 2016 multiple scattering on the Smith microsurface
(addon/lab/reference/heitz2016/medium.py): the microsurface seen as a random medium, its height
sampling (the free-path law) and the chi-square of the visible-normal sampler seen from below.

Every Monte Carlo comparison uses a fixed seed and a tolerance in units of its own standard
error (the estimators are unbiased; 4 to 4.5 standard errors unless said otherwise)."""
import math

import numpy as np
import pytest

from addon.lab.reference.heitz2016 import D_wi, projected_area, sample_height, sample_vndf_below
from addon.lab.reference.microfacet import Microfacet, normalize
from addon.lab.reference.quadrature import composite_gauss_legendre
from heitz2016_helpers import polar, rng_for  # tests/heitz2016_helpers.py
from test_reference_chi2 import pearson


# ---------------------------------------------------------------------------------------------
# Height sampling (the free-path law).
# ---------------------------------------------------------------------------------------------
def test_height_sampling_follows_the_free_path_law():
    """sample_height: an upward ray from h0 escapes with probability C1(h0)^Lambda and, when it
    hits, P(C1(h) <= c) = 1 - (C1(h0)/c)^Lambda (conditioned); a downward ray always hits with
    P(C1(h) <= c) = (c / C1(h0))^(1 + Lambda). Catches the classic slip of using Lambda instead
    of 1 + Lambda downwards (which breaks the height-correlated G2 and the energy balance)."""
    mf = Microfacet("ggx", 0.6)
    rng = rng_for("height")
    n = 400_000
    h0 = 0.2
    c0 = 0.5 * (h0 + 1.0)
    for w in (normalize(np.array([0.7, 0.1, 0.4])), normalize(np.array([0.2, 0.0, 0.95]))):
        lam = float(mf.lambda_(w))
        h, esc = sample_height(mf, np.broadcast_to(w, (n, 3)), np.full(n, h0), rng.random(n))
        p_esc = c0 ** lam
        assert abs(esc.mean() - p_esc) < 4.5 * math.sqrt(p_esc * (1 - p_esc) / n)
        c = 0.5 * (h[~esc] + 1.0)
        assert np.all((c >= c0 - 1e-12) & (c <= 1.0))
        for cq in (0.65, 0.8, 0.95):
            p = (1.0 - (c0 / cq) ** lam) / (1.0 - p_esc)
            assert abs((c <= cq).mean() - p) < 4.5 * math.sqrt(p * (1 - p) / len(c))
        # downward along -w
        h, esc = sample_height(mf, np.broadcast_to(-w, (n, 3)), np.full(n, h0), rng.random(n))
        assert not esc.any()
        c = 0.5 * (h + 1.0)
        for cq in (0.1, 0.3, 0.5):
            p = (cq / c0) ** (1.0 + lam)
            assert abs((c <= cq).mean() - p) < 4.5 * math.sqrt(p * (1 - p) / n)


# ---------------------------------------------------------------------------------------------
# Visible normals seen from below: chi-square in the stretched slope plane.
# ---------------------------------------------------------------------------------------------
N_T, N_E, NODES = 20, 20, 8


def _slope_frame(mf, wi):
    ws = normalize(np.array([mf.alpha_x * wi[0], mf.alpha_y * wi[1], wi[2]]))
    sin_t = math.hypot(ws[0], ws[1])
    cot = ws[2] / sin_t
    c, s = ws[0] / sin_t, ws[1] / sin_t
    a = abs(cot)
    if mf.ggx:
        w_t = w_e = 1.0 + a
    else:
        w_t = 1.0 / (1.0 + 2.0 * a) if cot < 0 else 1.0 + a
        w_e = 0.7
    return cot, c, s, w_t, w_e


def _cells_of(mf, wi, m):
    """(q, r) of normals m: q = t / (t + w_t), t = cot - xi >= 0 where visible; r = eta /
    (|eta| + w_e), with (xi, eta) the stretched slopes in the frame of wi's azimuth."""
    cot, c, s, w_t, w_e = _slope_frame(mf, wi)
    xs = (-m[:, 0] / m[:, 2]) / mf.alpha_x
    ys = (-m[:, 1] / m[:, 2]) / mf.alpha_y
    xi, eta = c * xs + s * ys, -s * xs + c * ys
    t = cot - xi
    return t / (t + w_t), eta / (np.abs(eta) + w_e)


def _slope_histogram(mf, wi, m):
    q, r = _cells_of(mf, wi, m)
    bad = int(np.sum(q < 0.0))  # invisible normals: no cell, expected 0
    q, r = q[q >= 0.0], r[q >= 0.0]
    i = np.clip((q * N_T).astype(int), 0, N_T - 1)
    j = np.clip(((r + 1.0) * 0.5 * N_E).astype(int), 0, N_E - 1)
    return np.bincount(i * N_E + j, minlength=N_T * N_E).reshape(N_T, N_E), bad


def _slope_expected(mf, wi):
    """Integral of D_wi over every (q, r) cell, by Gauss-Legendre in (q, r): the solid angle is
    dw = m.z^3 d(slope) (slope density P22 = D cos^4), the stretch adds alpha_x alpha_y, the
    maps add dt/dq = w_t / (1 - q)^2 and d eta / dr = w_e / (1 - |r|)^2. Only Microfacet.D and
    the two-sided projected area enter: nothing of the sampler."""
    cot, c, s, w_t, w_e = _slope_frame(mf, wi)
    q, wq = composite_gauss_legendre(np.linspace(0.0, 1.0, N_T + 1), NODES)
    r, wr = composite_gauss_legendre(np.linspace(-1.0, 1.0, N_E + 1), NODES)
    Q, R = np.meshgrid(q, r, indexing="ij")
    t = w_t * Q / (1.0 - Q)
    eta = w_e * R / (1.0 - np.abs(R))
    jac = np.outer(wq * w_t / (1.0 - q) ** 2, wr * w_e / (1.0 - np.abs(r)) ** 2)
    xi = cot - t
    sx = mf.alpha_x * (c * xi - s * eta)
    sy = mf.alpha_y * (s * xi + c * eta)
    m = normalize(np.stack([-sx, -sy, np.ones_like(sx)], axis=-1))
    vals = D_wi(mf, np.broadcast_to(wi, m.shape), m) * m[..., 2] ** 3 \
        * mf.alpha_x * mf.alpha_y * jac
    return vals.reshape(N_T, NODES, N_E, NODES).sum(axis=(1, 3))


VNDF_CASES = [(d, al, th) for d in ("ggx", "beckmann")
              for al in ((0.1, 0.1), (0.5, 0.5), (1.0, 1.0), (0.2, 0.6))
              for th in (95.0, 120.0, 150.0, 175.0)]
VNDF_CONTROLS = [(d, (0.5, 0.5), th) for d in ("ggx", "beckmann") for th in (30.0, 85.0)]
VNDF_THRESHOLD = 1.0 - 0.99 ** (1.0 / (len(VNDF_CASES) + len(VNDF_CONTROLS)))


@pytest.mark.parametrize("dist, alpha, theta", VNDF_CASES + VNDF_CONTROLS)
def test_visible_normals_from_both_sides_chi2(dist, alpha, theta):
    """m ~ D_wi(m) = <wi, m>+ D(m) / A(wi) for rays hitting the microsurface from below
    (sample_vndf_below: GGX caps without the flip, Beckmann by rejection), 200k normals,
    20 x 20 cells in the stretched slope plane of wi's azimuth (the plain (theta, phi) cells of
    test_reference_chi2 cannot resolve the crescents seen from below); theta < 90 are controls of
    the harness with the existing Microfacet.sample_vndf. Catches: a wrong projected area from
    below (|wi.z| Lambda), the flip of the existing sampler (normals invisible from wi), a wrong
    rejection law."""
    mf = Microfacet(dist, *alpha)
    wi = polar(theta)
    n = 200_000
    rng = rng_for("vndf", dist, alpha, theta)
    if projected_area(mf, wi) == 0.0:
        # Beckmann seen steeply from below (here stretched cot(theta) = -114 for alpha 0.1 at
        # 175 deg): Lambda = exp(-13000) underflows, nothing is visible, and the walk never
        # samples this case: such an upward ray escapes from any height.
        h, esc = sample_height(mf, np.broadcast_to(-wi, (1000, 3)), rng.uniform(-1, 1, 1000),
                               rng.random(1000))
        assert esc.all()
        return
    u = rng.random((2, n))
    wis = np.broadcast_to(wi, (n, 3))
    if wi[2] < 0:
        m = sample_vndf_below(mf, wis, u[0], u[1], rng)
    else:
        m = mf.sample_vndf(wis, u[0], u[1])
    assert np.all(np.isfinite(m)) and np.all(m[:, 2] >= 0.0)
    obs, bad = _slope_histogram(mf, wi, m)
    assert bad == 0, f"{bad} normals invisible from wi"
    prob = _slope_expected(mf, wi)
    assert prob.sum() == pytest.approx(1.0, abs=2e-3)  # the cells cover D_wi
    stat, dof, p = pearson(obs, n * prob)
    print(f"vndf {dist} {alpha} {theta}: chi2 {stat:.1f} dof {dof} p {p:.3g}")
    assert p > VNDF_THRESHOLD


def test_visible_normals_below_chi2_has_power():
    """The harness rejects the naive mistake, the existing sampler fed wi from below (it flips
    wi and samples the normals visible from -wi), and a Beckmann sampler judged as GGX."""
    wi = polar(120.0)
    n = 100_000
    rng = rng_for("vndf-power")
    u = rng.random((2, n))
    mf = Microfacet("ggx", 0.5)
    m = mf.sample_vndf(np.broadcast_to(wi, (n, 3)), u[0], u[1])
    assert _slope_histogram(mf, wi, m)[1] > 1000
    mb = sample_vndf_below(Microfacet("beckmann", 0.5), np.broadcast_to(wi, (n, 3)), u[0], u[1],
                           rng)
    obs, bad = _slope_histogram(mf, wi, mb)
    assert bad == 0
    assert pearson(obs, n * _slope_expected(mf, wi))[2] < 1e-12
