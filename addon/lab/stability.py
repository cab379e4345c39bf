"""Numerical stability on stiff and extreme inputs: a numpy sweep and an OSL stress grid.

`numpy_sweep` evaluates and samples every catalog model that has a numpy reference over a dense
grid of extreme inputs: roughness from 0 (and the alpha = 1e-7 delta threshold, straddled) to 1
and beyond (clamped by the catalog), NaN and negative roughness, incidence up to 90 degrees minus
1e-6 (and exactly 90), eta in {1, 1 +- 1e-6, 1/10, 10, 100} (and 0, NaN, clamped), complex-IOR
extremes, wo = wi, wo ~ wi, the mirror direction, wo.h -> 0, grazing wo, and uniforms at 0 and
1 - 2^-53. It counts NaN, Inf and negative values (f, f cos, sample weight, pdf), non-unit
sampled directions, and energy violations: a Monte Carlo albedo above 1 by more than its noise
bound (z_crit standard errors, Sidak-corrected over all albedo tests, plus 1e-9).

`osl_stress_grid` renders the same kinds of extremes through the OSL shaders, the values fed
through linked Value nodes (which bypass the node sockets' own ranges), and counts NaN, Inf and
negative pixels; every sphere's rim is a grazing view.

New catalog models join automatically: parameters are enumerated from the catalog (enums over
all their items, known parameters over their extreme lists, any other float over
min / default / max and beyond). A model whose `make_bsdf` is missing is listed as skipped.
Nothing here needs bpy except `osl_stress_grid`.
"""
from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..catalog import COLOR, ENUM, MODELS
from ..shaders import OSL_DIR, uses_lamps
from .grid import sidak_z
from .reference import make_bsdf
from .reference.microfacet import ALPHA_DELTA

NAN = float("nan")
ALPHA_DELTA_ROUGHNESS = math.sqrt(ALPHA_DELTA)  # roughness whose alpha is the delta threshold
ROUGHNESS = (0.0, 1e-9, 3.1e-4, ALPHA_DELTA_ROUGHNESS, 3.2e-4, 1e-3, 0.01, 0.05, 0.2, 0.5, 0.8,
             1.0, 1.5, 100.0, -1.0, NAN)
ETAS = (1.0, 1.0 + 1e-6, 1.0 - 1e-6, 0.1, 10.0, 100.0, 0.0, NAN)
CONDUCTORS = (  # (n, k) per RGB channel
    ((0.001,) * 3, (0.0,) * 3), ((0.001,) * 3, (100.0,) * 3), ((100.0,) * 3, (0.0,) * 3),
    ((100.0,) * 3, (100.0,) * 3), ((1.0,) * 3, (0.0,) * 3), ((1.0,) * 3, (1e-6,) * 3),
    ((0.156, 0.424, 1.38), (3.602, 2.472, 1.914)), ((-1.0, NAN, 0.0), (NAN, -2.0, 0.0)),
)
OTHER_FLOATS = {"anisotropy": (0.0, 0.5, 1.0, 2.0), "specular": (0.0, 0.5, 1.0, NAN)}
# Incidence angles in degrees (90 - 1e-6 is the limit; exactly 90 must give 0).
THETA_I = (0.0, 1e-4, 30.0, 60.0, 80.0, 89.0, 89.9, 89.999, 90.0 - 1e-6, 90.0)
MAX_COMBOS = 6000  # per model (a deterministic subsample beyond)


# -- parameter combinations ------------------------------------------------------------------
def _float_candidates(param):
    if param.id == "roughness":
        return ROUGHNESS
    if param.id == "ior":
        return ETAS
    if param.id in OTHER_FLOATS:
        return OTHER_FLOATS[param.id]
    lo, hi = param.min, param.max
    values = [param.default, NAN]
    if lo is not None:
        values += [lo, lo - 1.0]
    if hi is not None:
        values += [hi, hi * 2.0 + 1.0]
    return tuple(values)


