"""Distribution of normals: normalisation of D cos and of the visible-normal pdfs (Smith and
V-cavity) by deterministic quadrature, the V-cavity pdf identity, exact Beckmann Lambda, the
delta limit and numerical traps (docs/models.md)."""
import math

import numpy as np
import pytest

from addon.lab.reference.microfacet import Microfacet, dot

ALPHAS = (0.01, 0.05, 0.2, 0.5, 1.0)
INCIDENCE = (0.0, 30.0, 60.0, 80.0, 89.0)
DISTRIBUTIONS = ("ggx", "beckmann")


def gl(a, b, n):
    x, w = np.polynomial.legendre.leggauss(n)
    a, b = np.asarray(a, dtype=float)[..., None], np.asarray(b, dtype=float)[..., None]
    return 0.5 * (b - a) * x + 0.5 * (a + b), 0.5 * (b - a) * w


def integrate_normals(pdf, wi, c, n=64):
    """Integral of pdf(m) dm over the upper hemisphere, independent of the samplers.

    theta = atan(c tan psi) (c ~ alpha, so the lobe is spread over psi in [0, pi/2]) with psi
    panels split where the visibility boundary wi.m = 0 appears (theta = pi/2 - theta_i); for
    each theta the azimuth runs over the visible range |phi - phi_i| < phi_c (wi.m > 0; where
    the pdf is zero anyway) split at phi_c2 (wi.m' = 0, the V-cavity kink) and at phi_i, so
    every panel integrand is smooth."""
    ti = math.acos(wi[2])
    phi_i = math.atan2(wi[1], wi[0])
    psi_b = math.atan(math.tan(0.5 * math.pi - ti) / c) if ti > 0 else 0.5 * math.pi
    edges = sorted({0.0, 0.5 * psi_b, psi_b, 0.5 * (psi_b + 0.5 * math.pi), 0.5 * math.pi})
    total = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        psi, wpsi = gl(a, b, n)
        tp = np.tan(psi)
        theta = np.arctan(c * tp)
        jac = c / np.cos(psi) ** 2 / (1.0 + (c * tp) ** 2)  # dtheta / dpsi
        if ti > 0:
            cc = 1.0 / np.tan(theta) / math.tan(ti)
            phi_c = np.arccos(np.clip(-cc, -1, 1))
            phi_c2 = np.arccos(np.clip(cc, -1, 1))
        else:
            phi_c, phi_c2 = np.full_like(theta, math.pi), np.full_like(theta, 0.5 * math.pi)
        for lo, hi in ((-phi_c, -phi_c2), (-phi_c2, 0 * phi_c), (0 * phi_c, phi_c2),
                       (phi_c2, phi_c)):
            phi, wphi = gl(phi_i + lo, phi_i + hi, n)  # (n_theta, n_phi)
            st = np.sin(theta)[:, None]
            m = np.stack([st * np.cos(phi), st * np.sin(phi),
                          np.cos(theta)[:, None] + 0 * phi], axis=-1)
            vals = pdf(m) * st * wphi
            total += np.sum(vals.sum(1) * wpsi * jac)
    return total


