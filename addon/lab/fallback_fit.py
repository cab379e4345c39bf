"""The fitted corrections of the native branches (addon/fallback.py, FITTED), fitted to the
numpy reference (`make fallback-fit`).

Without OSL, Lee's V-grooves render as Cycles' Metallic BSDF (Multiscatter GGX; Beckmann has no
multiscatter variant in Cycles, so single scattering) or, for Fresnel None, a Glossy BSDF
(addon/fallback.py). Cycles' energy compensation (Kulla & Conty 2017, "Revisiting physically
based shading at Imageworks", appendix) keeps a white metal's energy, as the grooves do, but a
groove's later bounces keep more light where the Fresnel reflectance is low: on gold's blue
channel at roughness 0.7 Lee's albedo is 27% above the native one at grazing incidence. The
native branch therefore adds a correction lobe, a single-scattering Glossy BSDF with the same
distribution and roughness, whose colour

    C(r, x, F0) = sum_ijk c_ijk r^i x^j F0^k,   x = 1 - n.wi (Layer Weight's Facing),
                                                 F0 = the channel's reflectance at normal incidence

is fitted here by weighted least squares so that native + correction has the model's directional
albedo: E_native + E_1 max(C, 0) = E_lee, with E_1 the single-scattering albedo for F = 1, and
the relative error as the residual. One polynomial per distribution and groove shape; the
training set is the presets' metals, four dielectrics and F = 1 over roughness 0.05-1.

Cook-Torrance's branch (a Lambertian share plus the specular share of a Beckmann metal with
Smith masking) falls short of the model's V-cavity masking at grazing incidence (blue_rubber:
-12% at mu = 0.01); its specular share gets a correction lobe fitted the same way, one
polynomial for metals and one for dielectrics (the model has no Fresnel None; against a single
one for both: mean relative error of the metals 1.11% -> 1.07%, of the dielectrics 2.53% ->
2.50%, their worst 7.3% and 12.9% -> 14.3%; gold_cook_torrance's worst 2.65% -> 1.57%).

Heitz 2016's metals get a lobe as Lee's (the walk against Cycles' Multiscatter GGX, whose average
Fresnel is an F82 fit). Its glass, and Walter's Separable masking, get a scale instead: the
native closure times max(C, 0), fitted so that E_native max(C, 0) = E. Heitz's glass needs it
because the native Glass BSDF (Multiscatter GGX) keeps all the light while the walk, as the
shader renders it, loses what it sends forward through the interface (docs/models.md, sec. 5:
up to a tenth at grazing incidence); Separable masking shadows more than Cycles'
Height-correlated closure. Heitz's moments are Monte Carlo (HEITZ_WALKS walks per incidence,
seeded by the inputs, so a fit and its test read the same numbers). Which enum splits a
model's fit, and which items are a lobe or a scale: fallback.FITTED.

The native albedo is Cycles' closure in numpy: single scattering from the Walter reference
(Cycles' GGX and Beckmann with Height-correlated masking are the same BSDF, exact conductor
Fresnel from Blender 5.0), times Cycles' energy compensation for Multiscatter GGX,
1 + F_ms (1 - E) / E with F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg)) (Kulla & Conty, eq. in
the appendix, one F_ss cancelled), where Cycles estimates a conductor's average Fresnel F_ss from
an F82 fit to F(1) and F(1/7) (Hoffman 2019, "Fresnel equations considered harmful") and reads
E and E_avg from 32-point tables (here: exact quadrature, so the model is a little sharper than
Cycles). Measured against renders by `make report` (section "fallback").
"""
from __future__ import annotations

import json
import zlib
from typing import NamedTuple

import numpy as np

from .. import fallback, presets
from ..catalog import MODELS
from .reference import make_bsdf, quadrature
from .reference.fresnel import fresnel_conductor
from .reference.heitz2016.moments import directional_moments_mc

LEE, COOK_TORRANCE, HEITZ = MODELS["lee_vgroove"], MODELS["cook_torrance"], MODELS["heitz2016"]
WALTER_GLASS = MODELS["walter_glass"]
FIT_MODELS = [MODELS[m] for m in fallback.FITTED]
# The Heitz 2016 walk's moments are Monte Carlo (reference/heitz2016/moments.py): this many walks
# per incidence, from a seed fixed by the sample's inputs (its standard error about 2e-4 for a
# metal, up to 2e-3 for glass at grazing incidence: far below the errors fitted).
HEITZ_WALKS = 40_000
ORDERS = {"roughness": 3, "facing": 3, "f0": 2}  # highest power of r, x, F0
TERMS = [(i, j, k) for i in range(ORDERS["roughness"] + 1) for j in range(ORDERS["facing"] + 1)
         for k in range(ORDERS["f0"] + 1)]
