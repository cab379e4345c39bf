"""Walter 2007 rough glass, rendered (issue 3).

1. Single interface (spheres invisible to secondary rays, so a refracted ray meets the world
   unchanged): every roughness, eta 1.5, 1/1.5, 1.0001 and 3, against the numpy reference
   (reflection plus transmission moments over the whole sphere of directions). Under the white
   furnace this is the furnace test: the mean is R + T albedo, which single scattering keeps
   below 1.
2. Solid glass spheres (visible to secondary rays, so neighbours are seen) against Cycles'
   own `dielectric_bsdf` with the same distribution, height-correlated G2 and IOR. They are
   not closed balls: Cycles never hits a point-cloud sphere from inside, so a refracted ray
   leaves unchanged; glass seen from inside is tests/test_render_back_faces.py.
   World light sampling is off: measured, Cycles' rough glass closure under MIS with the world
   returns more than 1 in a white furnace (1.007 at roughness 0.7, single interface), while
   with BSDF sampling alone it matches itself and ours.
3. IOR 1 is a clean pass-through: the sphere vanishes (pixels equal the world behind it).
What this catches: a wrong refraction direction or Jacobian, a wrong lobe choice or weight,
a wrong transmission G2, NaN at TIR or eta = 1.
"""
import functools

import numpy as np
import pytest

pytestmark = pytest.mark.render

bpy = pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")

from addon.lab import grid, harness  # noqa: E402
from addon.lab.grid import SphereSpec  # noqa: E402

ROUGHNESS = (0.05, 0.3, 0.7, 1.0)
SAMPLES = 256


def _rows(etas):
    return [{"distribution": "ggx", "masking": "height_correlated", "sampler": "vndf", "ior": e}
            for e in etas]


# wi outside the denser medium (1.5, 3), inside it (1/1.5: total internal reflection near the
# critical angle), and the nearly index-matched interface; plus Walter's own sampler and G2.
# History: eta 1/1.5 and 3 failed here (-0.0047 +- 0.0006 and -0.0049 +- 0.0005) until the
# moment tables refined themselves around the critical angle (quadrature.tabulate_moments) and
# the refraction lobe's closure normal stopped being bent by Cycles at eta 3 (osl/cycles.h,
# refraction_closure_normal).
# The GGX rows render with the default Light Sampling (Native + Residual); the last GGX row keeps
# the pure stochastic estimator, and the separable GGX row splits with the separable bound.
ROWS = _rows((1.5, 1 / 1.5, 1.0001, 3.0)) + [
    {"distribution": "beckmann", "masking": "separable", "sampler": "dcos", "ior": 1.5},
    {"distribution": "ggx", "masking": "separable", "sampler": "vndf", "ior": 1 / 1.5},
    {"distribution": "ggx", "masking": "height_correlated", "sampler": "vndf", "ior": 1.5,
     "estimator": "stochastic"}]


def specs_for(rows=ROWS):
    return [SphereSpec("walter_glass", {**row, "roughness": r},
                       f"{row['distribution']} {row['masking']} {row['sampler']} "
                       f"{row.get('estimator', '')} eta={row['ior']:.4g} r={r}")
            for row in rows for r in ROUGHNESS]


SPECS = specs_for()


@functools.lru_cache(maxsize=None)
def single_interface_render(env_key):
    env = grid.ENVIRONMENTS[env_key]
    specs = SPECS
    layout, image, _ = harness.render_specs(specs, env, SAMPLES, seed=11, cell_px=40)
    reference = grid.reference_grid_image(layout, specs, env)
    return env, layout, image, reference, specs


def check_against_reference(env, layout, image, reference, specs):
    assert np.isfinite(image).all() and (image >= 0).all()
    bands = grid.band_stats(layout, image, reference)
    z_crit = grid.sidak_z(3 * len(bands))
    bad = [f"{specs[b.sphere].label} mu {b.band} side {b.side}: bias {b.bias} se {b.stderr} ref {b.reference}"
           for b in bands if grid.inconsistent(b, z_crit)]
    assert not bad, f"z_crit {z_crit:.2f}, {env.name}:\n" + "\n".join(bad)


@pytest.mark.parametrize("env_key", ["white", "gradient"])
def test_single_interface_matches_reference(env_key):
    check_against_reference(*single_interface_render(env_key))


@pytest.mark.parametrize("env_key", ["white", "gradient"])
def test_single_interface_within_one_percent(env_key):
    env, layout, image, reference, specs = single_interface_render(env_key)
    failures = grid.relative_bias_failures(layout, image, reference, [s.label for s in specs])
    assert not failures, "\n".join(failures)


def test_single_interface_furnace_loses_energy_only_when_rough():
    env, layout, image, reference, specs = single_interface_render("white")
    spheres = grid.band_stats(layout, image, reference, bands=((0.05, 1.0001),), sides=False)
    for s in spheres:
        spec = specs[s.sphere]
        mean = s.reference[1] + s.bias[1]
        assert mean <= 1.0 + 4 * s.stderr[1], f"{spec.label}: furnace {mean} above 1"
        if spec.values["roughness"] <= 0.05:
            assert abs(mean - 1.0) < 2e-3, f"{spec.label}: smooth glass must conserve ({mean})"


NATIVE_ROWS = ("ggx", "beckmann")


def native_glass(distribution, roughness, ior=1.5):
    alpha = roughness * roughness
    source = ('#include "stdcycles.h"\nshader native(output closure color BSDF = 0) {\n'
              f'    BSDF = dielectric_bsdf(N, vector(0), color(1), color(1), {alpha!r}, '
              f'{alpha!r}, {ior!r}, "{distribution}");\n}}')
    return lambda: harness.osl_material(source, f"native glass {distribution} {roughness}")


