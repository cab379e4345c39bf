"""The light-sampled split (addon/lab/reference/split.py, twin of osl/split.h): the native
part c(wi) F f_ggx must stay under the model for every reachable wo, or Cycles would drop the
residual's negative weights and the render would be too dark; the residual sampler must carry
exactly f - c F f_ggx; the native closures must carry our Fresnel; the OSL constants must be
the numpy ones.

What this catches: a masking bound that is not a bound (separable), a residual weight that
forgets a factor, a native Fresnel (Cycles' conductor_bsdf, dielectric_bsdf) that is not ours."""

import numpy as np
import pytest

from addon.lab.reference import fresnel_conductor, fresnel_dielectric, make_bsdf
from addon.lab.reference import split
from addon.lab.reference.microfacet import Microfacet, normalize
import osl_text  # tests/osl_text.py

NS = np.exp(np.linspace(np.log(0.001), np.log(100.0), 41))  # the catalog's range of N
KS = np.concatenate([[0.0, 1e-4, 1e-2], np.exp(np.linspace(np.log(0.05), np.log(100.0), 25))])


LOS = (0.0, 0.05, 0.3, 0.7071, 0.95)
X = np.concatenate([np.linspace(0.0, 1e-3, 2001), np.linspace(1e-3, 0.99, 20001),
                    np.linspace(0.99, 1.0, 20001)])


def _dense_min(F, lo, chunk=1000):
    """min over the grid's x >= lo of F(x) (x along axis 0), in chunks: the whole grid at once
    is 48 million complex values (gigabytes of temporaries, whose first page faults alone took
    20 s of the test here)."""
    x = X[X >= lo]
    return np.min([F(x[i:i + chunk]).min(axis=0) for i in range(0, len(x), chunk)], axis=0)


@pytest.mark.parametrize("lo", LOS)
def test_conductor_fresnel_minimum_is_a_tight_lower_bound(lo):
    """Blender 4.x's native factor (osl/split.h conductor_lower_bound, where Cycles'
    conductor_bsdf is approximate): the search's minimum never exceeds the dense grid's, and is
    tight within its margin where the grid resolves the dip."""
    n, k = np.meshgrid(NS, KS)
    n, k = n.ravel(), k.ravel()
    found = split.conductor_min(n, k, np.full(n.shape, float(lo)))
    dense = _dense_min(lambda x: fresnel_conductor(x[:, None], n, k), lo)
    assert np.all(found <= dense + 1e-15), (n[found > dense], k[found > dense])
    # Tight (within the margin) where the grid resolves the dip right of the critical angle
    # (for n << 1 it is narrower than the grid; the search is not).
    resolved = (n >= 1.0) | (1.0 - split.critical_cos(n) > 0.05)
    assert np.all((found >= dense * (1.0 - 3e-4))[resolved])  # margin 1e-4, grid 5e-5 in x


def _cycles_conductor_fresnel_f32(c, n, k):
    """Cycles' conductor Fresnel (kernel/closure/bsdf_util.h, fresnel_conductor_polarized with
    an ambient IOR of 1), transcribed in float32 as the kernel computes it: the polarised
    reflectances from u^2, v^2 = (sqrt(t1^2 + 4 n^2 k^2) +- t1) / 2, t1 = n^2 - k^2 - sin^2."""
    f = np.float32
    c, n, k = f(c), f(n), f(k)
    t1 = n * n - k * k - (f(1) - c * c)
    t2 = np.sqrt(t1 * t1 + (f(2) * n * k) ** 2)
    u2, v2 = np.maximum(f(0.5) * (t2 + t1), f(0)), np.maximum(f(0.5) * (t2 - t1), f(0))
    u, v = np.sqrt(u2), np.sqrt(v2)
    rs = ((c - u) ** 2 + v2) / ((c + u) ** 2 + v2)
    t3, t4 = (n * n - k * k) * c, f(2) * n * k * c
    rp = ((t3 - u) ** 2 + (t4 - v) ** 2) / ((t3 + u) ** 2 + (t4 + v) ** 2)
    return (f(0.5) * (rs + rp)).astype(float)


