"""Deterministic reference for sphere images: directional moments of a BRDF by quadrature.

For an orthographic pixel seeing normal n with view wi (mu = wi.n, t the unit tangent toward wi)
under an environment linear in direction, L(w) = a + b (w.d), the pixel value is

    a E(mu) + b (Vn(mu) (d.n) + Vt(mu) (d.t)),
    E = integral f cos_o dwo,   (Vn, Vt) = n and t components of integral f cos_o wo dwo

(the binormal component vanishes: the BRDF is symmetric about the plane of incidence; for an
anisotropic BRDF the moments here are for wi in the plane of the tangent).

Quadrature (`directional_moments`). The specular lobe is integrated over microfacet normals m
parametrised by the inverse CDF of D(m)(m.n) (`Microfacet.sample_dcos`): u1 in [0, 1) radial,
u2 in [0, 1/2] azimuth (the other half by the symmetry y -> -y, i.e. doubled), on a tensor
product of composite Gauss-Legendre rules with `order` nodes per panel and dimension: u2 on
panels graded toward u2 = 1/4 (`_u2_edges`, per mu); for each u2 and mu, u1 = v^2 with v on
[0, v_horizon] (the closed-form v where wo meets the horizon; beyond it the integrand is 0) on
panels graded toward the horizon (`_v_edges`; v makes the slope radius analytic at the pole).
Cutting at the horizon keeps the integrand smooth (Smith masking), so the rule converges fast.
The integrand is f(wi, wo(m)) wo.n |dwo/dm| / pdf_dcos(m) with wo = reflect(wi, m),
|dwo/dm| = 4 |wo.m| (Walter 2007 eq. 14), f from `bsdf.eval_specular` (the evaluation formula,
not the samplers' weights). The Lambertian part is analytic: E_d = albedo,
first moment (2/3) albedo n. A delta lobe (roughness 0) is exact: E = R(mu),
(Vn, Vt) = R(mu) (mu, -sqrt(1 - mu^2)) with R the mirror reflectance.
Convergence (order N vs 2N) is tested in tests/test_reference_quadrature.py.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .microfacet import dot, reflect

# Panels of v = sqrt(u1): fractions of [0, v_horizon] and theta levels toward the horizon.
V_BODY = (0.0,) + tuple(1.0 - 4.0 ** -k for k in range(1, 10))  # GGX tail: 1 - v ~ alpha^2
THETA_LEVELS = 3
U2_GRADED_PANELS = 4  # per side of u2 = 1/4, see _u2_edges
DEFAULT_ORDER = 6


def composite_gauss_legendre(edges, order: int):
    """Nodes and weights of the composite Gauss-Legendre rule with `order` nodes per panel.
    edges (..., P + 1) -> nodes, weights (..., P * order)."""
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.asarray(edges, dtype=float)
    a, b = edges[..., :-1, None], edges[..., 1:, None]
    nodes = 0.5 * (b - a) * x + 0.5 * (a + b)
    weights = 0.5 * (b - a) * w
    shape = edges.shape[:-1] + (-1,)
    return nodes.reshape(shape), weights.reshape(shape)


def _u2_edges(mu):
    """Panels of u2 in [0, 1/2], graded geometrically toward u2 = 1/4 from both sides down to a
    width of mu / (2 pi): there the normals are perpendicular to the plane of incidence
    (cos phi_m = 0) and the horizon cut turns over within an azimuth range of about mu."""
    delta = np.clip(mu / (2.0 * np.pi), 1e-5, 0.25)[:, None]
    k = np.arange(U2_GRADED_PANELS)[None, :] / (U2_GRADED_PANELS - 1.0)
    offsets = 0.25 * (delta / 0.25) ** k  # 0.25 ... delta
    zero = np.zeros_like(delta)
    return np.concatenate([zero, 0.25 - offsets, zero + 0.25, 0.25 + offsets[:, ::-1],
                           zero + 0.5], axis=1)


def _incident(mu):
    mu = np.clip(np.atleast_1d(np.asarray(mu, dtype=float)), 0.0, 1.0)
    s = np.sqrt(1.0 - mu * mu)
    return mu, s, np.stack([s, np.zeros_like(mu), mu], axis=-1)


def _v_edges(mf, mu, s, u2, vcavity=False):
    """Panel edges in v = sqrt(u1) on [0, v_horizon] per (mu, u2): shape (c, n2, P + 1).

    Along a line of constant u2 the normal m stays in the vertical plane of azimuth phi_m
    (slope direction -(ax cos 2 pi u2, ay sin 2 pi u2)). With theta the polar angle of m,
    wo.z = 2 (wi.m)(m.z) - wi.z = s cos(phi_m) sin(2 theta) + mu cos(2 theta)
         = A cos(2 theta - beta), beta = atan2(s cos phi_m, mu),
    so wo.z > 0 exactly for theta < theta_h = beta/2 + pi/4: the horizon. Integrating up to it
    leaves the integrand smooth for Smith masking (wo.z > 0 implies wi.m = wo.m > 0), but
    Smith G varies on the scale of alpha in wo.z there, which may lie far out in the tail of D
    (tiny in v): so the edges are V_BODY * v_h plus the images of theta_h (1 - 4^-k),
    k = 1..THETA_LEVELS, graded geometrically in theta toward the horizon; for V-cavity masking
    also the angles where its min() switches branch (closed forms below)."""
    phi = 2.0 * np.pi * u2
    cx, sy = mf.alpha_x * np.cos(phi), mf.alpha_y * np.sin(phi)
    alpha_phi = np.hypot(cx, sy)  # |slope| per unit standard radius
    cos_phi_m = -cx / alpha_phi
    beta = np.arctan2(s[:, None] * cos_phi_m, mu[:, None])
    theta_h = 0.5 * beta + 0.25 * np.pi  # (c, n2)

    def v_of_theta(theta):
        r2 = (np.tan(np.minimum(theta, 0.5 * np.pi - 1e-12)) / alpha_phi[..., None]) ** 2
        # Inverse of sample_dcos's radial map (Walter 2007 eqs. 28, 35).
        return np.sqrt(r2 / (1.0 + r2) if mf.ggx else -np.expm1(-r2))

    grade = 1.0 - 4.0 ** -np.arange(1, THETA_LEVELS + 1)
    theta_edges = [theta_h[..., None] * grade]
    if vcavity:
        # Kinks of min(1, G1_vc(wi), G1_vc(wo)) along the line, with c = s cos(phi_m):
        # wi.m' = 0 at tan theta = mu / c; G1_vc(wi) = G1_vc(wo) (wo.z = wi.z) at
        # tan theta = c / mu; wo.m' = 0, i.e. 2 (wi.m) cos(2 theta) = wi.m', which reduces to
        # tan(3 theta) = -mu / c. Candidates outside (0, theta_h) collapse onto theta_h.
        c = s[:, None] * cos_phi_m
        m_ = mu[:, None] + np.zeros_like(c)
        kinks = [np.arctan2(m_, c), np.arctan2(c, m_)]
        kinks += [(np.arctan2(-m_, c) + k * np.pi) / 3.0 for k in range(3)]
        kinks = np.stack(kinks, axis=-1)
        inside = (kinks > 0.0) & (kinks < theta_h[..., None])
        theta_edges.append(np.where(inside, kinks, theta_h[..., None]))
    v_h = v_of_theta(theta_h[..., None])
    edges = np.concatenate([v_h * np.asarray(V_BODY)]
                           + [v_of_theta(t) for t in theta_edges] + [v_h], axis=-1)
    return np.sort(edges, axis=-1)


def directional_moments(bsdf, mu, order: int = DEFAULT_ORDER, chunk: int = 16):
    """(E, Vn, Vt), each of shape (len(mu), 3), for wi = (sqrt(1 - mu^2), 0, mu).

    `bsdf` is a `MicrofacetBRDF` (anything with .mf, .is_delta, .eval_specular,
    .delta_reflectance, .diffuse_albedo)."""
    mu, s, wi = _incident(mu)
    albedo = np.asarray(bsdf.diffuse_albedo, dtype=float)
    E = np.zeros(mu.shape + (3,)) + albedo
    Vn = np.zeros(mu.shape + (3,)) + (2.0 / 3.0) * albedo
    Vt = np.zeros(mu.shape + (3,))
    if bsdf.is_delta:
        R = bsdf.delta_reflectance(wi)
        return E + R, Vn + R * mu[:, None], Vt - R * s[:, None]
    mf = bsdf.mf
    U2, W2 = composite_gauss_legendre(_u2_edges(mu), order)
    W2 = 2.0 * W2  # the half u2 in [1/2, 1) by symmetry
    for start in range(0, len(mu), chunk):
        sl = slice(start, start + chunk)
        u2, w2 = U2[sl], W2[sl]  # (c, n2)
        # u1 = v^2: the slope radius is analytic in v (it goes like sqrt(u1) at u1 = 0,
        # which would spoil Gauss-Legendre convergence in u1).
        v, wv = composite_gauss_legendre(
            _v_edges(mf, mu[sl], s[sl], u2, bsdf.masking == "vcavity"), order)  # (c,n2,n1)
        W = 2.0 * v * wv * w2[..., None]
        m = mf.sample_dcos(v * v, u2[..., None])
        pdf = mf.pdf_dcos(m)
        W = np.where(pdf > 0.0, W / np.where(pdf > 0.0, pdf, 1.0), 0.0)
        w_in = wi[sl, None, None, :]
        wo = reflect(w_in, m)
        f = bsdf.eval_specular(w_in, wo)
        g = W * 4.0 * np.abs(dot(wo, m)) * np.maximum(wo[..., 2], 0.0)
        E[sl] += np.einsum("ijk,ijkc->ic", g, f)
        Vn[sl] += np.einsum("ijk,ijkc->ic", g * wo[..., 2], f)
        Vt[sl] += np.einsum("ijk,ijkc->ic", g * wo[..., 0], f)
    return E, Vn, Vt


@dataclass(frozen=True)
class MomentTable:
    """Moments on a grid uniform in x = log(mu), mu in [MU_MIN, 1].

    E and Vn are even in theta_i and Vt odd, so E, Vn and Vt / sin(theta_i) are smooth functions
    of mu up to mu = 1; the log spacing resolves the grazing structure (Fresnel, and Smith
    masking, which changes on the scale mu ~ alpha)."""

    x: np.ndarray  # (n,) log(mu), uniform
    E: np.ndarray  # (n, 3)
    Vn: np.ndarray  # (n, 3)
    Vt_over_sin: np.ndarray  # (n, 3)


# The table stops short of mu = 0 (where f is not defined); below it the end value is used.
MU_MIN = 0.005


def tabulate_moments(bsdf, n_mu: int = 48, order: int = DEFAULT_ORDER) -> MomentTable:
    """Moments at n_mu incidences uniform in log(mu) on [MU_MIN, 1], for `moments_at`."""
    x = np.linspace(np.log(MU_MIN), 0.0, n_mu)
    mu = np.minimum(np.exp(x), 1.0 - 1e-8)  # Vt / sin(theta) at theta -> 0 as a limit
    if hasattr(bsdf, "directional_moments"):  # a model with its own deterministic moments (Lee)
        E, Vn, Vt = bsdf.directional_moments(mu)
    else:
        E, Vn, Vt = directional_moments(bsdf, mu, order=order)
    return MomentTable(x, E, Vn, Vt / np.sqrt(1.0 - mu * mu)[:, None])


def moments_at(table: MomentTable, mu):
    """(E, Vn, Vt) at any mu (shape (...,) -> each (..., 3)) by 4-point Lagrange (cubic)
    interpolation in log(mu); mu below MU_MIN takes the MU_MIN values."""
    mu = np.clip(np.asarray(mu, dtype=float), MU_MIN, 1.0)
    x = np.log(mu).ravel()
    h = table.x[1] - table.x[0]
    n = len(table.x)
    pos = np.clip((x - table.x[0]) / h, 0.0, n - 1.0)
    i0 = np.clip(np.floor(pos).astype(int) - 1, 0, n - 4)  # stencil i0 .. i0 + 3
    t = pos - i0  # position within the stencil, nodes at 0, 1, 2, 3
    w = np.stack([-(t - 1) * (t - 2) * (t - 3) / 6.0, t * (t - 2) * (t - 3) / 2.0,
                  -t * (t - 1) * (t - 3) / 2.0, t * (t - 1) * (t - 2) / 6.0], axis=-1)
    idx = i0[:, None] + np.arange(4)[None, :]
    shape = np.shape(mu) + (3,)
    E, Vn, Vts = (np.einsum("pk,pkc->pc", w, v[idx]).reshape(shape)
                  for v in (table.E, table.Vn, table.Vt_over_sin))
    return E, Vn, Vts * np.sqrt(1.0 - mu * mu)[..., None]