@pytest.mark.parametrize("env_key", ["white", "gradient"])
def test_whole_glass_balls_match_cycles_dielectric_bsdf(env_key):
    env = grid.ENVIRONMENTS[env_key]
    specs = [SphereSpec("walter_glass", {"distribution": d, "roughness": r, "ior": 1.5,
                                         "masking": "height_correlated", "sampler": "vndf"},
                        f"{d} r={r}") for d in NATIVE_ROWS for r in ROUGHNESS]
    natives = [native_glass(d, r) for d in NATIVE_ROWS for r in ROUGHNESS]
    common = dict(solid=True, max_bounces=32, light_sampling=False)
    layout, ours, _ = harness.render_specs(specs, env, SAMPLES, seed=21, **common)
    _, native, _ = harness.render_specs(None, env, SAMPLES, seed=22, materials=natives, **common)
    assert np.isfinite(ours).all()
    stats = grid.band_stats(layout, ours, native)
    z_crit = grid.sidak_z(3 * len(stats))
    bad = [f"{specs[s.sphere].label} mu {s.band} side {s.side}: ours - native {s.bias}, se {s.stderr}"
           for s in stats if (np.abs(s.bias) > z_crit * np.maximum(s.stderr, 1e-7)).any()]
    assert not bad, f"z_crit {z_crit:.2f}, {env.name}:\n" + "\n".join(bad)


def test_ior_one_is_a_clean_pass_through():
    specs = [SphereSpec("walter_glass", {"roughness": r, "ior": 1.0}) for r in ROUGHNESS]
    layout, image, _ = harness.render_specs(specs, grid.GRADIENT, 4, seed=5, solid=True)
    index, _, _ = layout.pixel_geometry()
    sphere = image[index >= 0][:, :3]
    # Straight through: every sphere pixel sees the world along -z, like the background.
    assert np.abs(sphere - grid.GRADIENT.radiance(-grid.VIEW)).max() < 1e-6


def test_stress_grid_has_no_nan_inf_or_negative_pixel():
    """IOR from 1/10 to 10, values at and around 1, invalid values (clamped as documented:
    NaN -> 1.5, below 0.01 -> 0.01), roughness 0 to 1 (IOR below 1: total internal reflection;
    back faces are in tests/test_render_back_faces.py); every sphere has grazing views at its
    rim.
    Values reach the shader through linked Value nodes (see test_render_bad_input.py)."""
    iors = (0.1, 0.5, 1 / 1.5, 1 - 1e-6, 1.0, 1 + 1e-6, 1.5, 3.0, 10.0, 0.0, -1.0, float("nan"))
    roughness = (0.0, 1e-4, 0.3, 1.0)
    makers = [lambda ior=ior, r=r, name=f"stress {i} {j}": harness.linked_model_material(
                  "walter_glass", {"ior": ior, "roughness": r}, name)
              for i, ior in enumerate(iors) for j, r in enumerate(roughness)]
    layout, image, _ = harness.render_specs(None, grid.GRADIENT, 16, seed=9, cols=8,
                                            materials=makers, solid=True, max_bounces=32)
    assert np.isfinite(image).all(), "NaN or Inf pixels"
    assert (image >= 0).all(), "negative pixels"


def _lookdev_glass_centre(estimator, seed):
    """The look-dev view of the rough_glass preset (a closed, concave Suzanne: refraction in,
    internal reflections, refraction out) under its sky alone, no clamps: the image centre.
    Suzanne is flat-shaded here: with smooth normals Cycles' own closures (the native part of
    Native + Residual) reject directions below the geometric normal when sampling but not when
    evaluating, while a delta lobe's normal is bent instead, and the two estimators differed
    by 0.5% on this view (-0.00065 +- 0.00013 over three seed pairs, z -5; flat-shaded
    -0.00015 +- 0.00014), before and after the back-face fix alike."""
    from addon import presets
    from addon.catalog import MODELS
    from addon.lab import lookdev

    preset = presets.find("rough_glass")
    values = dict(MODELS[preset.model_id].resolve(preset.params), estimator=estimator)
    scene = lookdev.build_view(lambda: harness.model_material(preset.model_id, values, estimator),
                               96, 72, seed=seed)
    for obj in scene.objects:
        if obj.type == "LIGHT":
            obj.hide_render = True
        elif obj.name == "Suzanne":
            obj.data.shade_flat()
    scene.cycles.sample_clamp_indirect = 0.0
    scene.cycles.blur_glossy = 0.0
    scene.cycles.samples = 256
    image, _ = harness.render(scene)
    return np.asarray(image)[24:56, 28:68, :3]


def test_native_and_stochastic_agree_inside_a_closed_glass_object():
    """Native + Residual and Stochastic are two estimators of one model, so on a closed glass
    object their means agree within noise. What this catches: a native part that is wrong on
    the inside of glass. Cycles' dielectric_bsdf reflection on back faces (eta < 1) rendered
    this view 22% darker than Stochastic (sky alone; 41% with the look-dev's lamps) while every
    sphere-grid test passed (Blender 5.3 inverting the IOR it was handed on back faces:
    docs/cycles-osl.md), so the split is used entering the glass only. Noise: the per-pixel
    differences of the two independent renders."""
    a = _lookdev_glass_centre("light_sampled", 1)
    b = _lookdev_glass_centre("stochastic", 2)
    assert np.isfinite(a).all() and np.isfinite(b).all()
    d = (a - b).mean(axis=-1).ravel()
    se = d.std(ddof=1) / np.sqrt(d.size)
    mean = float(b.mean())
    assert abs(d.mean()) < 4.0 * se, (d.mean(), se, mean)
    assert 4.0 * se < 0.05 * mean, (se, mean)  # power: a 5% difference would show
