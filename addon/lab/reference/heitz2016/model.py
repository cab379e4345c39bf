"""The catalog model `heitz2016` (Heitz, Hanika, d'Eon & Dachsbacher 2016; osl/heitz2016.osl;
docs/models.md sec. 5) as make_bsdf builds it: HeitzBSDF, a conductor or dielectric walk
(heitz2016.conductor, heitz2016.dielectric) in the interface the lab's tools use, its builder
registered with reference.bsdf.builds; and the walk's Monte Carlo moment tables for the
sphere-grid reference (`moment_tables` on the nodes of `table_nodes`).
"""
from __future__ import annotations

import math

import numpy as np

from ....catalog import alphas
from ..bsdf import builds
from ..microfacet import Microfacet
from ..quadrature import MU_MIN, MomentTable, merge
from .conductor import HeitzConductor
from .dielectric import HeitzDielectric
from .medium import TINY
from .moments import directional_moments_mc
from .walk import MAX_ORDER, SmithWalk, rows


# -- the catalog model ------------------------------------------------------------------------
class _PreparedStream:
    """An rng for `SmithWalk`: the first draw (the first event's four numbers, rows of the
    walks that start) comes from prepared uniforms, every later one from a seeded Generator."""

    def __init__(self, first, seed: int):
        self.first = first
        self.rest = np.random.default_rng(seed)

    def random(self, shape):
        if self.first is not None and tuple(shape) == self.first.shape:
            out, self.first = self.first, None
            return out
        return self.rest.random(shape)


class HeitzBSDF:
    """The catalog model `heitz2016` (make_bsdf) in the interface the lab's tools use: a
    conductor or dielectric walk (`walk`) with `max_order` events, and
      eval(wi, wo), eval_cos(wi, wo): Monte Carlo estimates (mean of `eval_walks` walks from a
        fixed seed) of f and f |cos_o|: the walk has no closed form;
      sample(wi, u): one walk per row, u (N, >= 4) the first event's uniforms (height, visible
        normal, Fresnel choice), later events from a seed derived from u; returns (wo, weight,
        pdf) with pdf a one-walk estimate of the density of wo (that of the F = 1 walk for a
        conductor, the walk's own for a dielectric, whose weights are 1);
      directional_moments(mu): (E, Vn, Vt) from `moment_walks` sampled walks per mu (Monte
        Carlo; `moment_tables` gives them with their standard errors)."""

    diffuse_albedo = np.zeros(3)
    stochastic_eval = True  # eval is a Monte Carlo estimate, not a closed form

    def __init__(self, walk: SmithWalk, max_order: int = MAX_ORDER, eval_walks: int = 16,
                 moment_walks: int = 200_000, seed: int = 0):
        self.walk = walk
        self.mf = walk.mf
        self.max_order = int(max_order)
        self.eval_walks = eval_walks
        self.moment_walks = moment_walks
        self.seed = seed
        self.has_transmission = walk.has_transmission
        self.is_delta = walk.mf.delta
        if walk.dielectric:
            self._density = walk
        else:
            self._density = HeitzConductor(walk.mf, "none")

    def __repr__(self):
        return f"HeitzBSDF({self.walk!r}, max_order={self.max_order})"

    def eval_cos(self, wi, wo):
        lead = np.broadcast_shapes(np.shape(wi), np.shape(wo))[:-1]
        wi, wo = np.broadcast_arrays(rows(wi), rows(wo))
        mean, _ = self.walk.eval_mean(wi, wo, self.eval_walks, np.random.default_rng(self.seed),
                                      self.max_order)
        return mean.reshape(lead + (3,))

    def eval(self, wi, wo):
        cos_o = np.abs(np.asarray(wo, dtype=float)[..., 2:3])
        fc = self.eval_cos(wi, wo)
        return np.where(cos_o > 0.0, fc / np.where(cos_o > 0.0, cos_o, 1.0), 0.0)

    def sample(self, wi, u):
        lead = np.shape(wi)[:-1]  # any (..., 3), as the other models
        wi = rows(wi)
        u = np.asarray(u, dtype=float).reshape(len(wi), -1)
        if u.shape[1] < 4:
            raise IndexError("the walk's first event takes 4 uniforms")
        first = np.clip(u[wi[:, 2] > 0.0, :4], 0.0, 1.0 - 2.0 ** -53)
        seed = int(np.frombuffer(np.ascontiguousarray(u).tobytes(), dtype=np.uint64).sum()
                   % (2 ** 63)) if u.size else 0
        s = self.walk.sample(wi, _PreparedStream(first, seed), self.max_order)
        live = s.weight.max(axis=1) > 0.0
        pdf = np.zeros(len(wi))
        if live.any():
            est = self._density.eval(wi[live], s.wo[live], np.random.default_rng(seed + 1),
                                     self.max_order)
            pdf[live] = est[:, 0] / np.maximum(np.abs(s.wo[live, 2]), TINY)
        return s.wo.reshape(lead + (3,)), s.weight.reshape(lead + (3,)), pdf.reshape(lead)

    def directional_moments(self, mu):
        m = directional_moments_mc(self.walk, mu, self.moment_walks,
                                   np.random.default_rng(self.seed), self.max_order)
        return m.E, m.Vn, m.Vt


