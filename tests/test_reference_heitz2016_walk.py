"""Heitz, Hanika, d'Eon & Dachsbacher 2016 multiple scattering on the Smith microsurface
(addon/lab/reference/heitz2016/walk.py and its materials): reciprocity of the stochastic
evaluation (with the eta^2 rule of Cycles' transmission convention) and of the walk itself
(patch transport), and the chi-square of the sampler against the evaluation.

Every Monte Carlo comparison uses a fixed seed and a tolerance in units of its own standard
error (the estimators are unbiased; 4 to 4.5 standard errors unless said otherwise)."""
import math

import numpy as np
import pytest

from addon.lab.reference.heitz2016 import HeitzConductor, HeitzDielectric, flip
from addon.lab.reference.microfacet import Microfacet, dot, normalize
from addon.lab.reference.special import chi2_sf
from heitz2016_helpers import (  # tests/heitz2016_helpers.py
    GOLD_K, GOLD_N, polar, rand_dirs, rng_for, z_of)


# ---------------------------------------------------------------------------------------------
# Reciprocity of the stochastic evaluation.
# ---------------------------------------------------------------------------------------------
def _pairs(rng, n):
    """Pairs away from grazing (|z| >= 0.3). Toward grazing wo the evaluation can be a
    rare-event estimator: measured, Beckmann alpha (0.3, 1), wi.z = 0.89, wo.z = 0.19 along the
    smooth axis: the order-2 term from wi has relative SE 1.0 at 200k walks (a handful of walks
    carry it) while from wo it has 1%; at 30k walks the forward estimate then misses 1.7 % of f
    with an SE that does not show it (z = -26). Unbiased, but no use for a z-test."""
    return rand_dirs(rng, n, zmin=0.3), rand_dirs(rng, n, zmin=0.3)


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_reciprocity_reflection(dist):
    """f(wi, wo) = f(wo, wi) for the full multiple-scattering BRDF, statistically: estimates of
    eval / |wo.z| from wi and of eval / |wi.z| from wo (30k walks each, independent) agree within
    4.5 combined standard errors on 10 pairs, for a gold conductor (RGB), anisotropic roughness,
    and the dielectric's reflection (paths through the lower medium included). Catches any
    asymmetry of the walk's higher orders (e.g. the masking of wo taken at the wrong height, a
    one-sided projected area).

    Beckmann is tested at alpha >= 0.6 only: with its light tails the higher orders become
    rare-event estimators at lower roughness, in both directions (measured, alpha 0.6, a pair
    with wi.z = 0.71, wo.z = 0.42: the order-3 term from wi has its 5 largest of 4M walks
    carrying 93 % of it); the sample SE then misses the error and |z| reached 5 .. 25 in 8 of 12
    seeds at alpha 0.6 / (0.3, 1). At the alphas below, max |z| over 10 seeds was 1 .. 3.7."""
    rng = rng_for("recip", dist)
    wi, wo = _pairs(rng, 10)
    if dist == "ggx":
        cases = [HeitzConductor(Microfacet(dist, 0.6), n=GOLD_N, k=GOLD_K),
                 HeitzConductor(Microfacet(dist, 0.3, 1.0), fresnel="none"),
                 HeitzDielectric(Microfacet(dist, 0.8), 1.5)]
    else:
        cases = [HeitzConductor(Microfacet(dist, 0.8), n=GOLD_N, k=GOLD_K),
                 HeitzConductor(Microfacet(dist, 0.8, 1.0), fresnel="none"),
                 HeitzDielectric(Microfacet(dist, 0.8), 1.5)]
    for b in cases:
        f1, s1 = b.eval_mean(wi, wo, 30_000, rng)
        f2, s2 = b.eval_mean(wo, wi, 30_000, rng)
        z = z_of(f1 / wo[:, 2:3], s1 / wo[:, 2:3], f2 / wi[:, 2:3], s2 / wi[:, 2:3])
        print(f"reciprocity {b!r}: max |z| {np.abs(z).max():.2f}")
        assert np.abs(z).max() < 4.5


