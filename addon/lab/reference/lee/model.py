"""LeeBRDF, the catalog's lee_vgroove (Lee et al. 2018) as a numpy BRDF: the analytic sampler,
the evaluation (closed form for symmetric grooves, the partner-wall integral for asymmetric
ones) and deterministic directional moments, with Max Bounces (docs/lee-asymmetric-grooves.md
sec. 4) read one way by all three; and its builder, registered with bsdf.builds when the
package is imported (make_bsdf("lee_vgroove", ...)).
"""
from __future__ import annotations

import numpy as np

from ....catalog import alphas
from ..bsdf import builds
from ..microfacet import Microfacet
from ..vgroove import fresnel_fn
from .asymmetric import eval_asymmetric
from .directional_moments import moments
from .fresnel_table import FresnelTable
from .geometry import kmax_for
from .sampler import sample
from .symmetric import eval


class LeeBRDF:
    """The catalog's lee_vgroove as a numpy BRDF (make_bsdf): the analytic sampler, the
    evaluation (symmetric grooves: closed form, `eval`; asymmetric grooves: the integral over
    the partner wall by Gauss-Legendre, `eval_asymmetric`, 0.03-0.5 ms of CPU per direction,
    most at GGX roughness 1 with a conductor; doc sec. 5), and deterministic directional
    moments for the sphere-grid reference (quadrature.tabulate_moments uses
    `directional_moments` when a BSDF has one: the generic quadrature integrates single-facet
    lobes around reflect_about(wi, m), which multi-bounce lobes are not). Both evaluations sum
    k = 1 .. kterms, the derived bound (paths beyond carry < 1e-4 of the energy), and are
    reciprocal to rounding.

    Max Bounces (`kmax`, the catalog's max_bounces; 0 = the derived bound) has one meaning
    everywhere, sampler, eval, moments and the OSL shader: the first kmax bounces of a path get
    their Fresnel factor, later bounces reflect with F = 1, and every path is followed to its
    exact exit. So a low limit brightens and desaturates (never darkens) a conductor, and with
    F = 1 nothing changes: the furnace stays exactly 1 at any limit."""

    masking = "vcavity"  # for code that asks; the model has its own multi-bounce masking

    def __init__(self, mf: Microfacet, groove: str = "symmetric", fresnel: str = "conductor",
                 ior: float = 1.5, n=(1.0, 1.0, 1.0), k=(0.0, 0.0, 0.0), tint=(1.0, 1.0, 1.0),
                 max_bounces_param: float = 0.0, quad: dict | None = None):
        if groove not in ("symmetric", "asymmetric"):
            raise ValueError(f"groove must be symmetric or asymmetric, not {groove!r}")
        self.mf = mf
        self.groove = groove
        self.fresnel_kind = fresnel
        self.ior, self.n, self.k = float(ior), np.asarray(n, dtype=float), np.asarray(k, dtype=float)
        self.fresnel = fresnel_fn(fresnel, ior, n, k)
        self.tint = np.asarray(tint, dtype=float)
        self.diffuse_albedo = np.zeros(3)
        self.is_delta = mf.delta
        alpha = max(mf.alpha_x, mf.alpha_y)
        # Max Bounces: the bounces of a path that get their Fresnel factor (later ones F = 1;
        # every path is followed to its exit), in the sampler, eval and the moments alike.
        self.kmax = kmax_for(alpha, mf.distribution, groove, max_bounces_param)
        # The terms eval sums: the derived bound whatever Max Bounces (longer paths carry less
        # than 1e-4 of the energy), so eval's cost does not grow with Max Bounces.
        self.kterms = kmax_for(alpha, mf.distribution, groove, 0.0)
        self.quad = dict(quad or {})
        # Sampler and eval use the Fresnel tabulated (interpolation error < 1e-7 per bounce,
        # float32's level; the exact formula per bounce dominated their cost); self.fresnel
        # stays the exact callable. Public: light_sampling.low_orders evaluates with it too.
        self.fresnel_table = FresnelTable(self.fresnel)

    def delta_reflectance(self, wi):
        """Roughness 0: one mirror bounce, tint F(wi.n) (zeros otherwise)."""
        wi = np.asarray(wi, dtype=float)
        if not self.is_delta:
            return np.zeros(wi.shape)
        c = np.clip(wi[..., 2], 0.0, 1.0)
        return np.where((wi[..., 2] > 0.0)[..., None], self.tint * self.fresnel(c), 0.0)

    def sample(self, wi, u):
        """(wo, weight RGB, k) from lee.sample; u (..., 3) symmetric or (..., 6) asymmetric."""
        wi = np.asarray(wi, dtype=float)
        if self.is_delta:
            shape = np.broadcast_shapes(wi.shape, np.shape(u)[:-1] + (3,))
            wi = np.broadcast_to(wi, shape)
            return (wi * np.array([-1.0, -1.0, 1.0]), self.delta_reflectance(wi),
                    np.ones(shape[:-1], dtype=np.int64))
        wo, w, k = sample(wi, u, self.mf, self.fresnel_table, self.groove, self.kmax)
        return wo, w * self.tint, k

    def eval(self, wi, wo):
        """f(wi, wo) RGB, without the cosine (zeros for roughness 0, a delta)."""
        if self.is_delta:
            return np.zeros(np.broadcast_shapes(np.shape(wi), np.shape(wo)))
        if self.groove == "symmetric":
            return eval(wi, wo, self.mf, self.fresnel_table, self.kterms, self.kmax) * self.tint
        return eval_asymmetric(wi, wo, self.mf, self.fresnel_table, self.kterms,
                               fresnel_bounces=self.kmax) * self.tint

    eval_specular = eval

    def directional_moments(self, mu, order=None):
        """(E, Vn, Vt) for wi = (sqrt(1 - mu^2), 0, mu), each (len(mu), 3) (see moments())."""
        mu = np.clip(np.atleast_1d(np.asarray(mu, dtype=float)), 0.0, 1.0)
        if self.is_delta:
            wi = np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=-1)
            R = self.delta_reflectance(wi)
            return R, R * mu[:, None], -R * np.sqrt(1.0 - mu * mu)[:, None]
        E, Vn, Vt = moments(mu, self.mf, self.fresnel, self.groove, self.kmax, **self.quad)
        return E * self.tint, Vn * self.tint, Vt * self.tint


@builds("lee_vgroove")
def _lee_vgroove(params) -> LeeBRDF:
    # Lee et al. 2018: kaleidoscopic multi-bounce V-grooves.
    ax, _ = alphas(params["roughness"])
    return LeeBRDF(Microfacet(params["distribution"], ax), groove=params["groove"],
                   fresnel=params["fresnel_type"], ior=params["ior"], n=params["n"],
                   k=params["k"], tint=params["base_color"],
                   max_bounces_param=params["max_bounces"])
