"""Lee et al. 2018, asymmetric V-grooves: the evaluation `lee.eval_asymmetric` (the integral over
the partner wall, docs/lee-asymmetric-grooves.md sec. 5) against the analytic sampler
`lee.sample` (chi-square goodness of fit, normalisation, gold albedo), the brute-force tracer
(addon/lab/reference/vgroove.py), reciprocity, and the convergence of its quadrature. numpy only.

Coordinates. A direction wo is binned by the groove that can send wi to it: phi = the azimuth of
wi + wo (the groove frame t; folded to [0, pi] by the symmetry y -> -y, wi lies in the xz
plane) and the 2D exit angle theta_o in that frame, which then lies in (-theta_i, pi/2). In
(phi, theta_o) the solid angle is d omega = |(wi + wo).t| d theta_o d phi (the doc's Jacobian
argument with c = 1), which cancels the 1/|(wi + wo).t| of the BRDF: the density f cos |h.t| is
bounded, and per-bin Gauss-Legendre sums converge where (theta, phi) bins would meet the
integrable singularity at the mirror direction. theta_o is stretched by
v = atan(tan(theta_h) / a) with theta_h = (theta_o + theta_i)/2 (the first wall's angle for
k = 1) and a = max(alpha, 0.3), normalised to [0, 1] per phi. The change of variables is
checked on the symmetric closed-form eval
(test_canonical_coordinates_integrate_the_symmetric_eval)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from addon.lab.reference import lee, make_bsdf
from addon.lab.reference import vgroove as vg
from addon.lab.reference.microfacet import Microfacet
from addon.lab.reference.special import chi2_sf, erfinv
from test_reference_lee import _pairs  # random (wi, wo) pairs over the hemisphere

DISTS = ("ggx", "beckmann")
ALPHAS = (0.1, 0.5, 1.0)
ANGLES = (0.0, 30.0, 60.0, 80.0)
ONE = vg.fresnel_fn("none")
GOLD = vg.fresnel_fn("conductor")
FAMILY_ALPHA = 0.01
NPHI, NV, SUB = 16, 16, 3  # bins; Gauss-Legendre nodes per bin and axis (a 48 x 48 grid)
# Error of the 48 x 48 grid for the integral of f cos (F = 1: exactly 1 up to the truncation,
# < 1e-4): measured at most 4.5e-4 over the 24 cases below (GGX alpha 0.5 at 80 degrees; the
# others below 1e-4), and at most 6e-4 between this grid and the 96 x 96 one (F = 1 and gold;
# docs/lee-asymmetric-grooves.md sec. 7). The gold integrand is the same one times a smooth
# product of Fresnel factors in (0, 1].
QUAD_ERR = 5e-4
TRUNCATION = lee.TRUNCATION


def _wi(deg):
    t = math.radians(deg)
    return np.array([math.sin(t), 0.0, math.cos(t)])


def _sidak(m):
    return 1.0 - (1.0 - FAMILY_ALPHA) ** (1.0 / m)


def _z_two_sided(p):
    return math.sqrt(2.0) * float(erfinv(1.0 - p))


def gold_and_one(c):
    """A Fresnel whose channels are (gold G, 1, gold B): one evaluation or one sampling pass
    gives the F = 1 lobe (channel 1) and two conductor ones."""
    g = GOLD(c)
    return np.stack([g[..., 1], np.ones_like(g[..., 1]), g[..., 2]], axis=-1)


def _stretch(theta_h, a):
    return np.arctan(np.tan(theta_h) / a)


def canonical(wi, wo, alpha):
    """(phi in [0, pi], v in [0, 1]) of directions wo (see the module docstring)."""
    h = wi + wo
    phi = np.arctan2(h[:, 1], h[:, 0])
    t = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=-1)
    ti = np.arctan2(t @ wi, wi[2])
    to = np.arctan2(np.sum(wo * t, -1), wo[:, 2])
    a = max(alpha, 0.3)
    v = _stretch(0.5 * (to + ti), a) / _stretch(0.5 * (0.5 * math.pi + ti), a)
    return np.abs(phi), np.clip(v, 0.0, 1.0 - 1e-15)


def grid(wi, alpha, sub=SUB):
    """Gauss-Legendre nodes (sub x sub per bin) of (phi, v) on [0, pi] x [0, 1]: directions wo
    (NPHI sub, NV sub, 3) and weights such that sum(weight * f) = integral f cos d omega over
    the hemisphere (the fold y -> -y counted twice)."""
    x, w = np.polynomial.legendre.leggauss(sub)
    x, w = 0.5 * (x + 1.0), 0.5 * w

    def nodes(nbins):
        return (((np.arange(nbins)[:, None] + x) / nbins).ravel(),
                np.tile(w, nbins) / nbins)

    (p, wp), (v, wv) = nodes(NPHI), nodes(NV)
    P, V = np.meshgrid(p * math.pi, v, indexing="ij")
    t = np.stack([np.cos(P), np.sin(P), np.zeros_like(P)], axis=-1)
    u = np.stack([-np.sin(P), np.cos(P), np.zeros_like(P)], axis=-1)
    pi_, wu = t @ wi, u @ wi
    ti, rho = np.arctan2(pi_, wi[2]), np.hypot(pi_, wi[2])
    a = max(alpha, 0.3)
    top = np.arctan(np.tan(0.5 * (0.5 * math.pi + ti)) / a)  # v = 1 <=> theta_o = pi/2
    tb = np.tan(V * top)
    to = -ti + 2.0 * np.arctan(a * tb)
    dto_dv = 2.0 * a * (1.0 + tb * tb) / (1.0 + (a * tb) ** 2) * top
    wo = rho[..., None] * (np.sin(to)[..., None] * t + np.cos(to)[..., None]
                           * np.array([0.0, 0.0, 1.0])) - wu[..., None] * u
    ht = pi_ + rho * np.sin(to)  # (wi + wo).t > 0
    weight = 2.0 * math.pi * np.outer(wp, wv) * dto_dv * ht * wo[..., 2]
    return wo, weight


def bin_masses(wi, mf, f_of, sub=SUB):
    """Integral of f cos over each (phi, v) bin (NPHI x NV, RGB). At normal incidence f is
    evaluated on one azimuth and copied to the others (isotropic D: rotational symmetry; the
    other incidences test every azimuth)."""
    wo, weight = grid(wi, mf.alpha_x, sub)
    if wi[0] == 0.0 and wi[1] == 0.0:
        f = np.broadcast_to(f_of(wo[0]), wo.shape[:2] + (3,))
    else:
        f = f_of(wo.reshape(-1, 3)).reshape(wo.shape[:2] + (3,))
    m = f * weight[..., None]
    return m.reshape(NPHI, sub, NV, sub, 3).sum(axis=(1, 3)).reshape(-1, 3)


def histogram(wi, wo, alpha):
    phi, v = canonical(wi, wo, alpha)
    i = np.minimum((phi / math.pi * NPHI).astype(int), NPHI - 1)
    j = np.minimum((v * NV).astype(int), NV - 1)
    return np.bincount(i * NV + j, minlength=NPHI * NV).astype(float)


def chi2_p(observed, mass):
    """Pearson goodness of fit of counts against bin masses (renormalised; bins expected below
    5 pooled)."""
    n = observed.sum()
    exp = n * mass / mass.sum()
    low = exp < 5.0
    exp = np.append(exp[~low], exp[low].sum())
    obs = np.append(observed[~low], observed[low].sum())
    if exp[-1] < 5.0:
        exp, obs = exp[:-1], obs[:-1]
    return chi2_sf(float(np.sum((obs - exp) ** 2 / exp)), len(obs) - 1)


# -- the test's own coordinates, on the symmetric closed form ------------------------------------
@pytest.mark.parametrize("dist", DISTS)
def test_canonical_coordinates_integrate_the_symmetric_eval(dist):
    """The (phi, v) grid with d omega = |(wi + wo).t| d theta_o d phi integrates the symmetric
    closed-form eval (F = 1, tested elsewhere against the tracer) to 1 within QUAD_ERR: catches
    a wrong Jacobian or a wrong domain in this file's coordinates, which the asymmetric tests
    below rely on."""
    for alpha in (0.1, 0.5):
        mf = Microfacet(dist, alpha)
        for deg in (0.0, 60.0, 80.0):
            wi = _wi(deg)
            total = bin_masses(wi, mf, lambda wo: lee.eval(wi, wo, mf, ONE))[:, 0].sum()
            assert abs(total - 1.0) < QUAD_ERR + TRUNCATION, (alpha, deg, total)


# -- eval against the sampler --------------------------------------------------------------------
CASES = [(d, a, deg) for d in DISTS for a in ALPHAS for deg in ANGLES]


@pytest.mark.parametrize("dist,alpha,deg", CASES)
def test_asymmetric_eval_matches_sampler(dist, alpha, deg):
    """For one wi: (1) chi-square goodness of fit of 100k directions of the analytic sampler
    against the bin integrals of eval cos (F = 1) on 16 x 16 (phi, v) bins, family level 0.01
    (Sidak over the 24 cases); (2) the integral of eval cos with F = 1 is 1 (the sampler's
    albedo, every weight being 1) within the quadrature error plus the truncation; (3) with gold
    (G and B channels), the integral of eval cos equals the sampler's mean weight within
    z standard errors (Sidak over 48 comparisons) plus the quadrature error.
    Catches: a wrong Jacobian (c_k, sin(theta_l)), a wrong groove density g or Z, a missing
    frame, landing side or k window, a wrong exit-angle inversion, and wrong bounce cosines in
    the Fresnel product (3)."""
    rng = np.random.default_rng(20 + CASES.index((dist, alpha, deg)))
    n = 100000
    mf = Microfacet(dist, alpha)
    wi = _wi(deg)
    wo, w, _ = lee.sample(wi, rng.random((n, 6)), mf, gold_and_one, "asymmetric")
    mass = bin_masses(wi, mf, lambda o: lee.eval_asymmetric(wi, o, mf, gold_and_one))
    total = mass.sum(axis=0)
    # (2) normalisation (F = 1): the sampler's albedo is exactly 1.
    assert np.all(w[:, 1] == 1.0)
    assert abs(total[1] - 1.0) < QUAD_ERR + TRUNCATION, total[1]
    # (1) shape.
    p = chi2_p(histogram(wi, wo, alpha), mass[:, 1])
    assert p > _sidak(len(CASES)), p
    # (3) gold albedo.
    z = _z_two_sided(_sidak(2 * len(CASES)))
    for ch in (0, 2):
        mean, se = w[:, ch].mean(), w[:, ch].std() / math.sqrt(n)
        assert abs(total[ch] - mean) < z * se + QUAD_ERR + TRUNCATION, (ch, total[ch], mean, se)


def test_chi2_would_see_a_wrong_jacobian():
    """The goodness of fit is not blind: the symmetric groove's Jacobian factor 2k in place of
    the asymmetric c_k = k (even k) halves the k = 2 term, and the same sampler directions then
    fail (p < 1e-6) on GGX alpha 0.5 at 60 degrees, where they pass against the right eval."""
    rng = np.random.default_rng(19)
    mf = Microfacet("ggx", 0.5)
    wi = _wi(60.0)
    wo, _, _ = lee.sample(wi, rng.random((100000, 6)), mf, ONE, "asymmetric")
    obs = histogram(wi, wo, 0.5)
    right = bin_masses(wi, mf, lambda o: lee.eval_asymmetric(wi, o, mf, ONE))[:, 0]
    k1 = bin_masses(wi, mf, lambda o: lee.eval_asymmetric(wi, o, mf, ONE, kmax=1))[:, 0]
    k12 = bin_masses(wi, mf, lambda o: lee.eval_asymmetric(wi, o, mf, ONE, kmax=2))[:, 0]
    assert chi2_p(obs, right - 0.5 * (k12 - k1)) < 1e-6
    assert chi2_p(obs, right) > _sidak(len(CASES))


# -- eval against the tracer ---------------------------------------------------------------------
TRACER_CASES = [("ggx", 0.5, 60.0), ("beckmann", 1.0, 30.0)]


@pytest.mark.parametrize("dist,alpha,deg", TRACER_CASES)
def test_asymmetric_eval_matches_tracer(dist, alpha, deg):
    """Brute-force traced directions (200k rays, partner walls from the tracer's numerical
    inverse CDF, walls intersected one by one) against the bin integrals of eval cos: chi-square
    at family level 0.01. Independent of the kaleidoscope formulas the sampler and eval share,
    so it catches an error common to both (a wrong count, exit angle or groove density)."""
    rng = np.random.default_rng(30 + TRACER_CASES.index((dist, alpha, deg)))
    mf = Microfacet(dist, alpha)
    wi = _wi(deg)
    wo, thr, _ = vg.trace(wi, mf, 200000, rng, ONE, "asymmetric")
    assert np.all(thr == 1.0)
    mass = bin_masses(wi, mf, lambda o: lee.eval_asymmetric(wi, o, mf, ONE))[:, 0]
    assert chi2_p(histogram(wi, wo, alpha), mass) > _sidak(len(TRACER_CASES))


# -- reciprocity, convergence, the BSDF object -----------------------------------------------------
@pytest.mark.parametrize("dist", DISTS)
def test_asymmetric_eval_reciprocity(dist):
    """f(wi, wo) = f(wo, wi) to 1e-9 (measured: 6e-14), F = 1 and gold: the quadrature is
    invariant under path reversal (the window is the same set of grooves both ways), so not
    only the integral but the rule is reciprocal. Catches an asymmetric window, a Fresnel
    product in the wrong bounce order, a density g that is not symmetric once multiplied by
    sin(theta_l), or a frame that is missed one way."""
    rng = np.random.default_rng(40)
    wi, wo = _pairs(rng, 300)
    for alpha in ALPHAS:
        mf = Microfacet(dist, alpha)
        for fresnel in (ONE, GOLD):
            a = lee.eval_asymmetric(wi, wo, mf, fresnel)
            b = lee.eval_asymmetric(wo, wi, mf, fresnel)
            assert np.allclose(a, b, rtol=1e-9, atol=0.0)
            assert np.count_nonzero(a[:, 0]) > 250


@pytest.mark.parametrize("dist", DISTS)
def test_asymmetric_eval_partner_quadrature_converges(dist):
    """n vs 2n for the partner-angle rule: over random pairs, the cosine-weighted relative change
    d(n) = sum |f_n - f_2n| cos / sum f_2n cos is below 1e-3 from the default n = 12 to 24
    (measured at most 7e-4, alpha 1) and drops by at least 3x from 24 to 48 (measured 4x: the
    integrand has kinks where len_k reaches 0, so the rule converges as n^-2). Catches a rule
    that does not resolve the partner peak or the window ends, or that does not converge."""
    rng = np.random.default_rng(41)
    wi, wo = _pairs(rng, 400)
    cos = wo[:, 2]
    for alpha in (0.1, 1.0):
        mf = Microfacet(dist, alpha)
        f = [lee.eval_asymmetric(wi, wo, mf, ONE, n_partner=n)[:, 0] for n in (12, 24, 48)]
        d1 = np.sum(np.abs(f[0] - f[1]) * cos) / np.sum(f[1] * cos)
        d2 = np.sum(np.abs(f[1] - f[2]) * cos) / np.sum(f[2] * cos)
        assert d1 < 1e-3 and d2 < d1 / 3.0, (alpha, d1, d2)


@pytest.mark.parametrize("dist", DISTS)
def test_asymmetric_eval_monte_carlo_rule_is_unbiased(dist):
    """eval_asymmetric with u (one random node per side, frame and k: the estimate the Native +
    Residual shader aims with, lee_low_orders_asymmetric) has the quadrature's value as its
    mean: per pair of directions, z-tested over 4,000 draws against the 48-node rule, whose own
    error is below 1e-3 (test above). Catches a node weight or interval that is not the
    rule's (a 5% error reads z > 10 at the brightest pairs)."""
    rng = np.random.default_rng(43)
    wi, wo = _pairs(rng, 24)
    n = 4000
    for alpha in (0.2, 0.8):
        mf = Microfacet(dist, alpha)
        ref = lee.eval_asymmetric(wi, wo, mf, GOLD, kmax=6, n_partner=48)
        W_i, W_o = np.repeat(wi, n, 0), np.repeat(wo, n, 0)
        u = rng.random((len(W_i), 2, 6, 2))
        mc = lee.eval_asymmetric(W_i, W_o, mf, GOLD, kmax=6, u=u).reshape(len(wi), n, 3)
        assert np.all(mc >= 0.0) and np.all(np.isfinite(mc))
        mean, se = mc.mean(1), mc.std(1) / math.sqrt(n)
        lit = ref[:, 1] > 1e-3 * ref[:, 1].max()
        assert np.count_nonzero(lit) >= 6
        z = (mean - ref)[lit] / np.hypot(se[lit], 1e-3 * ref[lit])
        assert np.all(np.abs(z) < 4.5), (alpha, z)