@pytest.mark.parametrize("eta", [1.5, 1 / 1.5])
def test_reciprocity_transmission_eta_squared(eta):
    """Transmission in Cycles' convention (a refraction weighs 1, f_t = Walter eq. 21 as written;
    glass.py): f_t(wi, wo; eta) = eta^2 f_t(flip(wo), flip(wi); 1/eta), i.e.
    f_t(wi -> wo) / n_o^2 = f_t(wo -> wi) / n_i^2 with n_i = 1 above and n_o = eta below.
    Tested on the multiple-scattering walk with 30k walks per direction on 10 pairs (|z| < 4.5);
    the same data without the eta^2 is rejected (median |z| > 8), so the test tells the
    conventions apart. Catches: a 1/eta^2 radiance factor slipped into the walk, eta not inverted
    below the interface."""
    rng = rng_for("recip-t", eta)
    mf = Microfacet("ggx", 0.6)
    fwd = HeitzDielectric(mf, eta)
    rev = HeitzDielectric(mf, 1.0 / eta)
    wi = rand_dirs(rng, 10, zmin=0.15)
    wo = normalize(rand_dirs(rng, 10, lower=True) + 1.2 * normalize(-wi))
    wo[:, 2] = -np.maximum(np.abs(wo[:, 2]), 0.1)
    wo = normalize(wo)
    f1, s1 = fwd.eval_mean(wi, wo, 30_000, rng)
    f2, s2 = rev.eval_mean(flip(wo), flip(wi), 30_000, rng)
    a, a_se = f1 / np.abs(wo[:, 2:3]), s1 / np.abs(wo[:, 2:3])
    b, b_se = eta ** 2 * f2 / wi[:, 2:3], eta ** 2 * s2 / wi[:, 2:3]
    keep = a[:, 0] > 1e-3
    assert keep.sum() >= 6
    z = z_of(a, a_se, b, b_se)[keep, 0]
    z_wrong = z_of(a, a_se, b / eta ** 2, b_se / eta ** 2)[keep, 0]
    print(f"transmission reciprocity eta {eta:.3f}: max |z| {np.abs(z).max():.2f}, "
          f"without eta^2 median |z| {np.median(np.abs(z_wrong)):.1f}")
    assert np.abs(z).max() < 4.5
    assert np.median(np.abs(z_wrong)) > 8.0


def _cone(rng, d, half, n):
    """n directions uniform (in solid angle) in the cone of half-angle `half` around d, and
    the cone's solid angle."""
    cmin = math.cos(half)
    c = 1.0 - (1.0 - cmin) * rng.random(n)
    s = np.sqrt(1.0 - c * c)
    ph = 2.0 * math.pi * rng.random(n)
    t = normalize(np.cross(d, [0.3, 0.5, 0.8]))
    b = np.cross(d, t)
    w = c[:, None] * d + s[:, None] * (np.cos(ph)[:, None] * t + np.sin(ph)[:, None] * b)
    return w, 2.0 * math.pi * (1.0 - cmin)


def _transport(bsdf, dA, dB, half, n, rng, orders=(1, 2, None)):
    """T(A -> B) = integral over A x B of f |cos_i| |cos_o|, per scattering order (None: all),
    from the sampler: wi uniform in cone A, weight x |wi.z| x [wo in cone B] x |A|. Bounded
    summands: no heavy tails, unlike the evaluation."""
    wi, area = _cone(rng, dA, half, n)
    s = bsdf.sample(wi, rng)
    g = area * np.abs(wi[:, 2]) * s.weight[:, 0] * (dot(s.wo, dB) > math.cos(half))
    out = []
    for k in orders:
        x = g if k is None else g * (s.order == k)
        out.append((x.mean(), x.std(ddof=1) / math.sqrt(n)))
    return out


