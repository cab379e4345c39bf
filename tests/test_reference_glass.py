"""Walter 2007 rough glass (`walter_glass`, addon/lab/reference/glass.py) over the whole sphere of
outgoing directions: the formulas, weight = eval |cos| / pdf, chi-square goodness of fit of
both samplers, the BTDF reciprocity relation, energy (R + T <= 1, = 1 for perfect glass), total
internal reflection, the index-matched pass-through, and the quadrature of the moments
(convergence, the delta seam, agreement with Monte Carlo)."""
import math

import numpy as np
import pytest

from addon.lab.reference import make_bsdf
from addon.lab.reference.fresnel import fresnel_dielectric
from addon.lab.reference.glass import MicrofacetGlass, transmission_jacobian
from addon.lab.reference.microfacet import normalize, refract_about
from addon.lab.reference.quadrature import directional_moments
from test_reference_chi2 import pearson, s_of_tan2, theta_of_s

RNG_SEED = 20240612
ETAS = (1.5, 1 / 1.5, 1.0001, 3.0)
MU = np.concatenate([[0.02, 0.035, 0.05, 0.075], np.linspace(0.1, 1.0, 10)])


def glass(**values):
    return make_bsdf("walter_glass", values)


def random_dirs(rng, n, lower=False):
    v = rng.normal(size=(n, 3))
    v[:, 2] = -np.abs(v[:, 2]) if lower else np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def incident(theta_deg, phi=0.3):
    t = math.radians(theta_deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


def flip(w):
    return w * np.array([1.0, 1.0, -1.0])


# -- formulas ---------------------------------------------------------------------------------
def test_make_bsdf_and_clamps():
    b = glass()
    assert isinstance(b, MicrofacetGlass) and b.eta == 1.5 and b.sampler == "vndf"
    assert b.masking == "height_correlated" and b.mf.distribution == "ggx"
    assert glass(ior=0.0).eta == 0.01 and glass(ior=float("nan")).eta == 1.5
    assert glass(roughness=0.0).is_delta and not glass(roughness=0.0).is_passthrough
    with pytest.raises(ValueError):
        MicrofacetGlass(b.mf, sampler="vcavity")


@pytest.mark.parametrize("eta", [1.5, 1 / 1.5])
@pytest.mark.parametrize("dist, masking", [("ggx", "height_correlated"),
                                           ("beckmann", "separable")])
def test_reflection_lobe_is_walter_reflection(eta, dist, masking):
    """f_r of the glass equals walter_reflection with dielectric Fresnel of the same eta."""
    rng = np.random.default_rng(RNG_SEED)
    values = dict(roughness=0.4, distribution=dist, masking=masking, ior=eta,
                  base_color=(0.9, 0.6, 0.3))
    g = glass(**values)
    r = make_bsdf("walter_reflection", dict(values, fresnel_type="dielectric"))
    wi, wo = random_dirs(rng, 5000), random_dirs(rng, 5000)
    assert np.allclose(g.eval(wi, wo), r.eval(wi, wo), rtol=1e-10, atol=1e-290)
    assert np.all(g.eval_transmission(wi, wo) == 0)


@pytest.mark.parametrize("eta", ETAS)
@pytest.mark.parametrize("dist, masking", [("ggx", "height_correlated"),
                                           ("beckmann", "separable")])
def test_transmission_formula(eta, dist, masking):
    """f_t at wo = refract_about(wi, m) equals Walter 2007 eq. 21 written with that m (so the
    generalised half vector recovers m), and is 0 where no refraction leads."""
    rng = np.random.default_rng(RNG_SEED)
    g = glass(roughness=0.6, distribution=dist, masking=masking, ior=eta)
    wi = random_dirs(rng, 20000)
    m = g.mf.sample_dcos(rng.random(20000), rng.random(20000))
    wo, ok = refract_about(wi, m, eta)
    im, om = np.sum(wi * m, -1), np.sum(wo * m, -1)
    ok &= (im > 0) & (wo[:, 2] < 0)
    assert ok.mean() > 0.2
    wi, wo, m, im, om = wi[ok], wo[ok], m[ok], im[ok], om[ok]
    walter = (np.abs(im * om) / (wi[:, 2] * np.abs(wo[:, 2])) * eta ** 2
              * (1 - fresnel_dielectric(im, eta)) * g.mf.G2(wi, wo, m, masking) * g.mf.D(m)
              / (im + eta * om) ** 2)
    assert np.allclose(g.eval(wi, wo)[:, 0], walter, rtol=1e-8, atol=0)
    assert np.allclose(g.half_vector_transmission(wi, wo), m, atol=1e-9)
    # Snell pairs with the wrong orientation (wo.h > 0 side) and wo above: no transmission.
    assert np.all(g.eval_transmission(wi, -wo) == 0)
    assert np.all(g.eval_transmission(wi, flip(wo)) == 0)


@pytest.mark.parametrize("eta", [1.5, 1 / 1.5, 3.0])
@pytest.mark.parametrize("dist, masking", [("ggx", "height_correlated"),
                                           ("beckmann", "separable")])
def test_btdf_reciprocity(eta, dist, masking):
    """Walter 2007 (discussion of eq. 21): f_t(i -> o) / n_o^2 = f_t(o -> i) / n_i^2. With
    relative indices (wi's side is +z, eta = n_o / n_i): f_t(wi, wo; eta) =
    eta^2 f_t(flip(wo), flip(wi); 1/eta), flip = (x, y, -z) (the same interface seen from
    below). So the BTDF itself is not symmetric unless eta = 1; f_r is."""
    rng = np.random.default_rng(RNG_SEED)
    a = glass(roughness=0.5, distribution=dist, masking=masking, ior=eta)
    b = glass(roughness=0.5, distribution=dist, masking=masking, ior=1 / eta)
    # Pairs around the refracted direction (where f_t is large) and uniform pairs.
    wi = random_dirs(rng, 40000)
    m = a.mf.sample_vndf(wi, rng.random(40000), rng.random(40000))
    wo, ok = refract_about(wi, m, eta)
    wo = np.where((ok & (wo[:, 2] < 0))[:, None], wo, random_dirs(rng, 40000, lower=True))
    wo[:10000] = random_dirs(rng, 10000, lower=True)
    fa = a.eval(wi, wo)
    fb = b.eval(flip(wo), flip(wi))
    assert np.mean(fa[:, 0] > 0) > 0.3
    # (1 - F cancels near the critical angle: relative 1e-8 where f_t is 1e-8 of its peak.)
    assert np.allclose(fa, eta ** 2 * fb, rtol=1e-9, atol=1e-12 * fa.max())
    assert not np.allclose(fa[fa[:, 0] > 1e-3], fb[fa[:, 0] > 1e-3], rtol=0.1)
    # Reflection is symmetric, on both sides.
    wr = random_dirs(rng, 20000)
    for bsdf in (a, b):
        assert np.allclose(bsdf.eval(wi[:20000], wr), bsdf.eval(wr, wi[:20000]), rtol=1e-10,
                           atol=0)


# -- sampling ---------------------------------------------------------------------------------
@pytest.mark.parametrize("sampler", ["dcos", "vndf"])
@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
@pytest.mark.parametrize("eta", ETAS)
def test_weight_is_eval_cos_over_pdf(sampler, dist, eta):
    """weight = f |cos_o| / pdf to 1e-5 over the whole sphere, pdf including the lobe choice
    (F or 1 - F), and equal to `pdf(wi, wo)`; zero-weight samples have pdf 0; visible-normal
    weights are at most the tint."""
    rng = np.random.default_rng(RNG_SEED)
    tint = np.array([0.9, 0.7, 0.4])
    for r in (0.05, 0.3, 0.7, 1.0):
        bsdf = glass(roughness=r, distribution=dist, sampler=sampler, ior=eta,
                     base_color=tuple(tint))
        n = 20000
        wi = random_dirs(rng, n)
        wi[:1000, 2] = rng.random(1000) * 1e-3  # grazing incidence too
        wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        wo, weight, pdf = bsdf.sample(wi, rng.random((n, 3)))
        for v in (wo, weight, pdf):
            assert np.all(np.isfinite(v))
        assert np.all(weight >= 0) and np.all(pdf >= 0)
        ok = pdf > 0
        assert np.all(weight[~ok] == 0)
        assert ok.mean() > 0.4 and np.mean(wo[ok, 2] < 0) > 0.05  # both lobes present
        expected = bsdf.eval_cos(wi[ok], wo[ok]) / pdf[ok, None]
        assert np.allclose(weight[ok], expected, rtol=1e-5, atol=0)
        assert np.allclose(bsdf.pdf(wi[ok], wo[ok]), pdf[ok], rtol=1e-5, atol=0)
        if sampler == "vndf":
            assert weight.max() <= tint.max() + 1e-12  # G2 / G1 <= 1


# Chi-square goodness of fit over the whole sphere of wo. Each valid sample wo is binned by its
# lobe (reflection wo.z > 0, transmission wo.z < 0) and its microfacet normal m (the half
# vector normalize(wi + wo), resp. the generalised one), on N_THETA x N_PHI cells in
# (s(theta_m), phi_m) per lobe, s the D cos CDF coordinate of test_reference_chi2 (narrow lobes
# spread over all rows). wo <-> (lobe, m) is one to one, so the cells are a partition of the
# sphere of wo; samples with zero weight (wi.m <= 0, wrong side) form one more cell.
# Expected counts come from the pdf over wo, `bsdf.pdf`, by quadrature mapped to m:
# P(cell) = integral over the cell's m of pdf(wi, wo(m)) |dwo/dm| dm, |dwo/dm| = 4 |wo.m|
# (reflection) or `transmission_jacobian` (refraction), cut where wo(m) is not a valid sample.
# The cuts are curves in m; each phi cell is split at the azimuths where they cross the theta
# node (closed forms below), so the quadrature never straddles a jump: wi.m = 0, the
# reflection horizon, the total-internal-reflection cone wi.m = k and the transmission horizon.
CHI2_N = 200_000
N_THETA, N_PHI, NODES, SUBROWS = 12, 16, 5, 1
CHI2_CASES = [("ggx", sampler, eta, theta, alpha) for sampler in ("dcos", "vndf")
              for eta in (1.5, 1 / 1.5) for theta in (0.0, 30.0, 80.0, 89.9)
              for alpha in (0.05, 0.5, 1.0)]
CHI2_CASES += [("beckmann", sampler, eta, theta, 0.5) for sampler in ("dcos", "vndf")
               for eta in (1.5, 1 / 1.5) for theta in (30.0, 89.9)]
CHI2_THRESHOLD = 1.0 - 0.99 ** (1.0 / len(CHI2_CASES))  # Sidak, family significance 0.01
CHI2_P = {}


def cut_values(theta, wi, eta):
    """The cuts as wi.m = c(theta) on the circle of normals at polar angle theta: (T, 4) values
    of c. With mu = wi.z, s = |wi_xy|: wi.m = mu cos(t) + s sin(t) cos(dphi); the cuts are
    wi.m = 0; wi.m = k = sqrt(1 - eta^2) (TIR, eta < 1); the reflection horizon wo.z =
    2 (wi.m) cos(t) - mu = 0; the transmission horizon wo.z = (c / eta - cos_t) cos(t) -
    mu / eta = 0, i.e. c = (a^2 + 1 - eta^2) / (2 a), a = mu / cos(t) (squared from
    c - a = eta cos_t >= 0; where that fails, a value no circle reaches)."""
    mu, s = wi[2], math.hypot(wi[0], wi[1])
    ct, st = np.cos(theta), np.sin(theta)
    k = math.sqrt(max(1 - eta * eta, 0.0))
    a = mu / np.maximum(ct, 1e-300)
    c_th = (a * a + 1 - eta * eta) / (2 * a)
    c_th = np.where((eta < 1) & (c_th >= a), c_th, 2.0 * s * st + mu * ct + 1.0)
    return np.stack([0.0 * ct, np.full_like(ct, k), 0.5 * mu / np.maximum(ct, 1e-300), c_th],
                    axis=-1)


def cut_azimuths(theta, wi, eta):
    """cos(phi_m - phi_i) where the cuts cross the circle at theta (T,) -> (T, 4); outside
    [-1, 1]: no crossing."""
    mu, s = wi[2], math.hypot(wi[0], wi[1])
    if s < 1e-12:
        return np.full(np.shape(theta) + (4,), 2.0)
    den = np.maximum(s * np.sin(theta), 1e-300)[..., None]
    return (cut_values(theta, wi, eta) - mu * np.cos(theta)[..., None]) / den


def tangent_thetas(wi, eta):
    """Polar angles where a cut touches a circle of constant theta (cos dphi = +-1, i.e.
    c(theta) - mu cos(theta) = +-s sin(theta); at normal incidence the cuts are such circles):
    there the phi-integrated cell integrand has a square-root kink, a jump or a thin sliver
    (the transmission horizon near m.z = 0 at grazing incidence), so the theta rule is split
    and graded there. Sign changes on a dense grid (geometric toward 0 and pi / 2), refined by
    bisection."""
    g = np.unique(np.concatenate([0.5 * np.pi * np.linspace(0, 1, 4001)[1:-1],
                                  0.5 * np.pi * np.logspace(-9, 0, 2000, endpoint=False),
                                  0.5 * np.pi * (1 - np.logspace(-9, 0, 2000, endpoint=False))]))
    mu, s = wi[2], math.hypot(wi[0], wi[1])

    def h(t):
        d = cut_values(t, wi, eta) - mu * np.cos(t)[..., None]
        r = s * np.sin(t)[..., None]
        return np.concatenate([d - r, d + r], axis=-1)  # (T, 8)

    hg = h(g)
    i, k = np.nonzero(np.sign(hg[:-1]) != np.sign(hg[1:]))
    lo, hi = g[i], g[i + 1]
    s_lo = np.sign(hg[i, k])
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        hm = h(mid)[np.arange(len(mid)), k]
        left = np.sign(hm) == s_lo
        lo, hi = np.where(left, mid, lo), np.where(left, hi, mid)
    return 0.5 * (lo + hi)


def expected_cells(bsdf, wi, a):
    """Probabilities (2, N_THETA, N_PHI) of the (lobe, m) cells."""
    dist = bsdf.mf.distribution
    x, w = np.polynomial.legendre.leggauss(NODES)
    # Rows: Gauss-Legendre in q = sqrt(1 - s) (as test_reference_chi2) on the row edges, the
    # tangent thetas and edges graded geometrically toward them.
    q_rows = np.sqrt(1.0 - np.linspace(0.0, 1.0, N_THETA * SUBROWS + 1))
    t_b = tangent_thetas(wi, bsdf.eta)
    q_b = np.sqrt(1.0 - s_of_tan2(dist, np.tan(t_b) ** 2, a))
    grade = 4.0 ** -np.arange(1, 4)
    nearest = np.searchsorted(-q_rows, -q_b)  # q_rows is decreasing
    q_up = q_rows[np.clip(nearest - 1, 0, len(q_rows) - 1)]
    q_dn = q_rows[np.clip(nearest, 0, len(q_rows) - 1)]
    q_edges = np.unique(np.concatenate(
        [q_rows, q_b, (q_b[:, None] + (q_up - q_b)[:, None] * grade).ravel(),
         (q_b[:, None] + (q_dn - q_b)[:, None] * grade).ravel()]))[::-1]
    qa, qb = q_edges[:-1, None], q_edges[1:, None]
    q = (0.5 * (qb - qa) * x + 0.5 * (qa + qb)).ravel()
    wq = (0.5 * (qa - qb) * w).ravel()
    q = np.where(wq > 0, np.clip(q, 1e-7, 1.0), 0.5)  # s < 1: theta_of_s stays finite
    theta, dtheta = theta_of_s(dist, 1.0 - q * q, a)
    row = np.clip(((1.0 - q * q) * N_THETA).astype(int), 0, N_THETA - 1)
    wt = wq * 2.0 * q * dtheta * np.sin(theta)  # (T,)
    phi_i = math.atan2(wi[1], wi[0])
    # For eta > 1 only wi.m = 0 and the reflection horizon cut (k = 0, no transmission horizon).
    curves = [0, 1, 2, 3] if bsdf.eta < 1 else [0, 2]
    dphi = np.arccos(np.clip(cut_azimuths(theta, wi, bsdf.eta)[:, curves], -1, 1))
    kinks = np.mod(phi_i + np.concatenate([dphi, -dphi], -1), 2 * math.pi)  # (T, K)
    p_edges = np.linspace(0.0, 2 * math.pi, N_PHI + 1)
    p0, p1 = p_edges[:-1], p_edges[1:]
    inner = np.clip(kinks[:, None, :], p0[None, :, None], p1[None, :, None])  # (T, P, K)
    edges = np.sort(np.concatenate([np.broadcast_to(p0[None, :, None], inner.shape[:2] + (1,)),
                                    inner,
                                    np.broadcast_to(p1[None, :, None], inner.shape[:2] + (1,))],
                                   -1), -1)
    e0, e1 = edges[..., :-1, None], edges[..., 1:, None]
    phi = 0.5 * (e1 - e0) * x + 0.5 * (e0 + e1)  # (T, P, K + 1, NODES)
    wp = 0.5 * (e1 - e0) * w
    st = np.sin(theta)[:, None, None, None]
    m = np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi),
                                     np.cos(theta)[:, None, None, None]), -1)
    im = np.sum(wi * m, -1)
    wo_r = 2.0 * im[..., None] * m - wi
    val_r = np.where((im > 0) & (wo_r[..., 2] > 0),
                     bsdf.pdf(wi, wo_r) * 4.0 * np.abs(np.sum(wo_r * m, -1)), 0.0)
    wo_t, ok = refract_about(wi, m, bsdf.eta)
    val_t = np.where(ok & (im > 0) & (wo_t[..., 2] < 0),
                     bsdf.pdf(wi, wo_t) * transmission_jacobian(wi, wo_t, m, bsdf.eta), 0.0)
    out = []
    for val in (val_r, val_t):
        cells = (val * wp).sum(axis=(2, 3)) * wt[:, None]  # (T, P)
        out.append(np.stack([np.bincount(row, cells[:, j], minlength=N_THETA)
                             for j in range(N_PHI)], axis=-1))
    return np.stack(out)