def test_cycles_conductor_fresnel_is_the_exact_formula_to_float_rounding():
    """The split hands a conductor's whole single-scattering lobe to Cycles' conductor_bsdf,
    so its Fresnel must be ours: the same closed form, which in float32 stays within 2.5e-4
    (absolute) of the exact double formula over the catalog's range of N and K. It would
    catch a Schlick or F82 approximation (errors of 1e-2 and more at grazing). Excluded: the
    index-matched corner (|N - 1| < 0.2 and K < 0.2, no visible reflection), where both float
    forms, Cycles' and our shader's, cancel catastrophically near grazing."""
    x = np.concatenate([np.linspace(0.0, 1e-3, 101), np.linspace(1e-3, 1.0, 1501)])
    n, k, c = np.meshgrid(NS, KS, x, indexing="ij")
    exact = fresnel_conductor(c, n, k)
    with np.errstate(all="ignore"):
        cycles = _cycles_conductor_fresnel_f32(c, n, k)
    far = ~((np.abs(n - 1.0) < 0.2) & (k < 0.2))
    err = np.abs(cycles - exact)[far]
    assert np.all(np.isfinite(err)) and err.max() < 5e-4, err.max()
    # A Schlick approximation from the same F0 is far off: the check has power.
    F0 = exact[..., -1:]
    schlick = F0 + (1.0 - F0) * (1.0 - c) ** 5
    assert np.abs(schlick - exact)[far].max() > 1e-2


def _cycles_dielectric_fresnel_f32(c, eta):
    """Cycles' dielectric Fresnel (kernel/closure/bsdf_util.h, fresnel_dielectric_polarized),
    transcribed in float32: eta cos_t from Snell's law, total internal reflection where
    eta^2 - sin^2 <= 0, the two polarised reflectances averaged."""
    f = np.float32
    c, eta = f(c), f(eta)
    g2 = eta * eta - (f(1) - c * c)
    g = np.sqrt(np.maximum(g2, f(0)))
    with np.errstate(invalid="ignore", divide="ignore"):  # c = g = 0: taken by the TIR branch
        rs = ((c - g) / (c + g)) ** 2
        rp = ((eta * eta * c - g) / (eta * eta * c + g)) ** 2
    return np.where(g2 <= 0, 1.0, (f(0.5) * (rs + rp)).astype(float))


def test_cycles_dielectric_fresnel_is_the_exact_formula_to_float_rounding():
    """The split hands a dielectric's reflection to Cycles' dielectric_bsdf, so its Fresnel
    must be ours, from outside and from inside (total internal reflection included): within
    1e-4 of the exact double formula over IOR 0.01-100 (the catalog's range) and every angle
    (measured 5.4e-5, just past a critical angle, where F has a square-root cusp and float
    rounding of eta cos_t shows; 5e-7 at the 99.9th percentile), away from grazing incidence on
    an index-matched interface, where both float forms cancel. A Schlick approximation is off by
    more than 1e-2."""
    eta = np.exp(np.linspace(np.log(0.01), np.log(100.0), 201))
    x = np.concatenate([np.linspace(0.0, 1e-3, 101), np.linspace(1e-3, 1.0, 1501)])
    e, c = np.meshgrid(eta, x, indexing="ij")
    exact = fresnel_dielectric(c, e)
    with np.errstate(all="ignore"):
        cycles = _cycles_dielectric_fresnel_f32(c, e)
    far = ~((np.abs(e - 1.0) < 0.05) & (c < 0.05))
    err = np.abs(cycles - exact)[far]
    assert np.all(np.isfinite(err)) and err.max() < 1e-4, err.max()
    F0 = exact[:, -1:]
    schlick = F0 + (1.0 - F0) * (1.0 - c) ** 5
    assert np.abs(schlick - exact)[far & (e > 1)].max() > 1e-2