def moment_tables(bsdf: HeitzBSDF, mu, n_walks: int, rng):
    """Moment tables of the walk for the sphere-grid reference, with their Monte Carlo error:
    (table, se_table), two quadrature.MomentTable on the nodes `mu` (in (0, 1]; see
    `table_nodes`), the second holding the standard errors of E, Vn and Vt (moments_at on it
    interpolates the errors, which is what a reference pixel's error is up to the
    interpolation weights)."""
    mu = np.unique(np.asarray(mu, dtype=float))
    x = np.log(mu)
    m = directional_moments_mc(bsdf.walk, np.minimum(mu, 1.0 - 1e-8), n_walks, rng,
                               bsdf.max_order)
    empty = MomentTable(np.zeros(0), *(np.zeros((0, 3)),) * 3)
    return merge(empty, x, (m.E, m.Vn, m.Vt)), merge(empty, x, (m.E_se, m.Vn_se, m.Vt_se))


def table_nodes(n_mu: int = 24, uniform_from: float | None = None, spacing: float = 0.025):
    """Incidences for `moment_tables`: n_mu nodes uniform in log(mu) on [MU_MIN, 1] (as the
    quadrature tables), or, with `uniform_from`, those below it and nodes every `spacing` in mu
    from it to 1: glass seen from the denser side bends on the scale of the roughness around
    the critical angle (where quadrature.tabulate_moments refines by itself), and cubic
    interpolation through Monte Carlo nodes wants them evenly spaced (clustered nodes amplify
    their noise)."""
    mu = np.exp(np.linspace(np.log(MU_MIN), 0.0, max(int(n_mu), 4)))
    if uniform_from is None:
        return mu
    even = np.arange(1.0, uniform_from - 1e-9, -spacing)[::-1]
    return np.concatenate([mu[mu < even[0] - 0.5 * spacing], even])


@builds("heitz2016")
def _heitz2016(params) -> HeitzBSDF:
    ax, _ = alphas(params["roughness"])
    mf = Microfacet(params["distribution"], ax, ax)
    if params["fresnel_type"] == "dielectric":
        # As the shader renders it: Cycles' refraction closure cannot return forward transmission.
        walk = HeitzDielectric(mf, params["ior"], tint=params["base_color"],
                               forward_transmission=False)
    else:
        walk = HeitzConductor(mf, params["fresnel_type"], n=params["n"], k=params["k"],
                              tint=params["base_color"])
    return HeitzBSDF(walk, max_order=int(math.floor(params["max_order"] + 0.5)))
