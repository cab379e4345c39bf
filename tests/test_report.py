"""`make report` in its smoke mode: the page, the plots and the numbers exist and make sense.

The smoke run (scripts/report.py --smoke: two sample counts, one tiny grid per model variant
without the Stochastic rows that have a Native + Residual twin, the gradient environment, a
small stability sweep, no OSL stress grid, the Lee section at tiny settings) runs in a fresh
process, so it also checks the command line. The helpers that turn curves into the table are
tested on synthetic curves whose answer is known.
"""
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from addon.lab import report

ROOT = Path(__file__).resolve().parent.parent
NUMBER = r"[0-9]+(?:\.[0-9]+)?(?:e[-+]?[0-9]+)?"


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    pytest.importorskip("bpy", reason="bpy is part of the pinned test environment")
    out = tmp_path_factory.mktemp("report")
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "report.py"), "--smoke",
                           "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return out, proc.stdout


@pytest.mark.render
def test_smoke_page_states_machine_versions_and_numbers(smoke):
    out, log = smoke
    page = (out / "report.md").read_text()
    # Progress was printed as it ran: what, i/n, elapsed.
    assert re.search(r"\[report +[0-9.]+ s\] \(\d+/\d+\) gradient: ", log), log[-2000:]
    assert re.search(r"Generated .* on \d{4}-\d\d-\d\d \d\d:\d\d", page)
    assert re.search(r"Machine: .+, \d+ logical cores", page)
    assert re.search(r"Blender \(bpy\) \d+\.\d+", page) and re.search(r"numpy \d+\.\d+", page)
    assert "OptiX" in page  # run, or the plain statement that it was not
    # The time table has a time for every row and a ratio for every row with a native closure.
    time_table = page.split("Time to 1% relative RMSE")[1].split("Relative RMSE at")[0]
    rows = [line for line in time_table.splitlines() if line.startswith("| Walter GGX F=1 /")]
    assert len(rows) >= 3, page
    for line in rows:
        assert re.search(NUMBER + r" m?s", line), line
    assert any(re.search(r"\| " + NUMBER + r" \|$", line) for line in rows), rows
    # Stability counts are numbers.
    assert re.search(r"\| \*\*all\*\* \| \d+ \| [0-9,]+ \| \*\*\d+\*\* \| \*\*\d+\*\* \|", page)
    for table in ("| order N |", "| sphere, sampler | max pixel |", "var / max at"):
        assert table in page
    # Specialization: both variants timed, memory read from Cycles, unused groups removed
    # (groups in the file without / with: every model's, then only the one used).
    from addon.catalog import MODELS
    spec = [line for line in page.splitlines() if line.startswith("| gold (Walter GGX) |")]
    assert len(spec) == 1 and re.search(rf"\| {NUMBER} s \| {NUMBER} s \| {NUMBER} \| "
                                        rf"{NUMBER} \| {NUMBER} \| {len(MODELS)} / 1 \|$", spec[0]), spec


@pytest.mark.render
def test_smoke_results_hold_finite_decreasing_errors(smoke):
    out, _ = smoke
    results = json.loads((out / "results.json").read_text())
    series = results["convergence"]["gradient"]
    assert len(series) >= 8
    falling = 0
    for key, pts in series.items():
        (s0, t0, e0), (s1, t1, e1) = pts[0], pts[-1]
        assert s0 < s1 and t0 > 0 and t1 > 0, key
        assert 0 < e1 < 5 and math.isfinite(e0), (key, pts)
        falling += e1 < e0
    assert falling >= len(series) - 1, series  # 8x the samples: the error falls
    assert all(isinstance(t["seconds"], (int, float)) or t["how"] == "floor"
               for t in results["time_to_target"])
    costs = results["reference_cost"]
    assert costs[-1]["max_abs"] == 0 and costs[0]["max_abs"] > 0
    study = results["sampler_study"]["walter_reflection"]
    # The seed's claim at grazing incidence: visible normals weigh at most 1, D cos does not.
    assert max(study["vndf r=0.3"]["max"]) <= 1 + 1e-9
    assert study["dcos r=0.3"]["max"][-1] > 1.5


@pytest.mark.render
def test_smoke_plots_are_pictures_with_content(smoke):
    import matplotlib.image as mpimg

    out, _ = smoke
    for name in ("rmse_vs_time.png", "sampler_weights.png", "fireflies.png", "grids.png",
                 "lee_furnace.png"):
        path = out / name
        assert path.exists() and path.stat().st_size > 5000, name
        img = mpimg.imread(path)
        assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100, name
        assert img[..., :3].std() > 0.05, f"{name} looks blank"


LEE_ROWS = ("Lee symmetric GGX", "Lee asymmetric GGX", "Lee symmetric Beckmann")
SINGLE_ROWS = ("Walter GGX (single)", "Cook-Torrance (single)")