def random_values(rng, model_id):
    v = dict(roughness=float(rng.uniform(0.04, 1.0)),
             masking=str(rng.choice(["height_correlated", "separable"])))
    if model_id == "walter_reflection":
        v.update(distribution=str(rng.choice(["ggx", "beckmann"])),
                 anisotropy=float(rng.choice([0.0, rng.uniform(0, 1)])),
                 fresnel_type=str(rng.choice(["conductor", "dielectric", "none"])),
                 ior=float(np.exp(rng.uniform(np.log(0.01), np.log(100)))),
                 n=tuple(np.exp(rng.uniform(np.log(0.001), np.log(100), 3))),
                 k=tuple(rng.uniform(0, 10, 3) * rng.choice([0, 1, 10])))
    else:
        v.update(ior=float(np.exp(rng.uniform(np.log(0.05), np.log(20)))))
    return v


@pytest.mark.parametrize("model_id", ["walter_reflection", "walter_glass"])
def test_residual_is_never_negative(model_id):
    rng = np.random.default_rng(11)
    for _ in range(150):
        values = random_values(rng, model_id)
        bsdf = make_bsdf(model_id, values)
        inside_glass = model_id == "walter_glass" and values["ior"] <= 1.0
        assert split.supports_split(bsdf) != inside_glass
        wi = normalize(rng.normal(size=(1500, 3)))
        wi[:, 2] = np.abs(wi[:, 2])
        wo = normalize(rng.normal(size=(1500, 3)))
        wo[:, 2] = np.abs(wo[:, 2])
        f = bsdf.eval(wi, wo)
        r = split.eval_residual(bsdf, wi, wo)
        assert np.all(r >= -1e-12 * np.maximum(f, 1.0)), values


def _cycles_beckmann_lambda_f32(a):
    """Cycles' Beckmann Lambda in float32, from 1 / (alpha tan)^2 as Cycles computes it: 0 where
    alpha^2 tan^2 < 0.39, else Walter 2007 eq. 27's rational form."""
    s = (1.0 / a.astype(np.float32) ** 2).astype(np.float32)
    b = (np.float32(1.0) / np.sqrt(np.maximum(s, np.float32(0.39)))).astype(np.float32)
    lam = ((np.float32(0.396) * b - np.float32(1.259)) * b + np.float32(1.0)) / (
        (np.float32(2.181) * b + np.float32(3.535)) * b)
    return np.where(s < np.float32(0.39), np.float32(0.0), lam).astype(np.float64)


def test_beckmann_native_lambda_and_its_gap():
    """The Beckmann split rests on three facts. (1) lambda_native is what Cycles' Beckmann closure
    evaluates: a float32 transcription of its formula agrees to 1e-5 (relative to 1 + Lambda).
    (2) BECKMANN_LAMBDA_GAP bounds (Lambda - lambda_native) / (1 + Lambda) over a dense scan
    of a = 1 / (alpha tan) (measured 0.003117 at a = 1.34) and is tight (within 3% of it), so
    c = (1 - 2 gap) G_lo never lets c G2_native exceed G_lo G2_hc. (3) The native part is used
    only where Cycles' sampling of it is unbiased within BECKMANN_SAMPLING_TOLERANCE. What it
    would catch: a transcription error, a threshold moved, a gap rounded below the
    approximation's error (then the residual goes negative where Cycles' Lambda is low), or a
    native part handed to Cycles where its sampling is off by 0.3%."""
    a = np.concatenate([np.geomspace(1e-4, 1.0, 20001), np.linspace(1.0, 8.0, 70001)])
    mf = Microfacet("beckmann", 1.0)
    theta = np.arctan(1.0 / a)
    w = np.stack([np.sin(theta), np.zeros_like(a), np.cos(theta)], axis=-1)
    exact, native = mf.lambda_(w), split.lambda_native(mf, w)
    assert np.all(np.abs(native - _cycles_beckmann_lambda_f32(a)) <= 1e-5 * (1.0 + exact))
    gap = (exact - native) / (1.0 + exact)
    assert gap.max() <= split.BECKMANN_LAMBDA_GAP
    assert gap.max() > 0.97 * split.BECKMANN_LAMBDA_GAP - 1e-4, gap.max()
    # (3) Where the native part is used (exact Lambda(wi) <= the tolerance), Cycles' sampling
    # factor (1 + lambda_native) / (1 + Lambda) is within that tolerance of 1; elsewhere it
    # reaches 0.3% (the factor a native part there would have carried).
    kappa = (1.0 + native) / (1.0 + exact) - 1.0
    used = exact <= split.BECKMANN_SAMPLING_TOLERANCE
    assert used.any() and (~used).any()
    assert np.abs(kappa[used]).max() <= split.BECKMANN_SAMPLING_TOLERANCE
    assert np.abs(kappa[~used]).max() > 0.003
    wi = np.stack([np.sin(theta), np.zeros_like(a), np.cos(theta)], axis=-1)
    bsdf = make_bsdf("walter_reflection", {"distribution": "beckmann", "roughness": 1.0})
    assert np.array_equal(split.native_factor(bsdf, wi)[:, 0] > 0.0, used)