def parameter_combos(model_id: str, max_combos: int = MAX_COMBOS, roughness=None) -> list:
    """Raw (unclamped) parameter dicts for a model: the product of each parameter's extremes,
    with the IOR varied only where it is used (dielectric Fresnel, or no Fresnel switch) and
    (n, k) only for conductor Fresnel."""
    model = MODELS[model_id]
    ids = {p.id for p in model.params}
    axes = []
    for p in model.params:
        # The estimator changes how the shader samples, not the BSDF the numpy twin evaluates
        # (the split's own twin is tested in tests/test_reference_split.py).
        if p.id in ("n", "k", "ior", "estimator"):
            continue
        if p.kind == ENUM:
            axes.append((p.id, p.items))
        elif p.kind == COLOR:
            axes.append((p.id, (p.default,)))
        elif p.id == "roughness" and roughness is not None:
            axes.append((p.id, tuple(roughness)))
        else:
            axes.append((p.id, _float_candidates(p)))
    combos = []
    for values in itertools.product(*(v for _, v in axes)):
        base = dict(zip((k for k, _ in axes), values))
        fresnel = base.get("fresnel_type")
        if "ior" in ids and fresnel in (None, "dielectric"):
            combos += [{**base, "ior": eta} for eta in ETAS]
        elif {"n", "k"} <= ids and fresnel == "conductor":
            combos += [{**base, "n": n, "k": k} for n, k in CONDUCTORS]
        else:
            combos.append(base)
    # A deterministic shuffle: a stride or a time budget then still covers every axis.
    order = np.random.default_rng(1).permutation(len(combos))[:max_combos]
    return [combos[i] for i in order]


def describe(values: dict) -> str:
    parts = []
    for k, v in values.items():
        if isinstance(v, tuple):
            v = "(" + ", ".join(f"{x:.4g}" for x in v) + ")"
        elif isinstance(v, float):
            v = f"{v:.6g}"
        parts.append(f"{k}={v}")
    return " ".join(parts)


# -- directions and uniforms -----------------------------------------------------------------
def _dir(theta, phi):
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def incident_directions() -> np.ndarray:
    """(n_wi, 3): THETA_I at azimuth 0, and the non-trivial ones again at azimuth 0.7 rad
    (anisotropic lobes are not symmetric there)."""
    theta = np.radians(THETA_I)
    wi = [_dir(t, 0.0) for t in theta] + [_dir(t, 0.7) for t in theta[2:]]
    return np.array(wi)


def outgoing_directions(wi: np.ndarray, rng) -> np.ndarray:
    """(n_wo, 3) stiff outgoing directions for one wi, both hemispheres."""
    mirror = wi * np.array([-1.0, -1.0, 1.0])
    flat = np.array([wi[0], wi[1], 0.0])
    fl = np.linalg.norm(flat)
    flat = flat / fl if fl > 0 else np.array([1.0, 0.0, 0.0])
    wo = [wi, mirror, -wi, -mirror, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])]
    for eps in (1e-12, 1e-7, 1e-4):  # wo ~ wi and ~ mirror
        wo += [_unit(wi + eps * np.array([0.3, 0.9, -0.2])), _unit(mirror + eps * np.array([0.5, -0.4, 0.7]))]
    for dz in (0.0, 1e-9, 1e-6, 1e-3):  # wo.h -> 0: wo nearly opposite wi
        wo += [_unit(np.array([-flat[0], -flat[1], dz])), _unit(-wi + np.array([0.0, 0.0, dz]))]
    graze = np.radians(90.0 - 1e-6)
    for phi in (0.0, 0.5 * np.pi, np.pi, 1.3 * np.pi):
        wo += [_dir(graze, phi), _dir(np.pi - graze, phi), _dir(0.5 * np.pi, phi)]
    wo += list(_unit(rng.normal(size=(16, 3))))
    return np.array(wo)


EXTREME_U = (0.0, 1e-12, 0.5, 1.0 - 1e-12, 1.0 - 2.0 ** -53)


def uniforms(n_dims: int, rng, n_random: int = 48) -> np.ndarray:
    """(n_u, n_dims): every pair of EXTREME_U in the first two dimensions (the others random,
    then all extreme alike), and random points."""
    ex = np.array(EXTREME_U)
    pairs = np.array(list(itertools.product(ex, repeat=2)))
    rest = rng.random((len(pairs), n_dims - 2))
    same = np.repeat(ex[:, None], n_dims, 1)
    return np.concatenate([np.concatenate([pairs, rest], 1), same, rng.random((n_random, n_dims))])