def histogram_cells(bsdf, wi, wo, valid, a):
    lower = wo[:, 2] < 0
    m = np.where(lower[:, None], bsdf.half_vector_transmission(wi, wo), normalize(wi + wo))
    z = np.clip(m[:, 2], 1e-300, 1.0)
    s = s_of_tan2(bsdf.mf.distribution, (1.0 - z * z) / (z * z), a)
    i = np.clip((s * N_THETA).astype(int), 0, N_THETA - 1)
    phi = np.mod(np.arctan2(m[:, 1], m[:, 0]), 2 * math.pi)
    j = np.clip((phi / (2 * math.pi) * N_PHI).astype(int), 0, N_PHI - 1)
    idx = (lower * N_THETA + i) * N_PHI + j
    return np.bincount(idx[valid], minlength=2 * N_THETA * N_PHI).reshape(2, N_THETA, N_PHI)


@pytest.mark.parametrize("dist, sampler, eta, theta_deg, alpha", CHI2_CASES)
def test_sampler_chi2_whole_sphere(dist, sampler, eta, theta_deg, alpha):
    bsdf = glass(roughness=math.sqrt(alpha), distribution=dist, sampler=sampler, ior=eta)
    wi = incident(theta_deg)
    case = CHI2_CASES.index((dist, sampler, eta, theta_deg, alpha))
    rng = np.random.default_rng([RNG_SEED, case])
    wo, weight, pdf = bsdf.sample(wi, rng.random((CHI2_N, 3)))
    valid = pdf > 0
    prob = expected_cells(bsdf, wi, alpha)
    rest = 1.0 - prob.sum()  # probability of a zero-weight sample
    assert rest > -2e-3
    observed = np.append(histogram_cells(bsdf, wi, wo, valid, alpha).ravel(),
                         np.sum(~valid))
    expected = np.append(CHI2_N * prob.ravel(), CHI2_N * max(rest, 0.0))
    stat, dof, p = pearson(observed, expected)
    CHI2_P[(dist, sampler, eta, theta_deg, alpha)] = p
    print(f"{dist} {sampler} eta {eta:.3f} {theta_deg} alpha {alpha}: chi2 {stat:.1f} "
          f"dof {dof} p {p:.3g}; P(reflect) {prob[0].sum():.4f} P(zero) {rest:.4f} "
          f"(observed {np.mean(~valid):.4f})")
    assert p > CHI2_THRESHOLD, f"chi2 = {stat:.1f} with {dof} dof, p = {p:.3g}"


