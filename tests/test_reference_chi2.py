"""Chi-square goodness-of-fit of every sampler of microfacet normals (Mitsuba / pbrt style).

For each (sampler, distribution, incidence, alpha): draw N = 10^6 normals m with a fixed
numpy Generator seed, histogram them on 20 x 40 cells over (theta_m, phi_m), compare with the
expected counts N * integral of the sampler's pdf over each cell (8 x 8 Gauss-Legendre nodes
per cell, in the coordinates below, split at the pdfs' kinks), pool the cells with expected count < 5 into one, and compute Pearson's statistic.
The p-value is the exact chi-square survival function (regularised upper incomplete gamma,
addon/lab/reference/special.chi2_sf). Significance 0.01 for the family, Sidak-corrected:
each test must have p > 1 - 0.99^(1/number of tests).

The theta cells are uniform in s = the radial D cos CDF of the isotropic distribution with
alpha = max(ax, ay) (GGX s = tan^2 / (alpha^2 + tan^2), Beckmann s = 1 - exp(-tan^2/alpha^2)),
i.e. a monotone map of cos theta, so that narrow lobes spread over all 20 rows; phi cells are
uniform. The expected counts come from the pdf by quadrature, never from the sampling code.
"""
import math

import numpy as np
import pytest

from addon.lab.reference.microfacet import Microfacet
from addon.lab.reference.special import chi2_sf

N_SAMPLES = 1_000_000
N_THETA, N_PHI = 20, 40
NODES = 8
SEED = 12345
FAMILY_ALPHA = 0.01

INCIDENCE = (0.0, 30.0, 80.0, 89.9)
ALPHAS = (0.05, 0.5, 1.0)
# dcos does not depend on the incidence: one case per (distribution, alpha).
CASES = [("dcos", dist, 0.0, (a, a)) for dist in ("ggx", "beckmann") for a in ALPHAS]
CASES += [(sampler, dist, theta, (a, a)) for sampler in ("vndf", "vcavity")
          for dist in ("ggx", "beckmann") for theta in INCIDENCE for a in ALPHAS]
# Anisotropic roughness with wi off the axes (exercises stretching and the azimuth rotation).
CASES += [(sampler, dist, 80.0, (0.1, 0.4)) for sampler in ("vndf", "vcavity")
          for dist in ("ggx", "beckmann")]
THRESHOLD = 1.0 - (1.0 - FAMILY_ALPHA) ** (1.0 / len(CASES))
PHI_I = 0.3


def s_of_tan2(dist, tan2, a):
    return tan2 / (a * a + tan2) if dist == "ggx" else -np.expm1(-tan2 / (a * a))


def theta_of_s(dist, s, a):
    """theta(s) and d theta / d s for the cell coordinate s (inverse of s_of_tan2)."""
    if dist == "ggx":
        T = a * np.sqrt(s / (1.0 - s))
        dT = a / (2.0 * np.sqrt(s) * (1.0 - s) ** 1.5)
    else:
        L = -np.log1p(-s)
        T = a * np.sqrt(L)
        dT = a / (2.0 * np.sqrt(L) * (1.0 - s))
    return np.arctan(T), dT / (1.0 + T * T)


def histogram(m, dist, a):
    z = np.clip(m[:, 2], 0.0, 1.0)
    with np.errstate(divide="ignore"):
        tan2 = (1.0 - z * z) / (z * z)
    s = s_of_tan2(dist, tan2, a)
    s = np.where(np.isfinite(s), s, 1.0)
    i = np.clip((s * N_THETA).astype(int), 0, N_THETA - 1)
    phi = np.mod(np.arctan2(m[:, 1], m[:, 0]), 2 * math.pi)
    j = np.clip((phi / (2 * math.pi) * N_PHI).astype(int), 0, N_PHI - 1)
    return np.bincount(i * N_PHI + j, minlength=N_THETA * N_PHI).reshape(N_THETA, N_PHI)