def test_split_is_only_offered_where_it_is_exact():
    assert split.supports_split(make_bsdf("walter_reflection", {"distribution": "beckmann"}))
    assert not split.supports_split(make_bsdf("walter_glass", {"distribution": "beckmann"}))
    assert not split.supports_split(make_bsdf("walter_reflection", {"roughness": 0.01}))
    assert not split.supports_split(make_bsdf("cook_torrance", {}))
    assert not split.supports_split(make_bsdf("walter_glass", {"ior": 1.0}))
    assert not split.supports_split(make_bsdf("walter_glass", {"ior": 1 / 1.5}))  # inside
    assert split.supports_split(make_bsdf("walter_reflection", {"roughness": 0.04}))


@pytest.mark.parametrize("values", [
    {"fresnel_type": "conductor", "roughness": 0.5},
    {"fresnel_type": "conductor", "roughness": 0.8, "masking": "separable", "anisotropy": 0.6},
    {"fresnel_type": "dielectric", "ior": 0.4, "roughness": 0.3},
    {"fresnel_type": "conductor", "roughness": 0.5, "distribution": "beckmann"},
    {"fresnel_type": "none", "roughness": 0.3, "distribution": "beckmann", "masking": "separable",
     "anisotropy": 0.5},
])
def test_residual_sampler_carries_f_minus_the_native_part(values):
    """mean residual weight = E - c E_n, the three albedos from independent streams (E_n the
    native closure's, its own Fresnel F_n included)."""
    bsdf = make_bsdf("walter_reflection", values)
    rng = np.random.default_rng(5)
    n = 1 << 17
    for theta in (0.0, 50.0, 80.0):
        t = np.radians(theta)
        wi = np.array([np.sin(t) * 0.8, np.sin(t) * 0.6, np.cos(t)])
        _, w_r = split.sample_residual(bsdf, wi, rng.random((n, 3)))
        _, w_f, _ = bsdf.sample(wi, rng.random((n, 3)))
        wo_g, w_g, _ = split.native_closure(bsdf).sample(wi, rng.random((n, 3)))
        w_g = w_g * split.native_fresnel(bsdf, np.sum(wi * normalize(wi + wo_g), axis=-1))
        assert np.all(w_r >= 0.0)
        c = split.native_weight(bsdf, wi)
        expected = w_f.mean(0) - c * w_g.mean(0)
        se = np.sqrt((w_r.var(0) + w_f.var(0) + (c ** 2) * w_g.var(0)) / n)
        assert np.all(np.abs(w_r.mean(0) - expected) < 5 * se + 1e-9), (theta, w_r.mean(0), expected)


