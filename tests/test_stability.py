"""Numerical stability on stiff and extreme inputs (addon/lab/stability.py), fast subsets of what
`make report` runs in full.

numpy: every catalog model with a numpy twin, evaluated and sampled over extreme inputs (a
strided subset of the full sweep's parameter combinations, every stiff direction and uniform):
no NaN, no Inf, no negative value, no non-unit sampled direction, no Monte Carlo albedo above
1 beyond its noise. OSL: the quick stress grid rendered through the shaders (values through
linked Value nodes; every rim a grazing view): no NaN, Inf or negative pixel.
"""
import math

import numpy as np
import pytest

from addon.lab import stability
from addon.catalog import MODELS


@pytest.fixture(scope="module")
def sweep():
    return stability.numpy_sweep(stride=25, albedo_samples=256, combo_seconds=3.0,
                                 model_seconds=8.0)


def test_sweep_covers_every_model_and_enough_cases(sweep):
    assert sweep["_total"].cases >= 100_000
    for model_id in MODELS:
        rec = sweep[model_id]
        assert rec.skipped or rec.combos > 0, model_id
    # Every enum item and the stiff values appear in the full parameter lists.
    combos = stability.parameter_combos("walter_reflection")
    assert {c["sampler"] for c in combos} == set(MODELS["walter_reflection"].param("sampler").items)
    assert any(c.get("ior") == 1.0 + 1e-6 for c in combos)
    assert any(isinstance(c["roughness"], float) and math.isnan(c["roughness"]) for c in combos)
    wi = stability.incident_directions()
    assert np.isclose(wi[:, 2].min(), 0.0) and (wi[:, 2] > 0).sum() >= len(wi) - 2


def test_numpy_sweep_has_no_nan_inf_negative_or_energy_gain(sweep):
    tot = sweep["_total"]
    counts = {k: getattr(tot, k) for k in ("nan", "inf", "negative", "non_unit", "energy",
                                          "errors")}
    assert not any(counts.values()), f"{counts}:\n" + "\n".join(tot.examples)


def test_energy_check_would_see_a_gain():
    """The albedo test is not blind: the same sweep over a BSDF whose sample weights are 3%
    above the reference's flags energy violations (and nothing else)."""
    from addon.lab.reference import make_bsdf

    class Brighter:
        def __init__(self, bsdf):
            self.bsdf = bsdf
            self.diffuse_albedo = bsdf.diffuse_albedo

        def eval(self, wi, wo):
            return self.bsdf.eval(wi, wo)

        def eval_cos(self, wi, wo):
            return self.bsdf.eval_cos(wi, wo)

        def sample(self, wi, u):
            wo, w, pdf = self.bsdf.sample(wi, u)
            return wo, 1.03 * w, pdf

    values = {"fresnel_type": "none", "roughness": 0.2}
    result = stability.numpy_sweep(
        models=["walter_reflection"], roughness=(0.2,), albedo_samples=4096, stride=7,
        factory=lambda m, v: Brighter(make_bsdf(m, {**v, **values})))
    rec = result["walter_reflection"]
    assert rec.energy > 0 and rec.nan == rec.inf == rec.negative == 0, rec.examples


@pytest.mark.render
@pytest.mark.parametrize("env_key", ["gradient", "sun"])
def test_osl_stress_grid_has_no_bad_pixel(env_key):
    """Under the sun lamp the extreme values also go through the residual aimed at it, its
    controls and the control variate (the lamp is handed over and predicted), the code paths
    the gradient world alone never takes. The sun's grid holds the cases that may read the lamp
    (the light-sampled estimator, above the mirror's roughness: stability.stress_cases) and
    leaves the others to the gradient's. The gradient's values are constants (folded into each
    case's compiled shader), the sun's are read per object as the shader runs (a third of the
    shaders to compile: 33 for 110 cases): both ways a value can reach the shader."""
    pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")
    from addon.lab.report.scenes import add_sun

    sun = env_key == "sun"
    result = stability.osl_stress_grid(env_key, quick=True, cell_px=12,
                                       sun=add_sun if sun else None,
                                       lamp_paths=sun, per_object=sun)
    assert result.spheres >= 40 and result.pixels > 1000
    assert (result.nan, result.inf, result.negative) == (0, 0, 0), result.bad
