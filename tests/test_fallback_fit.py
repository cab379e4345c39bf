"""The fitted corrections of the native branches (addon/fallback_fit.json, made by
`make fallback-fit` from addon/lab/fallback_fit.py; fallback.FITTED says which) are current and
do what they say.

- They match the catalog (each fitted model's distributions and enum items, one polynomial
  each) and the presets they were trained on: catches a fit that drifted from the catalog or
  the presets.
- The errors stated for each fitted preset (albedo, and the lobe's mean direction) are what the
  numpy reference and the numpy model of Cycles' closures give today with its coefficients (to
  1e-6; Heitz 2016's Monte Carlo moments are seeded by their inputs): catches a change to a
  model's reference, to the native branch's model or to the presets after which the fit was not
  run again.
- At a roughness it was not trained on (0.65), for every training material, it lowers the
  mean and the worst relative albedo error of every variant.
No bpy: tests/test_render_fallback_fit.py renders the lobes and scales built from these
coefficients.
"""
import numpy as np
import pytest

from addon import fallback
from addon.lab import fallback_fit

DATA = fallback.fit()


def test_the_fit_matches_the_catalog_and_the_presets():
    assert DATA["catalog"] == fallback_fit.catalog_items()
    assert sorted(DATA["variants"]) == sorted(v.key for v in fallback_fit.VARIANTS)
    assert [tuple(t) for t in DATA["terms"]] == fallback_fit.TERMS
    assert all(len(v["coefficients"]) == len(DATA["terms"]) for v in DATA["variants"].values())
    assert DATA["training"]["materials"] == {m: fallback_fit.training_materials(m)
                                             for m in fallback_fit.catalog_items()}
    assert sorted(DATA["presets"]) == [p.id for p in fallback_fit.measured_presets()]


@pytest.mark.parametrize("preset", [p.id for p in fallback_fit.measured_presets()])
def test_the_stated_preset_errors_are_reproduced(preset):
    p = next(p for p in fallback_fit.measured_presets() if p.id == preset)
    got = fallback_fit.preset_errors(p, DATA)
    stated = DATA["presets"][preset]
    assert set(got) == set(stated)
    for name in got:
        for stat in ("worst", "mean"):
            assert got[name][stat] == pytest.approx(stated[name][stat], rel=1e-6, abs=1e-9), \
                f"{preset} {name} {stat}: run `make fallback-fit`"


@pytest.mark.parametrize("variant", fallback_fit.VARIANTS, ids=lambda v: v.key)
def test_the_correction_lowers_the_error_of_every_variant(variant):
    c = DATA["variants"][variant.key]["coefficients"]
    s = fallback_fit.stack([fallback_fit.samples(variant, 0.65, m)
                            for m in fallback_fit.variant_materials(variant)])
    before = fallback_fit.summary(fallback_fit.errors(s))
    after = fallback_fit.summary(fallback_fit.errors(s, c))
    print(f"\n[fallback fit] {variant.key}: worst {before['worst']:.3f} -> {after['worst']:.3f}, "
          f"mean {before['mean']:.4f} -> {after['mean']:.4f}")
    assert after["mean"] < before["mean"] and after["worst"] < before["worst"]


def test_the_polynomial_is_the_sum_of_its_terms():
    """fallback_fit.correction, the numpy twin of the nodes' Horner evaluation, against the
    terms written out."""
    rng = np.random.default_rng(0)
    c = rng.normal(size=len(fallback_fit.TERMS))
    r, x, f0 = 0.37, 0.81, 0.44
    expected = sum(ci * r ** i * x ** j * f0 ** k for ci, (i, j, k) in zip(c, fallback_fit.TERMS))
    assert fallback_fit.correction(c, r, x, f0) == pytest.approx(expected, rel=1e-12)