ROUGHNESS = tuple(np.round(np.r_[0.05, np.arange(0.1, 1.01, 0.1)], 2))
MU, _ = np.polynomial.legendre.leggauss(12)
MU = tuple(0.5 * (MU + 1.0))
DIELECTRIC_IORS = (1.33, 1.5168, 1.8, 2.42)
WHITE = {"fresnel_type": "none"}


class Variant(NamedTuple):
    """One fitted polynomial: the model, its distribution and the item of the model's enum
    that has polynomials of its own (fallback.FITTED: Lee's groove shape, Cook-Torrance's and
    Heitz's Fresnel, Walter's masking)."""
    model: str
    distribution: str
    item: str

    @property
    def key(self) -> str:  # fallback.fit()["variants"] key, read by fallback.py
        return "/".join((self.model, self.distribution, self.item))

    @property
    def lobe(self) -> bool:
        """An added lobe (True) or a scale of the native closure (False): fallback.FITTED."""
        return self.item in fallback.FITTED[self.model].lobe

    @property
    def glass(self) -> bool:
        """The native branch is a Glass BSDF (reflection and transmission)."""
        return self.model == WALTER_GLASS.id or (self.model == HEITZ.id
                                                 and self.item == "dielectric")


def distributions(model) -> tuple:
    """The model's distributions (Cook-Torrance has Beckmann's alone, no switch)."""
    ids = {p.id for p in model.params}
    return model.param("distribution").items if "distribution" in ids else ("beckmann",)


VARIANTS = [Variant(m.id, d, item) for m in FIT_MODELS for d in distributions(m)
            for item in fallback.FITTED[m.id].lobe + fallback.FITTED[m.id].scale]


def variant_of(model_id: str, values: dict) -> Variant | None:
    """The variant whose polynomial the branch uses for resolved catalog `values` (None: the
    plain branch, e.g. Walter's Height-correlated masking, which is exact)."""
    if model_id not in fallback.FITTED:
        return None
    variant = Variant(model_id, values.get("distribution", "beckmann"),
                      values[fallback.FITTED[model_id].enum])
    return variant if variant in VARIANTS else None


# -- Cycles' native closures in numpy ----------------------------------------------------------
# Moments are (E, Vn, Vt), each (len(mu), 3): albedo and the reflected light's first moment
# along n and toward wi's tangent (reference/quadrature.py).
def single_moments(distribution: str, r: float, mu, fresnel: str = "none", n=(1, 1, 1),
                   k=(0, 0, 0)):
    """Single-scattering GGX or Beckmann with Height-correlated masking (Walter 2007; Cycles'
    Glossy and Metallic BSDFs)."""
    bsdf = make_bsdf("walter_reflection", {
        "roughness": r, "distribution": distribution, "masking": "height_correlated",
        "fresnel_type": fresnel, "n": tuple(n), "k": tuple(k)})
    return np.stack(quadrature.directional_moments(bsdf, np.asarray(mu, dtype=float)))


def single_albedo(distribution: str, r: float, mu):
    """E_1(mu) (len(mu), 3): the albedo for F = 1."""
    return single_moments(distribution, r, mu)[0]


def average_albedo(distribution: str, r: float, order: int = 32) -> float:
    """E_avg = 2 integral_0^1 E_1(mu) mu dmu (Gauss-Legendre)."""
    x, w = np.polynomial.legendre.leggauss(order)
    mu = 0.5 * (x + 1.0)
    return float(np.sum(w * mu * single_albedo(distribution, r, mu)[:, 0]))


def fss_conductor(n, k):
    """Cycles' average Fresnel of a conductor: the F82 model (F0, and B from F at cos = 1/7)
    integrated, F_ss = F0 + (1 - F0) / 21 - B / 126, clamped to [0, 1]."""
    n, k = np.asarray(n, dtype=float), np.asarray(k, dtype=float)
    f0, f82 = fresnel_conductor(1.0, n, k), fresnel_conductor(1.0 / 7.0, n, k)
    f5 = (6.0 / 7.0) ** 5
    b = 7.0 / (f5 * 6.0 / 7.0) * (f0 + (1.0 - f0) * f5 - f82)
    return np.clip(f0 + (1.0 - f0) / 21.0 - b / 126.0, 0.0, 1.0)