@pytest.mark.render
def test_smoke_lee_section_has_its_four_parts(smoke):
    out, log = smoke
    page = (out / "report.md").read_text()
    assert "## 5. Lee 2018 (V-grooves)" in page, page[-3000:]
    section = page.split("## 5. Lee 2018 (V-grooves)")[1].split("## How to regenerate")[0]
    assert "Lee section, " not in page, "a Lee part failed (see the page's notes)"
    for heading in ("### White furnace", "### Render cost per sample",
                    "### Closed form against the brute-force tracer",
                    "### Accuracy of the moment rules"):
        assert heading in section, heading
    assert "![Lee white furnace](lee_furnace.png)" in section
    # Settings are stated; the furnace table has one row per model with a mean +- noise per alpha.
    assert re.search(r"\d+ samples per pixel, \d+ px cells", section)
    for label in LEE_ROWS + SINGLE_ROWS + ("Cycles multi-GGX",):
        row = [line for line in section.splitlines() if line.startswith(f"| {label} |")]
        assert row and len(re.findall(NUMBER + " ± " + NUMBER, row[0])) == 4, (label, row)
    cost = [line for line in section.split("### Render cost")[1].split("###")[0].splitlines()
            if line.startswith("| Lee ")]
    assert len(cost) == 3 and all(re.search(r"\*\*-?" + NUMBER + r"\*\*", c) for c in cost), cost
    assert re.search(r"\[report +[0-9.]+ s\] \(\d+/\d+\) Lee shader cost: ", log), log[-2000:]


@pytest.mark.render
def test_smoke_lee_furnace_keeps_energy_and_numbers_are_finite(smoke):
    out, _ = smoke
    lee = json.loads((out / "results.json").read_text())["lee"]
    f = lee["furnace"]
    assert f["alphas"] == [0.25, 0.5, 0.75, 1.0]
    means, noise = f["means"], f["noise"]
    for label in LEE_ROWS + SINGLE_ROWS + ("Cycles multi-GGX",):
        assert len(means[label]) == 4 and len(noise[label]) == 4, label
        assert all(math.isfinite(m) and 0 < m < 1.5 for m in means[label]), (label, means[label])
        assert all(math.isfinite(s) and s >= 0 for s in noise[label]), (label, noise[label])
    for label in LEE_ROWS:
        # Within its stated noise of 1 (zero: with F = 1 every sample weighs 1) plus float32.
        for m, s in zip(means[label], noise[label]):
            assert abs(m - 1.0) <= 3 * s + 1e-4, (label, means[label], noise[label])
        # Above single scattering at alpha = 1, well beyond both noises.
        for single in SINGLE_ROWS:
            gap = means[label][-1] - means[single][-1]
            assert gap > 3 * (noise[label][-1] + noise[single][-1]) and gap > 0.1, (label, single)
    # Cycles' multi-GGX recovers most of what single-scattering GGX loses.
    walter, multi = means["Walter GGX (single)"][-1], means["Cycles multi-GGX"][-1]
    assert multi - walter > 0.5 * (1 - walter), (multi, walter)


@pytest.mark.render
def test_smoke_lee_cost_tracer_and_moments_are_finite(smoke):
    out, _ = smoke
    lee = json.loads((out / "results.json").read_text())["lee"]
    cost = {k: v for k, v in lee["cost"].items() if not k.startswith("_")}
    lo, hi = lee["cost"]["_setup"]["samples"]
    assert len(cost) == 4 and lo < hi
    for k, v in cost.items():  # ratios from one run, side by side; no assertion on speed
        for key in ("ms_per_sample", "ratio_to_cook_torrance", "ratio_min", "ratio_max"):
            assert isinstance(v[key], float) and math.isfinite(v[key]), (k, key, v)
    assert cost["Cook-Torrance (V-cavity sampler)"]["ratio_to_cook_torrance"] == 1.0
    assert lee["tracer"]
    for k, v in lee["tracer"].items():
        assert 0 < v["albedo_G"] < 1 and v["closed_form_order"] is not None, (k, v)
        for key in ("closed_form_s", "sampler_s", "tracer_s", "tracer_over_closed_form"):
            assert isinstance(v[key], float) and math.isfinite(v[key]) and v[key] > 0, (k, key)
        # The brute-force tracer agrees with the closed form (a 5-sigma statistical check).
        assert abs(v["tracer_z"]) < 5, (k, v)
        assert all(q["error"] < 0.05 for q in v["quadrature"]), v["quadrature"]
    assert lee["moments"]
    for k, v in lee["moments"].items():  # the default rules' documented accuracy (< 1e-3)
        assert math.isfinite(v["max_abs_error"]) and 0 <= v["max_abs_error"] < 1e-3, (k, v)
        assert v["seconds_per_mu"] > 0


