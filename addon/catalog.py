"""The catalog of models and their parameters: the single source of truth.

Node groups (addon/nodes.py), preset validation, the numpy reference (addon/lab/reference) and the
tests are all driven from MODELS below. Imports nothing but the standard library, so it loads
without bpy.

Parameter ids are the OSL shader parameter names and the keys of the reference's parameter dicts;
labels are what the user sees on the node group (and the socket names everywhere). Enums are
passed to OSL as ints (their index in `items`), so an unlinked enum is a constant the OSL compiler
folds away (docs/cycles-osl.md); the node shows them as menus of the items' display labels
(`ENUM_ITEMS`) where Blender has menu sockets in shader node groups.

`doc` is what the artist reads: the socket tooltip, the node group's description. It says in
plain words what the input does to the look; the formulas behind it are in docs/models.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

FLOAT, COLOR, ENUM = "float", "color", "enum"
# How a parameter is shown on the node (Param.socket), where its kind alone does not say:
# FACTOR: a float as a 0-1 slider; VECTOR: a colour-kind (RGB) value as three plain numbers, as
# Blender's Metallic BSDF shows its complex IOR (values far above 1 are the point there).
FACTOR, VECTOR = "FACTOR", "VECTOR"


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
    socket: str = ""  # FACTOR, VECTOR or "" (the kind's own socket)

    def index(self, item: str) -> int:
        """OSL int code of an enum item."""
        return self.items.index(item)

    @property
    def item_labels(self) -> tuple[str, ...]:
        """Display labels of an enum's items, in code order (the menu's entries)."""
        return tuple(ITEM_LABELS[self.id][item] for item in self.items)

    def item_label(self, item: str) -> str:
        """The display label of an enum item (given by id)."""
        if item not in self.items:
            raise ValueError(f"{self.label}: {item!r} is not one of {self.items}")
        return ITEM_LABELS[self.id][item]

    def item_doc(self, item: str) -> str:
        return ITEM_DOCS[self.id][item]

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
# Roughness as in Cycles: alpha = roughness^2 (docs/models.md, Conventions). 0 is a perfect
# mirror (delta lobe).
ROUGHNESS = Param("roughness", "Roughness", FLOAT, 0.5, 0.0, 1.0, socket=FACTOR,
                  doc="Microsurface roughness: 0 is a mirror, higher values blur reflections into "
                      "a wider, dimmer highlight, 1 is very rough.")
IOR = Param("ior", "IOR", FLOAT, 1.5, 0.01, 100.0,
            doc="Index of refraction of a non-metal (1.33 water, 1.5 glass or plastic, 2.42 "
                "diamond): higher values reflect more, most visibly when the surface faces you. "
                "Used when Fresnel is Dielectric.")
# Gold at R 650 nm, G 550 nm, B 450 nm (Johnson & Christy 1972, PRB 6, 4370; interpolated).
# Real and imaginary part of the complex IOR n + ik, per RGB channel (docs/models.md, sec. 1).
CONDUCTOR_N = Param("n", "N (complex IOR)", COLOR, (0.156, 0.424, 1.38), 0.001, 100.0,
                    socket=VECTOR,
                    doc="Refractive index of a metal for red, green and blue, as measured "
                        "(with K it gives the metal its colour; the presets cite their "
                        "sources). Used when Fresnel is Conductor.")
CONDUCTOR_K = Param("k", "K (extinction)", COLOR, (3.602, 2.472, 1.914), 0.0, 100.0,
                    socket=VECTOR,
                    doc="Extinction coefficient of a metal for red, green and blue, as measured: "
                        "higher values make that colour reflect more strongly. Used when Fresnel "
                        "is Conductor.")
# The weight multiplies the specular lobe (white is physical).
TINT = Param("base_color", "Specular Tint", COLOR, (1.0, 1.0, 1.0), 0.0, 1.0,
             doc="Colours the reflection; white is physically correct, darker or coloured "
                 "values are an artistic departure.")

# Every enum item, in OSL code order: (id, display label, what it does). A model's enum offers
# a prefix of these items, so one item has one int code in every shader; the add-on generates
# the OSL #defines (MFL_<ENUM>_<ITEM>) from the ids, the node's menus show the labels.
ENUM_ITEMS: dict[str, tuple[tuple[str, str, str], ...]] = {
    "distribution": (
        ("ggx", "GGX", "Bright core with long soft tails, as Cycles' default glossy"),
        ("beckmann", "Beckmann", "A tighter highlight that fades quickly at its edge"),
    ),
    "masking": (
        ("height_correlated", "Height-correlated",
         "Shadowing between microfacets as Cycles computes it"),
        ("separable", "Separable",
         "Shadowing as in the 2007 paper: a little darker at grazing angles on rough surfaces"),
    ),
    "fresnel_type": (
        ("conductor", "Conductor", "A metal, coloured by N and K"),
        ("dielectric", "Dielectric", "A non-metal such as plastic, lacquer or glass, set by IOR"),
        ("none", "None", "No Fresnel effect: full-strength reflection at every angle"),
    ),
    "sampler": (
        ("dcos", "D·cos (Walter 2007)", "The original 2007 sampling: noisier, most of all at "
                                        "grazing angles"),
        ("vndf", "Visible normals (Heitz 2014)", "Samples only the facets facing the viewer: "
                                                 "least noise for the Walter models"),
        ("vcavity", "V-cavity visible normals", "The same for V-shaped cavities: least noise "
                                                "for Cook-Torrance"),
    ),
    "groove": (
        ("symmetric", "Symmetric", "Both walls of a groove slope alike"),
        ("asymmetric", "Asymmetric", "The walls of a groove slope independently"),
    ),
    # docs/light-sampling.md: the native part plus a non-negative stochastic residual.
    "estimator": (
        ("light_sampled", "Native + Residual",
         "Cycles aims rays at lamps, the sun and bright sky for most of a GGX reflection, and "
         "the rest is aimed at the scene's lamps, so highlights clear up fast"),
        ("stochastic", "Stochastic",
         "The teaching form: one random mirror direction per sample, which finds lamps only "
         "by chance (far noisier under small lamps and the sun)"),
    ),
}
ENUMS: dict[str, tuple[str, ...]] = {
    enum: tuple(item for item, _, _ in entries) for enum, entries in ENUM_ITEMS.items()}
ITEM_LABELS: dict[str, dict[str, str]] = {
    enum: {item: label for item, label, _ in entries} for enum, entries in ENUM_ITEMS.items()}
ITEM_DOCS: dict[str, dict[str, str]] = {
    enum: {item: doc for item, _, doc in entries} for enum, entries in ENUM_ITEMS.items()}
SAMPLERS = ENUMS["sampler"]
# The samplers' formulas: docs/models.md, sec. 3.
SAMPLER_DOC = ("How reflection directions are picked at random: changes the noise and render "
               "time, not the converged look. Visible normals gives the least noise.")
DISTRIBUTION_DOC = ("Shape of the highlight: GGX has a bright core with long soft tails, "
                    "Beckmann a tighter highlight that fades quickly.")
FRESNEL_DOC = ("How reflection strength changes with the viewing angle: Conductor for metals "
               "(set by N and K), Dielectric for non-metals (set by IOR), None reflects at full "
               "strength everywhere.")
# Smith G2, height-correlated (Heitz 2014, Cycles, pbrt-v4) or separable (Walter 2007):
# docs/models.md, sec. 2.
MASKING_DOC = ("How microfacets shadow one another: Height-correlated as in Cycles, or Separable "
               "as in the 2007 paper (a little darker at grazing angles on rough surfaces).")

# Same converged image either way: only the noise changes (docs/light-sampling.md).
ESTIMATOR = Param("estimator", "Light Sampling", ENUM, "light_sampled", items=ENUMS["estimator"],
                  doc="Native + Residual lets Cycles aim rays at lamps, the sun and bright sky "
                      "for a GGX reflection (all of it with Height-Correlated masking); the "
                      "rest (all of a Beckmann one) is aimed at the scene's lamps, and toward "
                      "each lamp Cycles aims at most of it too, so highlights from small lamps "
                      "clear up fast. Stochastic finds lamps only by chance. Both converge to "
                      "the same image.")

MODELS: dict[str, Model] = {}


def _add(model: Model) -> Model:
    for p in model.params:
        if p.kind == ENUM:
            full = ENUMS[p.id]
            assert p.items == full[:len(p.items)], f"{model.id}.{p.id}: items must prefix {full}"
    MODELS[model.id] = model
    return model


# Formulas: docs/models.md, sec. 1 (f = d R_d + s R_s, s + d = 1, Beckmann D, V-cavity G, exact
# Fresnel, Lambertian R_d by the native diffuse()).
COOK_TORRANCE = _add(Model(
    id="cook_torrance",
    label="Microfacet Cook-Torrance (1982)",
    year=1982,
    shader="cook_torrance",
    tags=("diffuse", "glossy"),
    doc="Cook-Torrance (1982): a glossy highlight over a matte diffuse base, for plastics, "
        "paints and rubber, or tarnished metals with the Conductor Fresnel.",
    params=(
        Param("base_color", "Diffuse Color", COLOR, (0.8, 0.8, 0.8), 0.0, 1.0,
              doc="Colour of the matte (diffuse) part under the glossy reflection."),
        Param("specular", "Specular", FLOAT, 0.5, 0.0, 1.0, socket=FACTOR,
              doc="Share of the glossy reflection against the diffuse colour: 0 is fully "
                  "matte, 1 fully glossy; the two shares always add up to one."),
        ROUGHNESS,
        Param("fresnel_type", "Fresnel", ENUM, "dielectric", items=ENUMS["fresnel_type"][:2],
              doc="How reflection strength changes with the viewing angle: Conductor for "
                  "metals (set by N and K), Dielectric for non-metals (set by IOR)."),
        IOR, CONDUCTOR_N, CONDUCTOR_K,
        Param("sampler", "Sampler", ENUM, "vcavity", items=SAMPLERS,
              doc="How reflection directions are picked at random: changes the noise and "
                  "render time, not the converged look. V-cavity visible normals gives the "
                  "least noise for this model."),

        ESTIMATOR,
    ),
))

# Formulas: docs/models.md, sec. 2 (reflection), and Conventions (anisotropy as in Cycles).
WALTER_REFLECTION = _add(Model(
    id="walter_reflection",
    label="Microfacet Reflection (Walter 2007)",
    year=2007,
    shader="walter_reflection",
    tags=("glossy",),
    doc="Walter (2007) glossy reflection for metals, coatings and lacquers: a GGX or Beckmann "
        "highlight, round or stretched, with metal, non-metal or no Fresnel.",
    params=(
        TINT,
        ROUGHNESS,
        Param("anisotropy", "Anisotropy", FLOAT, 0.0, 0.0, 1.0, socket=FACTOR,
              doc="Stretches the highlight along the surface tangent, as on brushed metal: 0 "
                  "is round, 1 strongly stretched."),
        Param("distribution", "Distribution", ENUM, "ggx", items=ENUMS["distribution"],
              doc=DISTRIBUTION_DOC),
        Param("masking", "Masking", ENUM, "height_correlated", items=ENUMS["masking"],
              doc=MASKING_DOC),
        Param("fresnel_type", "Fresnel", ENUM, "conductor", items=ENUMS["fresnel_type"],
              doc=FRESNEL_DOC),
        IOR, CONDUCTOR_N, CONDUCTOR_K,
        Param("sampler", "Sampler", ENUM, "vndf", items=SAMPLERS[:2], doc=SAMPLER_DOC),
        ESTIMATOR,
    ),
))


# Formulas: docs/models.md, sec. 2 (glass: Walter's BTDF, Cycles' transport convention, total
# internal reflection, index matching).
WALTER_GLASS = _add(Model(
    id="walter_glass",
    label="Microfacet Glass (Walter 2007)",
    year=2007,
    shader="walter_glass",
    tags=("glossy", "transmission", "transparent"),
    doc="Walter (2007) rough glass: reflects and refracts light, from clear (roughness 0) to "
        "frosted; IOR 1 makes the surface vanish.",
    params=(
        # Multiplies both lobes (and the pass-through at IOR 1): not a specular-only tint.
        Param("base_color", "Tint", COLOR, (1.0, 1.0, 1.0), 0.0, 1.0,
              doc="Colours the light the glass reflects and lets through; white is physically "
                  "correct."),
        ROUGHNESS,
        Param("ior", "IOR", FLOAT, 1.5, 0.01, 100.0,
              doc="Index of refraction (1.33 water, 1.5 glass, 2.42 diamond): higher values "
                  "bend light more and reflect more; 1 makes the surface invisible, below 1 "
                  "it behaves as seen from inside the glass."),
        Param("distribution", "Distribution", ENUM, "ggx", items=ENUMS["distribution"],
              doc=DISTRIBUTION_DOC),
        Param("masking", "Masking", ENUM, "height_correlated", items=ENUMS["masking"],
              doc=MASKING_DOC),
        Param("sampler", "Sampler", ENUM, "vndf", items=SAMPLERS[:2], doc=SAMPLER_DOC),
        ESTIMATOR,
    ),
))


# Formulas: docs/models.md, sec. 4, and docs/lee-asymmetric-grooves.md.
LEE_VGROOVE = _add(Model(
    id="lee_vgroove",
    label="Microfacet Multi-Bounce V-Groove (Lee 2018)",
    year=2018,
    shader="lee_vgroove",
    tags=("glossy",),
    doc="Lee (2018) multi-bounce reflection: light bounces between the walls of tiny V-grooves, "
        "so rough metals keep their brightness and deepen their colour instead of turning "
        "dark; with no Fresnel it loses no energy at any roughness.",
    params=(
        TINT,
        ROUGHNESS,
        Param("distribution", "Distribution", ENUM, "ggx", items=ENUMS["distribution"],
              doc="Spread of the groove slopes: GGX has a bright core with long soft tails, "
                  "Beckmann a tighter highlight that fades quickly."),
        Param("groove", "Groove", ENUM, "symmetric", items=ENUMS["groove"],
              doc="Shape of the grooves: Symmetric (both walls slope alike) or Asymmetric "
                  "(the walls slope independently); both keep the same overall roughness."),
        Param("fresnel_type", "Fresnel", ENUM, "conductor", items=ENUMS["fresnel_type"],
              doc=FRESNEL_DOC + " Applied at every bounce."),
        IOR, CONDUCTOR_N, CONDUCTOR_K,
        # 0: kmax from the roughness (docs/models.md, sec. 4, "Bounce bound").
        Param("max_bounces", "Max Bounces", FLOAT, 0.0, 0.0, 1000.0,
              doc="How many bounces inside a groove get their Fresnel colour: 0 chooses from "
                  "the roughness; a low limit renders faster but leaves later bounces "
                  "uncoloured, so deep grooves come out brighter and paler."),
        # The first six bounces are aimed at the lamps; for symmetric grooves the first bounce
        # toward each lamp is also light-sampled by Cycles (docs/light-sampling.md, "Lee").
        Param("estimator", "Light Sampling", ENUM, "light_sampled", items=ENUMS["estimator"],
              doc="Native + Residual aims the first six bounces inside a groove at the scene's "
                  "lamps, and with Symmetric grooves also lets Cycles aim rays at the lamps for "
                  "the first bounce, so highlights from small lamps clear up fast; longer paths "
                  "find lamps by chance. Stochastic finds all of it by chance. Both converge to "
                  "the same image."),
    ),
))


# Formulas: docs/models.md, sec. 5, and docs/multiple-scattering.md.
HEITZ2016 = _add(Model(
    id="heitz2016",
    label="Microfacet Multiple Scattering (Heitz 2016)",
    year=2016,
    shader="heitz2016",
    tags=("glossy", "transmission", "transparent"),
    doc="Heitz et al. (2016) multiple scattering: light may bounce several times on the "
        "microsurface before it leaves, so rough metals and rough glass keep their brightness "
        "instead of turning dark; with no Fresnel it loses no energy at any roughness.",
    params=(
        # Multiplies the whole walk's weight (both lobes of the glass): not a specular-only tint.
        Param("base_color", "Tint", COLOR, (1.0, 1.0, 1.0), 0.0, 1.0,
              doc="Colours all the light the surface sends back (and, as glass, lets through); "
                  "white is physically correct."),
        ROUGHNESS,
        Param("distribution", "Distribution", ENUM, "ggx", items=ENUMS["distribution"],
              doc=DISTRIBUTION_DOC),
        Param("fresnel_type", "Fresnel", ENUM, "conductor", items=ENUMS["fresnel_type"],
              doc="What the surface is made of: Conductor for metals (set by N and K), "
                  "coloured again at every bounce; Dielectric for rough glass (set by IOR), "
                  "which reflects or refracts at every bounce and lets light through; None "
                  "reflects everything and loses no energy."),
        Param("ior", "IOR", FLOAT, 1.5, 0.01, 100.0,
              doc="Index of refraction of the glass (1.33 water, 1.5 glass, 2.42 diamond): "
                  "higher values bend light more and reflect more; 1 makes the surface "
                  "invisible. Used when Fresnel is Dielectric."),
        CONDUCTOR_N, CONDUCTOR_K,
        Param("max_order", "Max Bounces", FLOAT, 100.0, 1.0, 1000.0,
              doc="How many bounces on the microsurface light may make before it is given up "
                  "(that light is lost, so low values darken rough surfaces): 1 is single "
                  "scattering; at 100 less than 1 in 100,000 paths is lost."),
        # The first order is Cycles' GGX exactly (docs/models.md, sec. 5); a metal's later
        # bounces are aimed at the handed-over lamps, glass's are not.
        Param("estimator", "Light Sampling", ENUM, "light_sampled", items=ENUMS["estimator"],
              doc="Native + Residual lets Cycles aim rays at lamps, the sun and bright sky for "
                  "the first bounce of a GGX surface, most of its light; a metal's later "
                  "bounces are aimed at the scene's lamps, glass's find lamps by chance. "
                  "Stochastic finds all of it by chance. Both converge to the same image."),
    ),
))


def alphas(roughness: float, anisotropy: float = 0.0) -> tuple[float, float]:
    """Cycles' mapping from (roughness, anisotropy) to (alpha_x, alpha_y)."""
    a = roughness * roughness
    aspect = math.sqrt(1.0 - 0.9 * min(max(anisotropy, 0.0), 1.0))
    return a / aspect, a * aspect
