"""Light Sampling of the Heitz et al. 2016 conductor (osl/heitz2016.osl, "Native + Residual";
docs/light-sampling.md): the residual the walk keeps once the native closure carries c of the
first order, evaluated stochastically (`eval_residual`) and sampled aimed at the lamps by a
partition of directions (`sample_aimed_residual`, with lamps.py, the twin of osl/lamps.h).
"""
from __future__ import annotations

import numpy as np

from .. import lamps as lamp_twin
from .conductor import HeitzConductor
from .walk import MAX_ORDER, rows


# -- Light Sampling: the aimed residual (osl/heitz2016.osl) -----------------------------------
def eval_residual(walk: HeitzConductor, wi, wo, c, rng, max_order: int = MAX_ORDER):
    """One unbiased estimate per row of the residual r(wi, wo) |wo.n| = f |wo.n| - c F f_ggx
    |wo.n| (RGB) of the conductor walk, as the shader's eval_residual: the first order in closed
    form with F (1 - c) for F (F (1 - c) D G2 / (4 wi.n), G2 height-correlated: eval_single's
    form), plus one walk's next-event terms from the second event on. c: (3,) or (N, 3), the
    share of the first order the native part carries (split.native_factor: 1, the native part
    being Cycles' conductor_bsdf, F included)."""
    wi, wo = np.broadcast_arrays(rows(wi), rows(wo))
    F, val = walk.single_kernel(wi, wo)
    first = F * np.maximum(1.0 - np.asarray(c, dtype=float), 0.0) * val[:, None] * walk.tint
    higher = walk.run(wi, rng, max_order, wo=wo, from_order=2)[1]
    return first + higher


# Walks averaged per aimed direction (osl MFL_HEITZ_EVAL_WALKS).
EVAL_WALKS = 4


def eval_residual_mean(walk: HeitzConductor, wi, wo, c, rng, max_order: int = MAX_ORDER,
                       walks: int = EVAL_WALKS):
    """The mean of `walks` independent eval_residual estimates (osl eval_residual_mean)."""
    return sum(eval_residual(walk, wi, wo, c, rng, max_order) for _ in range(walks)) / walks


def sample_aimed_residual(walk: HeitzConductor, records, P, wi, c, rng,
                          max_order: int = MAX_ORDER):
    """The shader's residual sample with the lamps (osl/heitz2016.osl, lamps.py twin): rows of
    wi at points P (normal z). The directions toward the lamps, L = {lamps_pdf > 0}, and the
    rest are two integrals: with probability lam a direction from lamps_pdf weighted
    eval_residual_mean / (lam lamps_pdf) covers L, otherwise the walk (its first-order exit
    weighing F (1 - c), later orders their throughput) counted only outside L, over 1 - lam,
    covers the rest. Returns (wo, weight RGB); E[weight g(wo)] = integral r |cos| g for any
    records (a stale table moves noise only)."""
    wi = rows(wi)
    n = len(wi)
    P = np.broadcast_to(np.asarray(P, dtype=float), (n, 3))
    Ng = np.broadcast_to([0.0, 0.0, 1.0], (n, 3))
    lam, _ = lamp_twin.guide_fraction(records, P, Ng) if records else (np.zeros(n), None)
    u = rng.random((n, 4))
    aimed = u[:, 0] < lam
    wo = np.zeros((n, 3))
    weight = np.zeros((n, 3))
    if aimed.any():
        a = np.nonzero(aimed)[0]
        d = lamp_twin.sample_lamps(records, P[a], Ng[a], u[a, 1], u[a, 2], u[a, 3])
        p = lamp_twin.lamps_pdf(records, P[a], Ng[a], d)
        ok = (d[:, 2] > 0.0) & (p > 0.0)
        r = eval_residual_mean(walk, wi[a], d, c, rng, max_order)
        wo[a] = d
        weight[a] = np.where(ok[:, None], r / np.where(ok, lam[a] * p, 1.0)[:, None], 0.0)
    rest = np.nonzero(~aimed)[0]
    if len(rest):
        s = walk.sample(wi[rest], rng, max_order)
        w = np.where((s.order == 1)[:, None], s.weight * np.maximum(1.0 - np.asarray(c), 0.0),
                     s.weight)
        if records:
            inside = lamp_twin.lamps_pdf(records, P[rest], Ng[rest], s.wo) > 0.0
            w = np.where(inside[:, None], 0.0, w / (1.0 - lam[rest])[:, None])
        wo[rest] = s.wo
        weight[rest] = w
    return wo, weight