# -- the sweep -----------------------------------------------------------------------------
@dataclass
class ModelSweep:
    model_id: str
    combos: int = 0
    eval_cases: int = 0
    sample_cases: int = 0
    albedo_tests: int = 0
    nan: int = 0
    inf: int = 0
    negative: int = 0
    non_unit: int = 0
    energy: int = 0
    errors: int = 0  # exceptions raised on an input (each one is a failure)
    timeouts: int = 0  # combinations stopped by the per-combination time limit (listed)
    budget_stop: int = 0  # combinations left out when the model's time budget ran out
    unsupported: int = 0  # combinations whose eval raises NotImplementedError (not counted)
    max_albedo: float = 0.0
    examples: list = field(default_factory=list)
    skipped: str = ""
    seconds: float = 0.0

    @property
    def cases(self) -> int:
        return self.eval_cases + self.sample_cases

    @property
    def failures(self) -> int:
        return self.nan + self.inf + self.negative + self.non_unit + self.energy + self.errors


def _note(rec: ModelSweep, kind: str, values: dict, detail: str, limit: int = 12):
    if len(rec.examples) < limit:
        rec.examples.append(f"{kind}: {rec.model_id} {describe(values)} {detail}")


def _count(rec, name, arr, values, what, where_fn, signed=False):
    """Count NaN / Inf / negative (unless `signed`) entries of arr, one per case; record the
    first offending input."""
    arr = np.asarray(arr, dtype=float)
    per = arr.reshape(arr.shape[0], -1) if arr.ndim > 1 else arr[:, None]
    nan = np.isnan(per).any(1)
    inf = np.isinf(per).any(1)
    neg = np.zeros_like(nan) if signed else (per < 0).any(1) & ~nan
    for label, mask in (("NaN", nan), ("Inf", inf), ("negative", neg)):
        c = int(mask.sum())
        if c:
            setattr(rec, {"NaN": "nan", "Inf": "inf", "negative": "negative"}[label],
                    getattr(rec, {"NaN": "nan", "Inf": "inf", "negative": "negative"}[label]) + c)
            i = int(np.argmax(mask))
            _note(rec, f"{label} in {what}.{name}", values, where_fn(i) + f" -> {per[i]}")


U_DIMS = 8  # uniforms drawn per sample; a model takes the first 3, 4, 6 or 8 it needs


def _sample(bsdf, wi, u):
    """bsdf.sample with the fewest uniforms it accepts (3 for a microfacet normal, one more for
    a lobe choice, more for a groove: the catalog does not say, so try)."""
    for n in (3, 4, 6, U_DIMS):
        try:
            return bsdf.sample(wi, u[..., :n])
        except (IndexError, ValueError):
            if n == U_DIMS:
                raise


class _Timeout(Exception):
    pass


class _time_limit:
    """SIGALRM-based limit (main thread on Unix; elsewhere no limit)."""

    def __init__(self, seconds):
        self.seconds = seconds
        self.armed = False

    def __enter__(self):
        import signal
        import threading

        if self.seconds and hasattr(signal, "setitimer") and \
                threading.current_thread() is threading.main_thread():
            def handler(*_):
                raise _Timeout()
            self.old = signal.signal(signal.SIGALRM, handler)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)
            self.armed = True
        return self

    def __exit__(self, *exc):
        import signal

        if self.armed:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self.old)
        return False


