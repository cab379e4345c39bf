"""Anisotropic Walter reflection against Cycles' own anisotropic GGX (headless Cycles with OSL).

The sphere-grid reference assumes an isotropic BSDF (its moments put wi in the tangent plane),
so anisotropy is held against an exact native control instead: Cycles'
`microfacet("ggx", N, T, alpha_x, alpha_y, 0, 0)` is height-correlated Smith GGX with F = 1
(docs/light-sampling.md), and `conductor_bsdf` adds the exact conductor Fresnel. The control
shaders build their tangent T with the add-on's own `make_frame` (osl/cycles.h), from the
point-cloud spheres' dPdu, which points every way across a sphere: the tangents are not aligned
with the view. Only the frame is shared; D, G2, the sampling and the Fresnel are Cycles'.

What this catches: swapped or wrongly stretched alpha_x / alpha_y, a tangent the native part and
the residual read differently, a wrong anisotropic Lambda or visible-normal sampler, in both the
stochastic estimator and the light-sampled split. Noise: two independent renders, the band's
standard error combined in quadrature; Sidak-corrected threshold (family-wise 1e-3).
"""
import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon import shaders  # noqa: E402
from addon.catalog import MODELS, alphas  # noqa: E402
from addon.lab import grid, harness  # noqa: E402
from addon.lab.grid import SphereSpec  # noqa: E402

SAMPLES = 256
ANISOTROPY = 0.7
ROUGHNESS = (0.3, 0.6)
GOLD_N = MODELS["walter_reflection"].param("n").default
GOLD_K = MODELS["walter_reflection"].param("k").default
CASES = [  # (our values, native closure body with {ax}, {ay})
    ({"fresnel_type": "none", "estimator": "stochastic", "sampler": "vndf"},
     'microfacet("ggx", N, t, {ax:.9g}, {ay:.9g}, 0.0, 0)'),
    ({"fresnel_type": "none", "estimator": "stochastic", "sampler": "dcos"},
     'microfacet("ggx", N, t, {ax:.9g}, {ay:.9g}, 0.0, 0)'),
    # (Light Sampling would return this very closure: height-correlated GGX gold is Cycles'
    # conductor_bsdf; our own anisotropic conductor maths renders stochastically.)
    ({"fresnel_type": "conductor", "estimator": "stochastic"},
     'conductor_bsdf(N, t, {ax:.9g}, {ay:.9g}, color({n[0]}, {n[1]}, {n[2]}), '
     'color({k[0]}, {k[1]}, {k[2]}), "ggx")'),
    # No native control has separable masking: the split is held against the stochastic
    # estimator of the same BSDF (the next row), which uses no native closure at all.
    ({"fresnel_type": "conductor", "estimator": "light_sampled", "masking": "separable"}, None),
    ({"fresnel_type": "conductor", "estimator": "stochastic", "masking": "separable"}, None),
]


def native_source(body: str, roughness: float) -> str:
    ax, ay = alphas(roughness, ANISOTROPY)
    header = shaders.inline_headers('#include "stdcycles.h"\n#include "cycles.h"\n')
    closure = body.format(ax=ax, ay=ay, n=GOLD_N, k=GOLD_K)
    return (shaders.enum_defines() + shaders.version_defines() + header +
            "\nshader native(output closure color BSDF = 0) {\n"
            f"    vector t, b;\n    make_frame(N, t, b);\n    BSDF = {closure};\n}}\n")


def specs():
    return [SphereSpec("walter_reflection", {**values, "roughness": r, "anisotropy": ANISOTROPY},
                       f"{values} r={r}") for values, _ in CASES for r in ROUGHNESS]


@pytest.fixture(scope="module")
def renders():
    env = grid.ENVIRONMENTS["gradient"]
    _, ours = harness.render_seeds(specs(), env, SAMPLES, (1, 2), cell_px=40)
    makers = [None if body is None else
              (lambda body=body, r=r: harness.osl_material(native_source(body, r), f"native {r}"))
              for _, body in CASES for r in ROUGHNESS]
    layout, native, _ = harness.render_specs([None] * len(makers), env, SAMPLES, seed=3,
                                            cell_px=40, materials=makers)
    return layout, ours, native


def test_anisotropic_ggx_matches_cycles(renders):
    layout, ours, native = renders
    labels = [s.label for s in specs()]
    compared = [i for i, (_, body) in enumerate(CASES) for _ in ROUGHNESS if body is not None]
    bands = [b for b in grid.band_stats(layout, ours[0], native[..., :3]) if b.sphere in
             {i * len(ROUGHNESS) + j for i in set(compared) for j in range(len(ROUGHNESS))}]
    z_crit = grid.sidak_z(3 * len(bands))
    failures = []
    for b in bands:
        # ours - native has the noise of both renders: the band's own scatter already holds
        # both (each pixel of either render has an independent stream).
        if (np.abs(b.bias) > z_crit * b.stderr).any():
            failures.append(f"{labels[b.sphere]} mu {b.band} side {b.side}: ours - native "
                            f"{b.bias}, stderr {b.stderr}")
    assert not failures, f"z_crit {z_crit:.2f}:\n" + "\n".join(failures)
    # Power: a 1% difference in the brightest band would show.
    bright = max(bands, key=lambda b: float(np.max(b.reference)))
    assert float(np.max(bright.stderr)) * z_crit < 0.01 * float(np.max(bright.reference))


def test_separable_split_matches_stochastic(renders):
    """Per band of mu, the mean of the split's sphere equals the stochastic sphere's (same
    geometry, independent estimators): catches a separable bound that is not a lower bound
    under anisotropy (dropped negative weights) or a residual that mis-weights the tangent."""
    layout, ours, _ = renders
    index, _, mu = layout.pixel_geometry()
    split_row, stochastic_row = len(CASES) - 2, len(CASES) - 1
    z_crit = grid.sidak_z(3 * len(grid.MU_BANDS) * len(ROUGHNESS) * len(ours))
    failures = []
    for image in ours:
        for j, r in enumerate(ROUGHNESS):
            for lo, hi in grid.MU_BANDS:
                band = (mu >= lo) & (mu < hi)
                a = image[..., :3][band & (index == split_row * len(ROUGHNESS) + j)]
                b = image[..., :3][band & (index == stochastic_row * len(ROUGHNESS) + j)]
                se = np.sqrt(a.var(0) / len(a) + b.var(0) / len(b))
                diff = a.mean(0) - b.mean(0)
                if (np.abs(diff) > z_crit * se).any():
                    failures.append(f"r={r} mu [{lo}, {hi}): split - stochastic {diff}, se {se}")
    assert not failures, f"z_crit {z_crit:.2f}:\n" + "\n".join(failures)