# -- deltas: perfect glass, total internal reflection, the pass-through --------------------------
@pytest.mark.parametrize("eta", ETAS)
def test_roughness_zero_is_perfect_glass(eta):
    """Roughness 0: the mirror direction with probability F, else the refracted one (none
    under TIR), weight tint, pdf = the lobe's probability; eval 0; moments R + T = tint."""
    rng = np.random.default_rng(RNG_SEED)
    tint = np.array([0.9, 0.7, 0.4])
    for sampler in ("dcos", "vndf"):
        bsdf = glass(roughness=0.0, ior=eta, sampler=sampler, base_color=tuple(tint))
        assert bsdf.is_delta and not bsdf.is_passthrough
        n = 100000
        mu = rng.random(n)
        wi = np.stack([np.sqrt(1 - mu * mu), np.zeros(n), mu], -1)
        wo, weight, pdf = bsdf.sample(wi, rng.random((n, 3)))
        F = fresnel_dielectric(mu, eta)
        refl = wo[:, 2] > 0
        assert np.allclose(wo[refl], wi[refl] * [-1, -1, 1])
        wt, ok = refract_about(wi, [0.0, 0.0, 1.0], eta)
        assert np.all(ok[~refl]) and np.allclose(wo[~refl], wt[~refl])
        assert np.allclose(weight, tint) and np.allclose(pdf, np.where(refl, F, 1 - F))
        # The lobe choice follows F: binomial test on the count of reflections.
        assert abs(refl.sum() - F.sum()) < 5 * math.sqrt(np.sum(F * (1 - F)))
        assert np.all(bsdf.eval(wi, wo) == 0)
        E, Vn, Vt = directional_moments(bsdf, MU)
        assert np.allclose(E, tint, rtol=0, atol=1e-15)
        R = fresnel_dielectric(MU, eta)[:, None]
        wt, ok = refract_about(np.stack([np.sqrt(1 - MU ** 2), 0 * MU, MU], -1), [0, 0, 1.0], eta)
        T = np.where(ok, 1 - fresnel_dielectric(MU, eta), 0.0)[:, None]
        assert np.allclose(Vn, tint * (R * MU[:, None] + T * wt[:, 2:3]), atol=1e-15)
        assert np.allclose(Vt, tint * (-R * np.sqrt(1 - MU ** 2)[:, None] + T * wt[:, 0:1]),
                           atol=1e-15)


