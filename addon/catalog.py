"""The catalog of models and their parameters: the single source of truth.

Node groups (addon/nodes.py), preset validation, the numpy reference (addon/lab/reference) and the
tests are all driven from MODELS below. Imports nothing but the standard library, so it loads
without bpy.

Parameter ids are the OSL shader parameter names and the keys of the reference's parameter dicts;
labels are what the user sees on the node group. Enums are passed to OSL as ints (their index in
`items`), so an unlinked enum is a constant the OSL compiler folds away (docs/cycles-osl.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

FLOAT, COLOR, ENUM = "float", "color", "enum"


@dataclass(frozen=True)
class Param:
    id: str
    label: str
    kind: str
    default: object
    # Range accepted by the node socket and enforced (clamped) by the shader and the reference.
    min: float | None = None
    max: float | None = None
    items: tuple[str, ...] = ()
    doc: str = ""

    def index(self, item: str) -> int:
        """OSL int code of an enum item."""
        return self.items.index(item)

    def clamp(self, value):
        """The documented clamp: NaN -> default, then [min, max], per channel for colours."""
        if self.kind == ENUM:
            if isinstance(value, str):
                if value not in self.items:
                    raise ValueError(f"{self.label}: {value!r} is not one of {self.items}")
                return value
            i = int(value)
            return self.items[min(max(i, 0), len(self.items) - 1)]
        if self.kind == COLOR:
            return tuple(_clamp_scalar(v, d, self.min, self.max) for v, d in zip(value, self.default))
        return _clamp_scalar(value, self.default, self.min, self.max)


def _clamp_scalar(v, default, lo, hi):
    v = float(v)
    if math.isnan(v):
        v = float(default)
    if lo is not None:
        v = max(v, lo)
    if hi is not None:
        v = min(v, hi)
    return v


@dataclass(frozen=True)
class Model:
    id: str
    label: str
    year: int
    shader: str  # osl/<shader>.osl
    params: tuple[Param, ...]
    doc: str = ""
    # Kinds of light the model scatters ("diffuse", "glossy", "transmission", "transparent"):
    # scene specialization (addon/specialize.py) sets Cycles' bounces from them.
    tags: tuple[str, ...] = field(default=())

    def param(self, pid: str) -> Param:
        for p in self.params:
            if p.id == pid:
                return p
        raise KeyError(f"{self.id} has no parameter {pid!r}")

    def defaults(self) -> dict:
        return {p.id: p.default for p in self.params}

    def resolve(self, values: dict | None = None) -> dict:
        """Defaults overlaid with `values`, each clamped to its documented range.

        Unknown keys are refused with a message naming them (presets and tests go through here).
        """
        values = dict(values or {})
        unknown = set(values) - {p.id for p in self.params}
        if unknown:
            raise KeyError(f"{self.id}: unknown parameter(s) {sorted(unknown)}; "
                           f"accepted: {[p.id for p in self.params]}")
        return {p.id: p.clamp(values.get(p.id, p.default)) for p in self.params}


# Shared parameters ------------------------------------------------------------------------
# Roughness as in Cycles: alpha = roughness^2. Roughness 0 is a perfect mirror (delta lobe).
ROUGHNESS = Param("roughness", "Roughness", FLOAT, 0.5, 0.0, 1.0,
                  doc="Cycles roughness r; alpha = r^2. 0 is a perfect mirror.")
IOR = Param("ior", "IOR", FLOAT, 1.5, 0.01, 100.0,
            doc="Relative index of refraction eta = n_t / n_i of a dielectric. NaN -> 1.5.")
# Gold at R 650 nm, G 550 nm, B 450 nm (Johnson & Christy 1972, PRB 6, 4370; interpolated).
CONDUCTOR_N = Param("n", "N (complex IOR)", COLOR, (0.156, 0.424, 1.38), 0.001, 100.0,
                    doc="Real part n of a conductor's complex IOR n + ik, per RGB channel.")
CONDUCTOR_K = Param("k", "K (extinction)", COLOR, (3.602, 2.472, 1.914), 0.0, 100.0,
                    doc="Imaginary part k of a conductor's complex IOR, per RGB channel.")
TINT = Param("base_color", "Color", COLOR, (1.0, 1.0, 1.0), 0.0, 1.0,
             doc="Multiplies the specular lobe (1 is physical).")

# Every enum, with its items in OSL code order. A model's enum offers a prefix of these items,
# so one item has one int code in every shader; the add-on generates the OSL #defines
# (MFL_<ENUM>_<ITEM>) from this table.
ENUMS: dict[str, tuple[str, ...]] = {
    "distribution": ("ggx", "beckmann"),
    "masking": ("height_correlated", "separable"),
    "fresnel_type": ("conductor", "dielectric", "none"),
    "sampler": ("dcos", "vndf", "vcavity"),
    "groove": ("symmetric", "asymmetric"),
}
SAMPLERS = ENUMS["sampler"]
SAMPLER_DOC = ("dcos: Walter 2007, m ~ D(m)(m.n); vndf: Heitz & d'Eon 2014 visible normals of the "
               "Smith microsurface; vcavity: visible normals of the V-cavity microsurface "
               "(Heitz 2014, seed fig. 14)")

MODELS: dict[str, Model] = {}


def _add(model: Model) -> Model:
    for p in model.params:
        if p.kind == ENUM:
            full = ENUMS[p.id]
            assert p.items == full[:len(p.items)], f"{model.id}.{p.id}: items must prefix {full}"
    MODELS[model.id] = model
    return model


COOK_TORRANCE = _add(Model(
    id="cook_torrance",
    label="Microfacet Cook-Torrance (1982)",
    year=1982,
    shader="cook_torrance",
    tags=("diffuse", "glossy"),
    doc="f = d R_d + s R_s, s + d = 1; R_s = F D G / (4 (n.wi)(n.wo)) with Beckmann D, "
        "V-cavity G (Torrance-Sparrow) and exact Fresnel; R_d Lambertian (native diffuse()).",
    params=(
        Param("base_color", "Color", COLOR, (0.8, 0.8, 0.8), 0.0, 1.0, doc="Diffuse colour of R_d."),
        Param("specular", "Specular", FLOAT, 0.5, 0.0, 1.0,
              doc="Specular fraction s; the diffuse fraction is d = 1 - s."),
        ROUGHNESS,
        Param("fresnel_type", "Fresnel", ENUM, "dielectric", items=ENUMS["fresnel_type"][:2],
              doc="Exact conductor Fresnel with N, K, or exact dielectric Fresnel with IOR."),
        IOR, CONDUCTOR_N, CONDUCTOR_K,
        Param("sampler", "Sampler", ENUM, "vcavity", items=SAMPLERS, doc=SAMPLER_DOC),
    ),
))

WALTER_REFLECTION = _add(Model(
    id="walter_reflection",
    label="Microfacet Reflection (Walter 2007)",
    year=2007,
    shader="walter_reflection",
    tags=("glossy",),
    doc="f_r = F G2 D / (4 |wi.n| |wo.n|) with GGX or Beckmann D, separable or "
        "height-correlated Smith G2, and exact Fresnel.",
    params=(
        TINT,
        ROUGHNESS,
        Param("anisotropy", "Anisotropy", FLOAT, 0.0, 0.0, 1.0,
              doc="As Cycles: aspect = sqrt(1 - 0.9 a); alpha_x = r^2 / aspect, "
                  "alpha_y = r^2 aspect, along the surface tangent."),
        Param("distribution", "Distribution", ENUM, "ggx", items=ENUMS["distribution"]),
        Param("masking", "Masking", ENUM, "height_correlated",
              items=ENUMS["masking"],
              doc="Smith G2: height-correlated 1/(1+L(wi)+L(wo)) (Heitz 2014, Cycles) or "
                  "separable G1(wi) G1(wo) (Walter 2007)."),
        Param("fresnel_type", "Fresnel", ENUM, "conductor", items=ENUMS["fresnel_type"],
              doc="Exact conductor (N, K), exact dielectric (IOR), or none (F = 1)."),
        IOR, CONDUCTOR_N, CONDUCTOR_K,
        Param("sampler", "Sampler", ENUM, "vndf", items=SAMPLERS[:2], doc=SAMPLER_DOC),
    ),
))


WALTER_GLASS = _add(Model(
    id="walter_glass",
    label="Microfacet Glass (Walter 2007)",
    year=2007,
    shader="walter_glass",
    tags=("glossy", "transmission", "transparent"),
    doc="Rough dielectric interface: f_r = F G2 D / (4 |wi.n| |wo.n|) plus Walter's BTDF "
        "f_t = |wi.h||wo.h| / (|wi.n||wo.n|) n_o^2 (1 - F) G2 D / (n_i wi.h + n_o wo.h)^2, "
        "GGX or Beckmann D, separable or height-correlated G2, exact Fresnel with total "
        "internal reflection; Cycles' transport convention (no 1/eta^2 factor). IOR 1 is a "
        "clean pass-through; roughness 0 is perfect glass.",
    params=(
        TINT,
        ROUGHNESS,
        IOR,
        Param("distribution", "Distribution", ENUM, "ggx", items=ENUMS["distribution"]),
        Param("masking", "Masking", ENUM, "height_correlated", items=ENUMS["masking"],
              doc="Smith G2 for both lobes: height-correlated 1/(1+L(wi)+L(wo)) (as Cycles and "
                  "pbrt-v4) or separable G1(wi) G1(wo) (Walter 2007)."),
        Param("sampler", "Sampler", ENUM, "vndf", items=SAMPLERS[:2], doc=SAMPLER_DOC),
    ),
))


LEE_VGROOVE = _add(Model(
    id="lee_vgroove",
    label="Microfacet Multi-Bounce V-Groove (Lee 2018)",
    year=2018,
    shader="lee_vgroove",
    tags=("glossy",),
    doc="Kaleidoscopic multiple mirror reflection inside V-grooves (Lee, Jarabo, Jeon, Gutierrez, "
        "Kim 2018): a groove and an entry point are sampled, the bounce count and the exit "
        "direction follow in closed form, and the sample carries the product of the exact "
        "Fresnel terms of its bounces. With F = 1 every sample weighs exactly 1 (no energy "
        "loss at any roughness). Derivation: docs/lee-asymmetric-grooves.md.",
    params=(
        TINT,
        ROUGHNESS,
        Param("distribution", "Distribution", ENUM, "ggx", items=ENUMS["distribution"]),
        Param("groove", "Groove", ENUM, "symmetric", items=ENUMS["groove"],
              doc="symmetric: both walls drawn from D (Heitz's V-cavities); asymmetric: the "
                  "partner wall from the size-biased law D(theta) sin^2(theta), which keeps "
                  "the projected-area distribution of normals equal to D."),
        Param("fresnel_type", "Fresnel", ENUM, "conductor", items=ENUMS["fresnel_type"],
              doc="Exact conductor (N, K), exact dielectric (IOR), or none (F = 1), per bounce."),
        IOR, CONDUCTOR_N, CONDUCTOR_K,
        Param("max_bounces", "Max Bounces", FLOAT, 0.0, 0.0, 1000.0,
              doc="0 = derived from the roughness (paths beyond carry < 1e-4 of the energy); "
                  "otherwise the Fresnel loop stops at this count (later bounces count as "
                  "F = 1; the exit direction is always exact)."),
    ),
))


def alphas(roughness: float, anisotropy: float = 0.0) -> tuple[float, float]:
    """Cycles' mapping from (roughness, anisotropy) to (alpha_x, alpha_y)."""
    a = roughness * roughness
    aspect = math.sqrt(1.0 - 0.9 * min(max(anisotropy, 0.0), 1.0))
    return a / aspect, a * aspect