def test_reciprocity_of_the_walk_by_patch_transport():
    """Reciprocity of the walk itself, order by order, from the sampler alone: the energy
    carried from a cone of directions A into a cone B, T(A -> B), equals T(B -> A) (1M walks
    each way, |z| < 4.5 for orders 1, 2 and all): GGX and Beckmann conductors (the Beckmann case
    is the configuration whose evaluation is too heavy-tailed for a z-test), anisotropic, the
    dielectric's reflection; for transmission T(A -> B; eta) = eta^2 T(flip B -> flip A; 1/eta)
    (Cycles' convention). Catches what the evaluation-based test cannot resolve: an asymmetry in
    the higher orders of the random walk."""
    rng = rng_for("patch")
    half, n = 0.2, 1_000_000
    dA = normalize(np.array([-0.26, -0.65, 0.71]))
    dB = normalize(np.array([0.56, -0.72, 0.42]))
    cases = [(HeitzConductor(Microfacet("ggx", 0.5), fresnel="none"), None),
             (HeitzConductor(Microfacet("beckmann", 0.6), fresnel="none"), None),
             (HeitzConductor(Microfacet("beckmann", 0.6, 1.0), fresnel="none"), None),
             (HeitzDielectric(Microfacet("ggx", 0.7), 1.5), None),
             (HeitzDielectric(Microfacet("ggx", 0.7), 1.5), HeitzDielectric(Microfacet("ggx", 0.7),
                                                                           1 / 1.5)),
             (HeitzDielectric(Microfacet("ggx", 0.7), 1 / 1.5),
              HeitzDielectric(Microfacet("ggx", 0.7), 1.5))]
    for fwd, rev in cases:
        if rev is None:  # reflection: A -> B against B -> A
            a = _transport(fwd, dA, dB, half, n, rng)
            b = _transport(fwd, dB, dA, half, n, rng)
            scale = 1.0
        else:  # transmission A -> B (B around the refraction of a steep dA through n)
            dT = normalize(np.array([-0.2, -0.3, 0.93]))
            t = -dT[:2] / fwd.eta
            dR = np.array([t[0], t[1], -math.sqrt(1.0 - t @ t)])
            a = _transport(fwd, dT, dR, half, n, rng)
            b = _transport(rev, flip(dR), flip(dT), half, n, rng)  # flip(B) -> flip(A), 1/eta
            scale = fwd.eta ** 2
        for (ma, sa), (mb, sb), k in zip(a, b, (1, 2, "all")):
            z = z_of(ma, sa, scale * mb, scale * sb)
            print(f"patch transport {fwd!r} {'T' if rev else 'R'} order {k}: "
                  f"{ma:.4e} vs {scale * mb:.4e}, z {z:.2f}")
            assert abs(z) < 4.5
            assert ma > 0.0


def test_bidirectional_eval_is_unbiased():
    """eval(bidirectional=True) (the average with the reverse walk, through reciprocity) has the
    same mean as the unidirectional estimator (within 4.5 standard errors), reflection and
    transmission."""
    rng = rng_for("bidir")
    wi, wo = _pairs(rng, 5)
    b = HeitzConductor(Microfacet("ggx", 0.7), n=GOLD_N, k=GOLD_K)
    m1, s1 = b.eval_mean(wi, wo, 20_000, rng)
    m2, s2 = b.eval_mean(wi, wo, 20_000, rng, bidirectional=True)
    assert np.abs(z_of(m1, s1, m2, s2)).max() < 4.5
    d = HeitzDielectric(Microfacet("ggx", 0.7), 1.5)
    wt = normalize(rand_dirs(rng, 5, lower=True) - wi)
    wt[:, 2] = -np.maximum(np.abs(wt[:, 2]), 0.1)
    wt = normalize(wt)
    m1, s1 = d.eval_mean(wi, wt, 20_000, rng)
    m2, s2 = d.eval_mean(wi, wt, 20_000, rng, bidirectional=True)
    assert np.abs(z_of(m1, s1, m2, s2)).max() < 4.5


# ---------------------------------------------------------------------------------------------
# Chi-square: the sampler against the stochastic evaluation.
# ---------------------------------------------------------------------------------------------
N_COS, N_PHI = 12, 24
CELL_WALKS = 2048
SAMPLES_CHI2 = 60_000  # few samples against many evaluation walks: see pearson_noisy_expected


def _sphere_cells(sphere):
    c = np.linspace(-1.0 if sphere else 0.0, 1.0, (2 if sphere else 1) * N_COS + 1)
    p = np.linspace(0.0, 2 * math.pi, N_PHI + 1)
    return c, p


