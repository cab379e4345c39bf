"""Lee 2018 reference for sphere images: the deterministic directional moments of LeeBRDF
(addon/lab/reference/lee/directional_moments.py `moments`) against Monte Carlo of the analytic
sampler `lee.sample`, the derived bounce bound in closed form (the OSL shader's formula) against
the search `lee.max_bounces`, and the OSL shader's constants against the numpy twin. numpy only."""
from __future__ import annotations

import math

import numpy as np
import pytest

from addon.catalog import MODELS
from addon.lab.reference import lee, make_bsdf
from addon.lab.reference import vgroove as vg
from addon.lab.reference.microfacet import Microfacet
from addon.lab.reference.quadrature import tabulate_moments
import osl_text  # tests/osl_text.py

OSL = "lee_vgroove.osl"
GOLD_N = MODELS["lee_vgroove"].param("n").default
GOLD_K = MODELS["lee_vgroove"].param("k").default
GOLD = vg.fresnel_fn("conductor", n=GOLD_N, k=GOLD_K)
# Accuracy of the default quadrature rules (MOMENT_NODES), as measured by
# addon/lab/bench_lee.py:moments_accuracy (finer rules) and used as floors in test_render_lee.py.
ACCURACY = {"symmetric": 2e-4, "asymmetric": 1.5e-3}


@pytest.mark.parametrize("groove", ["symmetric", "asymmetric"])
@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_closed_form_bound_equals_search(dist, groove):
    alphas = np.concatenate([np.geomspace(1e-4, 1.0, 60), [0.0025, 0.09, 0.49, 1.0]])
    for a in alphas:
        assert lee.max_bounces_closed_form(a, dist, groove) == lee.max_bounces(a, dist, groove), a


def test_osl_constants_match_numpy_tail_ratios():
    text = osl_text.source(OSL)
    for dist in ("ggx", "beckmann"):
        for groove in ("symmetric", "asymmetric"):
            name = f"LEE_TAIL_{dist.upper()}_{groove.upper()}"
            value = osl_text.define_float(text, name)
            assert value == pytest.approx(lee.tail_ratio(dist, groove), rel=1e-8), name


def test_osl_aiming_constants_match_numpy():
    """The Native + Residual twins agree on the bounce terms aimed at the lamps, the Beckmann
    variable's cap and where the asymmetric rule's uniforms start."""
    text = osl_text.source(OSL)
    for name, value in (("LEE_AIMED_ORDERS", lee.AIMED_ORDERS),
                        ("LEE_PARTNER_DIM", lee.PARTNER_DIM),
                        ("LEE_BECKMANN_Y_MAX", lee.BECKMANN_Y_MAX)):
        assert osl_text.define_float(text, name) == value, name


def test_kmax_user_value_and_default():
    assert lee.kmax_for(1.0, "ggx", "symmetric", 0.0) == 158  # docs table
    assert lee.kmax_for(1.0, "ggx", "symmetric", 3.7) == 3
    assert lee.kmax_for(1.0, "ggx", "symmetric", 0.2) == 1
    b = make_bsdf("lee_vgroove", {"roughness": 1.0, "max_bounces": 5})
    assert b.kmax == 5


def test_fresnel_table_is_exact_enough():
    table = lee.FresnelTable(GOLD)
    c = np.random.default_rng(0).random(100000)
    assert np.abs(table(c) - GOLD(c)).max() < 1e-7
    assert np.array_equal(table(np.array([0.0, 0.5, 1.0])), GOLD(np.array([0.0, 0.5, 1.0])))


@pytest.mark.parametrize("groove", ["symmetric", "asymmetric"])
def test_furnace_moments_are_exactly_one(groove):
    mu = np.array([1.0, 0.5, 0.05, 0.005])
    E, Vn, Vt = lee.moments(mu, Microfacet("ggx", 1.0), None, groove, n_theta=32, n_phi=32)
    assert np.abs(E - 1.0).max() < 1e-12
    assert (Vn > 0).all() and (np.abs(Vt) <= 1).all()


def test_mirror_moments():
    b = make_bsdf("lee_vgroove", {"roughness": 0.0})
    mu = np.array([1.0, 0.3])
    E, Vn, Vt = b.directional_moments(mu)
    F = GOLD(mu)
    assert np.allclose(E, F) and np.allclose(Vn, F * mu[:, None])
    assert np.allclose(Vt, -F * np.sqrt(1 - mu * mu)[:, None])


def test_tabulate_moments_uses_the_lee_hook():
    b = make_bsdf("lee_vgroove", {"roughness": 0.3, "distribution": "beckmann"})
    table = tabulate_moments(b, n_mu=4)
    E, _, _ = b.directional_moments(np.minimum(np.exp(table.x), 1.0 - 1e-8))
    assert np.allclose(table.E, E)


CASES = [  # (groove, distribution, alpha, mu)
    ("symmetric", "ggx", 0.49, 0.6),
    ("symmetric", "ggx", 1.0, 0.08),
    ("symmetric", "beckmann", 0.09, 1.0),
    ("symmetric", "beckmann", 1.0, 0.3),
    ("asymmetric", "ggx", 1.0, 0.6),
    ("asymmetric", "ggx", 0.09, 0.1),
    ("asymmetric", "beckmann", 1.0, 0.15),
    ("asymmetric", "beckmann", 0.49, 0.9),
]


@pytest.mark.parametrize("groove,dist,alpha,mu", CASES)
def test_moments_match_sampler_monte_carlo(groove, dist, alpha, mu):
    """E, Vn, Vt by the default deterministic rule against 2^19 samples of lee.sample (gold):
    agreement within 4.5 standard errors (Sidak-safe for 72 comparisons at 1e-3) plus the
    rule's accuracy."""
    mf = Microfacet(dist, alpha)
    kmax = lee.max_bounces(alpha, dist, groove)
    E, Vn, Vt = (x[0] for x in lee.moments(np.array([mu]), mf, GOLD, groove, kmax))
    rng = np.random.default_rng(7)
    wi = np.array([math.sqrt(1 - mu * mu), 0.0, mu])
    n = 1 << 19
    wo, w, _ = lee.sample(wi, rng.random((n, 3 if groove == "symmetric" else 6)), mf, GOLD,
                          groove, kmax)
    for name, est, x in (("E", E, w), ("Vn", Vn, w * wo[:, 2:3]), ("Vt", Vt, w * wo[:, 0:1])):
        mc, se = x.mean(0), x.std(0) / math.sqrt(n)
        tol = 4.5 * se + ACCURACY[groove]
        assert (np.abs(est - mc) <= tol).all(), f"{name}: quadrature {est} MC {mc} se {se}"