def test_lee_brdf_eval_both_grooves():
    """LeeBRDF.eval: asymmetric grooves evaluate (no NotImplementedError) with the tint and the
    catalog's Fresnel applied, symmetric grooves are the closed form, roughness 0 gives zeros."""
    rng = np.random.default_rng(42)
    wi, wo = _pairs(rng, 50)
    mf = Microfacet("ggx", 0.4)
    tint = np.array([0.5, 0.8, 1.0])
    for groove, fn in (("symmetric", lee.eval), ("asymmetric", lee.eval_asymmetric)):
        b = lee.LeeBRDF(mf, groove, "conductor", n=(0.2, 0.4, 1.4), k=(3.0, 2.5, 1.8), tint=tint)
        ref = fn(wi, wo, mf, b.fresnel, b.kmax) * tint
        assert np.allclose(b.eval(wi, wo), ref, rtol=1e-6, atol=0.0)
        assert np.count_nonzero(ref[:, 0]) > 40
        d = lee.LeeBRDF(Microfacet("ggx", 0.0), groove)
        assert np.all(d.eval(wi, wo) == 0.0)


# -- Max Bounces: one meaning in the sampler, eval and the closed-form albedo --------------------
MB_CASES = [(g, mb, deg) for g in ("symmetric", "asymmetric") for mb in (1, 2, 5)
            for deg in (0.0, 60.0)]


