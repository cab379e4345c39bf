"""Monte Carlo directional moments of the Heitz et al. 2016 walk (heitz2016.walk): the twin of
quadrature.directional_moments for a model whose BSDF has no closed form, as means of the
sampled walks' weights with their standard errors. The sphere-grid reference tabulates them
(heitz2016.model.moment_tables).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .walk import MAX_ORDER, SmithWalk, mean_se


class MCMoments(NamedTuple):
    E: np.ndarray        # (len(mu), 3), as quadrature.directional_moments
    Vn: np.ndarray
    Vt: np.ndarray
    E_se: np.ndarray
    Vn_se: np.ndarray
    Vt_se: np.ndarray
    lost: np.ndarray     # (len(mu),) walks stopped at max_order


def directional_moments_mc(bsdf: SmithWalk, mu, n_walks: int, rng,
                           max_order: int = MAX_ORDER, order: int | None = None) -> MCMoments:
    """Monte Carlo twin of quadrature.directional_moments: for wi = (sqrt(1 - mu^2), 0, mu),
    E = integral f |cos_o| dwo, (Vn, Vt) = the n and t (= x, toward wi) components of
    integral f |cos_o| wo dwo (over the whole sphere for the dielectric: transmission makes Vn
    negative), as means of weight, weight wo.z, weight wo.x over n_walks sampled walks, with
    their standard errors. Each (len(mu), 3). order=k keeps only the walks of exactly k
    scattering events (order=1: the single-scattering moments, to compare with
    quadrature.directional_moments of the height-correlated Walter model)."""
    mu = np.atleast_1d(np.asarray(mu, dtype=float))
    out = [np.zeros((len(mu), 3)) for _ in range(6)]
    lost = np.zeros(len(mu), dtype=int)
    for i, m in enumerate(mu):
        s = math.sqrt(max(1.0 - m * m, 0.0))
        wi = np.broadcast_to(np.array([s, 0.0, m]), (n_walks, 3))
        smp = bsdf.sample(wi, rng, max_order)
        w = smp.weight if order is None else smp.weight * (smp.order == order)[:, None]
        for j, x in enumerate((w, w * smp.wo[:, 2:3], w * smp.wo[:, 0:1])):
            out[j][i], out[j + 3][i] = mean_se(x)
        lost[i] = int(smp.lost.sum())
    return MCMoments(*out, lost)