def test_bench_lee_markdown_skips_settings_and_lists():
    from addon.lab.bench_lee import furnace_markdown, markdown

    table = markdown({"a": {"x": 1.5, "y": None, "pts": [1, 2]}, "_setup": {"samples": [1, 2]}})
    assert table.splitlines() == ["| case | x | y |", "|---|---|---|", "| a | 1.5 | - |"]
    rows = furnace_markdown((0.5, 1.0), {"m": [1.0, 0.5]}, {"m": [0.0, 0.01]}).splitlines()
    assert rows[-1] == "| m | 1.0000 ± 0 | 0.5000 ± 0.01 |"


def test_time_to_target_interpolates_on_log_log():
    # e = c / sqrt(t): the crossing of 1% is exact on the log-log line.
    t = np.array([0.01, 0.04, 0.16, 0.64])
    e = 0.04 * np.sqrt(0.01 / t)  # 4%, 2%, 1%, 0.5%
    pts = [(i, ti, ei) for i, (ti, ei) in enumerate(zip(t, e))]
    sec, how = report.time_to_target(pts[:2] + [(2, 0.1, 0.0126)] + pts[3:])
    assert how == "interpolated" and 0.1 < sec < 0.64
    sec, how = report.time_to_target(pts[:2])  # 2% at 0.04 s -> 1% at 0.16 s along 1/sqrt(t)
    assert how == "extrapolated" and sec == pytest.approx(0.16)
    floor = [(1, 0.01, 0.05), (4, 0.04, 0.03), (16, 0.16, 0.029), (64, 0.64, 0.0288)]
    assert report.time_to_target(floor) == (float("inf"), "floor")
    assert report.time_to_target([(1, 0.5, 0.005)]) == (0.5, "first")


def test_every_model_runs_under_every_lamp_heitz_held_to_itself_there():
    # Would catch a model left out of a lamp's time-to-1% table again (Heitz 2016 was: its
    # numpy evaluation is a walk), or a walk's noisy evaluation used as a lamp's reference.
    from addon.lab.report import config, convergence, rows as report_rows

    notes = []
    rows = report_rows.build_rows(notes)
    per_env = convergence.rows_per_env(config.config("full"), rows)
    heitz = [r for r in rows if r.model_id == "heitz2016"]
    assert heitz and any(r.variant == heitz[0].variant and r.sampler == "native" for r in rows)
    for env, env_rows in per_env.items():
        assert [r.key for r in rows if r not in env_rows] == [], env
        lamp = env in config.LAMP_ENVS
        for r in heitz:
            assert report_rows.self_referenced(r, env) == lamp, (env, r.key)
            specs = report_rows.specs_for(r, (0.5,), env)
            assert (specs == [None]) == lamp, (env, r.key)
    assert not any(report_rows.self_referenced(r, "point") for r in rows
                   if r.model_id in ("walter_reflection", "cook_torrance", "lee_vgroove"))


def test_sun_cone_rule_integrates_the_solid_angle_and_a_cosine():
    half = math.radians(report.SUN_ANGLE_DEG) / 2
    dirs, w = report.sun_cone_nodes(half, 8, 16)
    assert w.sum() == pytest.approx(2 * math.pi * (1 - math.cos(half)), rel=1e-12)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    d = report.sun_unit()
    # integral of (w.d)^2 over the cone = 2 pi (1 - cos^3) / 3
    assert (w * (dirs @ d) ** 2).sum() == pytest.approx(2 * math.pi * (1 - math.cos(half) ** 3) / 3,
                                                        rel=1e-10)


@pytest.mark.render
def test_smoke_comparisons_keep_energy_where_the_models_do(smoke):
    """The seed's figures 21-23 in numpy: in the white furnace Lee's grooves (both shapes) and
    Heitz 2016's walk keep all the energy, single scattering loses some at roughness 0.5; for
    gold every model reflects less than in the furnace."""
    out, _ = smoke
    curves = json.loads((out / "results.json").read_text())["comparisons"]["curves"]
    by = {(c["fresnel"], c["model"]): np.asarray(c["albedo"]) for c in curves}
    for model in ("Lee symmetric", "Lee asymmetric", "Heitz 2016"):
        np.testing.assert_allclose(by[("none", model)], 1.0, atol=1e-6)
    for model in ("Walter single (GGX)", "Cook-Torrance single (Beckmann, V-cavity)"):
        assert by[("none", model)].min() < 0.99, model
    for (fresnel, model), albedo in by.items():
        if fresnel == "conductor":
            assert np.all(albedo < by[("none", model)] + 1e-9), model
    assert (out / "multiple_scattering.png").stat().st_size > 10_000