@pytest.mark.parametrize("groove,mb,deg", MB_CASES)
def test_max_bounces_has_one_meaning(groove, mb, deg):
    """Max Bounces N (the catalog's max_bounces, LeeBRDF.kmax): the first N bounces of a path get
    their Fresnel factor, later bounces F = 1, every path is followed to its exit; the sampler,
    eval, the closed-form albedo and the OSL shader all read it so. GGX alpha 1 (derived bound
    158 symmetric, 74 asymmetric), catalog gold, N = 1, 2, 5:
    (1) the integral of LeeBRDF.eval cos on the (phi, v) grid equals the sampler's mean weight
    (200k samples) within z standard errors (Sidak over the 3 channels of every case) plus the
    grid's error and the truncation (measured |z| <= 2.9 on the G and B channels; the R channel,
    whose standard error is 1e-5 at N = 1, differs by up to 9e-5: the grid's error);
    (2) lee.albedo with kmax = N (deterministic, converged to about 1e-5) equals the same integral
    within the grid's error plus the truncation (measured at most 8.2e-5);
    (3) not blind: eval summing only k <= N (the former meaning of eval, which dropped the
    later bounces: 0.36 against the sampler's 0.95 for R at N = 1) misses the R channel by
    more than ten times the tolerance (measured 13 to 1050 times);
    (4) F = 1: every sample weighs exactly 1 and eval integrates to 1: no energy is lost or
    made at any N (the white furnace of tests/test_render_lee.py)."""
    rng = np.random.default_rng(50 + MB_CASES.index((groove, mb, deg)))
    n = 200000
    wi = _wi(deg)
    values = {"roughness": 1.0, "groove": groove, "max_bounces": float(mb)}
    b = make_bsdf("lee_vgroove", {**values, "fresnel_type": "conductor"})
    assert b.kmax == mb and b.kterms > 50
    mf = b.mf
    nu = 3 if groove == "symmetric" else 6
    _, w, _ = b.sample(wi, rng.random((n, nu)))
    mean, se = w.mean(axis=0), w.std(axis=0) / math.sqrt(n)
    total = bin_masses(wi, mf, lambda o: b.eval(wi, o)).sum(axis=0)
    z = _z_two_sided(_sidak(3 * len(MB_CASES)))
    tol = z * se + QUAD_ERR + TRUNCATION
    assert np.all(np.abs(total - mean) < tol), (total, mean, se)
    closed = lee.albedo(wi, mf, b.fresnel, groove, n=256 if groove == "symmetric" else 128,
                        kmax=mb, n_partner=64)
    assert np.all(np.abs(closed - total) < QUAD_ERR + TRUNCATION), (closed, total)
    fn = lee.eval if groove == "symmetric" else lee.eval_asymmetric
    dropped = bin_masses(wi, mf, lambda o: fn(wi, o, mf, b.fresnel, mb)).sum(axis=0)
    assert mean[0] - dropped[0] > 10.0 * tol[0], (dropped, mean)  # R: the most reflective
    one = make_bsdf("lee_vgroove", {**values, "fresnel_type": "none"})
    _, w1, _ = one.sample(wi, rng.random((20000, nu)))
    assert np.all(w1 == 1.0)
    total1 = bin_masses(wi, mf, lambda o: one.eval(wi, o)).sum(axis=0)
    assert np.all(np.abs(total1 - 1.0) < QUAD_ERR + TRUNCATION), total1