def direction(theta_deg, phi=0.7):
    t = math.radians(theta_deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


def nodes(ax, ay):
    """Gauss-Legendre nodes per panel: elongated (anisotropic) lobes vary faster in phi."""
    return 32 if ax == ay else 96


CASES = [(d, a, a) for d in DISTRIBUTIONS for a in ALPHAS] + \
        [("ggx", 0.05, 0.4), ("beckmann", 0.8, 0.1)]  # anisotropic


@pytest.mark.parametrize("dist, ax, ay", CASES)
def test_normalisation_dcos(dist, ax, ay):
    mf = Microfacet(dist, ax, ay)
    total = integrate_normals(mf.pdf_dcos, np.array([0.0, 0.0, 1.0]), math.sqrt(ax * ay),
                              nodes(ax, ay))
    assert total == pytest.approx(1.0, abs=1e-4)


@pytest.mark.parametrize("dist, ax, ay", CASES)
def test_normalisation_visible_normals(dist, ax, ay):
    """integral D_wi(m) dm = 1 (Smith: needs the exact Lambda) and the V-cavity analogue."""
    mf = Microfacet(dist, ax, ay)
    for theta in INCIDENCE:
        wi = direction(theta)
        c = math.sqrt(ax * ay)
        smith = integrate_normals(lambda m: mf.pdf_vndf(wi, m), wi, c, nodes(ax, ay))
        vcav = integrate_normals(lambda m: mf.pdf_vcavity(wi, m), wi, c, nodes(ax, ay))
        assert smith == pytest.approx(1.0, abs=1e-4), (theta, smith)
        assert vcav == pytest.approx(1.0, abs=1e-4), (theta, vcav)


@pytest.mark.parametrize("dist", DISTRIBUTIONS)
def test_vcavity_pdf_is_visible_normal_distribution(dist):
    """pdf_vcavity = 2 D m.z <wi,m>+ / (<wi,m>+ + <wi,m'>+) equals the V-cavity distribution of
    visible normals G1_vc(wi,m) <wi,m>+ D(m) / wi.z (Heitz 2014)."""
    rng = np.random.default_rng(3)
    mf = Microfacet(dist, 0.3, 0.7)
    wi = rng.normal(size=(20000, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    m = mf.sample_dcos(rng.random(20000), rng.random(20000))
    lhs = mf.pdf_vcavity(wi, m)
    rhs = mf.G1_vcavity(wi, m) * np.maximum(dot(wi, m), 0) * mf.D(m) / wi[:, 2]
    assert np.allclose(lhs, rhs, rtol=1e-12, atol=1e-300)
    assert np.mean(lhs > 0) > 0.5


@pytest.mark.parametrize("alpha", (0.05, 0.3, 1.0, 2.0))
def test_beckmann_lambda_matches_smith_integral(alpha):
    """Smith: Lambda(w) = 1/cot(t) integral_{cot t}^inf (q - cot t) P1(q) dq with the Beckmann
    slope marginal P1(q) = exp(-q^2/alpha^2) / (alpha sqrt(pi)) (Heitz 2014 eq. 72), by
    Gauss-Legendre, against the closed form with erfc."""
    mf = Microfacet("beckmann", alpha)
    for theta in (1.0, 20.0, 45.0, 70.0, 85.0, 89.0, 89.9):
        t = math.radians(theta)
        cot = 1.0 / math.tan(t)
        q, w = gl(cot, cot + 12.0 * alpha, 200)
        p1 = np.exp(-(q / alpha) ** 2) / (alpha * math.sqrt(math.pi))
        lam_num = np.sum(w * (q - cot) * p1) / cot
        lam = mf.lambda_(np.array([math.sin(t), 0.0, math.cos(t)]))
        assert abs(1 / (1 + lam) - 1 / (1 + lam_num)) < 1e-7, theta  # G1 to 1e-7
        if lam_num > 1e-12:
            assert lam == pytest.approx(lam_num, rel=2e-5), theta


def test_ggx_lambda_closed_form_and_anisotropy():
    mf = Microfacet("ggx", 0.3, 0.6)
    w = direction(60.0, phi=0.4)
    a0 = math.sqrt((0.3 * math.cos(0.4)) ** 2 + (0.6 * math.sin(0.4)) ** 2)
    expected = 0.5 * (-1 + math.sqrt(1 + a0 ** 2 * math.tan(math.radians(60)) ** 2))
    assert mf.lambda_(w) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("dist", DISTRIBUTIONS)
def test_delta_limit_and_traps(dist):
    """alpha below 1e-7 is a delta (m = n); tiny alphas, one zero axis, grazing directions and
    wi.m -> 0 give finite values everywhere."""
    rng = np.random.default_rng(5)
    n = 4000
    u = rng.random((n, 3))
    delta = Microfacet(dist, 0.0)
    assert delta.delta
    wi = direction(60.0)
    for m in (delta.sample_dcos(u[:, 0], u[:, 1]), delta.sample_vndf(wi, u[:, 0], u[:, 1]),
              delta.sample_vcavity(wi, u[:, 0], u[:, 1], u[:, 2])):
        assert np.array_equal(m, np.tile([0.0, 0.0, 1.0], (n, 1)))
    graze = np.array([[math.sin(math.radians(89.999)), 0, math.cos(math.radians(89.999))],
                      [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    for ax, ay in ((1e-7, 1e-7), (2e-7, 0.0), (0.0, 0.3), (1e-4, 1e-4), (1.0, 1.0)):
        mf = Microfacet(dist, ax, ay)
        for w in graze:
            ms = [mf.sample_dcos(u[:, 0], u[:, 1]), mf.sample_vndf(w, u[:, 0], u[:, 1]),
                  mf.sample_vcavity(w, u[:, 0], u[:, 1], u[:, 2])]
            for m in ms:
                assert np.all(np.isfinite(m)) and np.allclose(np.linalg.norm(m, axis=1), 1)
                assert np.all(m[:, 2] >= 0)
                vals = [mf.D(m), mf.lambda_(w), mf.G1(w, m), mf.pdf_dcos(m),
                        mf.pdf_vndf(w, m), mf.pdf_vcavity(w, m), mf.G1_vcavity(w, m)]
                for v in vals:
                    assert np.all(np.isfinite(v)) and np.all(v >= 0)
        # wi.m -> 0 exactly: a normal perpendicular to wi.
        m = np.array([[0.0, 1.0, 0.0], [-math.cos(0.3), 0.0, math.sin(0.3)]])
        w = np.array([[1.0, 0.0, 0.0], [math.sin(0.3), 0.0, math.cos(0.3)]])
        for masking in ("height_correlated", "separable", "vcavity"):
            assert np.all(np.isfinite(mf.G2(w, w, m, masking)))
