"""`make report`: error against render time, the samplers' weights, the reference's cost and
numerical stability, written to report/ as a Markdown page with PNG plots.

Sections (each a function below, orchestrated by `run`):
1. `convergence`: every model x sampler (catalog driven) and Cycles' native closure where one
   exists, rendered on sphere grids (one row of roughness values per model variant) under the
   white furnace, the smooth gradient and a small sun over a dim uniform world, at sample counts
   from 1 up; relative RMSE against the numpy reference against wall-clock render time.
   Timing: one scene per environment holding every row; each row is rendered alone through a
   render border with Cycles' persistent data on, so the one-off scene sync and OSL JIT (reported
   separately) are not in the per-render time, which is the wall clock of the render call.
2. `sampler_study`: Walter D cos against visible normals (Smith) against V-cavity visible
   normals in numpy: variance and maximum of the sample weight against incidence and roughness;
   and a firefly picture (`fireflies`).
3. `reference_cost`: time and accuracy of the reference image against quadrature order.
4. Stability: addon/lab/stability.py (numpy sweep, OSL stress grid).
5. `lee_section`: the Lee 2018 V-groove model (addon/lab/bench_lee.py): white-furnace grid over
   alpha against single scattering and Cycles' multi-GGX (table and picture), render cost per
   sample against the Cook-Torrance shader measured side by side, the closed-form albedo
   against the brute-force tracer at equal error, and the accuracy of the moment rules.
6. `optix_comparison`: only where bpy reports an OptiX device (untested without one).
"""
from __future__ import annotations

import datetime
import json
import math
import os
import platform
import shutil
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from . import grid, stability
from ..catalog import MODELS
from .native import native_source

TARGET = 0.01  # relative RMSE for the time-to-target table
MU_MIN_RMSE = 0.05  # the rim beyond is left out of the RMSE (see grid.MU_BANDS)
SUN_DIRECTION = (0.6, 0.48, 0.64)  # toward the sun, world space (same as the gradient's)
SUN_ANGLE_DEG = 4.0  # angular diameter
SUN_STRENGTH = 1.0  # irradiance at normal incidence, W/m^2
SUN_WORLD = 0.05  # the dim uniform world under the sun
GOLD = {"fresnel_type": "conductor"}  # catalog default n, k (gold)


# -- configuration --------------------------------------------------------------------------
@dataclass
class LeeConfig:
    """Settings of the Lee section (defaults: the full run)."""
    furnace_samples: int = 256
    furnace_px: int = 48
    cost_samples: tuple = (16, 384)  # the two sample counts whose time difference is taken
    cost_px: int = 32
    cost_repeats: int = 5
    tracer_n: int = 1 << 20
    tracer_cases: tuple = (("ggx", 0.5, 60.0), ("ggx", 1.0, 0.0), ("beckmann", 1.0, 80.0))
    quad_orders: tuple = (32, 64, 128, 256, 512)
    quad_ref: int = 1024
    target: float = 1e-4  # albedo error for the time-to-error comparison
    moment_mus: tuple = (1.0, 0.5, 0.2, 0.05, 0.01)
    moment_alphas: tuple = (0.09, 1.0)
    moment_grooves: tuple = ("symmetric", "asymmetric")
    moment_distributions: tuple = ("ggx", "beckmann")


@dataclass
class Config:
    mode: str
    samples: tuple
    cell_px: int
    roughness: tuple
    envs: tuple
    sweep_stride: int
    albedo_samples: int
    stress: str  # "full", "quick" or "none"
    study_samples: int
    study_thetas: tuple
    study_roughness: tuple
    fireflies_px: int
    ref_orders: tuple
    ref_high_order: int
    ref_cell_px: int
    sun_nodes: tuple  # (radial, azimuthal) of the sun-disk quadrature; the check uses half
    moment_order: int = 6
    seed: int = 0
    combo_seconds: float = 20.0  # stability sweep: per parameter combination
    model_seconds: float = 240.0  # stability sweep: per model
    lee: LeeConfig = field(default_factory=LeeConfig)


def config(mode: str) -> Config:
    theta_full = tuple(np.round(np.concatenate([np.linspace(0, 80, 9), [84, 87, 88.5, 89.5, 89.9]]), 3))
    if mode == "full":
        return Config("full", tuple(2 ** k for k in range(11)), 20, (0.1, 0.3, 0.6, 1.0),
                      ("white", "gradient", "sun"), 1, 1024, "full", 40000, theta_full,
                      (0.1, 0.3, 0.6, 1.0), 96, (2, 3, 4, 6, 8), 14, 32, (24, 48))
    if mode == "quick":
        return Config("quick", (1, 4, 16, 64, 256), 16, (0.1, 0.3, 0.6, 1.0),
                      ("white", "gradient", "sun"), 8, 256, "quick", 8000,
                      (0.0, 30.0, 60.0, 80.0, 87.0, 89.0, 89.9), (0.1, 0.3, 1.0), 64,
                      (2, 4, 6), 10, 16, (16, 32), combo_seconds=5.0, model_seconds=30.0,
                      lee=LeeConfig(furnace_samples=64, furnace_px=32, cost_samples=(16, 256),
                                    cost_px=24, cost_repeats=3, tracer_n=1 << 16,
                                    quad_orders=(32, 64, 128, 256), quad_ref=512,
                                    moment_mus=(1.0, 0.2, 0.01)))
    if mode == "smoke":
        return Config("smoke", (1, 8), 10, (0.3, 1.0), ("gradient",), 200, 64, "none", 500,
                      (0.0, 60.0, 89.9), (0.3,), 32, (2,), 4, 8, (8, 16), moment_order=4,
                      combo_seconds=1.0, model_seconds=3.0,
                      lee=LeeConfig(furnace_samples=16, furnace_px=16, cost_samples=(4, 32),
                                    cost_px=12, cost_repeats=2, tracer_n=1 << 14,
                                    tracer_cases=(("beckmann", 1.0, 80.0),),
                                    quad_orders=(32, 64, 128), quad_ref=256,
                                    moment_mus=(1.0, 0.01), moment_alphas=(1.0,),
                                    moment_distributions=("ggx",)))
    raise ValueError(f"unknown mode {mode!r}")


# -- progress --------------------------------------------------------------------------------
class Progress:
    def __init__(self, stream=None):
        self.start = time.perf_counter()
        self.stream = stream or sys.stdout

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def __call__(self, message: str, i: int | None = None, n: int | None = None):
        count = f"({i}/{n}) " if i is not None else ""
        self.stream.write(f"[report {self.elapsed():6.1f} s] {count}{message}\n")
        self.stream.flush()


# -- rows: model variants x samplers, and native closures ------------------------------------
@dataclass
class Row:
    key: str  # unique, e.g. "walter_reflection ggx F=1 / vndf"
    label: str
    model_id: str | None  # None for a native closure
    values: dict
    variant: str  # groups a model variant's samplers with its native closure
    sampler: str  # sampler item, or "native"
    native_kind: str | None = None


# Model variants whose native Cycles closure is the same BSDF (height-correlated Smith G2).
VARIANTS = {
    "cook_torrance": [("Cook-Torrance gold", {"specular": 1.0, **GOLD}, None)],
    "walter_reflection": [
        ("Walter GGX F=1", {"distribution": "ggx", "fresnel_type": "none"}, "ggx"),
        ("Walter Beckmann F=1", {"distribution": "beckmann", "fresnel_type": "none"}, "beckmann"),
        ("Walter GGX gold", {"distribution": "ggx", **GOLD}, "conductor"),
    ],
    "walter_glass": [("Walter GGX glass 1.5", {"distribution": "ggx", "ior": 1.5}, "glass")],
}


def reference_available(model_id: str) -> str:
    """'' when the numpy twin and the OSL shader exist, else why not."""
    from .reference import make_bsdf

    if model_id not in stability.osl_models():
        return "no OSL shader yet"
    try:
        make_bsdf(model_id, {})
    except Exception as exc:  # noqa: BLE001
        return f"no numpy reference yet ({type(exc).__name__}: {exc})"
    # The reference image needs the moment tables: probe them cheaply, with a time limit.
    from .reference.quadrature import tabulate_moments

    try:
        with stability._time_limit(5.0):
            tabulate_moments(make_bsdf(model_id, {"roughness": 0.5}), n_mu=4, order=2)
    except stability._Timeout:
        return "its reference moment tables are too slow for the report (probe > 5 s)"
    except Exception as exc:  # noqa: BLE001
        return f"no reference moment tables ({type(exc).__name__}: {exc})"
    return ""


