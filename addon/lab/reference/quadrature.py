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
The integrand is f(wi, wo(m)) wo.n |dwo/dm| / pdf_dcos(m) with wo = reflect_about(wi, m),
|dwo/dm| = 4 |wo.m| (Walter 2007 eq. 14), f from `bsdf.eval_specular` (the evaluation formula,
not the samplers' weights). The Lambertian part is analytic: E_d = albedo,
first moment (2/3) albedo n. A delta lobe (roughness 0) is exact: E = R(mu),
(Vn, Vt) = R(mu) (mu, -sqrt(1 - mu^2)) with R the mirror reflectance.
Convergence (order N vs 2N) is tested in tests/test_reference_quadrature.py.

Glass (a BSDF with `has_transmission`, addon/lab/reference/glass.py): the moments are over the
whole sphere, E = integral f |cos_o| dwo and (Vn, Vt) from integral f |cos_o| wo dwo,
reflection plus transmission (in the single-interface render the refracted ray leaves the
sphere in direction wo). The transmitted lobe uses the same D cos parametrisation, with
wo = refract_about(wi, m), |dwo/dm| = (wi.m + eta wo.m)^2 / (eta^2 |wo.m|), cut at total internal
reflection and the horizon (`_transmission_rule`); for eta < 1 both lobes get u2 panels at the
azimuths where those cuts make the line integrals non-smooth (`_u2_edges_glass`), one
incidence at a time. Perfect glass and the index-matched pass-through are exact. Convergence:
tests/test_reference_glass.py.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .glass import transmission_jacobian
from .microfacet import dot, reflect_about, refract_about

# Panels of v = sqrt(u1): fractions of [0, v_horizon] and theta levels toward the horizon.
V_BODY = (0.0,) + tuple(1.0 - 4.0 ** -k for k in range(1, 10))  # GGX tail: 1 - v ~ alpha^2
THETA_LEVELS = 3
U2_GRADED_PANELS = 4  # per side of u2 = 1/4, see _u2_edges
DEFAULT_ORDER = 6
TIR_LEVELS = 4  # grading toward the total-internal-reflection and horizon cuts of glass


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


def _u2_edges_glass(mu: float, s: float, eta: float, lobe: str, levels: int = 3):
    """Panels of u2 in [0, 1/2] for one incidence of glass and one lobe ("r" reflection,
    "t" transmission): those of `_u2_edges` plus, for eta < 1, edges graded geometrically
    (4^-k) from both sides toward the azimuths where the integral along a line of constant u2
    is not smooth: where the lobe's cuts (`_v_edges`, `_transmission_rule`) are tangent to the
    line or meet each other or theta = pi/2. With C = cos(phi_m) (isotropic:
    phi_m = pi + 2 pi u2, u2 = acos(-C) / (2 pi)), k = sqrt(1 - eta^2):
      both: the cone wi.m = k (total internal reflection) touches the line:
                                                            C = +-sqrt(k^2 - mu^2) / s;
      t: the cone reaches m.z = 0:                          C = k / s;
      t: the transmission horizon cut touches the line, which is also where it meets the cone
         (wo horizontal and grazing the facet, cos psi = -eta / s): C = +-sqrt(1 - eta^2/s^2);
      r: the reflection horizon cut (m = normalize(wi + wo_h), wo_h at azimuth psi) meets the
         cone where wi.wo_h = 2 k^2 - 1: cos psi = x = (2 k^2 - 1) / s,
         C = (s + x) / sqrt(s^2 + 2 s x + 1).
    (For eta > 1 the only such azimuth is C = 0, already graded by `_u2_edges`.)"""
    edges = [_u2_edges(np.array([mu]))[0]]
    if eta < 1.0 and s > 0.0:
        k2 = 1.0 - eta * eta
        C = []
        if mu * mu < k2:
            C += [np.sqrt(k2 - mu * mu) / s, -np.sqrt(k2 - mu * mu) / s]
        if lobe == "t":
            C.append(np.sqrt(k2) / s)
            if eta < s:
                C += [np.sqrt(1.0 - (eta / s) ** 2), -np.sqrt(1.0 - (eta / s) ** 2)]
        x = (2.0 * k2 - 1.0) / s
        if lobe == "r" and abs(x) <= 1.0:
            C.append((s + x) / np.sqrt(max(s * s + 2.0 * s * x + 1.0, 1e-300)))
        C = np.asarray([c for c in C if abs(c) <= 1.0])
        b = np.arccos(-C) / (2.0 * np.pi)
        f = 4.0 ** -np.arange(1, levels + 1)
        edges += [b, (b[:, None] * (1.0 - f)).ravel(), (b[:, None] + (0.5 - b[:, None]) * f).ravel()]
    return np.unique(np.clip(np.concatenate(edges), 0.0, 0.5))


def _incident(mu):
    mu = np.clip(np.atleast_1d(np.asarray(mu, dtype=float)), 0.0, 1.0)
    s = np.sqrt(1.0 - mu * mu)
    return mu, s, np.stack([s, np.zeros_like(mu), mu], axis=-1)


def _line_geometry(mf, u2):
    """Per line of constant u2: the slope scale alpha_phi (|slope| per unit standard radius)
    and the azimuth (cos, sin) of the normals m on it, and the map theta -> v = sqrt(u1)."""
    phi = 2.0 * np.pi * u2
    cx, sy = mf.alpha_x * np.cos(phi), mf.alpha_y * np.sin(phi)
    alpha_phi = np.hypot(cx, sy)  # |slope| per unit standard radius
    cos_phi_m, sin_phi_m = -cx / alpha_phi, -sy / alpha_phi

    def v_of_theta(theta):
        r2 = (np.tan(np.minimum(theta, 0.5 * np.pi - 1e-12)) / alpha_phi[..., None]) ** 2
        # Inverse of sample_dcos's radial map (Walter 2007 eqs. 28, 35).
        return np.sqrt(r2 / (1.0 + r2) if mf.ggx else -np.expm1(-r2))

    return cos_phi_m, sin_phi_m, v_of_theta


def _graded_around(breaks, lo, hi, levels):
    """theta edges graded geometrically (1 - 4^-k) toward each breakpoint from both sides,
    inside [lo, hi]: breaks (..., K), lo and hi (...) -> (..., 2 K levels)."""
    b = np.clip(breaks, lo[..., None], hi[..., None])[..., None]
    f = 4.0 ** -np.arange(1, levels + 1)
    left = b - (b - lo[..., None, None]) * f
    right = b + (hi[..., None, None] - b) * f
    return np.concatenate([left, right], axis=-1).reshape(b.shape[:-2] + (-1,))


def _graded_toward(b, ref, levels):
    """theta edges graded geometrically from ref toward b: b + (ref - b) 4^-k, k = 1..levels;
    b, ref (...) -> (..., levels)."""
    return b[..., None] + (ref - b)[..., None] * 4.0 ** -np.arange(1, levels + 1)


def _tir_window(mu, s, cos_phi_m, eta):
    """Along a line of normals m at polar angle theta in the azimuth phi_m, wi.m =
    mu cos(theta) + c sin(theta) = R cos(theta - gamma), c = s cos(phi_m). Refraction exists
    (no total internal reflection) where wi.m > k = sqrt(max(1 - eta^2, 0)) (k = 0: wi.m > 0),
    i.e. theta in (gamma - delta, gamma + delta), delta = acos(k / R); empty where k >= R.
    Returns (gamma - delta, gamma + delta), each (c, n2)."""
    c = s[:, None] * cos_phi_m
    R = np.hypot(mu[:, None], c)
    gamma = np.arctan2(c, mu[:, None])
    k = np.sqrt(max(1.0 - eta * eta, 0.0))
    delta = np.arccos(np.clip(k / R, 0.0, 1.0))
    return gamma - delta, gamma + delta


def _v_edges(mf, mu, s, u2, vcavity=False, tir_eta=None):
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
    also the angles where its min() switches branch (closed forms below). With `tir_eta` < 1
    (glass seen from the denser side) also the two angles where the Fresnel factor reaches
    total internal reflection (`_tir_window`; F has a square-root kink there), graded on both
    sides."""
    cos_phi_m, _, v_of_theta = _line_geometry(mf, u2)
    beta = np.arctan2(s[:, None] * cos_phi_m, mu[:, None])
    theta_h = 0.5 * beta + 0.25 * np.pi  # (c, n2)

    grade = 1.0 - 4.0 ** -np.arange(1, THETA_LEVELS + 1)
    theta_edges = [theta_h[..., None] * grade]
    if tir_eta is not None and tir_eta < 1.0:
        # 1 - F goes like a square root inside the window (F < 1): grade from inside.
        a, b = _tir_window(mu, s, cos_phi_m, tir_eta)
        lo = np.clip(a, 0.0, theta_h)
        up = np.clip(b, lo, theta_h)
        theta_edges += [lo[..., None], up[..., None], _graded_toward(lo, up, TIR_LEVELS),
                        _graded_toward(up, lo, TIR_LEVELS)]
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


def _transmission_rule(mf, mu, s, u2, eta, order):
    """Nodes m (c, n2, n1, 3) and weights du1 (c, n2, n1) on the lines of constant u2 for the
    transmitted lobe.

    Along a line of constant u2 (normals at polar angle theta in the azimuth phi_m) the
    refraction wo = refract_about(wi, m) exists and has wi.m > 0 for theta in the window of
    `_tir_window` intersected with [0, pi/2): [theta_lo, theta_hi]. At its ends the integrand
    goes to 0 like wi.m (eta > 1) or like 1 - F, a square root (total internal reflection,
    eta < 1). For eta > 1, wo.z < 0 on the whole window (cos_t > (wi.m) / eta); for eta < 1 wo
    may cross the horizon inside it, where wo is horizontal: m ~ wi + eta wo_h, wo_h =
    (cos psi, sin psi, 0), whose horizontal part is along phi_m: s sin(phi_m) =
    eta sin(psi - phi_m), tan(theta) = (s cos(phi_m) + eta cos(psi - phi_m)) / mu (two roots).
    Panels: the V_BODY fractions of [v_lo, v_hi] (the body and tail of D, as the reflection)
    mapped to theta, plus every breakpoint (the window's ends, the horizon roots) graded
    geometrically in theta. Unlike the reflection the window reaches m.z = 0 (theta = pi/2),
    where the integrand per unit u1 grows like 1 / m.z (an inverse square root in v): so the
    Gauss-Legendre nodes are placed in theta, with weights du1 = (du1/dtheta) dtheta, which is
    smooth there (du1 / pdf_dcos(m) = 2 pi sin(theta) dtheta for isotropic roughness), and m is
    built from (theta, phi_m) directly."""
    cos_phi_m, sin_phi_m, v_of_theta = _line_geometry(mf, u2)
    alpha_phi = np.hypot(mf.alpha_x * cos_phi_m, mf.alpha_y * sin_phi_m)[..., None]
    theta_max = 0.5 * np.pi
    a, b = _tir_window(mu, s, cos_phi_m, eta)
    lo = np.clip(a, 0.0, theta_max)
    hi = np.clip(b, lo, theta_max)
    theta_edges = [lo[..., None], hi[..., None], _graded_toward(lo, hi, TIR_LEVELS),
                   _graded_toward(hi, lo, TIR_LEVELS)]
    if eta < 1.0:
        c = s[:, None] * cos_phi_m
        sin_d = s[:, None] * sin_phi_m / eta
        cos_d = np.sqrt(np.maximum(1.0 - sin_d * sin_d, 0.0))
        roots = []
        for sign in (1.0, -1.0):
            tan_t = (c + sign * eta * cos_d) / mu[:, None]
            ok = (np.abs(sin_d) <= 1.0) & (tan_t > 0.0)
            roots.append(np.where(ok, np.arctan(np.maximum(tan_t, 0.0)), hi))
        roots = np.stack(roots, axis=-1)
        theta_edges += [np.clip(roots, lo[..., None], hi[..., None]),
                        _graded_around(roots, lo, hi, TIR_LEVELS)]
    # The body of D: V_BODY fractions in v, mapped back to theta (inverse of v_of_theta).
    v_lo, v_hi = v_of_theta(lo[..., None]), v_of_theta(hi[..., None])
    v = v_lo + (v_hi - v_lo) * np.asarray(V_BODY)
    u1 = np.minimum(v * v, 1.0 - 1e-16)
    r = np.sqrt(u1 / (1.0 - u1) if mf.ggx else -np.log1p(-u1))
    theta_edges.append(np.clip(np.arctan(alpha_phi * r), lo[..., None], hi[..., None]))
    edges = np.sort(np.concatenate(theta_edges, axis=-1), axis=-1)
    theta, wt = composite_gauss_legendre(edges, order)  # (c, n2, n1)
    # du1/dtheta of sample_dcos's radial map u1(r), r = tan(theta) / alpha_phi.
    tan_t = np.tan(theta)
    r = tan_t / alpha_phi
    du1_dr = 2.0 * r / (1.0 + r * r) ** 2 if mf.ggx else 2.0 * r * np.exp(-r * r)
    du1 = wt * du1_dr * (1.0 + tan_t * tan_t) / alpha_phi
    st = np.sin(theta)
    m = np.stack([st * cos_phi_m[..., None], st * sin_phi_m[..., None], np.cos(theta)], axis=-1)
    return m, du1


def directional_moments(bsdf, mu, order: int = DEFAULT_ORDER, chunk: int = 16):
    """(E, Vn, Vt), each of shape (len(mu), 3), for wi = (sqrt(1 - mu^2), 0, mu).

    `bsdf` is a `MicrofacetBRDF` (anything with .mf, .is_delta, .eval_specular,
    .delta_reflectance, .diffuse_albedo), or a BSDF with `has_transmission` (`MicrofacetGlass`:
    also .eta, .is_passthrough, .eval_transmission, .delta_transmission), whose moments are
    over the whole sphere: E = integral f |cos_o| dwo, (Vn, Vt) = integral f |cos_o| wo dwo,
    reflection plus transmission (wo.z < 0 there, so transmission makes Vn negative).

    Transmission: over microfacet normals with the same D cos parametrisation and rule as the
    reflection, wo = refract_about(wi, m), |dwo/dm| = (wi.m + eta wo.m)^2 / (eta^2 |wo.m|)
    (Walter 2007 eq. 17 inverted; eta = n_o / n_i), integrand f_t |cos_o| |dwo/dm| / pdf_dcos(m)
    with f_t from `eval_transmission`, cut where the refraction fails (total internal
    reflection, wi.m <= 0) or wo crosses the horizon (`_transmission_rule`). For eta < 1
    the reflection rule also gets edges at the Fresnel factor's TIR kinks. Deltas (perfect
    glass: mirror plus refraction by F; the index-matched pass-through: wo = -wi) are exact."""
    mu, s, wi = _incident(mu)
    albedo = np.asarray(bsdf.diffuse_albedo, dtype=float)
    E = np.zeros(mu.shape + (3,)) + albedo
    Vn = np.zeros(mu.shape + (3,)) + (2.0 / 3.0) * albedo
    Vt = np.zeros(mu.shape + (3,))
    transmission = getattr(bsdf, "has_transmission", False)
    if bsdf.is_delta:
        R = bsdf.delta_reflectance(wi)
        E, Vn, Vt = E + R, Vn + R * mu[:, None], Vt - R * s[:, None]
        if transmission:
            wo, T = bsdf.delta_transmission(wi)
            E, Vn, Vt = E + T, Vn + T * wo[:, 2:3], Vt + T * wo[:, 0:1]
        return E, Vn, Vt
    mf = bsdf.mf
    eta = bsdf.eta if transmission else None
    if transmission:  # u2 panels per incidence and lobe (`_u2_edges_glass`)
        chunks = []
        for i, (m_, s_) in enumerate(zip(mu, s)):
            rules = [composite_gauss_legendre(_u2_edges_glass(m_, s_, eta, lobe), order)
                     for lobe in "rt"]
            chunks.append((slice(i, i + 1),) + tuple(x[None] for r in rules for x in r))
    else:
        U2, W2 = composite_gauss_legendre(_u2_edges(mu), order)
        chunks = [(slice(i, i + chunk), U2[i:i + chunk], W2[i:i + chunk])
                  for i in range(0, len(mu), chunk)]
    for sl, u2, w2, *rule_t in chunks:  # u2, w2: (c, n2)
        w2 = 2.0 * w2  # the half u2 in [1/2, 1) by symmetry
        w_in = wi[sl, None, None, :]
        # u1 = v^2: the slope radius is analytic in v (it goes like sqrt(u1) at u1 = 0,
        # which would spoil Gauss-Legendre convergence in u1).
        v, wv = composite_gauss_legendre(
            _v_edges(mf, mu[sl], s[sl], u2, bsdf.masking == "vcavity", tir_eta=eta),
            order)  # (c,n2,n1)
        W = 2.0 * v * wv * w2[..., None]
        m = mf.sample_dcos(v * v, u2[..., None])
        pdf = mf.pdf_dcos(m)
        W = np.where(pdf > 0.0, W / np.where(pdf > 0.0, pdf, 1.0), 0.0)
        wo = reflect_about(w_in, m)
        f = bsdf.eval_specular(w_in, wo)
        g = W * 4.0 * np.abs(dot(wo, m)) * np.maximum(wo[..., 2], 0.0)
        E[sl] += np.einsum("ijk,ijkc->ic", g, f)
        Vn[sl] += np.einsum("ijk,ijkc->ic", g * wo[..., 2], f)
        Vt[sl] += np.einsum("ijk,ijkc->ic", g * wo[..., 0], f)
        if not transmission:
            continue
        u2, w2 = rule_t[0], 2.0 * rule_t[1]
        m, du1 = _transmission_rule(mf, mu[sl], s[sl], u2, eta, order)
        W = du1 * w2[..., None]
        pdf = mf.pdf_dcos(m)
        W = np.where(pdf > 0.0, W / np.where(pdf > 0.0, pdf, 1.0), 0.0)
        wo, ok = refract_about(w_in, m, eta)  # wo = (0, 0, 1) where it fails: f_t = 0 there
        f = bsdf.eval_transmission(w_in, wo)
        g = np.where(ok, W * transmission_jacobian(w_in, wo, m, eta), 0.0) \
            * np.maximum(-wo[..., 2], 0.0)
        E[sl] += np.einsum("ijk,ijkc->ic", g, f)
        Vn[sl] += np.einsum("ijk,ijkc->ic", g * wo[..., 2], f)
        Vt[sl] += np.einsum("ijk,ijkc->ic", g * wo[..., 0], f)
    return E, Vn, Vt


@dataclass(frozen=True)
class MomentTable:
    """Moments at nodes x = log(mu), mu in [MU_MIN, 1], increasing, refined where needed.

    E and Vn are even in theta_i and Vt odd, so E, Vn and Vt / sin(theta_i) are smooth functions
    of mu up to mu = 1; the log spacing resolves the grazing structure (Fresnel, and Smith
    masking, which changes on the scale mu ~ alpha). Glass seen from the denser side changes on
    the scale alpha around the critical angle, where `tabulate_moments` refines the nodes."""

    x: np.ndarray  # (n,) log(mu), increasing
    E: np.ndarray  # (n, 3)
    Vn: np.ndarray  # (n, 3)
    Vt_over_sin: np.ndarray  # (n, 3)


# The table stops short of mu = 0 (where f is not defined); below it the end value is used.
MU_MIN = 0.005
# Refinement (`tabulate_moments`): every interval's midpoint is computed and compared with the
# interpolated table; where any moment is off by more than TABLE_TOLERANCE the interval's halves
# are checked in turn, down to MIN_INTERVAL in log(mu), up to MAX_TABLE_NODES nodes in all.
TABLE_TOLERANCE = 2e-5
MAX_TABLE_NODES = 400
MIN_INTERVAL = 1e-6
END_FIT_MU = 0.98  # Vt / sin(theta) at mu = 1 is extrapolated from nodes up to here


def _node_mu(x):
    return np.minimum(np.exp(x), 1.0 - 1e-8)  # Vt / sin(theta) at theta -> 0 as a limit


def _moments(bsdf, mu, order):
    if hasattr(bsdf, "directional_moments"):  # a model with its own deterministic moments (Lee)
        return bsdf.directional_moments(mu)
    return directional_moments(bsdf, mu, order=order)


def merge(table: MomentTable, x, moments) -> MomentTable:
    """The table with nodes x (and their moments (E, Vn, Vt)) added."""
    mu = _node_mu(x)
    values = (moments[0], moments[1], moments[2] / np.sqrt(1.0 - mu * mu)[:, None])
    xs = np.concatenate([table.x, x])
    order = np.argsort(xs, kind="stable")
    old = (table.E, table.Vn, table.Vt_over_sin)
    return _end_limit(MomentTable(xs[order], *(np.concatenate([a, b])[order]
                                                for a, b in zip(old, values))))


def _end_limit(table: MomentTable) -> MomentTable:
    """Vt / sin(theta) at normal incidence as a limit: the node at mu = 1 - 1e-8 divides a
    moment that is 0 up to its quadrature error by sin = 1.4e-4, which amplified an error of
    2.5e-6 in Lee's moments into 0.018 (a visible dipole at the sphere's centre in the
    gradient). Vt / sin is smooth in x = log(mu) ~ -theta^2 / 2, so the end value is the cubic
    through the last four nodes with mu <= END_FIT_MU, extrapolated to x = 0."""
    fit = np.nonzero(table.x <= np.log(END_FIT_MU))[0][-4:]
    if len(fit) < 4 or table.x[-1] < np.log(END_FIT_MU):
        return table
    X, x0 = table.x[fit], table.x[-1]
    w = np.array([np.prod([(x0 - X[j]) / (X[k] - X[j]) for j in range(4) if j != k])
                  for k in range(4)])
    vts = table.Vt_over_sin.copy()
    vts[-1] = w @ vts[fit]
    return MomentTable(table.x, table.E, table.Vn, vts)


def _unbalanced(x):
    """Intervals more than twice as long as a neighbour (graded meshes keep the 4-point
    Lagrange stencils of `moments_at` well conditioned)."""
    h = np.diff(x)
    big = np.zeros(len(h), dtype=bool)
    big[1:] |= h[1:] > 2.01 * h[:-1]
    big[:-1] |= h[:-1] > 2.01 * h[1:]
    return big


def tabulate_moments(bsdf, n_mu: int = 48, order: int = DEFAULT_ORDER,
                     tol: float | None = TABLE_TOLERANCE,
                     max_nodes: int = MAX_TABLE_NODES) -> MomentTable:
    """Moments at n_mu incidences uniform in log(mu) on [MU_MIN, 1], refined for `moments_at`.

    Refinement (tol not None): the midpoint of every interval is computed and held against the
    interpolated table; intervals whose midpoint misses by more than `tol` (absolute, any of E,
    Vn, Vt, any channel) have both halves checked in the next round, until none miss, the
    intervals reach MIN_INTERVAL or the table has `max_nodes` nodes. Every computed midpoint
    joins the table, and intervals more than twice as long as a neighbour are split, so the
    mesh stays graded. So each table checks its own interpolation error: the 48 uniform nodes
    suffice for the reflection BRDFs (midpoint errors below 1e-5), while glass seen from the
    denser side needs nodes down to about alpha^2 / 10 around the critical angle (its moments
    jump there on the scale of the roughness), and rough glass more nodes near mu = 1.
    Models with their own `directional_moments` (Lee) keep the uniform nodes."""
    n_mu = max(int(n_mu), 4)
    x = np.linspace(np.log(MU_MIN), 0.0, n_mu)
    table = merge(MomentTable(np.zeros(0), *(np.zeros((0, 3)),) * 3), x,
                   _moments(bsdf, _node_mu(x), order))
    if tol is None or hasattr(bsdf, "directional_moments"):
        return table  # Lee's own moments are accurate to about 5e-5: refining would chase that
    check = np.ones(n_mu - 1, dtype=bool)  # intervals whose midpoint is to be checked
    while check.any() and len(table.x) < max_nodes:
        lo, hi = table.x[:-1][check], table.x[1:][check]
        keep = hi - lo > MIN_INTERVAL
        lo, hi = lo[keep][: max_nodes - len(table.x)], hi[keep][: max_nodes - len(table.x)]
        if len(lo) == 0:
            break
        mid = 0.5 * (lo + hi)
        exact = _moments(bsdf, _node_mu(mid), order)
        guess = moments_at(table, _node_mu(mid))
        err = np.max([np.abs(a - b).max(axis=-1) for a, b in zip(exact, guess)], axis=0)
        table = merge(table, mid, exact)
        while len(table.x) < max_nodes:
            split = _unbalanced(table.x)
            if not split.any():
                break
            extra = (0.5 * (table.x[:-1] + table.x[1:]))[split][: max_nodes - len(table.x)]
            table = merge(table, extra, _moments(bsdf, _node_mu(extra), order))
        # Next round: both halves of every interval whose midpoint missed.
        missed = mid[err > tol]
        check = np.isin(table.x[:-1], missed) | np.isin(table.x[1:], missed)
    return table


def moments_at(table: MomentTable, mu):
    """(E, Vn, Vt) at any mu (shape (...,) -> each (..., 3)) by 4-point Lagrange (cubic)
    interpolation in log(mu) on the table's nodes; mu below MU_MIN takes the MU_MIN values."""
    mu = np.clip(np.asarray(mu, dtype=float), MU_MIN, 1.0)
    x = np.log(mu).ravel()
    n = len(table.x)
    interval = np.clip(np.searchsorted(table.x, x, side="right") - 1, 0, n - 2)
    i0 = np.clip(interval - 1, 0, n - 4)  # stencil i0 .. i0 + 3
    nodes = table.x[i0[:, None] + np.arange(4)]  # (p, 4)
    w = np.ones_like(nodes)
    for k in range(4):
        for j in range(4):
            if j != k:
                w[:, k] *= (x - nodes[:, j]) / (nodes[:, k] - nodes[:, j])
    idx = i0[:, None] + np.arange(4)[None, :]
    shape = np.shape(mu) + (3,)
    E, Vn, Vts = (np.einsum("pk,pkc->pc", w, v[idx]).reshape(shape)
                  for v in (table.E, table.Vn, table.Vt_over_sin))
    return E, Vn, Vts * np.sqrt(1.0 - mu * mu)[..., None]