def test_total_internal_reflection():
    """eta = 1/1.5 (inside glass) beyond the critical angle asin(1/1.5) = 41.81 degrees:
    roughness 0 reflects everything (E = R = 1, Vn = mu, Vt = -sin); just below it
    refracts. Rough glass there transmits only through tilted facets, and nothing at all at
    any incidence where every facet the sampler draws is beyond critical."""
    eta = 1 / 1.5
    crit = math.degrees(math.asin(eta))
    assert round(crit, 2) == 41.81
    mu = np.cos(np.radians([crit + 0.01, 60.0, 89.0]))
    perfect = glass(roughness=0.0, ior=eta)
    E, Vn, Vt = directional_moments(perfect, mu)
    assert np.allclose(E, 1.0, atol=1e-15) and np.allclose(Vn, mu[:, None], atol=1e-15)
    assert np.allclose(Vt, -np.sqrt(1 - mu ** 2)[:, None], atol=1e-15)
    wi = np.stack([np.sqrt(1 - mu ** 2), 0 * mu, mu], -1)
    wo, weight, pdf = perfect.sample(wi, np.random.default_rng(RNG_SEED).random((3, 3)))
    assert np.all(wo[:, 2] > 0) and np.allclose(weight, 1) and np.allclose(pdf, 1)
    below = math.cos(math.radians(crit - 0.5))
    E, Vn, _ = directional_moments(perfect, [below])
    assert E[0, 0] == pytest.approx(1.0) and Vn[0, 0] < below  # some light refracted, downward
    # Rough, narrow (alpha = 1e-4): at 60 degrees essentially everything is reflected.
    rough = glass(roughness=0.01, ior=eta)
    E, Vn, Vt = directional_moments(rough, [0.5])
    assert E[0, 0] > 0.999 and Vn[0, 0] > 0.499