def _check_combo(rec, bsdf, values, WI_E, WO_E, WI_S, U_S, WI_A, UA, albedo_wi,
                 albedo_samples, z_crit):
    """Evaluate, sample and test the albedo of one BSDF; counts go into rec."""
    try:
        f = bsdf.eval(WI_E, WO_E)
    except NotImplementedError as exc:
        rec.unsupported += 1
        _note(rec, "eval not implemented (not counted)", values, str(exc), limit=3)
        f = None
    if f is not None:
        if hasattr(bsdf, "eval_cos"):
            fc = bsdf.eval_cos(WI_E, WO_E)
        else:
            fc = np.asarray(f, float) * np.abs(WO_E[:, 2])[:, None]
        where_e = lambda i: f"wi={WI_E[i].tolist()} wo={WO_E[i].tolist()}"  # noqa: E731
        _count(rec, "eval", f, values, "eval", where_e)
        _count(rec, "eval_cos", fc, values, "eval", where_e)
        rec.eval_cases += len(WI_E)
    wo, weight, pdf = _sample(bsdf, WI_S, U_S)
    where_s = lambda i: f"wi={WI_S[i].tolist()} u={U_S[i].tolist()}"  # noqa: E731
    _count(rec, "weight", weight, values, "sample", where_s)
    _count(rec, "pdf", pdf, values, "sample", where_s)
    _count(rec, "wo", wo, values, "sample", where_s, signed=True)
    wo = np.asarray(wo, dtype=float)
    live = np.asarray(weight, float).reshape(len(wo), -1).max(1) > 0
    bad_len = live & ~(np.abs(np.linalg.norm(wo, axis=-1) - 1.0) < 1e-6)
    if bad_len.any():
        rec.non_unit += int(bad_len.sum())
        i = int(np.argmax(bad_len))
        _note(rec, "non-unit wo", values, where_s(i) + f" -> {wo[i]}")
    rec.sample_cases += len(WI_S)
    # Energy: MC albedo (sample weights of the sampled lobes + analytic diffuse).
    _, wa, _ = _sample(bsdf, WI_A, UA)
    wa = np.nan_to_num(np.asarray(wa, float), nan=0.0, posinf=0.0)
    mean = wa.mean(1)
    se = wa.std(1, ddof=1) / math.sqrt(albedo_samples)
    diffuse = np.asarray(getattr(bsdf, "diffuse_albedo", 0.0), dtype=float)
    albedo = mean + diffuse
    rec.max_albedo = max(rec.max_albedo, float(albedo.max()))
    over = albedo - 1.0 > z_crit * se + 1e-9
    rec.albedo_tests += len(albedo_wi)
    if over.any():
        rows = np.nonzero(over.any(1))[0]
        rec.energy += len(rows)
        r = int(rows[0])
        _note(rec, "energy", values, f"wi={albedo_wi[r].tolist()} albedo={albedo[r]} "
              f"stderr={se[r]}")


def numpy_sweep(max_combos: int = MAX_COMBOS, albedo_samples: int = 1024, stride: int = 1,
                models=None, roughness=None, progress=None, seed: int = 0,
                factory=None, combo_seconds: float = 20.0, model_seconds: float = 240.0) -> dict:
    """The sweep over every catalog model (or `models`). Returns {model_id: ModelSweep} plus
    '_total' (a ModelSweep summing all) and '_z_crit' (the energy threshold in std errors).
    `factory(model_id, values)` builds the BSDF (default: the numpy reference's make_bsdf).
    A combination taking over `combo_seconds` is stopped and listed (a stiff input that is
    slow); a model stops after `model_seconds` (the combinations left out are counted)."""
    build = factory or make_bsdf

    rng = np.random.default_rng(seed)
    wis = incident_directions()
    wos = [outgoing_directions(w, rng) for w in wis]
    WI_E = np.concatenate([np.repeat(wis[i][None], len(wos[i]), 0) for i in range(len(wis))])
    WO_E = np.concatenate(wos)
    U = uniforms(U_DIMS, rng)
    WI_S = np.repeat(wis, len(U), 0)
    U_S = np.tile(U, (len(wis), 1))
    # Albedo: incidences where it is well defined (wi.z > 0), stratified-free plain MC.
    albedo_wi = wis[[0, 2, 3, 4, 5, 6, 8]]
    UA = rng.random((len(albedo_wi), albedo_samples, U_DIMS))
    WI_A = np.repeat(albedo_wi[:, None], albedo_samples, 1)

    plan = {}
    for model_id in (models or list(MODELS)):
        plan[model_id] = parameter_combos(model_id, max_combos, roughness)[::stride]
    n_albedo_tests = sum(len(c) for c in plan.values()) * len(albedo_wi)
    z_crit = max(sidak_z(n_albedo_tests * 3, 1e-3), 4.0)
    out = {}
    total = ModelSweep("all models")
    for model_id, combos in plan.items():
        rec = ModelSweep(model_id)
        start = time.perf_counter()
        try:
            build(model_id, {})
        except Exception as exc:  # noqa: BLE001 - a model without a numpy twin yet
            rec.skipped = f"no numpy reference ({type(exc).__name__}: {exc})"
            out[model_id] = rec
            continue
        for ci, values in enumerate(combos):
            if time.perf_counter() - start > model_seconds:
                rec.budget_stop = len(combos) - ci
                break
            if progress and ci % 500 == 0:
                progress(f"numpy sweep {model_id}: combination {ci + 1}/{len(combos)}")
            bsdf = build(model_id, values)
            rec.combos += 1
            with np.errstate(all="ignore"):
                try:
                    with _time_limit(combo_seconds):
                        _check_combo(rec, bsdf, values, WI_E, WO_E, WI_S, U_S, WI_A, UA,
                                     albedo_wi, albedo_samples, z_crit)
                except _Timeout:
                    rec.timeouts += 1
                    _note(rec, f"slower than {combo_seconds:g} s (stopped)", values, "")
                except Exception as exc:  # noqa: BLE001 - an exception is a finding too
                    rec.errors += 1
                    _note(rec, "exception", values, f"{type(exc).__name__}: {exc}")
        rec.seconds = time.perf_counter() - start
        out[model_id] = rec
        for name in ("combos", "eval_cases", "sample_cases", "albedo_tests", "nan", "inf",
                     "negative", "non_unit", "energy", "errors", "unsupported", "timeouts",
                     "budget_stop"):
            setattr(total, name, getattr(total, name) + getattr(rec, name))
        total.max_albedo = max(total.max_albedo, rec.max_albedo)
        total.examples += rec.examples
        total.seconds += rec.seconds
    out["_total"] = total
    out["_z_crit"] = z_crit
    return out