def _expected_by_eval(bsdf, wi, rng, sphere, order=None):
    """Per (cos theta_o, phi_o) cell: p = integral of E[eval] over the cell, estimated from
    CELL_WALKS uniform directions in the cell with one evaluation walk each, and its variance."""
    c, p = _sphere_cells(sphere)
    nc, npf = len(c) - 1, len(p) - 1
    u = rng.random((nc, npf, CELL_WALKS, 2))
    cz = c[:-1, None, None] + (c[1:] - c[:-1])[:, None, None] * u[..., 0]
    ph = p[None, :-1, None] + (p[1:] - p[:-1])[None, :, None] * u[..., 1]
    sz = np.sqrt(np.maximum(1.0 - cz * cz, 0.0))
    wo = np.stack([sz * np.cos(ph), sz * np.sin(ph), cz], axis=-1).reshape(-1, 3)
    est = bsdf.eval(np.broadcast_to(wi, wo.shape), wo, rng, order=order)[:, 0]
    est = est.reshape(nc, npf, CELL_WALKS)
    area = (c[1:] - c[:-1])[:, None] * (p[1:] - p[:-1])[None, :]
    mean = est.mean(axis=-1) * area
    var = est.var(axis=-1, ddof=1) * area ** 2 / CELL_WALKS
    return mean, var


def _observed(bsdf, wi, n, rng, sphere):
    c, p = _sphere_cells(sphere)
    s = bsdf.sample(np.broadcast_to(wi, (n, 3)), rng)
    assert not s.lost.any() and np.all(s.weight == 1.0)
    i = np.clip(np.searchsorted(c, s.wo[:, 2], side="right") - 1, 0, len(c) - 2)
    phi = np.mod(np.arctan2(s.wo[:, 1], s.wo[:, 0]), 2 * math.pi)
    j = np.clip((phi / (2 * math.pi) * N_PHI).astype(int), 0, N_PHI - 1)
    return np.bincount(i * N_PHI + j, minlength=(len(c) - 1) * N_PHI).reshape(len(c) - 1, N_PHI)


GRAZING_COS = 0.25  # cells with |cos theta_o| below this go to the pooled complement


def pearson_noisy_expected(observed, expected, expected_var, total, eligible=None,
                           min_expected=20.0):
    """Pearson's statistic when the expected counts are themselves unbiased estimates with variance
    expected_var (independent of the observed counts): sum (O - E)^2 / (E + Var E) over the kept
    cells (eligible, E >= min_expected), plus one pooled cell for all the others whose expected
    count is the complement total - sum E (variance sum Var E), not the sum of their own
    estimates; approximately chi-square with (kept cells) degrees of freedom
    (test_reference_chi2.pearson is the case Var E = 0 with the pool's own sum).

    Why the precautions: the stochastic evaluation is heavy-tailed in places (rare walks with
    large next-event terms, at orders >= 2 and low roughness, most of all toward grazing wo).
    Measured (GGX alpha (0.2, 0.8), 1e6 walks per cell): no bias, but the median of 2000-walk
    cell means is 0.94 .. 0.98 of the converged mean (0.78 toward grazing wo at alpha 0.2) and a
    cell's sample variance can fall short of the true one by an order of magnitude when its rare
    terms are not drawn; with 150k samples and 768 walks per cell the statistic was
    anti-conservative (p < 0.01 in 4 of 16 seeds, two below 1e-3). Hence: few samples (SAMPLES_CHI2)
    against many evaluation walks per cell (CELL_WALKS), so the evaluation's error is small next
    to the Poisson noise; cells below GRAZING_COS and cells with E < min_expected pooled; the
    pool's expectation from the exactly known total (every walk escapes; the evaluation's own
    total is tested against 1 in the energy tests). With these the p-values over 16 seeds per
    case look uniform (smallest 0.014 .. 0.18)."""
    o, e, v = (np.ravel(x).astype(float) for x in (observed, expected, expected_var))
    keep = e >= min_expected
    if eligible is not None:
        keep &= np.ravel(eligible)
    o_pool = float(total - o[keep].sum())
    e_pool = float(total - e[keep].sum())
    v_pool = float(v[keep].sum())
    stat = float(np.sum((o[keep] - e[keep]) ** 2 / (e[keep] + v[keep])))
    if e_pool > 0.0:
        stat += (o_pool - e_pool) ** 2 / (e_pool + v_pool)
    dof = int(keep.sum())
    return stat, dof, chi2_sf(stat, dof)