def eval_is_fast(model_id: str, values: dict, limit: float = 0.5) -> bool:
    """Whether 20,000 evaluations take under `limit` seconds (the sun term needs millions)."""
    from .reference import make_bsdf

    rng = np.random.default_rng(0)
    wi = np.broadcast_to([0.6, 0.0, 0.8], (20000, 3))
    wo = rng.normal(size=(20000, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    start = time.perf_counter()
    try:
        with stability._time_limit(limit * 4):
            with np.errstate(all="ignore"):
                make_bsdf(model_id, {**values, "roughness": 1.0}).eval(wi, wo)
    except Exception:  # noqa: BLE001 - a timeout or an error: not fast
        return False
    return time.perf_counter() - start < limit


def build_rows(notes: list) -> list:
    rows = []
    for model_id, model in MODELS.items():
        why = reference_available(model_id)
        if why:
            notes.append(f"{model.label}: left out of the convergence study: {why}.")
            continue
        variants = VARIANTS.get(model_id, [(model.label, {}, None)])
        samplers = (model.param("sampler").items
                    if any(p.id == "sampler" for p in model.params) else (None,))
        for label, values, native in variants:
            for s in samplers:
                v = dict(values, **({"sampler": s} if s else {}))
                rows.append(Row(f"{label} / {s or 'own'}", label, model_id, v, label, s or "own"))
            if native:
                rows.append(Row(f"{label} / native", label, None, {}, label, "native", native))
    return rows


def specs_for(row: Row, roughness) -> list:
    """SphereSpecs of a row (for natives: the model variant they stand for, for the reference)."""
    if row.model_id is not None:
        return [grid.SphereSpec(row.model_id, {**row.values, "roughness": r}, f"{row.key} r={r}")
                for r in roughness]
    model_id, values = NATIVE_TWIN[row.native_kind]
    return [grid.SphereSpec(model_id, {**values, "roughness": r}, f"{row.key} r={r}")
            for r in roughness]


NATIVE_TWIN = {
    "ggx": ("walter_reflection", {"distribution": "ggx", "fresnel_type": "none"}),
    "beckmann": ("walter_reflection", {"distribution": "beckmann", "fresnel_type": "none"}),
    "conductor": ("walter_reflection", {"distribution": "ggx", **GOLD}),
    "glass": ("walter_glass", {"distribution": "ggx", "ior": 1.5}),
}


# -- references ------------------------------------------------------------------------------
def _table_key(spec):
    return (spec.model_id, tuple(sorted((k, str(v)) for k, v in spec.values.items()
                                        if k != "sampler")))


class ReferenceTables:
    """Moment tables by (model, values without the sampler), computed once."""

    def __init__(self, order: int):
        self.order = order
        self.cache = {}

    def get(self, spec):
        from .reference import make_bsdf
        from .reference.quadrature import tabulate_moments

        key = _table_key(spec)
        if key not in self.cache:
            self.cache[key] = tabulate_moments(make_bsdf(spec.model_id, spec.values),
                                               order=self.order)
        return self.cache[key]


def sun_unit() -> np.ndarray:
    d = np.asarray(SUN_DIRECTION, dtype=float)
    return d / np.linalg.norm(d)


def sun_cone_nodes(half_angle: float, n_r: int, n_phi: int):
    """Directions and solid-angle weights of a product rule on the cone of half-angle
    `half_angle` around the sun: Gauss-Legendre in the polar angle (weight sin), midpoint
    (periodic trapezoid) in azimuth."""
    d = sun_unit()
    e1 = np.cross(d, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    x, w = np.polynomial.legendre.leggauss(n_r)
    theta = 0.5 * half_angle * (x + 1.0)
    wt = 0.5 * half_angle * w * np.sin(theta)
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    dirs = (np.cos(T)[..., None] * d + np.sin(T)[..., None]
            * (np.cos(P)[..., None] * e1 + np.sin(P)[..., None] * e2))
    weights = (wt[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :])
    return dirs.reshape(-1, 3), weights.reshape(-1)


def sun_term(layout, specs, radiance: float, half_angle: float, nodes: tuple) -> np.ndarray:
    """L_sun times the integral of f(wi, wo) |wo.n| over the sun's cone, per pixel (H, W, 3).
    Spheres are invisible to secondary rays, so a reflected or transmitted ray meets the sun
    directly (single-interface convention for glass)."""
    from .reference import make_bsdf

    index, normal, mu = layout.pixel_geometry()
    tangent = grid.tangent_toward_view(normal)
    flat = np.linalg.norm(tangent, axis=-1) < 0.5  # mu = 1: any tangent
    tangent[flat] = [1.0, 0.0, 0.0]
    binormal = np.cross(normal, tangent)
    dirs, weights = sun_cone_nodes(half_angle, *nodes)
    out = np.zeros(index.shape + (3,))
    bsdfs = {}
    for i, spec in enumerate(specs):
        sel = np.nonzero(index == i)
        if spec is None or len(sel[0]) == 0:
            continue
        key = _table_key(spec)
        if key not in bsdfs:
            bsdfs[key] = make_bsdf(spec.model_id, spec.values)
        bsdf = bsdfs[key]
        n, t, b, m = normal[sel], tangent[sel], binormal[sel], mu[sel]
        wi = np.stack([np.sqrt(np.clip(1.0 - m * m, 0.0, 1.0)), np.zeros_like(m), m], -1)
        vals = np.empty((len(m), 3))
        for start in range(0, len(m), 256):
            s = slice(start, start + 256)
            wo = np.stack([t[s] @ dirs.T, b[s] @ dirs.T, n[s] @ dirs.T], -1)  # (p, K, 3)
            with np.errstate(all="ignore"):
                f = bsdf.eval(wi[s, None, :], wo)
            f = np.nan_to_num(f)
            vals[s] = np.einsum("pkc,pk,k->pc", f, np.abs(wo[..., 2]), weights)
        out[sel] = radiance * vals
    return out


def reference_image(layout, specs, env_key, tables: ReferenceTables, sun=None, nodes=(24, 48)):
    """The reference of a grid under 'white', 'gradient' or 'sun' (then `sun` = (radiance,
    half_angle)); returns (image, sun-quadrature error estimate or 0)."""
    from .reference.quadrature import moments_at

    tabs = [None if s is None else tables.get(s) for s in specs]
    if env_key != "sun":
        return grid.reference_image(layout, tabs, grid.ENVIRONMENTS[env_key], moments_at), 0.0
    world = grid.Environment("sun world", SUN_WORLD)
    base = grid.reference_image(layout, tabs, world, moments_at)
    radiance, half = sun
    fine = sun_term(layout, specs, radiance, half, nodes)
    coarse = sun_term(layout, specs, radiance, half, (nodes[0] // 2, nodes[1] // 2))
    index, _, _ = layout.pixel_geometry()
    err = float(np.abs(fine - coarse)[index >= 0].max()) if (index >= 0).any() else 0.0
    return base + fine, err


# -- scenes ----------------------------------------------------------------------------------
def add_sun(scene, strength=SUN_STRENGTH, angle_deg=SUN_ANGLE_DEG):
    import bpy
    import mathutils

    light = bpy.data.lights.new("Microfacet Lab sun", "SUN")
    light.energy = strength
    light.angle = math.radians(angle_deg)
    obj = bpy.data.objects.new("Microfacet Lab sun", light)
    # A sun lamp shines along its local -Z: point +Z at the sun.
    obj.rotation_euler = mathutils.Vector(tuple(sun_unit())).to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(obj)
    return obj


def env_for(env_key):
    return grid.ENVIRONMENTS.get(env_key) or grid.Environment("sun over a dim world", SUN_WORLD)


def calibrate_sun(progress) -> dict:
    """Radiance of the sun lamp as Cycles renders it, read off a mirror sphere (roughness 0,
    F = 1: deterministic, one sample): pixels whose mirror direction lies in the sun's cone
    see L_sun + nothing else. Compared with strength / (2 pi (1 - cos(angle / 2)))."""
    from . import harness

    half = math.radians(SUN_ANGLE_DEG) / 2.0
    layout = grid.GridLayout(1, 1, cell_px=160)
    scene = harness.new_scene()
    mats = [harness.model_material("walter_reflection", {"roughness": 0.0, "fresnel_type": "none"},
                                   "sun mirror")]
    harness.build_grid_scene(layout, mats, env_for("sun"), 1, 0)
    add_sun(scene)
    image, _ = harness.render(scene)
    index, normal, _ = layout.pixel_geometry()
    wo = 2.0 * normal[..., 2:3] * normal - grid.VIEW
    cosang = wo @ sun_unit()
    inside = (index == 0) & (cosang > math.cos(half * 0.95))
    outside = (index == 0) & (cosang < math.cos(half * 1.05))
    vals = image[..., 0][inside] - SUN_WORLD
    formula = SUN_STRENGTH / (2.0 * math.pi * (1.0 - math.cos(half)))
    result = {"pixels_inside": int(inside.sum()), "formula": formula,
              "radiance": float(np.median(vals)) if len(vals) else formula,
              "spread": float(vals.max() - vals.min()) if len(vals) else 0.0,
              "outside_max": float(np.abs(image[..., 0][outside] - SUN_WORLD).max()),
              "half_angle": half}
    progress(f"sun calibration: radiance {result['radiance']:.3f} over {result['pixels_inside']} "
             f"mirror pixels (2 pi (1 - cos) formula: {formula:.3f})")
    return result


def set_border(scene, layout, row):
    r = scene.render
    r.use_border = True
    r.use_crop_to_border = False
    r.border_min_x, r.border_max_x = 0.0, 1.0
    r.border_max_y = 1.0 - row / layout.rows
    r.border_min_y = 1.0 - (row + 1) / layout.rows


def build_env_scene(rows, cfg, env_key, device="CPU"):
    """One scene per environment: row r of the grid is rows[r], one sphere per roughness."""
    from . import harness

    layout = grid.GridLayout(len(rows), len(cfg.roughness), cell_px=cfg.cell_px)
    scene = harness.new_scene()
    mats = []
    for row in rows:
        for r in cfg.roughness:
            name = f"{row.key} r={r}"
            if row.model_id is None:
                mats.append(harness.osl_material(native_source(row.native_kind, r), name))
            else:
                mats.append(harness.model_material(row.model_id, {**row.values, "roughness": r},
                                                   name))
    harness.build_grid_scene(layout, mats, env_for(env_key), 1, cfg.seed)
    if env_key == "sun":
        add_sun(scene)
    if device != "CPU":
        set_gpu(scene, device)
    scene.render.use_persistent_data = True
    return scene, layout


def relative_rmse(image, reference, sel) -> float:
    d = image[..., :3][sel] - reference[sel]
    return float(np.sqrt(np.mean(d * d)) / np.mean(reference[sel]))


# -- section 1: convergence ------------------------------------------------------------------
def convergence(cfg, rows, tables, progress, sun_cal=None) -> dict:
    from . import harness

    out = {"envs": {}, "setup_seconds": {}, "sun_quadrature_error": {}, "left_out": {}}
    all_rows = rows
    fast = {}
    for row in all_rows:
        model_id, values = ((row.model_id, row.values) if row.model_id
                            else NATIVE_TWIN[row.native_kind])
        if model_id not in fast:
            fast[model_id] = eval_is_fast(model_id, values)
    env_rows = {e: [r for r in all_rows if e != "sun" or fast[r.model_id or
                                                             NATIVE_TWIN[r.native_kind][0]]]
                for e in cfg.envs}
    for e, rs in env_rows.items():
        left = [r.key for r in all_rows if r not in rs]
        if left:
            out["left_out"][e] = left
    n_total = sum(len(rs) for rs in env_rows.values()) * len(cfg.samples)
    done = 0
    for env_key in cfg.envs:
        rows = env_rows[env_key]
        progress(f"{env_key}: building the scene ({len(rows)} rows x {len(cfg.roughness)} spheres)")
        t0 = time.perf_counter()
        scene, layout = build_env_scene(rows, cfg, env_key)
        harness.render(scene)  # sync + OSL JIT, once
        out["setup_seconds"][env_key] = time.perf_counter() - t0
        progress(f"{env_key}: scene sync and OSL JIT {out['setup_seconds'][env_key]:.1f} s; "
                 f"reference images")
        specs = [s for row in rows for s in specs_for(row, cfg.roughness)]
        sun = (sun_cal["radiance"], sun_cal["half_angle"]) if env_key == "sun" else None
        reference, sun_err = reference_image(layout, specs, env_key, tables, sun, cfg.sun_nodes)
        out["sun_quadrature_error"][env_key] = sun_err
        index, _, mu = layout.pixel_geometry()
        series = {}
        finals = np.zeros((layout.height, layout.width, 3))
        for r, row in enumerate(rows):
            set_border(scene, layout, r)
            sel = (index >= r * layout.cols) & (index < (r + 1) * layout.cols) & (mu > MU_MIN_RMSE)
            pts = []
            for k, spp in enumerate(cfg.samples):
                done += 1
                progress(f"{env_key}: {row.key}, {spp} samples", done, n_total)
                scene.cycles.samples = spp
                scene.cycles.seed = cfg.seed + 1000 * k + r + 1
                image, seconds = harness.render(scene)
                pts.append((spp, seconds, relative_rmse(image, reference, sel)))
            band = slice(r * layout.cell_px, (r + 1) * layout.cell_px)
            finals[band] = image[band, :, :3]
            series[row.key] = pts
        out["envs"][env_key] = {"series": series, "image": finals, "reference": reference,
                                "layout": layout}
    return out


def time_to_target(points, target=TARGET):
    """(seconds, how): interpolated on the log-log curve where it crosses `target`; beyond the
    last point extrapolated with the 1/sqrt(t) slope ('extrapolated'), or 'floor' when the last
    points stop falling (a bias); 'first' when the first point is already below."""
    t = np.array([p[1] for p in points], float)
    e = np.array([p[2] for p in points], float)
    below = np.nonzero(e <= target)[0]
    if len(below):
        k = int(below[0])
        if k == 0:
            return float(t[0]), "first"
        x0, x1 = np.log(e[k - 1]), np.log(e[k])
        y0, y1 = np.log(max(t[k - 1], 1e-6)), np.log(max(t[k], 1e-6))
        f = (np.log(target) - x0) / (x1 - x0) if x1 != x0 else 1.0
        return float(np.exp(y0 + f * (y1 - y0))), "interpolated"
    if len(e) >= 3 and e[-1] > 0.8 * e[-3]:
        return float("inf"), "floor"
    return float(t[-1] * (e[-1] / target) ** 2), "extrapolated"


def time_table(conv, rows) -> list:
    """Per env and row: time to TARGET and its ratio to the native closure of the variant."""
    table = []
    for env_key, data in conv["envs"].items():
        env_rows = [row for row in rows if row.key in data["series"]]
        times = {row.key: time_to_target(data["series"][row.key]) for row in env_rows}
        native = {row.variant: times[row.key][0] for row in env_rows if row.sampler == "native"}
        for row in env_rows:
            t, how = times[row.key]
            nat = native.get(row.variant)
            ratio = t / nat if nat and math.isfinite(t) and math.isfinite(nat) else None
            last = data["series"][row.key][-1]
            table.append({"env": env_key, "row": row.key, "variant": row.variant,
                          "sampler": row.sampler, "seconds": t, "how": how, "ratio": ratio,
                          "final_rmse": last[2], "final_samples": last[0]})
    return table


# -- section 2: samplers ---------------------------------------------------------------------
def _study_values(model, sampler, roughness):
    ids = {p.id for p in model.params}
    v = {"roughness": roughness, "sampler": sampler}
    if "fresnel_type" in ids and "none" in model.param("fresnel_type").items:
        v["fresnel_type"] = "none"
    elif "fresnel_type" in ids:  # a nearly perfect conductor: F ~ 1
        v.update(fresnel_type="conductor", n=(1.0, 1.0, 1.0), k=(100.0,) * 3)
    if "specular" in ids:
        v["specular"] = 1.0
    return v


def sampler_study(cfg, progress) -> dict:
    """Per model with a sampler switch: variance and maximum of the sample weight (F ~ 1)
    against incidence angle, per sampler and roughness."""
    from .reference import make_bsdf

    rng = np.random.default_rng(cfg.seed + 11)
    out = {}
    for model_id, model in MODELS.items():
        if not any(p.id == "sampler" for p in model.params):
            continue
        try:
            make_bsdf(model_id, {})
        except Exception:  # noqa: BLE001
            continue
        res = {}
        for sampler in model.param("sampler").items:
            for r in cfg.study_roughness:
                bsdf = make_bsdf(model_id, _study_values(model, sampler, r))
                var, mx, mean = [], [], []
                for th in cfg.study_thetas:
                    t = math.radians(th)
                    wi = np.array([math.sin(t), 0.0, math.cos(t)])
                    u = rng.random((cfg.study_samples, stability.U_DIMS))
                    _, w, _ = stability._sample(bsdf, np.broadcast_to(wi, (len(u), 3)), u)
                    w = np.asarray(w, float).mean(-1)
                    var.append(float(w.var()))
                    mx.append(float(w.max()))
                    mean.append(float(w.mean()))
                res[(sampler, r)] = {"variance": var, "max": mx, "mean": mean}
        out[model_id] = res
        progress(f"sampler study: {model.label} done")
    return out


FIREFLY_ROWS = (  # (label, model, values): F = 1 reflection, and rough glass (issue 3)
    ("Walter GGX reflection, F = 1", "walter_reflection",
     {"distribution": "ggx", "fresnel_type": "none", "roughness": 0.6}),
    ("Walter GGX glass, IOR 1.5", "walter_glass",
     {"distribution": "ggx", "ior": 1.5, "roughness": 0.6}),
)
FIREFLY_SAMPLERS = ("dcos", "vndf")


def fireflies(cfg, progress, out_dir) -> dict:
    """Rough spheres (roughness 0.6; reflection with F = 1, and glass) at 4 samples with D cos
    and with visible normals, beside the reference: the rim is the grazing view."""
    from . import harness
    from .reference.quadrature import moments_at

    specs = [grid.SphereSpec(model, {**values, "sampler": s}, f"{label}, {s}")
             for label, model, values in FIREFLY_ROWS for s in FIREFLY_SAMPLERS]
    layout, image, _ = harness.render_specs(specs, grid.GRADIENT, 4, seed=5,
                                            cols=len(FIREFLY_SAMPLERS), cell_px=cfg.fireflies_px)
    tables = ReferenceTables(cfg.moment_order)
    ref = grid.reference_image(layout, [tables.get(s) for s in specs], grid.GRADIENT, moments_at)
    index, _, mu = layout.pixel_geometry()
    stats = {}
    for i, s in enumerate(specs):
        sel = index == i
        rim = sel & (mu < 0.3)
        stats[s.label] = {"max": float(image[..., :3][sel].max()),
                          "rmse": relative_rmse(image, ref, sel & (mu > MU_MIN_RMSE)),
                          "rim_rmse": relative_rmse(image, ref, rim)}
    progress("fireflies rendered")
    return {"layout": layout, "image": image, "reference": ref, "stats": stats}


# -- section 3: reference cost ---------------------------------------------------------------
def reference_cost(cfg, rows, progress) -> list:
    """Time and accuracy of the gradient reference image of one grid (one row per model
    variant) against the quadrature order, relative to order `ref_high_order`."""
    from .reference.quadrature import moments_at

    seen, specs = set(), []
    for row in rows:
        if row.model_id and row.variant not in seen:
            seen.add(row.variant)
            specs += specs_for(row, cfg.roughness)
    layout = grid.GridLayout(-(-len(specs) // len(cfg.roughness)), len(cfg.roughness),
                             cell_px=cfg.ref_cell_px)
    index, _, mu = layout.pixel_geometry()
    sel = index >= 0
    results = []
    images = {}
    for order in tuple(cfg.ref_orders) + (cfg.ref_high_order,):
        progress(f"reference cost: quadrature order {order}")
        start = time.perf_counter()
        tables = ReferenceTables(order)
        img = grid.reference_image(layout, [tables.get(s) for s in specs], grid.GRADIENT,
                                   moments_at)
        images[order] = (img, time.perf_counter() - start)
    high, _ = images[cfg.ref_high_order]
    for order, (img, seconds) in images.items():
        d = np.abs(img - high)[sel]
        results.append({"order": order, "seconds": seconds, "max_abs": float(d.max()),
                        "rel_rmse": float(np.sqrt(np.mean(d * d)) / np.mean(high[sel])),
                        "spheres": len(specs)})
    return results


# -- section 5: Lee 2018 V-grooves -------------------------------------------------------------
def lee_section(cfg, progress, notes) -> dict:
    """The measurements of addon/lab/bench_lee.py at the mode's settings. Each part that fails is
    reported in `notes` (and left out of the page) rather than losing the run."""
    from . import bench_lee

    lc = cfg.lee
    out = {}

    def part(name, fn):
        start = time.perf_counter()
        try:
            out[name] = fn()
        except Exception as exc:  # noqa: BLE001 - report it rather than lose the page
            notes.append(f"Lee section, {name}: failed: {type(exc).__name__}: {exc}")
            progress(f"Lee {name} FAILED: {type(exc).__name__}: {exc}")
            return
        out.setdefault("seconds", {})[name] = time.perf_counter() - start

    def furnace():
        progress(f"Lee furnace grid: {len(bench_lee.furnace_rows())} models x "
                 f"{len(bench_lee.FURNACE_ALPHAS)} alphas, {lc.furnace_samples} samples")
        alphas = bench_lee.FURNACE_ALPHAS
        labels, layout, image, means = bench_lee.render_furnace(alphas, lc.furnace_samples,
                                                                lc.furnace_px)
        noise = bench_lee.furnace_noise(layout, image, labels, alphas)
        lee = means["Lee symmetric GGX"][-1]
        progress(f"Lee furnace at alpha {alphas[-1]:g}: Lee {lee:.4f}, Walter GGX "
                 f"{means['Walter GGX (single)'][-1]:.4f}, Cook-Torrance "
                 f"{means['Cook-Torrance (single)'][-1]:.4f}, Cycles multi-GGX "
                 f"{means['Cycles multi-GGX'][-1]:.4f}")
        return {"alphas": list(alphas), "labels": labels, "means": means, "noise": noise,
                "samples": lc.furnace_samples, "cell_px": lc.furnace_px, "layout": layout,
                "image": image}

    def cost():
        res = bench_lee.shader_cost(lc.cost_samples, lc.cost_px, lc.cost_repeats,
                                    progress=progress)
        progress("Lee shader cost per sample, x Cook-Torrance: " + ", ".join(
            f"{k} {v['ratio_to_cook_torrance']:.2f}" for k, v in res.items()
            if not k.startswith("_") and not k.startswith("Cook")))
        return res

    def tracer():
        res = bench_lee.tracer_vs_closed_form(lc.tracer_cases, n=lc.tracer_n, target=lc.target,
                                              quad_orders=lc.quad_orders, quad_ref=lc.quad_ref,
                                              progress=progress)
        progress("Lee tracer / closed form at equal albedo error: " + ", ".join(
            f"{k} x{v['tracer_over_closed_form']:.3g}" for k, v in res.items()))
        return res

    def moments():
        res = bench_lee.moments_accuracy(lc.moment_mus, lc.moment_alphas, lc.moment_grooves,
                                         lc.moment_distributions, progress=progress)
        worst = max(v["max_abs_error"] for v in res.values())
        progress(f"Lee moment rules: max abs error {worst:.2g}")
        return res

    part("furnace", furnace)
    part("cost", cost)
    part("tracer", tracer)
    part("moments", moments)
    return out


def plot_lee_furnace(furnace, path, dpi=80):
    """The furnace grid as rendered (linear, 1 = white: a sphere that keeps all the energy
    vanishes, the loss reads as darkening; dotted outlines mark the spheres) beside the
    sphere means against alpha."""
    from matplotlib.patches import Circle

    plt = _plt()
    layout, image, labels = furnace["layout"], furnace["image"], furnace["labels"]
    alphas, means, noise = furnace["alphas"], furnace["means"], furnace["noise"]
    fig, (ax_img, ax_plot) = plt.subplots(1, 2, figsize=(11, 4.6), dpi=dpi,
                                          gridspec_kw={"width_ratios": [1.15, 1]})
    ax_img.imshow(np.clip(np.nan_to_num(image[..., :3]), 0.0, 1.0), interpolation="nearest")
    ax_img.set_xticks([(c + 0.5) * layout.cell_px for c in range(len(alphas))])
    ax_img.set_xticklabels([f"alpha {a:g}" for a in alphas], fontsize=8)
    ax_img.set_yticks([(r + 0.5) * layout.cell_px for r in range(len(labels))])
    ax_img.set_yticklabels(labels, fontsize=8)
    ax_img.set_title("White furnace (L = 1), linear: a sphere keeping all energy vanishes",
                     fontsize=8)
    scale = max(layout.width, layout.height) / layout.ortho_scale
    for x, y in layout.centers():
        ax_img.add_patch(Circle((layout.width / 2 + x * scale - 0.5,
                                 layout.height / 2 - y * scale - 0.5),
                                layout.radius * scale, fill=False, lw=0.6, ls=":",
                                color="tab:blue"))
    for i, label in enumerate(labels):  # Lee rows coincide at 1: told apart by style
        lee = label.startswith("Lee")
        ax_plot.errorbar(alphas, means[label], yerr=noise[label], marker="os^Dvp"[i % 6],
                         ms=6 - 1.5 * i if lee else 3, mfc="none" if lee else None, capsize=2,
                         lw=2.4 - 0.7 * i if lee else 1.2, ls="-" if not lee else "--",
                         label=label)
    ax_plot.axhline(1.0, color="k", lw=0.6)
    ax_plot.set_xlabel("alpha (= roughness^2)", fontsize=8)
    ax_plot.set_ylabel("sphere mean (mu >= 0.05)", fontsize=8)
    ax_plot.set_title("Energy kept: multiple vs single scattering", fontsize=8)
    ax_plot.tick_params(labelsize=7)
    ax_plot.legend(fontsize=7, frameon=False)
    ax_plot.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# -- GPU (OptiX) ---------------------------------------------------------------------------------
def optix_devices() -> list:
    """Names of OptiX devices bpy reports (none on a machine without an NVIDIA GPU)."""
    try:
        import bpy

        prefs = bpy.context.preferences.addons["cycles"].preferences
        prefs.refresh_devices()
        return [d.name for d in prefs.get_devices_for_type("OPTIX")]
    except Exception:  # noqa: BLE001
        return []


def set_gpu(scene, kind="OPTIX"):
    import bpy

    prefs = bpy.context.preferences.addons["cycles"].preferences
    prefs.compute_device_type = kind
    for d in prefs.get_devices_for_type(kind):
        d.use = True
    scene.cycles.device = "GPU"


def optix_comparison(cfg, rows, tables, progress) -> dict:
    """UNTESTED here (no NVIDIA GPU): the white-furnace gallery at the largest sample count on
    the CPU and with OptiX; times, and agreement of the two images (relative RMSE of their
    difference against each one's own error to the reference)."""
    from . import harness

    spp = cfg.samples[-1]
    result = {}
    for device in ("CPU", "OPTIX"):
        progress(f"OptiX comparison: {device}, {spp} samples")
        scene, layout = build_env_scene(rows, cfg, "white", device)
        scene.render.use_border = False
        harness.render(scene)
        scene.cycles.samples = spp
        image, seconds = harness.render(scene)
        result[device] = (image, seconds)
    specs = [s for row in rows for s in specs_for(row, cfg.roughness)]
    reference, _ = reference_image(layout, specs, "white", tables)
    index, _, mu = layout.pixel_geometry()
    sel = (index >= 0) & (mu > MU_MIN_RMSE)
    cpu, gpu = result["CPU"][0], result["OPTIX"][0]
    return {"devices": optix_devices(), "samples": spp, "cpu_seconds": result["CPU"][1],
            "gpu_seconds": result["OPTIX"][1],
            "cpu_vs_gpu_rel_rmse": relative_rmse(cpu, gpu[..., :3], sel),
            "cpu_rel_rmse": relative_rmse(cpu, reference, sel),
            "gpu_rel_rmse": relative_rmse(gpu, reference, sel)}


# -- environment of the run ------------------------------------------------------------------
def machine_info() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    info = {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "platform": platform.platform(),
            "date": datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")}
    try:
        import bpy

        info["blender"] = bpy.app.version_string
        info["bpy_threads"] = bpy.context.scene.render.threads if bpy.context.scene else None
    except Exception:  # noqa: BLE001
        info["blender"] = "bpy not importable"
    try:
        import matplotlib

        info["matplotlib"] = matplotlib.__version__
    except ImportError:
        pass
    return info


# -- plots -----------------------------------------------------------------------------------
SAMPLER_STYLE = {"dcos": "--", "vndf": "-", "vcavity": ":", "own": "-", "native": "-"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_convergence(conv, rows, path, dpi=72):
    plt = _plt()
    envs = list(conv["envs"])
    fig, axes = plt.subplots(1, len(envs), figsize=(4.3 * len(envs) + 2.6, 4.2), dpi=dpi,
                             squeeze=False)
    variants = list(dict.fromkeys(r.variant for r in rows))
    colors = {v: plt.cm.tab10(i % 10) for i, v in enumerate(variants)}
    for ax, env_key in zip(axes[0], envs):
        series = conv["envs"][env_key]["series"]
        for row in rows:
            if row.key not in series:
                continue
            pts = np.array(series[row.key], float)
            native = row.sampler == "native"
            ax.loglog(np.maximum(pts[:, 1], 1e-4), pts[:, 2], SAMPLER_STYLE.get(row.sampler, "-"),
                      color="k" if native and False else colors[row.variant],
                      lw=2.6 if native else 1.2, marker="o" if native else ".", ms=3,
                      label=f"{row.variant} / {row.sampler}")
        t = np.array([p[1] for pts in series.values() for p in pts])
        e = np.array([p[2] for pts in series.values() for p in pts])
        t0, e0 = np.median(t), np.median(e) * 2.5
        tt = np.array([t.min(), t.max()]) if t.min() > 0 else np.array([1e-3, t.max()])
        ax.loglog(tt, e0 * np.sqrt(t0 / tt), color="0.4", lw=1, ls="-.", label="slope 1/sqrt(t)")
        ax.axhline(TARGET, color="0.6", lw=0.8)
        ax.set_title({"white": "white furnace", "gradient": "smooth gradient",
                      "sun": f"sun {SUN_ANGLE_DEG:g} deg over dim world"}.get(env_key, env_key),
                     fontsize=9)
        ax.set_xlabel("render time per row (s)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    axes[0][0].set_ylabel("relative RMSE vs numpy reference", fontsize=8)
    handles, labels = axes[0][-1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center right", fontsize=6.5, frameon=False)
    fig.tight_layout(rect=(0, 0, 1 - 2.5 / (4.3 * len(envs) + 2.6), 1))
    fig.savefig(path)
    plt.close(fig)


def plot_sampler_study(study, cfg, path, dpi=70):
    plt = _plt()
    models = list(study)
    if not models:
        return
    fig, axes = plt.subplots(len(models), 2, figsize=(9.5, 2.9 * len(models)), dpi=dpi,
                             squeeze=False)
    colors = {"dcos": "tab:red", "vndf": "tab:blue", "vcavity": "tab:green"}
    styles = ["-", "--", "-.", ":"]
    for i, model_id in enumerate(models):
        for (sampler, r), d in study[model_id].items():
            ls = styles[list(cfg.study_roughness).index(r) % 4]
            for j, key in enumerate(("variance", "max")):
                axes[i][j].semilogy(cfg.study_thetas, np.maximum(d[key], 1e-8), ls,
                                    color=colors.get(sampler, "k"), lw=1.2,
                                    label=f"{sampler} r={r}")
        axes[i][0].set_ylabel(f"{MODELS[model_id].label}\nvariance of weight", fontsize=8)
        axes[i][0].set_ylim(bottom=1e-8)
        axes[i][1].set_ylabel(f"max weight ({cfg.study_samples} samples)", fontsize=8)
        for ax in axes[i]:
            ax.tick_params(labelsize=7)
            ax.grid(True, which="both", lw=0.3, alpha=0.5)
    for ax in axes[-1]:
        ax.set_xlabel("incidence angle (deg)", fontsize=8)
    axes[0][1].legend(fontsize=6.5, ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def to_display(image):
    return np.clip(np.nan_to_num(image[..., :3]), 0.0, 1.0) ** (1.0 / 2.2)


def plot_fireflies(ff, path, dpi=90):
    """One row per FIREFLY_ROWS entry: D cos, visible normals, the numpy reference."""
    plt = _plt()
    layout, image, ref = ff["layout"], ff["image"], ff["reference"]
    c = layout.cell_px
    titles = ("D cos (Walter), 4 spp", "visible normals, 4 spp", "numpy reference")
    fig, axes = plt.subplots(len(FIREFLY_ROWS), 3, figsize=(7.2, 2.5 * len(FIREFLY_ROWS)),
                             dpi=dpi, squeeze=False)
    for r, (label, _, _) in enumerate(FIREFLY_ROWS):
        rows = slice(r * c, (r + 1) * c)
        panels = (image[rows, :c], image[rows, c:2 * c], ref[rows, :c])
        for j, (ax, img) in enumerate(zip(axes[r], panels)):
            ax.imshow(to_display(img), interpolation="nearest")
            ax.set_title(f"{label}\n{titles[j]}" if j == 0 else titles[j], fontsize=8)
            ax.axis("off")
    fig.suptitle("Roughness 0.6, gradient environment", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_grids(conv, rows, path, dpi=70):
    plt = _plt()
    envs = list(conv["envs"])
    fig, axes = plt.subplots(1, 2 * len(envs), figsize=(2.1 * 2 * len(envs), 0.33 * len(rows) + 1),
                             dpi=dpi, squeeze=False)
    for i, env_key in enumerate(envs):
        d = conv["envs"][env_key]
        for j, (title, img) in enumerate((("render", d["image"]), ("reference", d["reference"]))):
            ax = axes[0][2 * i + j]
            ax.imshow(to_display(img), interpolation="nearest")
            ax.set_title(f"{env_key}: {title}", fontsize=7)
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# -- the page --------------------------------------------------------------------------------
def _fmt_t(t, how):
    if how == "floor" or not math.isfinite(t):
        return "not reached (error stops falling)"
    s = f"{t:.3g} s" if t >= 0.01 else f"{t * 1000:.2g} ms"
    return {"extrapolated": f"~{s} (extrapolated)", "first": f"<= {s} (1st point)"}.get(how, s)


def _secs(t):
    return f"{t:.3g} s" if t >= 0.01 else f"{t * 1000:.2g} ms"


def write_page(path, cfg, info, notes, rows, conv, table, sun_cal, study, ff, refcost, sweep,
               stress, gpu, total_seconds, lee=None):
    L = []
    a = L.append
    a("# Microfacet Lab: accuracy and speed\n")
    a(f"Generated by `make report{' QUICK=1' if cfg.mode == 'quick' else ''}` "
      f"(`scripts/report.py`, mode **{cfg.mode}**) on {info['date']} in {total_seconds:.0f} s.\n")
    a(f"- Machine: {info['cpu']}, {info['cores']} logical cores ({info['platform']}); "
      "shared with other work, so times carry some noise.")
    a(f"- Versions: Blender (bpy) {info.get('blender')}, numpy {info['numpy']}, "
      f"Python {info['python']}, matplotlib {info.get('matplotlib', '?')}.")
    if gpu is None:
        a("- GPU: **the OptiX comparison was not run: no NVIDIA GPU (no OptiX device reported by "
          "bpy) on this machine.** The code path (`addon/lab/report.py: optix_comparison`) runs when "
          "bpy reports an OptiX device; it has not been tested.")
    else:
        a(f"- GPU: OptiX on {', '.join(gpu['devices'])}: white-furnace grid at {gpu['samples']} "
          f"samples, CPU {gpu['cpu_seconds']:.2f} s vs OptiX {gpu['gpu_seconds']:.2f} s "
          f"(x{gpu['cpu_seconds'] / max(gpu['gpu_seconds'], 1e-9):.1f}); relative RMSE CPU vs "
          f"GPU {gpu['cpu_vs_gpu_rel_rmse']:.4f}, against the reference CPU "
          f"{gpu['cpu_rel_rmse']:.4f}, GPU {gpu['gpu_rel_rmse']:.4f}.")
    for n in notes:
        a(f"- Note: {n}")
    a("")
    if conv:
        a("## 1. Error against render time\n")
        a(f"Each model variant x sampler (and Cycles' native closure for the same BSDF) is one "
          f"row of {len(cfg.roughness)} spheres, roughness {', '.join(map(str, cfg.roughness))}, "
          f"{cfg.cell_px} px cells, rendered at {', '.join(map(str, cfg.samples))} samples per "
          "pixel. Error: relative RMSE = RMS over the row's sphere pixels (mu > 0.05) and RGB of "
          "render - reference, over the mean reference. Time: wall clock of the render call for "
          "that row alone (render border, persistent data: the one-off scene sync and OSL JIT "
          "per environment, " + ", ".join(f"{k} {v:.1f} s" for k, v in conv["setup_seconds"].items())
          + ", are not included).\n")
        if sun_cal:
            a(f"Sun: {SUN_ANGLE_DEG:g} degree disk, strength {SUN_STRENGTH:g}, direction "
              f"{SUN_DIRECTION}, over a uniform world of {SUN_WORLD}. Its radiance as Cycles "
              f"renders it, read off a mirror sphere at one sample: {sun_cal['radiance']:.3f} "
              f"(spread {sun_cal['spread']:.2g} over {sun_cal['pixels_inside']} pixels; "
              f"strength / (2 pi (1 - cos(angle/2))) = {sun_cal['formula']:.3f}). The reference is "
              f"{SUN_WORLD} E(mu) plus the radiance times a product Gauss rule of f |wo.n| over "
              f"the sun's cone ({cfg.sun_nodes[0]} x {cfg.sun_nodes[1]} nodes; the half-order rule "
              f"differs by at most {conv['sun_quadrature_error'].get('sun', 0):.2g} absolute). "
              "Delta-lobe shaders find the sun only by chance; native closures sample it.\n")
        a("![relative RMSE against render time](rmse_vs_time.png)\n")
        a(f"Time to {TARGET:.0%} relative RMSE (interpolated on the log-log curve; beyond the "
          "last point extrapolated along 1/sqrt(t)) and its ratio to the native closure for the "
          "same BSDF measured in the same run:\n")
        envs = list(conv["envs"])
        a("| model variant / sampler | " + " | ".join(f"{e}: time | {e}: x native" for e in envs) + " |")
        a("|---|" + "---|---|" * len(envs))
        by = {(t["env"], t["row"]): t for t in table}
        for row in rows:
            cells = []
            for e in envs:
                t = by.get((e, row.key))
                if t is None:
                    cells += ["not run", "-"]
                    continue
                cells.append(_fmt_t(t["seconds"], t["how"]))
                cells.append("-" if row.sampler == "native" else
                             (f"{t['ratio']:.2g}" if t["ratio"] is not None else "n/a"))
            a(f"| {row.key} | " + " | ".join(cells) + " |")
        a("")
        a("'not reached (error stops falling)': the error levels off above the target over the "
          "last points, i.e. a bias against the reference (or, under the sun, noise too heavy "
          "to fall yet); the RMSE at the largest sample count is below. Ratios > 1: slower "
          "than the native closure.\n")
        a(f"Relative RMSE at {cfg.samples[-1]} samples:\n")
        a("| model variant / sampler | " + " | ".join(envs) + " |")
        a("|---|" + "---|" * len(envs))
        for row in rows:
            a(f"| {row.key} | " + " | ".join(f"{by[(e, row.key)]['final_rmse']:.4f}"
                                            if (e, row.key) in by else "not run" for e in envs) + " |")
        a("")
        for e, left in conv.get("left_out", {}).items():
            a(f"Not run under {e}: {', '.join(left)} (numpy eval too slow for the sun-disk "
              "quadrature of every pixel).\n")
        a(f"Renders at {cfg.samples[-1]} samples and references: ![grids](grids.png)\n")
    if study:
        a("## 2. The samplers: D cos against visible normals against V-cavity visible normals\n")
        a(f"numpy, F ~ 1 (Fresnel 'none' or a k = 100 conductor; Cook-Torrance with specular 1), "
          f"{cfg.study_samples} samples per point: variance and maximum of the sample weight "
          "f cos / pdf against incidence angle, per roughness.\n")
        a("![sample weights](sampler_weights.png)\n")
        thetas = list(cfg.study_thetas)
        pick = [th for th in (0.0, 60.0, 80.0, 89.0, 89.5, 89.9) if th in thetas] or thetas[:3]
        a("| model | sampler | roughness | " + " | ".join(f"var / max at {th:g} deg" for th in pick) + " |")
        a("|---|---|---|" + "---|" * len(pick))
        for model_id, res in study.items():
            for (sampler, r), d in res.items():
                cells = [f"{d['variance'][thetas.index(th)]:.3g} / {d['max'][thetas.index(th)]:.3g}"
                         for th in pick]
                a(f"| {MODELS[model_id].label} | {sampler} | {r} | " + " | ".join(cells) + " |")
        a("")
    if ff:
        a("Fireflies: rough spheres (reflection and glass) at 4 samples per pixel (the rim is "
          "the grazing view):\n")
        a("![fireflies](fireflies.png)\n")
        a("| sphere, sampler | max pixel | relative RMSE (mu > 0.05) | relative RMSE at the rim (mu < 0.3) |")
        a("|---|---|---|---|")
        for k, s in ff["stats"].items():
            a(f"| {k} | {s['max']:.3g} | {s['rmse']:.3f} | {s['rim_rmse']:.3f} |")
        a("")
    if refcost:
        a("## 3. Cost of the reference\n")
        hi = refcost[-1]
        a(f"The gradient reference image of {hi['spheres']} spheres ({cfg.ref_cell_px} px cells): "
          f"moment tables (48 incidences each) by quadrature of order N, against order "
          f"{hi['order']}.\n")
        a("| order N | time (s) | max abs difference | relative RMS difference |")
        a("|---|---|---|---|")
        for r in refcost:
            a(f"| {r['order']} | {r['seconds']:.2f} | {r['max_abs']:.2g} | {r['rel_rmse']:.2g} |")
        a("")
    if sweep:
        tot = sweep["_total"]
        a("## 4. Stability on stiff and extreme inputs\n")
        a(f"numpy sweep (`addon/lab/stability.py`): {tot.cases:,} cases ({tot.eval_cases:,} evaluations "
          f"f and f cos, {tot.sample_cases:,} samples) and {tot.albedo_tests:,} Monte Carlo albedo "
          f"tests ({cfg.albedo_samples} samples each, energy violation when the albedo exceeds 1 "
          f"by more than {sweep['_z_crit']:.2f} standard errors) over {tot.combos:,} parameter "
          "combinations: roughness 0, 1e-9, around the alpha = 1e-7 delta threshold, 1e-3 .. 1, "
          "beyond 1 and NaN (clamped by the catalog), eta in {1, 1 +- 1e-6, 0.1, 10, 100, 0, NaN}, "
          "conductor n, k extremes, every enum; incidence up to 90 deg - 1e-6 and 90; wo = wi, "
          "wo ~ wi, the mirror, wo.h -> 0, grazing wo, both hemispheres; uniforms at 0 and "
          "1 - 2^-53.\n")
        a("| model | combinations | cases | NaN | Inf | negative | non-unit wo | energy violations | exceptions | max albedo | time (s) |")
        a("|---|---|---|---|---|---|---|---|---|---|---|")
        sweep_notes = []
        for k, rec in sweep.items():
            if k.startswith("_"):
                continue
            if rec.skipped:
                a(f"| {MODELS[k].label} | skipped: {rec.skipped} | | | | | | | | | |")
                continue
            a(f"| {MODELS[k].label} | {rec.combos} | {rec.cases:,} | {rec.nan} | {rec.inf} | "
              f"{rec.negative} | {rec.non_unit} | {rec.energy} | {rec.errors} | {rec.max_albedo:.4f} | "
              f"{rec.seconds:.1f} |")
            extra = ((f" eval not implemented for {rec.unsupported} combinations (sampled "
                      "only)." if rec.unsupported else "")
                     + (f" {rec.timeouts} combinations slower than the per-combination limit "
                        f"of {cfg.combo_seconds:g} s (listed below)." if rec.timeouts else "")
                     + (f" Time budget ({cfg.model_seconds:g} s) spent: {rec.budget_stop} "
                        "combinations not run." if rec.budget_stop else ""))
            if extra:
                sweep_notes.append(f"{MODELS[k].label}:{extra}")
        a(f"| **all** | {tot.combos} | {tot.cases:,} | **{tot.nan}** | **{tot.inf}** | "
          f"**{tot.negative}** | {tot.non_unit} | **{tot.energy}** | **{tot.errors}** | "
          f"{tot.max_albedo:.4f} | {tot.seconds:.1f} |")
        a("")
        for n in sweep_notes:
            a(f"- {n}")
        a("")
        if tot.examples:
            a("First offending inputs:\n")
            a("```")
            L.extend(tot.examples[:20])
            a("```\n")
    if stress:
        a("OSL stress grid: the same kinds of extremes through the shaders, values fed by linked "
          "Value nodes (bypassing the sockets' ranges); every sphere's rim is a grazing view.\n")
        a("| environment | spheres | sphere pixels | NaN pixels | Inf pixels | negative pixels | render (s) |")
        a("|---|---|---|---|---|---|---|")
        for s in stress:
            a(f"| {s.env} | {s.spheres} | {s.pixels:,} | **{s.nan}** | **{s.inf}** | **{s.negative}** | {s.seconds:.1f} |")
        skipped = {m: w for s in stress for m, w in s.skipped.items()}
        for m, w in skipped.items():
            a(f"\n{MODELS[m].label}: not in the stress grid ({w}).")
        bad = [b for s in stress for b in s.bad]
        for b in bad[:20]:
            a(f"\n- bad sphere: {b[0]} {stability.describe(b[1])}: NaN {b[2]}, Inf {b[3]}, negative {b[4]}")
        a("")
    if lee:
        _write_lee(a, cfg, lee)
    a("## How to regenerate\n")
    a("`make report` (full, about 18-28 minutes on 2 cores), `make report QUICK=1` (about 5 "
      "minutes: fewer samples, smaller grids, a subset of the sweep), "
      "`python scripts/report.py --smoke` (seconds; used by the tests). Output: `report/` "
      "(this page, PNGs, `results.json`); the full run also refreshes the README figures in "
      "`docs/figures/`.")
    Path(path).write_text("\n".join(L) + "\n")


def _write_lee(a, cfg, lee):
    lc = cfg.lee
    a("## 5. Lee 2018 (V-grooves)\n")
    a("Lee, Jarabo, Jeon, Gutierrez, Kim 2018: multiple mirror reflection inside V-grooves in "
      "closed form (`lee_vgroove`, `osl/lee_vgroove.osl`, numpy twin `addon/lab/reference/lee.py`). "
      "Measured by `addon/lab/bench_lee.py` (`python -m addon.lab.bench_lee` runs it alone)"
      + (" at this mode's smaller settings, stated below." if cfg.mode != "full" else ".") + "\n")
    f = lee.get("furnace")
    if f:
        alphas, means, noise = f["alphas"], f["means"], f["noise"]
        a("### White furnace\n")
        a(f"A uniform white environment (L = 1), one row of spheres per model, alpha = "
          f"{', '.join(f'{x:g}' for x in alphas)} (roughness = sqrt(alpha)), {f['samples']} "
          f"samples per pixel, {f['cell_px']} px cells. A sphere that keeps all the energy is 1 "
          "everywhere and vanishes against the background; single scattering darkens, most at "
          "the rim.\n")
        a("![Lee white furnace](lee_furnace.png)\n")
        a("Sphere mean (pixels with mu >= 0.05, green channel) ± its standard error (pixel "
          "spread / sqrt(pixels): an upper bound where the expected value varies over the "
          "sphere, as for single scattering). Lee with F = 1: every sample weighs exactly 1, "
          "so zero noise. Walter GGX: height-correlated Smith, F = 1. Cook-Torrance: Beckmann, "
          "V-cavities, F >= 0.9996 (conductor n = 0.001, k = 100: the model has no F = 1 "
          "option). Cycles multi-GGX: `microfacet_multi_ggx_aniso`, white albedo.\n")
        from .bench_lee import furnace_markdown

        a(furnace_markdown(alphas, means, noise))
        a("")
        last = {k: v[-1] for k, v in means.items()}
        a(f"At alpha = {alphas[-1]:g} Lee keeps {last['Lee symmetric GGX']:.4f} of the energy, "
          f"Cycles' multi-GGX {last['Cycles multi-GGX']:.4f}; single scattering loses "
          f"{1 - last['Walter GGX (single)']:.0%} (Walter GGX) and "
          f"{1 - last['Cook-Torrance (single)']:.0%} (Cook-Torrance).\n")
    c = lee.get("cost")
    if c:
        st = c["_setup"]
        lo, hi = st["samples"]
        a("### Render cost per sample: Lee shader against Cook-Torrance\n")
        a(f"Gold, white furnace, one row of {st['spheres_per_row']} spheres (roughness "
          f"{', '.join(f'{r:g}' for r in st['roughness'])}, {st['cell_px']} px cells) per "
          "shader, all rows in ONE scene (scene sync and OSL JIT done once before timing, "
          f"{st['setup_seconds']:.1f} s). Each row rendered alone through a render border at "
          f"{lo} and {hi} samples, rows interleaved, {st['repeats']} repeats: the time per "
          f"sample is (t({hi}) - t({lo})) / {hi - lo}, which cancels the per-render overhead. "
          "Each number is taken within a repeat (rows rendered moments apart share the "
          "machine's load) and the median over the repeats shown; for the ratio to "
          "Cook-Torrance also its range.\n")
        a(f"| shader | ms per sample (row) | x Cook-Torrance | range over repeats | "
          f"render at {hi} samples (s) |")
        a("|---|---|---|---|---|")
        for k, v in c.items():
            if k.startswith("_"):
                continue
            a(f"| {k} | {v['ms_per_sample']:.3g} | **{v['ratio_to_cook_torrance']:.2f}** | "
              f"{v['ratio_min']:.2f} - {v['ratio_max']:.2f} | {v[f'seconds_at_{hi}']:.3g} |")
        a("")
    t = lee.get("tracer")
    if t:
        a("### Closed form against the brute-force tracer: time to the same albedo error\n")
        a(f"Directional albedo (green channel, gold, symmetric grooves) to an error of "
          f"{lc.target:g}. Closed form: the deterministic quadrature `lee.albedo` of order n "
          f"(n x n/2 groove normals); its error is the difference from order {lc.quad_ref} "
          f"(which itself moves by at most "
          f"{max(v['quad_ref_change'] for v in t.values()):.1g} from order {lc.quad_ref // 2}); "
          "the time is that of the first order from which every larger one is within the "
          f"target. Analytic sampler (`lee.sample`, what the shader does) and brute-force "
          f"tracer (`vgroove.trace`, rays bounced in explicit grooves): {lc.tracer_n:,} samples "
          "each, time scaled to a standard error equal to the target (t (s / target)^2). "
          "Last column: tracer mean - closed form, in the tracer's standard errors (a "
          "few units either way are chance).\n")
        a("| case | albedo | closed form: order, time | analytic sampler | brute-force tracer | "
          "tracer / closed form | tracer / sampler | tracer - closed form (s.e.) |")
        a("|---|---|---|---|---|---|---|---|")
        for k, v in t.items():
            cf = (f"{v['closed_form_order']}, {_secs(v['closed_form_s'])}"
                  if v["closed_form_order"] else "not reached")
            a(f"| {k} | {v['albedo_G']:.5f} | {cf} | {_secs(v['sampler_s'])} | "
              f"{_secs(v['tracer_s'])} | **{v['tracer_over_closed_form']:.3g}** | "
              f"{v['tracer_over_sampler']:.2f} | {v['tracer_z']:+.1f} |")
        a("")
    m = lee.get("moments")
    if m:
        a("### Accuracy of the moment rules\n")
        a("The directional moments (E, Vn, Vt) that the reference image is built from "
          "(`lee.moments`, default rules `lee.MOMENT_NODES`) against rules with about 8x the "
          "nodes (symmetric: a 384 x 384 tensor rule; asymmetric: 8x the partner points), gold, "
          f"at mu = {', '.join(f'{x:g}' for x in lc.moment_mus)}.\n")
        a("| grooves, distribution, alpha | max abs error of (E, Vn, Vt) | seconds per mu "
          "(default rule) |")
        a("|---|---|---|")
        for k, v in m.items():
            a(f"| {k} | {v['max_abs_error']:.2g} | {v['seconds_per_mu']:.3g} |")
        a("")


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return None
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else str(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if hasattr(obj, "__dataclass_fields__"):
        return _jsonable({k: v for k, v in asdict(obj).items() if k not in ("image", "layout")})
    return obj


# -- orchestration ---------------------------------------------------------------------------
README_FIGURES = ("rmse_vs_time.png", "sampler_weights.png", "fireflies.png")


def run(mode: str = "full", out_dir="report", figures_dir=None, progress=None,
        sections=("convergence", "samplers", "refcost", "stability", "lee")) -> dict:
    progress = progress or Progress()
    cfg = config(mode)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    info = machine_info()
    progress(f"mode {mode}: {info['cpu']}, {info['cores']} cores, Blender {info.get('blender')}, "
             f"numpy {info['numpy']}, Python {info['python']}")
    notes = []
    rows = build_rows(notes)
    for n in notes:
        progress(n)
    tables = ReferenceTables(cfg.moment_order)
    conv = table = sun_cal = study = ff = refcost = sweep = gpu = lee = None
    stress = []
    if "convergence" in sections:
        if "sun" in cfg.envs:
            sun_cal = calibrate_sun(progress)
        conv = convergence(cfg, rows, tables, progress, sun_cal)
        table = time_table(conv, rows)
        plot_convergence(conv, rows, out / "rmse_vs_time.png")
        plot_grids(conv, rows, out / "grids.png")
        devices = optix_devices()
        if devices:
            try:
                gpu = optix_comparison(cfg, rows, tables, progress)
            except Exception as exc:  # noqa: BLE001 - report it rather than lose the page
                notes.append(f"OptiX comparison failed: {type(exc).__name__}: {exc}")
        else:
            progress("no OptiX device reported by bpy: the GPU comparison is not run")
    if "samplers" in sections:
        study = sampler_study(cfg, progress)
        plot_sampler_study(study, cfg, out / "sampler_weights.png")
        ff = fireflies(cfg, progress, out)
        plot_fireflies(ff, out / "fireflies.png")
    if "refcost" in sections:
        refcost = reference_cost(cfg, rows, progress)
    if "stability" in sections:
        progress("numpy stability sweep")
        sweep = stability.numpy_sweep(albedo_samples=cfg.albedo_samples, stride=cfg.sweep_stride,
                                      progress=progress, combo_seconds=cfg.combo_seconds,
                                      model_seconds=cfg.model_seconds)
        tot = sweep["_total"]
        progress(f"numpy sweep: {tot.cases:,} cases, NaN {tot.nan}, Inf {tot.inf}, negative "
                 f"{tot.negative}, energy {tot.energy}")
        if cfg.stress != "none":
            for env_key in ("gradient", "sun"):
                progress(f"OSL stress grid under {env_key}")
                s = stability.osl_stress_grid(env_key, quick=cfg.stress == "quick",
                                              sun=add_sun if env_key == "sun" else None)
                progress(f"OSL stress grid {env_key}: {s.spheres} spheres, NaN {s.nan}, Inf "
                         f"{s.inf}, negative {s.negative}")
                stress.append(s)
        else:
            notes.append("smoke mode: the OSL stress grid is not rendered.")
    if "lee" in sections:
        lee = lee_section(cfg, progress, notes)
        if lee.get("furnace"):
            plot_lee_furnace(lee["furnace"], out / "lee_furnace.png")
    total = time.perf_counter() - start
    write_page(out / "report.md", cfg, info, notes, rows, conv, table, sun_cal, study, ff,
               refcost, sweep, stress, gpu, total, lee)
    results = {"mode": mode, "machine": info, "notes": notes, "seconds": total,
               "time_to_target": table, "sun_calibration": sun_cal, "reference_cost": refcost,
               "gpu": gpu,
               "convergence": {e: d["series"] for e, d in conv["envs"].items()} if conv else None,
               "sampler_study": {m: {f"{s} r={r}": v for (s, r), v in res.items()}
                                 for m, res in (study or {}).items()},
               "fireflies": ff["stats"] if ff else None,
               "stability": {k: v for k, v in (sweep or {}).items()},
               "osl_stress": [{k: v for k, v in asdict(s).items() if k not in ("image", "layout")}
                              for s in stress],
               "lee": ({k: ({kk: vv for kk, vv in v.items() if kk not in ("image", "layout")}
                            if k == "furnace" else v) for k, v in lee.items()}
                       if lee else None)}
    (out / "results.json").write_text(json.dumps(_jsonable(results), indent=1))
    if figures_dir:
        fig_dir = Path(figures_dir)
        fig_dir.mkdir(parents=True, exist_ok=True)
        for name in README_FIGURES:
            if (out / name).exists():
                shutil.copy(out / name, fig_dir / name)
    progress(f"wrote {out / 'report.md'} ({total:.0f} s)")
    return results