@pytest.mark.render
def test_smoke_comparisons_lobes_and_rendered_spheres(smoke):
    """Lobe slices: finite, non-negative, and the walk is never below its own first order
    (single-scattering Walter, height-correlated) beyond its noise, since its higher orders add
    light; the rendered rows and their cost per sample exist for every model."""
    out, _ = smoke
    data = json.loads((out / "results.json").read_text())["comparisons"]
    slices = {(s["model"], s["roughness"]): s for s in data["lobes"]["slices"]}
    for s in slices.values():
        f = np.asarray(s["f_cos"])
        assert np.isfinite(f).all() and (f >= 0).all(), s["model"]
    for r in {key[1] for key in slices}:
        heitz, walter = slices[("Heitz 2016", r)], slices[("Walter single (GGX)", r)]
        excess = np.asarray(heitz["f_cos"]) - np.asarray(walter["f_cos"])
        assert (excess > -5 * np.asarray(heitz["stderr"]) - 1e-9).all(), r
    costs = data["renders"]["costs"]
    assert [c["model"] for c in costs] == [s for s in ("Lee symmetric", "Lee asymmetric",
                                                       "Heitz 2016", "Walter single (GGX)")]
    assert all(c["seconds_per_sample"] >= 0 for c in costs)
    for name in ("lobe_slices.png", "comparison_spheres.png"):
        assert (out / name).stat().st_size > 5_000, name


@pytest.mark.render
def test_smoke_fallback_section_measures_every_preset(smoke):
    """The native-branch section: a row per preset with finite albedo errors over the bands
    of mu, the look's error under the gradient and under the sun, the picture, and the OSL-on
    cost of both variants, for all the presets and for a model's alone (the smoke run renders
    each model's first preset and times one model)."""
    from addon.catalog import MODELS
    from addon.lab.report.fallback import smoke_presets

    out, _ = smoke
    page = (out / "report.md").read_text()
    assert "## Without OSL: the native branch against the exact model" in page
    data = json.loads((out / "results.json").read_text())["fallback"]
    assert [e["preset"] for e in data["presets"]] == [p.id for p in smoke_presets("smoke")]
    assert {e["model"] for e in data["presets"]} == set(MODELS)
    for e in data["presets"]:
        assert len(e["albedo"]) >= 2 and len(e["gradient"]) == 3 and len(e["sun"]) == 3, e
        assert np.isfinite([b["error"] + b["noise"] for b in e["albedo"]]).all(), e
        assert np.isfinite(e["gradient"] + e["sun"] + e["gradient_noise"] + e["sun_noise"]).all(), e
        assert re.search(rf"\| {e['preset']} \| .+ \| {NUMBER}% \| {NUMBER}% \| {NUMBER}% \|", page)
    cost = data["cost"]
    assert cost["models"] and cost["models"].keys() <= {e["model"] for e in data["presets"]}
    for name, c in [("all", cost)] + list(cost["models"].items()):
        assert c["with"] and c["without"] and c["spheres"] > 0, name
        assert re.search(rf"\| {name} \| {c['spheres']} \| {NUMBER} \| {NUMBER} \| {NUMBER} \|",
                         page), name
    for model_id, c in cost["models"].items():  # each model's presets, and only those
        assert c["spheres"] == sum(e["model"] == model_id for e in data["presets"]), model_id
    assert (out / "fallback.png").stat().st_size > 1000


@pytest.mark.render
def test_smoke_lookdev_section_compares_noise_with_the_native_closure(smoke):
    """The look-dev section: for the smoke run's pair and light, finite positive variances over
    a mask of Suzanne's pixels, the samples and time ratios they give, and the table's row."""
    out, _ = smoke
    page = (out / "report.md").read_text()
    assert "## Look-dev: samples for equal noise against Cycles' closest closure" in page
    data = json.loads((out / "results.json").read_text())["lookdev"]
    assert data["mask_pixels"] > 50 and data["entries"], data
    for e in data["entries"]:
        for m in (e["ours"], e["native_measure"]):
            # the cost per sample is NaN where the smoke run's few samples cost below the noise
            assert m["finite"] and m["variance"] > 0 and m["mean"] > 0, e
            per_sample = float(m["per_sample"])  # results.json writes NaN as "nan"
            assert math.isnan(per_sample) or per_sample > 0, e
        assert e["samples_ratio"] == pytest.approx(
            e["ours"]["variance"] / e["native_measure"]["variance"])
        assert float(e["time_ratio"]) == pytest.approx(e["samples_ratio"] * float(e["cost_ratio"]),
                                                       nan_ok=True)
        assert re.search(rf"\| {e['preset']} \| {e['native']} \| x{NUMBER} \((x{NUMBER}|time -)\) \|",
                         page)
