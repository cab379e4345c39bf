"""The sphere-grid suites: each model family's spheres, sample count and numpy reference, as
tests/test_render_grids.py renders them under the white furnace and the gradient and holds
them to their reference with one body of tests. The suites' own tests (furnaces, Max Bounces,
lamps) stay in tests/test_render_lee.py and tests/test_render_heitz2016.py.

A suite's reference is a list of moment tables per sphere (quadrature, or the Heitz 2016 walk's
Monte Carlo tables with their standard errors, which join the noise), and an accuracy floor
per sphere (what limits the near-mirror spheres and the coarser asymmetric Lee rule).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Callable

import numpy as np

from addon.catalog import MODELS
from addon.lab import grid, table_cache
from addon.lab.grid import SphereSpec
from addon.lab.reference import make_bsdf
from addon.lab.reference.heitz2016 import moment_tables, table_nodes


@dataclass(frozen=True)
class Suite:
    name: str
    specs: list
    samples: int
    cell_px: int
    compute_tables: Callable[[], tuple]  # (tables, their standard errors or None)
    floors: Callable[[], list] = lambda: None  # per sphere; None: grid.REFERENCE_ACCURACY

    @property
    def labels(self) -> list:
        return [s.label for s in self.specs]

    def tables(self) -> tuple:
        return _tables(self.name)


ROUGHNESS = (0.05, 0.3, 0.7, 1.0)

# -- Cook-Torrance and Walter reflection, every sampler and estimator --------------------------
GOLD = {"fresnel_type": "conductor"}  # catalog default n, k: gold
GLASS = {"fresnel_type": "dielectric", "ior": 1.5}
_MODEL_ROWS = [
    ("cook_torrance", {"sampler": "dcos", "specular": 1.0, **GOLD}),
    ("cook_torrance", {"sampler": "vndf", "specular": 0.6, "base_color": (0.1, 0.4, 0.8),
                       **GLASS}),
    ("cook_torrance", {"sampler": "vcavity", "specular": 0.8, "base_color": (0.9, 0.2, 0.1),
                       **GOLD}),
]
for _distribution, _fresnel in (("ggx", GOLD),
                                ("beckmann", {"fresnel_type": "dielectric", "ior": 2.5})):
    for _masking in ("height_correlated", "separable"):
        for _sampler in ("dcos", "vndf"):
            _MODEL_ROWS.append(("walter_reflection", {"distribution": _distribution,
                                                      "masking": _masking,
                                                      "sampler": _sampler, **_fresnel}))
# GGX rows above render with the default Light Sampling (Native + Residual), which for
# height-correlated masking is Cycles' conductor_bsdf whatever the sampler; the pure stochastic
# estimator keeps two rows of its own (our own GGX maths; D cos at roughness 1 with
# height-correlated masking is too noisy at these samples for the 1% power check).
_STOCHASTIC_ROWS = [("walter_reflection", {"distribution": "ggx", "masking": masking,
                                           "sampler": sampler, "estimator": "stochastic",
                                           **GOLD})
                    for masking, sampler in (("height_correlated", "vndf"), ("separable", "dcos"))]


def _model_specs(rows):
    return [SphereSpec(model, {**values, "roughness": r},
                       f"{model} {values.get('distribution', '')} "
                       f"{values.get('masking', '')} {values['sampler']} "
                       f"{values.get('estimator', '')} r={r}")
            for model, values in rows for r in ROUGHNESS]


def _models_suite(name, rows, samples):
    specs = _model_specs(rows)
    return Suite(name, specs, samples=samples, cell_px=40,  # ~1000 px per sphere
                 compute_tables=lambda: (grid.reference_tables(specs), None))


# The two stochastic rows render apart at 256 samples, the rest at 192. Power use, measured under
# the gradient (the worst environment): the stochastic rows' worst 0.86 (separable D cos at
# roughness 1; 0.97 in the shared grid, on other pixels); the others' worst 0.88 at 192 samples
# (Beckmann D cos at roughness 1; Cook-Torrance's and Beckmann's D cos 0.75-0.77 at 256).
MODELS_SUITE = _models_suite("models", _MODEL_ROWS, samples=192)
MODELS_STOCHASTIC = _models_suite("models-stochastic", _STOCHASTIC_ROWS, samples=256)

# -- Lee 2018 V-grooves: reference from LeeBRDF's deterministic directional moments ------------
# Accuracy of the reference per groove kind (the default quadrature rules of lee.moments;
# measured by addon/lab/bench_lee.py:moments_accuracy, floors of
# tests/test_reference_lee_moments.py). Symmetric grooves meet grid.REFERENCE_ACCURACY's order;
# the asymmetric rule is a 3D low-discrepancy rule, coarser at the test's time budget.
LEE_ACCURACY = {"symmetric": 2e-4, "asymmetric": 1.5e-3}


def lee_floor(spec) -> float:
    return max(grid.REFERENCE_ACCURACY, LEE_ACCURACY[spec.values["groove"]])


_LEE_SPECS = [SphereSpec("lee_vgroove", {"groove": g, "distribution": d,
                                         "fresnel_type": "conductor", "roughness": r},
                         f"lee {g} {d} r={r}")
              for g in ("symmetric", "asymmetric") for d in ("ggx", "beckmann") for r in ROUGHNESS]

# 128 samples: the power check uses at most 0.73 of its margin (asymmetric GGX at roughness 1
# under the gradient; 0.54 at 256 samples, measured).
LEE = Suite("lee", _LEE_SPECS, samples=128, cell_px=32,
            compute_tables=lambda: (grid.reference_tables(_LEE_SPECS), None),
            floors=lambda: [lee_floor(s) for s in _LEE_SPECS])

# -- Heitz 2016 random walk: reference from the twin's Monte Carlo moment tables ---------------
HEITZ_N_MU = 24
HEITZ_WALKS = 200_000
_HEITZ_ROWS = [({"fresnel_type": "conductor", "distribution": d}, (0.3, 0.7, 1.0))
               for d in ("ggx", "beckmann")]
_HEITZ_ROWS += [({"fresnel_type": "dielectric", "distribution": "ggx", "ior": e},
                 (0.3, 0.7, 1.0)) for e in (1.5, 1 / 1.5)]
_HEITZ_ROWS += [({"fresnel_type": "dielectric", "distribution": "beckmann", "ior": 1.5},
                 (0.3, 1.0))]
# The GGX rows above render with the default Light Sampling (Native + Residual: the first order
# natively); the pure stochastic walk keeps rows of its own (Beckmann is stochastic anyway).
_HEITZ_ROWS += [({"fresnel_type": f, "distribution": "ggx", "ior": 1.5,
                  "estimator": "stochastic"}, (0.3, 1.0)) for f in ("conductor", "dielectric")]
_HEITZ_SPECS = [SphereSpec("heitz2016", {**values, "roughness": r},
                           f"heitz {values['fresnel_type']} {values['distribution']} "
                           f"eta={values.get('ior', 0):.3g} {values.get('estimator', '')} r={r}")
                for values, rs in _HEITZ_ROWS for r in rs]


def _heitz_nodes(values):
    """Glass seen from the denser side: even nodes every 0.025 in mu from 0.3 up (its moments
    bend around the critical angle, mu 0.75 at eta 1/1.5; the 24 log-spaced nodes missed that
    bend at roughness 0.3 by up to 0.026); else the 24 log-spaced nodes."""
    if values["fresnel_type"] == "dielectric" and values.get("ior", 1.5) < 1.0:
        return table_nodes(HEITZ_N_MU, uniform_from=0.3)
    return table_nodes(HEITZ_N_MU)


def _heitz_key(spec):
    """The estimator does not change the BSDF: one table per walk."""
    values = MODELS[spec.model_id].resolve(spec.values)
    return repr(sorted((k, v) for k, v in values.items() if k != "estimator"))


def _heitz_walk_tables():
    """(table, its standard errors) per sphere, flat: over a minute of walks."""
    rng = np.random.default_rng(2016)
    cache = {}
    for s in _HEITZ_SPECS:
        if _heitz_key(s) not in cache:
            cache[_heitz_key(s)] = moment_tables(make_bsdf(s.model_id, s.values),
                                                 _heitz_nodes(s.values), HEITZ_WALKS, rng)
    return [t for s in _HEITZ_SPECS for t in cache[_heitz_key(s)]]


def _heitz_tables():
    """Kept on disk between runs (addon/lab/table_cache.py)."""
    inputs = ([(_heitz_key(s), _heitz_nodes(s.values).tolist()) for s in _HEITZ_SPECS],
              HEITZ_WALKS, 2016)
    flat = table_cache.tables("heitz2016_grid", inputs, _heitz_walk_tables)
    return flat[0::2], flat[1::2]


HEITZ = Suite("heitz2016", _HEITZ_SPECS, samples=256, cell_px=40, compute_tables=_heitz_tables)

SUITES = {s.name: s for s in (MODELS_SUITE, MODELS_STOCHASTIC, LEE, HEITZ)}


@functools.lru_cache(maxsize=None)
def _tables(name):
    return SUITES[name].compute_tables()