def test_gold_native_share():
    """What the split is for: with height-correlated masking Cycles' conductor_bsdf carries all
    of gold (share 1 at every incidence: no residual to find lamps by chance); with separable
    masking at roughness 0.5 it carries 1 at normal incidence and still over 95% at 60 degrees
    (measured 0.9595, s.e. 2e-5), the residual the rest."""
    for theta in (0.0, 60.0, 85.0):
        t = np.radians(theta)
        wi = np.array([np.sin(t), 0.0, np.cos(t)])
        share, _ = split.albedo_share(make_bsdf("walter_reflection", {"roughness": 0.5}), wi,
                                      n=1 << 14)
        assert np.allclose(share, 1.0, rtol=0, atol=1e-12), (theta, share)
    sep = make_bsdf("walter_reflection", {"roughness": 0.5, "masking": "separable"})
    share, err = split.albedo_share(sep, np.array([np.sin(np.radians(60)), 0.0, 0.5]), n=1 << 15)
    assert np.all(share - 3 * err > 0.95) and np.all(share + 3 * err < 0.97), (share, err)


def test_osl_constants_match_the_twin():
    header = osl_text.source("split.h")

    def define(name):
        return osl_text.define_float(header, name)

    assert define("MFL_ALPHA_SPLIT_MIN") == split.ALPHA_SPLIT_MIN
    assert define("MFL_MIN_SEARCH_STEPS") == split.MIN_SEARCH_STEPS
    assert define("MFL_FRESNEL_MARGIN") == split.FRESNEL_MARGIN
    assert define("MFL_CUSP_K") == split.CUSP_K
    assert define("MFL_BECKMANN_LAMBDA_GAP") == split.BECKMANN_LAMBDA_GAP
    assert define("MFL_BECKMANN_SAMPLING_TOLERANCE") == split.BECKMANN_SAMPLING_TOLERANCE
    assert abs(define("MFL_GOLDEN") - split._GOLDEN) < 1e-15


def test_one_part_per_sample_keeps_the_sum():
    """E[part / probability] = native + residual for the shader's choice of one part."""
    rng = np.random.default_rng(2)
    w_n = rng.random((1000, 3)) * rng.choice([0, 1], (1000, 1))
    w_r = rng.random((1000, 3)) * rng.choice([0, 1, 1e-3], (1000, 1))
    q = split.selection_probability(w_n, w_r)
    assert np.all((q >= 0) & (q <= 1))
    # Both choices carry the same total weight: the choice adds noise only through colour.
    both = (w_n.sum(1) > 0) & (w_r.sum(1) > 0)
    assert np.allclose(w_n.sum(1)[both] / q[both], w_r.sum(1)[both] / (1 - q[both]))
    expected = q[:, None] * np.where(q[:, None] > 0, w_n / np.maximum(q, 1e-300)[:, None], 0) + \
        (1 - q)[:, None] * np.where(q[:, None] < 1, w_r / np.maximum(1 - q, 1e-300)[:, None], 0)
    assert np.allclose(expected, w_n + w_r)


def test_separable_residual_over_its_probability_stays_bounded():
    """Walter reflection picks the residual with probability 1 - c (c = G_lo = G1(wi)): for
    separable masking G2 - c G2_hc = (1 - c) G1(wo) G2_hc exactly, so the residual's weight over
    its probability never exceeds the height-correlated lobe's (no rare heavy sample), and the
    probability is 0 where the residual is (height-correlated masking, normal incidence). It
    would catch a part choice whose residual weight can blow up as c approaches 1."""
    rng = np.random.default_rng(8)
    for roughness in (0.1, 0.5, 1.0):
        sep = make_bsdf("walter_reflection", {"roughness": roughness, "masking": "separable"})
        wi = normalize(rng.normal(size=(4000, 3)))
        wi[:, 2] = np.abs(wi[:, 2])
        wo = normalize(rng.normal(size=(4000, 3)))
        wo[:, 2] = np.abs(wo[:, 2])
        h = normalize(wi + wo)
        mf = sep.mf
        g2, g2_hc = mf.G2(wi, wo, h, "separable"), mf.G2(wi, wo, h, "height_correlated")
        p_r = split.residual_probability(sep, wi)
        assert np.allclose(g2 - (1.0 - p_r) * g2_hc, p_r * mf.G1(wo, h) * g2_hc, atol=1e-12)
        hc = make_bsdf("walter_reflection", {"roughness": roughness})
        assert np.all(split.residual_probability(hc, wi) == 0.0)
    assert split.residual_probability(sep, np.array([0.0, 0.0, 1.0])) == 0.0
