"""Lee's and Cook-Torrance's native branches carry a correction lobe whose colour is a
polynomial fitted in numpy (addon/lab/fallback_fit.py) and built from Blender's math nodes
(fallback.correction). The lobe alone, rendered without OSL under the white furnace, has the
albedo the numpy polynomial predicts, E_1(mu) max(C(r, 1 - mu, F0), 0) (Lee's times the tint;
E_1: the single-scattering albedo of Cycles' Glossy BSDF, which is the Walter reference's). Bias
per sphere, band of mu and channel against its noise (the per-pixel scatter), |z| < 5 (about
1e-6 two-sided each, 162 comparisons). Would catch a coefficient wired to the wrong power,
Horner's rule in the wrong order, Facing read as mu, F0 of the wrong index (dielectric, None),
the groove, distribution or Fresnel switch picking the other polynomial, or the tint dropped.
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
]
CELL, SAMPLES = 40, 64


def predicted(model_id, values, mu):
    v = MODELS[model_id].resolve(values)
    variant = fallback_fit.variant_of(model_id, v)
    tint = np.asarray(v["base_color"]) if model_id == "lee_vgroove" else 1.0
    coefficients = fallback.fit()["variants"][variant.key]["coefficients"]
    c = np.maximum(fallback_fit.correction(coefficients, v["roughness"], (1.0 - mu)[:, None],
                                           fallback_fit.f0_of(v)[None, :]), 0.0)
    return fallback_fit.single_albedo(variant.distribution, v["roughness"], mu) * c * tint


def test_the_correction_lobe_renders_the_fitted_albedo():
    materials = [fallback_scenes.correction_material(
        m, c, "BECKMANN" if m == "cook_torrance" or c.get("distribution") == "beckmann"
        else "MULTI_GGX") for m, c in CASES]
    layout, image, _ = harness.render_specs(None, grid.WHITE, SAMPLES, seed=4, cols=len(CASES),
                                            cell_px=CELL, materials=materials, osl=False)
    index, _, mu = layout.pixel_geometry()
    reference = np.zeros(image.shape[:2] + (3,))
    mu_table = np.linspace(0.0, 1.0, 401)
    for i, case in enumerate(CASES):
        table = predicted(*case, mu_table)
        sel = index == i
        reference[sel] = np.stack([np.interp(mu[sel], mu_table, table[:, ch]) for ch in range(3)],
                                  axis=-1)
    stats = grid.band_stats(layout, image, reference, sides=False)
    assert len(stats) == 3 * len(CASES)
    z = np.array([s.bias / np.maximum(s.stderr, 1e-9) for s in stats])
    rel = np.array([s.bias / np.maximum(np.abs(s.reference), 1e-6) for s in stats])
    print(f"\n[fallback fit] relative bias per band: {np.abs(rel).max(axis=1).round(4).tolist()}")
    assert (np.abs(z) < 5.0).all(), [(s.sphere, s.band, zz.round(2).tolist())
                                     for s, zz in zip(stats, z) if (np.abs(zz) >= 5).any()]
    means = [image[index == i][:, :3].mean() for i in range(len(CASES))]
    assert min(means) > 0.005, means  # every lobe is there at all