def glass_moments(distribution: str, r: float, mu, ior: float):
    """Single-scattering rough glass with Height-correlated masking (Walter 2007; Cycles' Glass
    BSDF, GGX or Beckmann): moments over the whole sphere (reference/quadrature.py)."""
    bsdf = make_bsdf(WALTER_GLASS.id, {"roughness": r, "distribution": distribution,
                                       "masking": "height_correlated", "ior": ior})
    return np.stack(quadrature.directional_moments(bsdf, np.asarray(mu, dtype=float)))


def native_moments(variant: Variant, r: float, mu, material: dict):
    """The native branch without its correction (addon/fallback.py): for Lee and Heitz,
    Metallic (n, k) or Glossy (F = 1) with Multiscatter GGX or single-scattering Beckmann,
    or Heitz's glass, a Glass BSDF; for Walter and Cook-Torrance single scattering."""
    distribution = variant.distribution
    multiscatter = distribution == "ggx" and variant.model in (LEE.id, HEITZ.id)
    if variant.glass:
        moments = glass_moments(distribution, r, mu, material["ior"])
        # Cycles' Multiscatter GGX glass divides by the single-scattering albedo (reflection
        # plus transmission, read from its table): it keeps all the light.
        return moments / moments[0][None, :, :1] if multiscatter else moments
    if material["fresnel_type"] == "none":
        moments, f_ss = single_moments(distribution, r, mu), 1.0
    else:
        n, k = conductor_of(material)
        moments, f_ss = single_moments(distribution, r, mu, "conductor", n, k), fss_conductor(n, k)
    if not multiscatter:
        return moments
    e_1 = single_albedo("ggx", r, mu)[:, :1]
    e_avg = average_albedo("ggx", r)
    f_ms = f_ss * e_avg / (1.0 - f_ss * (1.0 - e_avg))
    return moments * (1.0 + f_ms * (1.0 - e_1) / e_1)


def conductor_of(material: dict):
    """(n, k) of the Metallic BSDF the branch uses: a dielectric is a conductor with k = 0."""
    if material.get("fresnel_type", "dielectric") == "dielectric":
        return (material["ior"],) * 3, (0.0, 0.0, 0.0)
    return tuple(material["n"]), tuple(material["k"])


def f0_of(material: dict) -> np.ndarray:
    if material.get("fresnel_type", "dielectric") == "none":
        return np.ones(3)
    n, k = conductor_of(material)
    return fresnel_conductor(1.0, np.asarray(n), np.asarray(k))


def exact_moments(variant: Variant, r: float, mu, material: dict):
    """The model's moments: Lee by its closed-form quadrature, Heitz 2016 by Monte Carlo
    (HEITZ_WALKS walks per incidence, seeded by the inputs), Cook-Torrance's specular share
    alone (specular 1) and Walter by reference/quadrature.py."""
    values = dict(material, roughness=r)
    mu = np.asarray(mu, dtype=float)
    if variant.model == LEE.id:
        values.update(distribution=variant.distribution, groove=variant.item)
        return np.stack(make_bsdf(LEE.id, values).directional_moments(mu))
    if variant.model == HEITZ.id:
        bsdf = make_bsdf(HEITZ.id, dict(values, distribution=variant.distribution))
        seed = zlib.crc32(json.dumps([variant.key, r, material], sort_keys=True).encode())
        m = directional_moments_mc(bsdf.walk, mu, HEITZ_WALKS, np.random.default_rng(seed),
                                   bsdf.max_order)
        return np.stack((m.E, m.Vn, m.Vt))
    if variant.model == COOK_TORRANCE.id:
        values["specular"] = 1.0
    else:
        values.update(distribution=variant.distribution, masking=variant.item)
    bsdf = make_bsdf(variant.model, values)
    return np.stack(quadrature.directional_moments(bsdf, mu))


# -- the polynomial ------------------------------------------------------------------------------
def basis(r, x, f0, terms=TERMS) -> np.ndarray:
    r, x, f0 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (r, x, f0)))
    return np.stack([r ** i * x ** j * f0 ** k for i, j, k in terms], axis=-1)


def correction(coefficients, r, x, f0, terms=TERMS):
    """C(r, x, F0) before the clamp at 0: what fallback.polynomial_color builds in nodes."""
    return basis(r, x, f0, terms) @ np.asarray(coefficients, dtype=float)