# -- OSL stress grid -----------------------------------------------------------------------
STRESS_ROUGHNESS = (-1.0, 0.0, 1e-9, 3.1e-4, 3.2e-4, 1e-3, 0.01, 1.0, 2.0, NAN)
STRESS_ETA = (0.0, 0.1, 1.0 - 1e-6, 1.0, 1.0 + 1e-6, 10.0, 100.0, NAN, -3.0)


def osl_models() -> list:
    """Catalog models whose OSL source exists (a model can be catalogued before its shader)."""
    return [m for m, model in MODELS.items() if (OSL_DIR / f"{model.shader}.osl").exists()]


def _reads_lamps(model, roughness) -> bool:
    """Whether a shader may read the lamps at this raw roughness: every one takes its mirror
    path, lamps unread, below alpha = ALPHA_DELTA (the catalog's clamp first)."""
    return model.param("roughness").clamp(roughness) >= ALPHA_DELTA_ROUGHNESS


def stress_cases(quick: bool = False, models=None, lamp_paths: bool = False) -> list:
    """(model_id, raw values) for the OSL stress grid: per model and per combination of its
    sampler, distribution and estimator switches, roughness extremes, IOR extremes (at roughness
    0 and 0.3, dielectric Fresnel where there is a switch) and conductor extremes (roughness
    0.3). `lamp_paths`: only the cases that may read the lamps: shaders with the lamp table,
    the light-sampled estimator (every shader gates the lamps on it), above the mirror's
    roughness (_reads_lamps)."""
    cases = []
    for model_id in (models if models is not None else list(MODELS)):
        model = MODELS[model_id]
        if lamp_paths and not uses_lamps(model):
            continue
        ids = {p.id for p in model.params}
        switches = [p for p in model.params if p.id in ("sampler", "distribution", "estimator")]
        items = [("light_sampled",) if p.id == "estimator" and lamp_paths else p.items
                 for p in switches]
        for combo in itertools.product(*items):
            base = dict(zip((p.id for p in switches), combo))
            rough = STRESS_ROUGHNESS[::3] if quick else STRESS_ROUGHNESS
            if lamp_paths:
                rough = [r for r in rough if _reads_lamps(model, r)]
            cases += [(model_id, {**base, "roughness": r}) for r in rough]
            if "ior" in ids:
                fres = {"fresnel_type": "dielectric"} if "fresnel_type" in ids else {}
                for r in ((0.3,) if quick else (0.0, 0.3)):
                    etas = STRESS_ETA[::2] if quick else STRESS_ETA
                    cases += [(model_id, {**base, **fres, "roughness": r, "ior": e}) for e in etas]
            if {"n", "k"} <= ids and "fresnel_type" in ids:
                conds = CONDUCTORS[::3] if quick else CONDUCTORS
                cases += [(model_id, {**base, "fresnel_type": "conductor", "roughness": 0.3,
                                      "n": n, "k": k}) for n, k in conds]
            if "specular" in ids and not quick:
                cases += [(model_id, {**base, "specular": s, "roughness": 0.5})
                          for s in (-1.0, 0.0, 2.0, NAN)]
    return cases