@pytest.mark.parametrize("eta", [1.0, 1 + 5e-6, 1 - 5e-6])
@pytest.mark.parametrize("roughness", [0.0, 0.5])
def test_index_matched_pass_through(eta, roughness):
    rng = np.random.default_rng(RNG_SEED)
    tint = (0.9, 0.7, 0.4)
    bsdf = glass(roughness=roughness, ior=eta, base_color=tint)
    assert bsdf.is_passthrough and bsdf.is_delta
    wi = random_dirs(rng, 1000)
    wo, weight, pdf = bsdf.sample(wi, rng.random((1000, 3)))
    assert np.array_equal(wo, -wi) and np.allclose(weight, tint) and np.all(pdf == 1)
    assert np.all(bsdf.eval(wi, random_dirs(rng, 1000, lower=True)) == 0)
    E, Vn, Vt = directional_moments(bsdf, MU)
    assert np.allclose(E, tint) and np.allclose(Vn, -MU[:, None] * tint)
    assert np.allclose(Vt, -np.sqrt(1 - MU ** 2)[:, None] * np.array(tint))
    # Just outside the threshold the interface is rough glass again.
    assert not glass(roughness=0.5, ior=1.0001).is_passthrough


@pytest.mark.parametrize("sampler", ["dcos", "vndf"])
def test_traps_no_nan(sampler):
    """alpha -> 0, grazing 89.999 degrees, eta in [0.1, 10] and near 1, wo = -wi, wo on the
    horizon: eval, pdf and sample stay finite and non-negative."""
    rng = np.random.default_rng(RNG_SEED)
    g = math.radians(89.999)
    dirs = np.array([[math.sin(g), 0, math.cos(g)], [-math.sin(g), 0, math.cos(g)],
                     [0, math.sin(g), -math.cos(g)], [0, 0, 1.0], [1.0, 0, 0], [0.6, 0, 0.8],
                     [0, 0, -1.0], [-0.6, 0, -0.8], [math.sin(g), 0, -math.cos(g)]])
    wi = np.repeat(dirs, len(dirs), axis=0)
    wo = np.tile(dirs, (len(dirs), 1))
    for eta in (0.1, 1 / 1.5, 0.99999, 1.00002, 1.0001, 1.5, 10.0):
        for r in (0.0, math.sqrt(1e-7) * 0.999, math.sqrt(1e-7), 1e-3, 0.5, 1.0):
            for dist in ("ggx", "beckmann"):
                bsdf = glass(roughness=r, ior=eta, distribution=dist, sampler=sampler)
                for v in (bsdf.eval(wi, wo), bsdf.pdf(wi, wo)):
                    assert np.all(np.isfinite(v)) and np.all(v >= 0), (eta, r, dist)
                u = rng.random((len(dirs), 200, 3))
                u[:, :4] = [[0, 0, 0], [1 - 2 ** -53] * 3, [0.5, 0.5, 0.5], [1e-300, 0.25, 0]]
                out = bsdf.sample(dirs[:, None, :], u)
                for v in out:
                    assert np.all(np.isfinite(v)), (eta, r, dist)