def samples(variant: Variant, r, material, mu=MU, offset=0.0, scale=1.0):
    """Arrays over (mu, channel): r, x, F0, whether the fit adds a lobe (else it scales the
    native closure); the moments (3, ...) of the model, of the native branch and of the
    single-scattering lobe with F = 1 (what a lobe adds to; zero for a scale). The model and
    its branch are both offset + scale * (the part fitted): Cook-Torrance's diffuse share and
    its specular."""
    mu = np.asarray(mu, dtype=float)
    exact = exact_moments(variant, r, mu, material)
    shape = exact.shape[1:]
    native = native_moments(variant, r, mu, material)
    single = (single_moments(variant.distribution, r, mu) if variant.lobe
              else np.zeros_like(native))
    return {"r": np.full(shape, r), "x": np.broadcast_to((1.0 - mu)[:, None], shape),
            "f0": np.broadcast_to(f0_of(material), shape), "lobe": np.full(shape, variant.lobe),
            "offset": np.broadcast_to(offset, exact.shape), "scale": np.full(shape, scale),
            "exact": offset + scale * exact, "native": native, "single": single}


def branch_moments(s: dict, coefficients=None):
    """The native branch's moments, with its correction (a lobe added or a scale) if
    coefficients are given."""
    part = s["native"]
    if coefficients is not None:
        c = np.maximum(correction(coefficients, s["r"], s["x"], s["f0"]), 0.0)
        part = np.where(s["lobe"], part + s["single"] * c, part * c)
    return s["offset"] + s["scale"] * part


def albedo_error(branch, exact) -> np.ndarray:
    """Relative albedo error of a branch's moments against the exact model's."""
    return branch[0] / exact[0] - 1.0


def errors(s: dict, coefficients=None) -> np.ndarray:
    """Relative albedo error of the branch against the model."""
    return albedo_error(branch_moments(s, coefficients), s["exact"])


def angle(moments):
    """Angle in degrees from the normal of the mean direction of the reflected light, (Vn, Vt)
    / E (negative: toward the mirror direction)."""
    return np.degrees(np.arctan2(moments[2], moments[1]))


def lobe_error(branch, exact) -> np.ndarray:
    """Angle in degrees between the mean directions of the light a branch and the exact model
    reflect: how far the highlight moves."""
    return np.abs(angle(branch) - angle(exact))


def lobe_errors(s: dict, coefficients=None) -> np.ndarray:
    return lobe_error(branch_moments(s, coefficients), s["exact"])


def training_materials(model: str = LEE.id) -> list[dict]:
    """The presets' metals, four dielectrics and F = 1, as far as the model has each Fresnel
    (a model without a Fresnel menu is glass: the dielectrics' IORs alone)."""
    ids = {p.id for p in MODELS[model].params}
    if "fresnel_type" not in ids:
        return [{"ior": ior} for ior in DIELECTRIC_IORS]
    metals, seen = [], set()
    for p in sorted(presets.load_all().values(), key=lambda p: p.id):
        v = p.params
        if v.get("fresnel_type") == "conductor" and (tuple(v["n"]), tuple(v["k"])) not in seen:
            seen.add((tuple(v["n"]), tuple(v["k"])))
            metals.append({"fresnel_type": "conductor", "n": list(v["n"]), "k": list(v["k"])})
    dielectrics = [{"fresnel_type": "dielectric", "ior": ior} for ior in DIELECTRIC_IORS]
    fresnel_none = [WHITE] if "none" in MODELS[model].param("fresnel_type").items else []
    return metals + dielectrics + fresnel_none


def variant_materials(variant: Variant) -> list[dict]:
    """The training materials of a variant: the model's, of the variant's Fresnel kind where
    that is what splits the fit."""
    materials = training_materials(variant.model)
    if fallback.FITTED[variant.model].enum != "fresnel_type":
        return materials
    return [m for m in materials if m["fresnel_type"] == variant.item]


def stack(many: list[dict]) -> dict:
    """Samples of many (roughness, material) pairs as flat arrays (moments: (3, N))."""
    def flat(a):
        return a.reshape(3, -1) if a.ndim == 3 else a.ravel()
    return {key: np.concatenate([flat(s[key]) for s in many], axis=-1) for key in many[0]}


