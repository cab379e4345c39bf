"""The native branches' fitted corrections (fallback.FITTED) are polynomials fitted in numpy
(addon/lab/fallback_fit.py) and built from Blender's math nodes.

- Lee's, Cook-Torrance's and Heitz's metals carry a correction lobe (fallback.correction). The
  lobe alone, rendered without OSL under the white furnace, has the albedo the numpy polynomial
  predicts, E_1(mu) max(C(r, 1 - mu, F0), 0) (Lee's and Heitz's times the tint; E_1: the
  single-scattering albedo of Cycles' Glossy BSDF, which is the Walter reference's).
- Heitz's glass and Walter's Separable masking scale the native closure
  (fallback.fitted_scale); the scale, emitted as a colour, is max(C, 0) per pixel (1 where the
  variant is not fitted).
Bias per sphere, band of mu and channel against its noise (the per-pixel scatter), |z| < 5
(about 1e-6 two-sided each). Would catch a coefficient wired to the wrong power, Horner's rule
in the wrong order, Facing read as mu, F0 of the wrong index (dielectric, None), the groove,
distribution, Fresnel or masking switch picking the other polynomial, or the tint dropped.
"""
import numpy as np
import pytest

pytestmark = [pytest.mark.render, pytest.mark.compat]

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import fallback  # noqa: E402
from addon.catalog import MODELS  # noqa: E402
from addon.lab import fallback_fit, fallback_scenes, grid, harness  # noqa: E402

GOLD = {"n": (0.156, 0.424, 1.38), "k": (3.602, 2.472, 1.914)}
CASES = [  # every distribution, groove and Fresnel kind, one tinted; Cook-Torrance's two
    ("lee_vgroove", {"roughness": 0.7, "fresnel_type": "conductor", **GOLD}),
    ("lee_vgroove", {"roughness": 0.6, "distribution": "beckmann", "fresnel_type": "dielectric",
                     "ior": 1.52}),
    ("lee_vgroove", {"roughness": 0.9, "groove": "asymmetric", "fresnel_type": "none",
                     "base_color": (0.9, 0.5, 0.2)}),
    ("lee_vgroove", {"roughness": 0.5, "distribution": "beckmann", "groove": "asymmetric",
                     "fresnel_type": "conductor", **GOLD}),
    ("cook_torrance", {"roughness": 0.85, "fresnel_type": "dielectric", "ior": 1.52}),
    ("cook_torrance", {"roughness": 0.9, "fresnel_type": "conductor", **GOLD}),
    ("heitz2016", {"roughness": 0.8, "fresnel_type": "conductor", **GOLD,
                   "base_color": (0.9, 0.7, 0.5)}),
    ("heitz2016", {"roughness": 0.7, "distribution": "beckmann", "fresnel_type": "conductor",
                   **GOLD}),
]
SCALE_CASES = [  # every scaled variant, and a plain one (scale 1)
    ("heitz2016", {"roughness": 0.6, "fresnel_type": "dielectric", "ior": 1.5168}),
    ("heitz2016", {"roughness": 0.9, "distribution": "beckmann", "fresnel_type": "dielectric",
                   "ior": 1.33}),
    ("walter_glass", {"roughness": 0.8, "masking": "separable", "ior": 1.8}),
    ("walter_glass", {"roughness": 0.6, "distribution": "beckmann", "masking": "separable",
                      "ior": 1.5}),
    ("walter_reflection", {"roughness": 0.9, "masking": "separable", "fresnel_type": "conductor",
                           **GOLD}),
    ("walter_reflection", {"roughness": 0.7, "distribution": "beckmann", "masking": "separable",
                           "fresnel_type": "none"}),
    ("walter_reflection", {"roughness": 0.7, "fresnel_type": "dielectric", "ior": 1.5}),
]
CELL, SAMPLES = 40, 64


