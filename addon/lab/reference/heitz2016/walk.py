"""The random walk on the Smith microsurface (Heitz, Hanika, d'Eon & Dachsbacher 2016) that the
conductor and the dielectric share (SmithWalk): sampling, the stochastic evaluation, albedo;
their results (WalkSample, Albedo). The scattering rule and the next-event term of an event are
the materials' (heitz2016.conductor, heitz2016.dielectric); the height and visible-normal laws
are heitz2016.medium's. The paper's own equation numbers are not cited (see the package doc).

* Sampling (`sample`): the walk starts above the surface going down along -wi, scatters until it
  escapes: upwards (reflection), or, for the dielectric, downwards from below (transmission).
  The weight is the product of the Fresnel factors (conductor) or 1 (dielectric), so with F = 1
  or without absorption the density of wo is f |wo.n| exactly. Walks that reach `max_order`
  scattering events without escaping are stopped with weight 0 and flagged `lost` (a bias of at
  most their fraction, reported).
* Stochastic evaluation (`eval`), as in the paper: the walk from wi, with at every scattering
  event a next-event term toward wo: throughput x phase function (wi_event -> wo) x the escape
  probability of wo from the event's height (G1(wo, h) above, G1(-wo, -h) below). Its expectation
  is f(wi, wo) |wo.n| (the BSDF times the cosine of wo, NOT f); each call is one unbiased estimate
  per row (up to the max_order truncation). `eval(..., bidirectional=True)` averages it with the
  reverse walk from wo turned into an estimate of the same quantity through reciprocity (f
  symmetric for reflection; f_t(wi, wo; eta) = eta^2 f_t(flip(wo), flip(wi); 1/eta) for
  transmission in Cycles' convention, flip(x, y, z) = (x, y, -z)): still unbiased. This averaging
  is my addition; I did not verify whether the paper combines the two directions (with MIS
  weights or otherwise), so the default is the unidirectional estimator.

Variance (measured; tests/test_reference_heitz2016_*.py and the report). The sampler's weights
are bounded (products of Fresnel factors), so albedos and moments from it have honest standard
errors. The stochastic evaluation is unbiased but can be heavy-tailed: the next-event term of a
rare walk can be many orders above the typical one (a hit from below, probability ~ Lambda,
has a phase function ~ 1 / (|w.z| Lambda); and with Beckmann's light tails reaching a given wo
at order >= 2 can be a rare event). Per-walk relative standard deviation, wi at 45 deg: GGX
alpha 0.5 / 1 and Beckmann 0.5 / 1: 0.2 .. 1.4; GGX alpha 0.1 toward grazing wo: ~50-60 (and
Beckmann alpha 0.6 order 3: the 5 largest of 4M walks carry 93 % of the term). The sample
standard error then understates the error when the rare walks were not drawn, so compare
evaluations in z-tests only where the tails are mild (the tests say where), or use the
sampler (patch transport, chi-square). bidirectional=True lowers the per-walk relative standard
deviation by about 1.3-2x in most configurations measured (not all: toward the normal at GGX
alpha 0.1 it rises from 0.7 to 1.1).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..microfacet import Microfacet
from .medium import sample_height

MAX_ORDER = 100  # scattering events before a walk is stopped (counted as lost)


# -- results -----------------------------------------------------------------------------------
class WalkSample(NamedTuple):
    wo: np.ndarray       # (N, 3) exit direction (wo.z < 0: transmission); (0,0,0) where lost
    weight: np.ndarray   # (N, 3) product of the Fresnel factors (conductor), 1 (dielectric), x tint
    order: np.ndarray    # (N,) number of scattering events (max_order where lost)
    lost: np.ndarray     # (N,) True: stopped at max_order without escaping (weight 0)


class Albedo(NamedTuple):
    E: np.ndarray        # (3,) integral of f |cos_o| over the sphere, mean of the weights
    E_se: np.ndarray     # (3,) its Monte Carlo standard error
    R: np.ndarray        # (3,) the part with wo.z > 0
    T: np.ndarray        # (3,) the part with wo.z < 0 (dielectric)
    R_se: np.ndarray
    T_se: np.ndarray
    lost: int            # walks stopped at max_order
    mean_order: float    # mean number of scattering events per walk


def rows(x):
    """x as rows (N, 3): any (..., 3) flattened (directions, RGB values)."""
    x = np.asarray(x, dtype=float)
    return x.reshape(-1, 3)


def mean_se(x):
    """Mean over the rows and its standard error."""
    n = len(x)
    se = x.std(axis=0, ddof=1) / math.sqrt(n) if n > 1 else np.zeros(x.shape[1:])
    return x.mean(axis=0), se


def flip(w):
    """(x, y, z) -> (x, y, -z): the same direction seen with the interface flipped."""
    return np.asarray(w, dtype=float) * np.array([1.0, 1.0, -1.0])


# -- the random walk --------------------------------------------------------------------------
class SmithWalk:
    """Shared random walk; subclasses set `dielectric` and the scattering rule (the hooks
    `_scatter`, `_next_event`, `_reverse_estimate`; heitz2016.conductor, heitz2016.dielectric)."""

    dielectric = False
    has_transmission = False

    def __init__(self, mf: Microfacet, tint=(1.0, 1.0, 1.0)):
        self.mf = mf
        self.tint = np.asarray(tint, dtype=float)
        self.diffuse_albedo = np.zeros(3)

    # Hooks -----------------------------------------------------------------------------
    def _next_height(self, wr, h, outside, u):
        return sample_height(self.mf, wr, h, u)

    def _escape_is_exit(self, wr, outside):
        return np.ones(len(wr), dtype=bool)

    # Walk --------------------------------------------------------------------------------
    def run(self, wi, rng, max_order, wo=None, order=None, from_order=1):
        """The random walk from wi (rows); if wo is given also the next-event estimate toward
        wo (rows), restricted to scattering order `order` when not None, and to the events from
        the `from_order`-th on. Returns (WalkSample, estimate or None). `sample` and `eval` are
        this; heitz2016.light_sampling's residual runs it from the second event."""
        wi = rows(wi)
        n = len(wi)
        out_wo = np.zeros((n, 3))
        out_w = np.zeros((n, 3))
        out_order = np.full(n, max_order, dtype=int)
        lost = np.zeros(n, dtype=bool)
        est = None if wo is None else np.zeros((n, 3))
        if wo is not None:
            wo = np.broadcast_to(rows(wo), (n, 3))
        idx = np.arange(n)
        wr = -wi  # travel direction
        h = np.ones(n)  # the top of the height support: C1 = 1
        outside = np.ones(n, dtype=bool)
        thr = np.ones((n, 3))
        valid = wi[:, 2] > 0.0
        idx, wr, h, outside, thr = idx[valid], wr[valid], h[valid], outside[valid], thr[valid]
        out_order[~valid] = 0
        for k in range(max_order + 1):
            if len(idx) == 0:
                break
            u = rng.random((len(idx), 4))
            h, esc = self._next_height(wr, h, outside, u[:, 0])
            if esc.any():
                e = idx[esc]
                out_wo[e] = wr[esc]
                out_w[e] = thr[esc]
                out_order[e] = k
            keep = ~esc
            idx, wr, h, outside, thr, u = (idx[keep], wr[keep], h[keep], outside[keep],
                                           thr[keep], u[keep])
            if k == max_order:
                lost[idx] = True
                break
            # scattering event number k + 1 at height h
            wi_ev = -wr
            if est is not None and (order is None or order == k + 1) and k + 1 >= from_order:
                est[idx] += thr * self._next_event(wi_ev, wo[idx], h, outside)
            if est is not None and order is not None and k + 1 >= order:
                break  # later events cannot contribute to a single order
            wr, thr, outside = self._scatter(wi_ev, thr, outside, u, rng)
        out_w = out_w * self.tint
        sample = WalkSample(out_wo, out_w, out_order, lost)
        if est is not None:
            est = est * self.tint
        return sample, est

    # Public API -------------------------------------------------------------------------
    def sample(self, wi, rng, max_order: int = MAX_ORDER) -> WalkSample:
        """One random walk per row of wi: WalkSample(wo, weight RGB, order, lost). wo has
        density f |wo.n| / (its integral) up to the weights; E[weight * g(wo)] =
        integral f(wi, wo) |wo.n| g(wo) dwo (minus the lost walks' share)."""
        return self.run(wi, rng, max_order)[0]

    def eval(self, wi, wo, rng, max_order: int = MAX_ORDER, order: int | None = None,
             bidirectional: bool = False):
        """One stochastic, unbiased estimate per row of f(wi, wo) |wo.n| (RGB; the BSDF times
        the cosine of wo, not f): the walk from wi with next-event estimation toward wo at
        every scattering event (the paper's stochastic evaluation). order=k keeps only the
        k-th scattering event's term (order=1: the first-order term, whose mean is
        `eval_single`). bidirectional=True averages with the reverse walk from wo (see the
        module doc), which needs twice the walks."""
        wi, wo = np.broadcast_arrays(rows(wi), rows(wo))
        fwd = self.run(wi, rng, max_order, wo=wo, order=order)[1]
        if not bidirectional:
            return fwd
        return 0.5 * (fwd + self._reverse_estimate(wi, wo, rng, max_order, order))

    def eval_mean(self, wi, wo, n_walks: int, rng, max_order: int = MAX_ORDER,
                  order: int | None = None, bidirectional: bool = False, chunk: int = 1 << 18):
        """Mean and standard error (each (P, 3)) of `eval` over n_walks walks per pair
        (rows of wi, wo)."""
        wi, wo = np.broadcast_arrays(rows(wi), rows(wo))
        P = len(wi)
        per = max(1, chunk // max(P, 1))
        done = 0
        scale = None
        mean = np.zeros((P, 3))
        M2 = np.zeros((P, 3))
        while done < n_walks:
            m = min(per, n_walks - done)
            e = self.eval(np.repeat(wi, m, axis=0), np.repeat(wo, m, axis=0), rng, max_order,
                          order, bidirectional).reshape(P, m, 3)
            if scale is None:  # values may be ~1e-170: squares would underflow
                scale = np.abs(e).max(axis=1)
                scale = np.where(scale > 0.0, scale, 1.0)
            e = e / scale[:, None, :]
            mb = e.mean(axis=1)
            M2b = ((e - mb[:, None, :]) ** 2).sum(axis=1)
            delta = mb - mean
            n_new = done + m
            mean = mean + delta * (m / n_new)
            M2 = M2 + M2b + delta * delta * (done * m / n_new)  # Chan et al.'s update
            done = n_new
        var = M2 / max(n_walks - 1, 1)
        return mean * scale, np.sqrt(var / n_walks) * scale

    def albedo(self, wi, n_walks: int, rng, max_order: int = MAX_ORDER,
               order: int | None = None) -> Albedo:
        """Directional albedo E(wi) = integral f |cos_o| dwo from n_walks sampled walks, with
        its standard error, the reflected / transmitted parts, the lost walks and the mean
        walk length. order=k keeps only walks of exactly k scattering events (order=1: the
        single-scattering albedo)."""
        wi = np.broadcast_to(rows(wi)[0], (n_walks, 3))
        s = self.sample(wi, rng, max_order)
        w = s.weight if order is None else s.weight * (s.order == order)[:, None]
        up = (s.wo[:, 2] > 0.0)[:, None]
        E, E_se = mean_se(w)
        R, R_se = mean_se(w * up)
        T, T_se = mean_se(w * ~up)
        return Albedo(E, E_se, R, T, R_se, T_se, int(s.lost.sum()), float(s.order.mean()))