def fit(s: dict) -> np.ndarray:
    """Least squares of the relative error (training samples: offset 0, scale 1): of a lobe,
    (E_1 C - (E - E_native)) / E; of a scale, (E_native C - E) / E."""
    exact, native, single = s["exact"][0], s["native"][0], s["single"][0]
    a = basis(s["r"], s["x"], s["f0"]) * (np.where(s["lobe"], single, native) / exact)[:, None]
    b = np.where(s["lobe"], (exact - native) / exact, 1.0)
    coefficients, *_ = np.linalg.lstsq(a, b, rcond=None)
    return coefficients


def summary(err: np.ndarray) -> dict:
    return {"worst": float(np.abs(err).max()), "mean": float(np.abs(err).mean())}


def report(s: dict, coefficients) -> dict:
    """Albedo (relative) and lobe (degrees) errors of the branch with the correction, and of
    the plain branch (without it)."""
    return {"albedo": summary(errors(s, coefficients)),
            "lobe": summary(lobe_errors(s, coefficients)),
            "albedo_plain": summary(errors(s)), "lobe_plain": summary(lobe_errors(s))}


def preset_samples(preset) -> tuple[str, dict]:
    """The preset's variant key and samples (Cook-Torrance: its diffuse share as the offset,
    its specular as the scale)."""
    v = preset.resolved()
    material = {k: v[k] for k in ("fresnel_type", "ior", "n", "k") if k in v}
    variant = variant_of(preset.model_id, v)
    if preset.model_id != COOK_TORRANCE.id:
        return variant.key, samples(variant, v["roughness"], material)
    diffuse = np.broadcast_to((1.0 - v["specular"]) * np.asarray(v["base_color"]), (len(MU), 3))
    offset = np.stack([diffuse, 2.0 / 3.0 * diffuse, 0.0 * diffuse])  # Lambertian moments
    return variant.key, samples(variant, v["roughness"], material, offset=offset,
                                scale=v["specular"])


def preset_errors(preset, data: dict) -> dict:
    variant, s = preset_samples(preset)
    return report(s, data["variants"][variant]["coefficients"])


def measured_presets():
    """The presets whose branch has a fitted correction (variant_of)."""
    return [p for p in sorted(presets.load_all().values(), key=lambda p: p.id)
            if variant_of(p.model_id, p.resolved()) is not None]


def run(progress=print) -> dict:
    """Fit every variant; return the data file's content."""
    out = {"format": 1,
           "about": "Generated by `make fallback-fit` (addon/lab/fallback_fit.py); do not edit.",
           "orders": ORDERS, "terms": [list(t) for t in TERMS],
           "catalog": catalog_items(),
           "training": {"roughness": list(ROUGHNESS), "mu": list(MU),
                        "materials": {m: training_materials(m) for m in catalog_items()}},
           "variants": {}, "presets": {}}
    for variant in VARIANTS:
        s = stack([samples(variant, r, m) for r in ROUGHNESS for m in variant_materials(variant)])
        c = fit(s)
        entry = out["variants"][variant.key] = {"coefficients": c.tolist(), **report(s, c)}
        progress(f"fallback fit {variant.key}: albedo worst "
                 f"{entry['albedo_plain']['worst']:.1%} -> {entry['albedo']['worst']:.1%}, "
                 f"mean {entry['albedo_plain']['mean']:.2%} -> {entry['albedo']['mean']:.2%}; "
                 f"lobe mean {entry['lobe_plain']['mean']:.1f} -> "
                 f"{entry['lobe']['mean']:.1f} deg")
    for p in measured_presets():
        out["presets"][p.id] = preset_errors(p, out)
    return out


def catalog_items() -> dict:
    """The catalog's items the variants depend on, per model (a drift check)."""
    return {m.id: {p.id: list(p.items) for p in m.params
                   if p.id in ("distribution", "groove", "fresnel_type", "masking")}
            for m in FIT_MODELS}


def write(data: dict, path=None) -> None:
    """One line per top-level entry, per variant and per preset (reviewable diffs)."""
    def block(name, value, last):
        if isinstance(value, dict) and name in ("variants", "presets"):
            inner = ",\n".join(f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in value.items())
            text = f" {json.dumps(name)}: {{\n{inner}\n }}"
        else:
            text = f" {json.dumps(name)}: {json.dumps(value)}"
        return text + ("" if last else ",")
    items = list(data.items())
    lines = [block(k, v, i == len(items) - 1) for i, (k, v) in enumerate(items)]
    (path or fallback.FIT_PATH).write_text("{\n" + "\n".join(lines) + "\n}\n", encoding="utf-8")

