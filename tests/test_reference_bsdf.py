"""Catalog models in numpy: reciprocity, sample weights against eval_cos / pdf, the roughness-0
mirror, and the numerical traps of docs/models.md (no NaN / Inf anywhere)."""
import math

import numpy as np
import pytest

from addon.catalog import MODELS
from addon.lab.reference import make_bsdf
from addon.lab.reference.fresnel import fresnel_conductor, fresnel_dielectric

RNG_SEED = 20240611

MODEL_VALUES = [
    ("cook_torrance", {}),
    ("cook_torrance", {"roughness": 0.2, "fresnel_type": "conductor", "specular": 0.9}),
    ("cook_torrance", {"roughness": 1.0, "ior": 1.0}),
    ("walter_reflection", {}),
    ("walter_reflection", {"distribution": "beckmann", "masking": "separable",
                           "fresnel_type": "dielectric", "roughness": 0.3}),
    ("walter_reflection", {"roughness": 0.7, "anisotropy": 0.8, "fresnel_type": "none"}),
    ("walter_reflection", {"roughness": 0.4, "anisotropy": 0.5, "distribution": "beckmann"}),
    ("walter_reflection", {"roughness": 0.02, "base_color": (0.9, 0.5, 0.2)}),
]


def random_dirs(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def all_sampler_cases():
    for model_id, values in MODEL_VALUES:
        for sampler in MODELS[model_id].param("sampler").items:
            yield model_id, dict(values, sampler=sampler)


@pytest.mark.parametrize("model_id, values", MODEL_VALUES)
def test_reciprocity(model_id, values):
    rng = np.random.default_rng(RNG_SEED)
    bsdf = make_bsdf(model_id, values)
    wi, wo = random_dirs(rng, 20000), random_dirs(rng, 20000)
    # Include near-specular pairs, where the lobe is large.
    wo[:5000] = wi[:5000] * [-1, -1, 1] + 0.05 * rng.normal(size=(5000, 3))
    wo[:5000, 2] = np.abs(wo[:5000, 2])
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    a, b = bsdf.eval(wi, wo), bsdf.eval(wo, wi)
    assert np.all(np.isfinite(a)) and np.all(a >= 0)
    assert np.allclose(a, b, rtol=1e-10, atol=0)


@pytest.mark.parametrize("model_id, values", list(all_sampler_cases()))
def test_weight_is_eval_cos_over_pdf(model_id, values):
    rng = np.random.default_rng(RNG_SEED)
    bsdf = make_bsdf(model_id, values)
    n = 50000
    wi = random_dirs(rng, n)
    wi[:2000, 2] = rng.random(2000) * 1e-3  # grazing incidence too
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo, weight, pdf = bsdf.sample(wi, rng.random((n, 3)))
    for v in (wo, weight, pdf):
        assert np.all(np.isfinite(v))
    assert np.all(weight >= 0) and np.all(pdf >= 0)
    ok = (pdf > 0) & (wo[:, 2] > 0)
    assert ok.mean() > 0.3  # not vacuous (dcos at alpha = 1 loses ~40% below the horizon)
    expected = bsdf.eval_specular(wi[ok], wo[ok]) * wo[ok, 2:3] / pdf[ok, None]
    assert np.allclose(weight[ok], expected, rtol=1e-5, atol=0)
    # Below the horizon the weight is 0.
    assert np.all(weight[wo[:, 2] <= 0] == 0)
    if values["sampler"] == "vndf" and model_id == "walter_reflection":
        assert weight.max() <= np.max(bsdf.tint) + 1e-12  # F G2 / G1 <= 1 for Smith


@pytest.mark.parametrize("model_id", ["cook_torrance", "walter_reflection"])
@pytest.mark.parametrize("fresnel_type", ["dielectric", "conductor"])
def test_roughness_zero_is_a_mirror(model_id, fresnel_type):
    rng = np.random.default_rng(RNG_SEED)
    values = {"roughness": 0.0, "fresnel_type": fresnel_type, "ior": 1.7}
    for sampler in MODELS[model_id].param("sampler").items:
        bsdf = make_bsdf(model_id, dict(values, sampler=sampler))
        assert bsdf.is_delta
        wi = random_dirs(rng, 1000)
        wo, weight, pdf = bsdf.sample(wi, rng.random((1000, 3)))
        assert np.allclose(wo, wi * [-1, -1, 1])
        c = wi[:, 2]
        F = (fresnel_dielectric(c, 1.7)[:, None] * np.ones(3) if fresnel_type == "dielectric"
             else fresnel_conductor(c[:, None], bsdf.n, bsdf.k))
        assert np.allclose(weight, F * bsdf.tint)
        assert np.all(pdf == 1.0)
        # The delta part has no finite value: eval is the diffuse part only.
        f = bsdf.eval(wi, wo)
        assert np.allclose(f, bsdf.diffuse_albedo / np.pi)


@pytest.mark.parametrize("model_id, values", list(all_sampler_cases()))
def test_traps_no_nan(model_id, values):
    """alpha -> 0 (1e-7 and just above), grazing 89.999 degrees, wo.h -> 0 (wo ~ -wi at the
    horizon), normal incidence, wo = wi: everything finite."""
    rng = np.random.default_rng(RNG_SEED)
    g = math.radians(89.999)
    dirs = np.array([[math.sin(g), 0, math.cos(g)], [0, math.sin(g), math.cos(g)],
                     [-math.sin(g), 0, math.cos(g)], [0, 0, 1.0], [1.0, 0, 0], [0.6, 0, 0.8],
                     [0, 0, -1.0]])
    wi = np.repeat(dirs, len(dirs), axis=0)
    wo = np.tile(dirs, (len(dirs), 1))
    for r in (0.0, math.sqrt(1e-7) * 0.999, math.sqrt(1e-7), 1e-3, 0.5, 1.0):
        bsdf = make_bsdf(model_id, dict(values, roughness=r))
        f = bsdf.eval(wi, wo)
        assert np.all(np.isfinite(f)) and np.all(f >= 0), r
        for w in dirs:
            u = rng.random((2000, 3))
            u[:10] = [[0, 0, 0], [1 - 2 ** -53] * 3, [0.5, 0.5, 0.5], [1e-300, 0.25, 0.5],
                      [0.999999, 0.0, 0.0], [0, 1 - 2 ** -53, 0], [0.5, 0, 1], [1e-9, 1e-9, 0],
                      [1 - 1e-12, 0.75, 0.3], [0.3, 0.25, 0.9]]
            out = bsdf.sample(np.broadcast_to(w, u.shape), u)
            for v in out:
                assert np.all(np.isfinite(v)), (r, w)