# -- quadrature of the moments ------------------------------------------------------------------
# Roughness r with alpha = r^2 in {0.0025, 0.09, 0.49, 1}.
ROUGHNESS = (0.05, 0.3, 0.7, 1.0)
QUAD_CASES = [("ggx", eta, r) for eta in (1.5, 1 / 1.5, 3.0) for r in ROUGHNESS]
QUAD_CASES += [("beckmann", eta, r) for eta in (1.5, 1 / 1.5, 3.0) for r in (0.3, 1.0)]


@pytest.mark.parametrize("dist, eta, roughness", QUAD_CASES)
def test_quadrature_converges_and_energy(dist, eta, roughness):
    """Order N vs 2N (N = 6) agree to 1e-4 absolute in E, Vn, Vt over the whole sphere; energy:
    0 <= E = R + T <= 1, |(Vn, Vt)| <= E, and E > 0.99 at small alpha away from grazing."""
    bsdf = glass(roughness=roughness, distribution=dist, ior=eta)
    a = np.stack(directional_moments(bsdf, MU, order=6))
    b = np.stack(directional_moments(bsdf, MU, order=12))
    err = np.abs(a - b).max()
    E, Vn, Vt = b
    print(f"{dist} eta {eta:.3f} r {roughness}: |order 6 - order 12| = {err:.1e}, "
          f"E in [{E.min():.4f}, {E.max():.6f}]")
    assert err < 1e-4 and np.all(np.isfinite(a))
    assert np.all(E <= 1 + 1e-6) and np.all(E >= 0)
    assert np.all(np.hypot(Vn, Vt) <= E + 1e-9)
    if roughness == 0.05:
        assert np.all(E[MU >= 0.3] > 0.99)


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_energy_index_near_one(dist):
    """eta = 1.0001 (not a pass-through): F ~ 0, so E = T is the Smith G2 loss only: <= 1,
    above 0.99 at small alpha away from grazing, and it converges."""
    for r in ROUGHNESS:
        bsdf = glass(roughness=r, distribution=dist, ior=1.0001)
        a = np.stack(directional_moments(bsdf, MU, order=6))
        b = np.stack(directional_moments(bsdf, MU, order=12))
        assert np.abs(a - b).max() < 1e-4
        E = b[0]
        assert np.all(E <= 1 + 1e-6) and np.all(E >= 0)
        if r == 0.05:
            assert np.all(E[MU >= 0.3] > 0.99)