def predicted(model_id, values, mu):
    v = MODELS[model_id].resolve(values)
    variant = fallback_fit.variant_of(model_id, v)
    tint = np.asarray(v["base_color"]) if model_id in ("lee_vgroove", "heitz2016") else 1.0
    coefficients = fallback.fit()["variants"][variant.key]["coefficients"]
    c = np.maximum(fallback_fit.correction(coefficients, v["roughness"], (1.0 - mu)[:, None],
                                           fallback_fit.f0_of(v)[None, :]), 0.0)
    return fallback_fit.single_albedo(variant.distribution, v["roughness"], mu) * c * tint


def predicted_scale(model_id, values, mu):
    v = MODELS[model_id].resolve(values)
    variant = fallback_fit.variant_of(model_id, v)
    if variant is None:
        return np.ones((len(mu), 3))
    coefficients = fallback.fit()["variants"][variant.key]["coefficients"]
    return np.maximum(fallback_fit.correction(coefficients, v["roughness"], (1.0 - mu)[:, None],
                                              fallback_fit.f0_of(v)[None, :]), 0.0)


def distribution(model_id, values):
    """The distribution as fallback.by_distribution passes it."""
    if model_id == "cook_torrance" or values.get("distribution") == "beckmann":
        return "BECKMANN"
    return "MULTI_GGX" if model_id in ("lee_vgroove", "heitz2016") else "GGX"


def render_against(cases, make, expected):
    """Render `make(model, values, distribution)` for each case without OSL under the white
    furnace; the per-band stats against `expected(model, values, mu)`."""
    materials = [make(m, c, distribution(m, c)) for m, c in cases]
    layout, image, _ = harness.render_specs(None, grid.WHITE, SAMPLES, seed=4, cols=len(cases),
                                            cell_px=CELL, materials=materials, osl=False)
    index, _, mu = layout.pixel_geometry()
    reference = np.zeros(image.shape[:2] + (3,))
    mu_table = np.linspace(0.0, 1.0, 401)
    for i, case in enumerate(cases):
        table = expected(*case, mu_table)
        sel = index == i
        reference[sel] = np.stack([np.interp(mu[sel], mu_table, table[:, ch]) for ch in range(3)],
                                  axis=-1)
    stats = grid.band_stats(layout, image, reference, sides=False)
    assert len(stats) == 3 * len(cases)
    return layout, image, index, stats


def test_the_scale_renders_the_fitted_factor():
    _, image, index, stats = render_against(SCALE_CASES, fallback_scenes.scale_material,
                                            predicted_scale)
    rel = np.array([s.bias / np.maximum(np.abs(s.reference), 1e-6) for s in stats])
    print(f"\n[fallback fit] scale, relative bias per band: "
          f"{np.abs(rel).max(axis=1).round(5).tolist()}")
    # An emission has no sampling noise: each pixel is the polynomial at its own mu (the 0.01 px
    # filter), evaluated in float32 by Cycles' math nodes. A wrong power, switch or F0 moves a
    # band by percents; 0.1% leaves room for float32 and the pixels' spread of mu in a band.
    assert (np.abs(rel) < 1e-3).all(), [(s.sphere, s.band, r.round(5).tolist())
                                        for s, r in zip(stats, rel) if (np.abs(r) >= 1e-3).any()]
    means = [image[index == i][:, :3].mean() for i in range(len(SCALE_CASES))]
    assert all(0.3 < m < 1.5 for m in means), means  # every scale is there, none runs away


def test_the_correction_lobe_renders_the_fitted_albedo():
    layout, image, index, stats = render_against(CASES, fallback_scenes.correction_material,
                                                 predicted)
    z = np.array([s.bias / np.maximum(s.stderr, 1e-9) for s in stats])
    rel = np.array([s.bias / np.maximum(np.abs(s.reference), 1e-6) for s in stats])
    print(f"\n[fallback fit] relative bias per band: {np.abs(rel).max(axis=1).round(4).tolist()}")
    assert (np.abs(z) < 5.0).all(), [(s.sphere, s.band, zz.round(2).tolist())
                                     for s, zz in zip(stats, z) if (np.abs(zz) >= 5).any()]
    means = [image[index == i][:, :3].mean() for i in range(len(CASES))]
    assert min(means) > 0.005, means  # every lobe is there at all
