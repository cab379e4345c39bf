"""The convergence study's rows: model variants x samplers x estimators (catalog driven: the
light-sampled split, "+ native", and the stochastic estimator), and Cycles' native
closures for the same BSDF; which models have a reference, and whose numpy eval is fast."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .. import grid, stability
from ..reference import make_bsdf
from ..reference.quadrature import tabulate_moments
from ...catalog import MODELS
from .config import GOLD, LAMP_ENVS


@dataclass
class Row:
    key: str  # unique, e.g. "walter_reflection ggx F=1 / vndf"
    label: str
    model_id: str | None  # None for a native closure
    values: dict
    variant: str  # groups a model variant's samplers with its native closure
    sampler: str  # sampler item ("vndf + native" with the light-sampled split), or "native"
    native_kind: str | None = None


# Model variants and the native Cycles closure for the same BSDF (height-correlated Smith G2),
# None where there is none.
VARIANTS = {
    "cook_torrance": [("Cook-Torrance gold", {"specular": 1.0, **GOLD}, None)],
    "walter_reflection": [
        ("Walter GGX F=1", {"distribution": "ggx", "fresnel_type": "none"}, "ggx"),
        ("Walter Beckmann F=1", {"distribution": "beckmann", "fresnel_type": "none"}, "beckmann"),
        ("Walter GGX gold", {"distribution": "ggx", **GOLD}, "conductor"),
        # Separable masking is not Cycles' BSDF: its row is held to its own numpy reference,
        # and timed against Cycles' conductor (the closest native closure) in the same run.
        ("Walter GGX gold separable", {"distribution": "ggx", "masking": "separable", **GOLD},
         None),
    ],
    "walter_glass": [("Walter GGX glass 1.5", {"distribution": "ggx", "ior": 1.5}, "glass")],
    # Lee's V-grooves (catalog defaults: symmetric, gold) beside Cycles' multiscatter GGX gold,
    # a different model, held to a render of itself (SELF_REFERENCE_FACTOR).
    "lee_vgroove": [(MODELS["lee_vgroove"].label, {}, "multi_ggx")],
    # Heitz 2016 (catalog defaults: GGX gold) beside the same closure, for the same reason.
    "heitz2016": [(MODELS["heitz2016"].label, {}, "multi_ggx")],
}

# Variants without a native closure of their own, timed against another variant's.
RATIO_TO = {"Walter GGX gold separable": "Walter GGX gold"}

NATIVE_TWIN = {
    "ggx": ("walter_reflection", {"distribution": "ggx", "fresnel_type": "none"}),
    "beckmann": ("walter_reflection", {"distribution": "beckmann", "fresnel_type": "none"}),
    "conductor": ("walter_reflection", {"distribution": "ggx", **GOLD}),
    "glass": ("walter_glass", {"distribution": "ggx", "ior": 1.5}),
    "multi_ggx": None,  # no numpy twin: held to a render of itself
}
# A native without a numpy twin is measured against its own render at this many times the
# study's largest sample count (its noise then adds about 3% to the errors measured).
SELF_REFERENCE_FACTOR = 16


def self_referenced(row, env_key: str | None = None) -> bool:
    """Whether a row is held to a render of itself (SELF_REFERENCE_FACTOR) under `env_key`: a
    native closure without a numpy twin anywhere; under a lamp (LAMP_ENVS), a model whose numpy
    evaluation is a Monte Carlo estimate (Heitz 2016's walk), too noisy for the per-pixel
    quadrature of a lamp. Such a row's error is its noise alone: it measures convergence, not
    bias (the render tests hold the model to numpy)."""
    if row.model_id is None:
        return NATIVE_TWIN[row.native_kind] is None
    return env_key in LAMP_ENVS and stochastic_eval(row.model_id, row.values)


def stochastic_eval(model_id: str, values: dict) -> bool:
    return bool(getattr(make_bsdf(model_id, values), "stochastic_eval", False))


def reference_available(model_id: str) -> str:
    """'' when the numpy twin and the OSL shader exist, else why not."""

    if model_id not in stability.osl_models():
        return "no OSL shader yet"
    try:
        make_bsdf(model_id, {})
    except Exception as exc:  # noqa: BLE001
        return f"no numpy reference yet ({type(exc).__name__}: {exc})"
    # The reference image needs the moment tables: probe them cheaply, with a time limit.

    try:
        with stability._time_limit(5.0):
            tabulate_moments(make_bsdf(model_id, {"roughness": 0.5}), n_mu=4, order=2)
    except stability._Timeout:
        return "its reference moment tables are too slow for the report (probe > 5 s)"
    except Exception as exc:  # noqa: BLE001
        return f"no reference moment tables ({type(exc).__name__}: {exc})"
    return ""


def eval_is_fast(model_id: str, values: dict, limit: float = 3.0) -> bool:
    """Whether 20,000 evaluations take under `limit` seconds (the sun term needs millions); a
    walk's evaluation (Heitz 2016) is a Monte Carlo estimate, held to a render of itself under
    the lamps instead (`self_referenced`). Measured on a 2-core
    AMD EPYC at roughness 1: Walter and Cook-Torrance under 0.01 s, Lee's symmetric grooves
    0.63 s, asymmetric 1.9 s. (A limit of 0.5 s left Lee's rows out of every lamp light on
    that machine and kept them on a faster one: the limit only guards against a model whose
    lamp reference would take hours.)"""

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
        estimators = (model.param("estimator").items
                      if any(p.id == "estimator" for p in model.params) else (None,))
        for label, values, native in variants:
            for s in samplers:
                for est in estimators:
                    v = dict(values, **({"sampler": s} if s else {}),
                             **({"estimator": est} if est else {}))
                    name = (s or "own") + (" + native" if est == "light_sampled" else "")
                    rows.append(Row(f"{label} / {name}", label, model_id, v, label, name))
            if native:
                rows.append(Row(f"{label} / native", label, None, {}, label, "native", native))
    return rows


def twin(row: Row, env_key: str | None = None) -> tuple:
    """(model id, values) of the numpy model a row is measured against ((None, None): itself)."""
    if self_referenced(row, env_key):
        return None, None
    return (row.model_id, row.values) if row.model_id else NATIVE_TWIN[row.native_kind]


def specs_for(row: Row, roughness, env_key: str | None = None) -> list:
    """SphereSpecs of a row (for natives: the model variant they stand for, for the reference;
    None for a self-referenced row)."""
    if self_referenced(row, env_key):
        return [None] * len(roughness)
    if row.model_id is not None:
        return [grid.SphereSpec(row.model_id, {**row.values, "roughness": r}, f"{row.key} r={r}")
                for r in roughness]
    model_id, values = NATIVE_TWIN[row.native_kind]
    return [grid.SphereSpec(model_id, {**values, "roughness": r}, f"{row.key} r={r}")
            for r in roughness]