@pytest.mark.parametrize("eta", ETAS)
@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_delta_seam(eta, dist):
    """Just above the delta threshold (alpha = 2e-7) the quadrature of the tiny lobes gives
    the moments of perfect glass (R + T = 1) to 1e-4."""
    mirror = np.stack(directional_moments(glass(roughness=0.0, ior=eta), MU))
    rough = glass(roughness=math.sqrt(2e-7), ior=eta, distribution=dist)
    assert not rough.is_delta
    assert np.abs(np.stack(directional_moments(rough, MU)) - mirror).max() < 1e-4


MC_CASES = [("ggx", "vndf", 1.5, 0.5, 0.3), ("ggx", "dcos", 1.5, 0.7, 0.8),
            ("beckmann", "vndf", 1 / 1.5, 0.7, 0.8), ("ggx", "vndf", 1 / 1.5, 1.0, 0.1),
            ("ggx", "dcos", 1 / 1.5, 0.3, 0.6), ("beckmann", "dcos", 3.0, 1.0, 0.2),
            ("ggx", "vndf", 3.0, 0.3, 0.05), ("ggx", "vndf", 1.0001, 0.7, 0.5)]


@pytest.mark.parametrize("dist, sampler, eta, roughness, mu", MC_CASES)
def test_quadrature_matches_monte_carlo(dist, sampler, eta, roughness, mu):
    """E, Vn, Vt by quadrature (from eval) against the sampler's mean weight, weight wo.z and
    weight wo.x (from the sampling code): within 4.5 standard errors (+ 1e-4)."""
    bsdf = glass(roughness=roughness, distribution=dist, sampler=sampler, ior=eta)
    wi = np.array([math.sqrt(1 - mu * mu), 0.0, mu])
    case = MC_CASES.index((dist, sampler, eta, roughness, mu))
    n = 400_000
    wo, weight, _ = bsdf.sample(wi, np.random.default_rng([RNG_SEED, case]).random((n, 3)))
    quad = np.stack(directional_moments(bsdf, [mu]))[:, 0, 0]
    for q, x in zip(quad, (weight[:, 0], weight[:, 0] * wo[:, 2], weight[:, 0] * wo[:, 0])):
        se = x.std() / math.sqrt(n)
        print(f"{dist} {sampler} eta {eta:.3f} r {roughness} mu {mu}: quadrature {q:.5f} "
              f"MC {x.mean():.5f} +- {se:.5f}")
        assert abs(x.mean() - q) < 4.5 * se + 1e-4