def _eligible(sphere):
    c, _ = _sphere_cells(sphere)
    lo = np.minimum(np.abs(c[:-1]), np.abs(c[1:]))
    return np.broadcast_to((lo >= GRAZING_COS - 1e-12)[:, None], (len(lo), N_PHI))


CHI2_CASES = [("conductor", "ggx", 0.5, 30.0), ("conductor", "ggx", 1.0, 70.0),
              ("conductor", "beckmann", 0.6, 0.0), ("conductor", "ggx", (0.2, 0.8), 50.0),
              ("dielectric", "ggx", 0.5, 40.0), ("dielectric", "ggx", 1.0, 75.0),
              ("dielectric_inv", "beckmann", 0.6, 20.0)]
CHI2_THRESHOLD = 1.0 - 0.99 ** (1.0 / len(CHI2_CASES))


def _chi2_bsdf(kind, dist, alpha):
    mf = Microfacet(dist, *(alpha if isinstance(alpha, tuple) else (alpha,)))
    if kind == "conductor":
        return HeitzConductor(mf, fresnel="none"), False
    return HeitzDielectric(mf, 1.5 if kind == "dielectric" else 1 / 1.5), True


@pytest.mark.parametrize("kind, dist, alpha, theta", CHI2_CASES)
def test_sampler_matches_eval_chi2(kind, dist, alpha, theta):
    """The walk's sampled directions (60k, weight 1: F = 1 or no absorption) against the stochastic
    evaluation integrated over 12 x 24 cells per hemisphere (uniform in cos theta_o and phi_o;
    2048 evaluation walks per cell), Pearson with the evaluation's variance in the denominator
    (pearson_noisy_expected); Sidak-corrected family significance 0.01. Every scattering order
    is in both, so this ties the sampler's higher orders to the next-event estimator. Catches a
    sampler and an evaluation that disagree anywhere in direction (which the albedo alone would
    not)."""
    bsdf, sphere = _chi2_bsdf(kind, dist, alpha)
    rng = rng_for("chi2", kind, dist, alpha, theta)
    wi = polar(theta, 0.4)
    n = SAMPLES_CHI2
    obs = _observed(bsdf, wi, n, rng, sphere)
    mean, var = _expected_by_eval(bsdf, wi, rng, sphere)
    assert mean.sum() == pytest.approx(1.0, abs=0.02)
    stat, dof, p = pearson_noisy_expected(obs, n * mean, n * n * var, n, _eligible(sphere))
    print(f"sampler vs eval {kind} {dist} {alpha} {theta}: chi2 {stat:.1f} dof {dof} p {p:.3g}")
    assert p > CHI2_THRESHOLD


def test_sampler_vs_eval_chi2_has_power():
    """The harness rejects the full sampler judged against the first-order evaluation alone (GGX
    alpha 1, where the higher orders carry 0.69 of the energy at normal incidence, and alpha 0.5,
    0.31 of it) — and against the other dielectric index."""
    rng = rng_for("chi2-power")
    n = SAMPLES_CHI2
    for a in (1.0, 0.5):
        bsdf = HeitzConductor(Microfacet("ggx", a), fresnel="none")
        wi = polar(20.0, 0.4)
        obs = _observed(bsdf, wi, n, rng, False)
        mean, var = _expected_by_eval(bsdf, wi, rng, False, order=1)
        assert pearson_noisy_expected(obs, n * mean, n * n * var, n, _eligible(False))[2] < 1e-12
    d = HeitzDielectric(Microfacet("ggx", 0.5), 1.5)
    wi = polar(40.0, 0.4)
    obs = _observed(d, wi, n, rng, True)
    mean, var = _expected_by_eval(HeitzDielectric(Microfacet("ggx", 0.5), 1.33), wi, rng, True)
    assert pearson_noisy_expected(obs, n * mean, n * n * var, n, _eligible(True))[2] < 1e-12
