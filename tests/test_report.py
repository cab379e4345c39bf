"""`make report` in its smoke mode: the page, the plots and the numbers exist and make sense.

The smoke run (scripts/report.py --smoke: two sample counts, one tiny grid per model variant,
the gradient environment, a small stability sweep, no OSL stress grid) runs in a fresh process,
so it also checks the command line. The helpers that turn curves into the table are tested on
synthetic curves whose answer is known.
"""
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from addon import report

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
    assert re.search(r"Blender \(bpy\) \d+\.\d+", page) and "numpy 1." in page
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
    for table in ("| order N |", "| sampler | max pixel |", "var / max at"):
        assert table in page


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
    for name in ("rmse_vs_time.png", "sampler_weights.png", "fireflies.png", "grids.png"):
        path = out / name
        assert path.exists() and path.stat().st_size > 5000, name
        img = mpimg.imread(path)
        assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100, name
        assert img[..., :3].std() > 0.05, f"{name} looks blank"


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


def test_sun_cone_rule_integrates_the_solid_angle_and_a_cosine():
    half = math.radians(report.SUN_ANGLE_DEG) / 2
    dirs, w = report.sun_cone_nodes(half, 8, 16)
    assert w.sum() == pytest.approx(2 * math.pi * (1 - math.cos(half)), rel=1e-12)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    d = report.sun_unit()
    # integral of (w.d)^2 over the cone = 2 pi (1 - cos^3) / 3
    assert (w * (dirs @ d) ** 2).sum() == pytest.approx(2 * math.pi * (1 - math.cos(half) ** 3) / 3,
                                                        rel=1e-10)