def linked_material(model_id: str, values: dict, name: str):
    """A maker of a material whose group node gets `values` (floats and colours) through links
    from Value / Combine XYZ nodes, so that the OSL clamps are what is tested (enums are set on
    the group's sockets)."""
    def make():
        from . import harness

        return harness.linked_model_material(model_id, values, name)
    return make


def numeric_values(model_id: str, values: dict) -> dict:
    """The values that are not menu choices (floats and colours)."""
    return {k: v for k, v in values.items() if MODELS[model_id].param(k).kind != ENUM}


def per_object_materials(cases) -> list:
    """One material per case, shared by the cases of the same model and menu choices, whose
    numeric inputs are read per object (harness.attribute_model_material)."""
    from . import harness

    made, mats = {}, []
    for model_id, values in cases:
        enums = {k: v for k, v in values.items() if k not in numeric_values(model_id, values)}
        key = (model_id, tuple(sorted(enums.items())),
               tuple(sorted(numeric_values(model_id, values))))
        if key not in made:
            made[key] = harness.attribute_model_material(model_id, enums, key[2],
                                                         f"stress {len(made)}")
        mats.append(made[key])
    return mats


@dataclass
class StressResult:
    env: str
    spheres: int
    pixels: int
    nan: int
    inf: int
    negative: int
    seconds: float
    bad: list  # (model_id, values, nan, inf, negative) per offending sphere
    skipped: dict = field(default_factory=dict)  # model_id -> why
    image: np.ndarray | None = None
    layout: object = None


def count_bad_pixels(layout, image, cases) -> tuple:
    index, _, _ = layout.pixel_geometry()
    px = image[..., :3]
    sphere = index >= 0
    nan = np.isnan(px).any(-1)
    inf = np.isinf(px).any(-1)
    neg = (px < 0).any(-1)
    bad = []
    for i, (model_id, values) in enumerate(cases):
        sel = index == i
        c = (int(nan[sel].sum()), int(inf[sel].sum()), int(neg[sel].sum()))
        if any(c):
            bad.append((model_id, values) + c)
    # Background pixels count too (they must be the environment).
    return int(sphere.sum()), int(nan.sum()), int(inf.sum()), int(neg.sum()), bad


def osl_stress_grid(env_name: str = "gradient", samples: int = 16, cell_px: int = 16,
                    quick: bool = False, cols: int = 12, seed: int = 7,
                    sun=None, lamp_paths: bool = False,
                    per_object: bool = False) -> StressResult:
    """Render the stress cases through the OSL shaders and count bad pixels. `env_name` is a
    key of grid.ENVIRONMENTS, or 'sun' with `sun` a callable(scene) adding the light;
    `lamp_paths` keeps the cases that may read it (stress_cases). The values come from Value
    nodes (constants, which Cycles and OSL's optimizer fold into one shader group per case),
    or with `per_object` from each sphere's own attributes (read as the shader runs, one
    group per model and menu choice: a third of the groups to compile under the sun)."""
    from .. import nodes
    from . import grid, harness

    scene = harness.new_scene()
    skipped = {m: "no OSL source" for m in MODELS if m not in osl_models()}
    for m in osl_models():
        try:
            nodes.ensure_group(m)
        except Exception as exc:  # noqa: BLE001 - a shader that does not compile is reported
            skipped[m] = f"does not compile: {exc}"
    cases = stress_cases(quick, [m for m in MODELS if m not in skipped], lamp_paths)
    env = grid.ENVIRONMENTS.get(env_name) or grid.Environment(env_name, 0.05)
    layout = grid.GridLayout(rows=-(-len(cases) // cols), cols=cols, cell_px=cell_px)
    mats = per_object_materials(cases) if per_object else \
        [harness.linked_model_material(m, v, f"stress {i}") for i, (m, v) in enumerate(cases)]
    harness.build_grid_scene(layout, mats, env, samples, seed)
    if per_object:
        for i, (model_id, values) in enumerate(cases):
            harness.set_object_values(scene.objects[harness.sphere_name(i)],
                                      numeric_values(model_id, values))
    if sun is not None:
        sun(scene)
    image, seconds = harness.render(scene)
    pixels, nan, inf, neg, bad = count_bad_pixels(layout, image, cases)
    return StressResult(env_name, len(cases), pixels, nan, inf, neg, seconds, bad, skipped,
                        image, layout)