def expected_probabilities(pdf, dist, a, wi=(0.0, 0.0, 1.0)):
    """Integral of pdf over every cell: Gauss-Legendre in q = sqrt(1 - s) (theta = theta(s),
    smooth cell integrands even for narrow lobes) and in phi, where each cell is split at the azimuths of
    the pdfs' kinks for the incidence wi: wi.m = 0 (visibility) and wi.m' = 0 (V-cavity)."""
    x, w = np.polynomial.legendre.leggauss(NODES)
    # Within each cell the variable is q = sqrt(1 - s) (s = 1 - q^2): visible-normal pdfs carry
    # a factor tan(theta) ~ 1/q (GGX) next to s -> 1, which ds = 2 q dq cancels.
    # Each cell is also split at theta* = pi/2 - theta_i, below which every azimuth is visible
    # (the kinks in phi appear there).
    ti, phi_i = math.acos(min(wi[2], 1.0)), math.atan2(wi[1], wi[0])
    q_star = math.sqrt(1.0 - s_of_tan2(dist, math.tan(0.5 * math.pi - ti) ** 2, a)) \
        if ti > 0 else 0.0
    q_edges = np.sqrt(1.0 - np.linspace(0.0, 1.0, N_THETA + 1))
    qa, qb = q_edges[:-1, None], q_edges[1:, None]  # qa > qb
    qm = np.clip(q_star, qb, qa)
    q0 = np.concatenate([qa, qm], axis=1)[..., None]  # (cells, 2 sub-panels, 1)
    q1 = np.concatenate([qm, qb], axis=1)[..., None]
    q = (0.5 * (q1 - q0) * x + 0.5 * (q0 + q1)).reshape(N_THETA, -1)
    wq = (0.5 * (q0 - q1) * w).reshape(N_THETA, -1)
    q, wq = q.ravel(), wq.ravel()
    q = np.where(wq > 0, q, 0.5)  # nodes of empty sub-panels (weight 0) kept finite
    s = 1.0 - q * q
    theta, dtheta = theta_of_s(dist, s, a)
    wt = wq * 2.0 * q * dtheta * np.sin(theta)  # (T,)
    with np.errstate(divide="ignore"):
        cc = np.cos(theta) / np.sin(theta) * (math.cos(ti) / math.sin(ti) if ti > 0 else np.inf)
    phi_c, phi_c2 = np.arccos(np.clip(-cc, -1, 1)), np.arccos(np.clip(cc, -1, 1))
    kinks = np.mod(phi_i + np.stack([phi_c, -phi_c, phi_c2, -phi_c2], -1), 2 * math.pi)
    p_edges = np.linspace(0.0, 2 * math.pi, N_PHI + 1)
    p0, p1 = p_edges[:-1], p_edges[1:]
    inner = np.clip(kinks[:, None, :], p0[None, :, None], p1[None, :, None])  # (T, P, 4)
    edges = np.sort(np.concatenate([np.broadcast_to(p0[None, :, None], inner.shape[:2] + (1,)),
                                    inner,
                                    np.broadcast_to(p1[None, :, None], inner.shape[:2] + (1,))],
                                   -1), -1)
    e0, e1 = edges[..., :-1, None], edges[..., 1:, None]  # (T, P, 5, 1)
    phi = 0.5 * (e1 - e0) * x + 0.5 * (e0 + e1)  # (T, P, 5, NODES)
    wp = 0.5 * (e1 - e0) * w
    st = np.sin(theta)[:, None, None, None]
    m = np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)[:, None, None, None]
                  + 0 * phi], -1)
    vals = (pdf(m) * wp).sum(axis=(2, 3)) * wt[:, None]  # (T, P)
    return vals.reshape(N_THETA, -1, N_PHI).sum(axis=1)


def pearson(observed, expected):
    observed, expected = observed.ravel().astype(float), expected.ravel()
    low = expected < 5.0
    if expected[low].sum() == 0.0 and observed[low].sum() > 0:
        return math.inf, 1, 0.0  # samples where the pdf is zero
    obs = np.append(observed[~low], observed[low].sum())
    exp = np.append(expected[~low], expected[low].sum())
    keep = exp > 0
    stat = float(np.sum((obs[keep] - exp[keep]) ** 2 / exp[keep]))
    dof = int(keep.sum()) - 1
    return stat, dof, chi2_sf(stat, dof)


@pytest.mark.parametrize("sampler, dist, theta_deg, alpha", CASES)
def test_sampler_chi2(sampler, dist, theta_deg, alpha):
    mf = Microfacet(dist, *alpha)
    t = math.radians(theta_deg)
    wi = np.array([math.sin(t) * math.cos(PHI_I), math.sin(t) * math.sin(PHI_I), math.cos(t)])
    # A fixed seed per case (the same seed everywhere would repeat one histogram: the cells
    # scale with alpha).
    rng = np.random.default_rng([SEED, CASES.index((sampler, dist, theta_deg, alpha))])
    u = rng.random((3, N_SAMPLES))
    if sampler == "dcos":
        m, pdf = mf.sample_dcos(u[0], u[1]), mf.pdf_dcos
    elif sampler == "vndf":
        m, pdf = mf.sample_vndf(wi, u[0], u[1]), (lambda mm: mf.pdf_vndf(wi, mm))
    else:
        m, pdf = mf.sample_vcavity(wi, u[0], u[1], u[2]), (lambda mm: mf.pdf_vcavity(wi, mm))
    assert np.all(np.isfinite(m)) and np.all(m[:, 2] >= 0)
    a = max(alpha)  # cells for the wider axis: the cell integrands stay bounded
    prob = expected_probabilities(pdf, dist, a, wi)
    assert prob.sum() == pytest.approx(1.0, abs=2e-3)  # the cells cover the pdf
    stat, dof, p = pearson(histogram(m, dist, a), N_SAMPLES * prob)
    print(f"{sampler} {dist} {theta_deg} {alpha}: chi2 {stat:.1f} dof {dof} p {p:.3g}")
    assert p > THRESHOLD, f"chi2 = {stat:.1f} with {dof} dof, p = {p:.3g} < {THRESHOLD:.2g}"


def test_chi2_detects_a_wrong_pdf():
    """The test has power: GGX samples judged against the Beckmann pdf of the same alpha, and
    the VNDF at 80 degrees judged against D cos, are rejected."""
    rng = np.random.default_rng(SEED)
    u = rng.random((2, N_SAMPLES // 4))
    ggx, beck = Microfacet("ggx", 0.5), Microfacet("beckmann", 0.5)
    m = ggx.sample_dcos(u[0], u[1])
    prob = expected_probabilities(beck.pdf_dcos, "ggx", 0.5)
    assert pearson(histogram(m, "ggx", 0.5), len(u[0]) * prob)[2] < 1e-12
    wi = np.array([math.sin(math.radians(80)), 0.0, math.cos(math.radians(80))])
    m = ggx.sample_vndf(wi, u[0], u[1])
    prob = expected_probabilities(ggx.pdf_dcos, "ggx", 0.5)
    assert pearson(histogram(m, "ggx", 0.5), len(u[0]) * prob)[2] < 1e-12
