"""The native branch of every node group: Cycles' nearest built-in BSDF, for where OSL does not run.

Where OSL is unavailable (Cycles with OSL off, which is every CUDA, HIP, Metal and oneAPI GPU)
Cycles creates no node for a Script node, and every input the Script node fed takes that
input's own default value; EEVEE removes every link to or from a Script node. The group's last
node is therefore a Mix Shader whose Factor (default 0) is fed by the Script node's float output
`shaders.SWITCH_OUTPUT`, which reads 1 whenever the shader runs:

    Factor 1 (OSL runs): the model's OSL closure, the native branch weighted 0 and dropped
    Factor 0 (no OSL, EEVEE, a failed compile): the native branch built here

The native branch is made of Blender's own shader nodes fed by the group's inputs, so it follows
linked inputs (a roughness texture still works). Enum inputs arrive as their int codes (the menu
switches' outputs); a Compare node turns a code into a 0/1 factor, and Mix nodes select between
the candidates. With unlinked inputs every factor is a constant Cycles folds away before
rendering, leaving one closure.

What each model falls back to is `NATIVE` below; why this works and what is exact, by Blender
version, is in docs/cycles-osl.md ("Where OSL does not run"); how near each preset comes is
measured by `make report` (section "fallback").
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

from . import compat
from .catalog import MODELS, Model

# The correction lobes and scales (FITTED): polynomial coefficients fitted to the numpy
# reference by addon/lab/fallback_fit.py (`make fallback-fit`), read here as data.
FIT_PATH = Path(__file__).resolve().with_name("fallback_fit.json")

SWITCH_NODE_NAME = "Microfacet Lab: OSL or native"
NATIVE_FRAME_NAME = "Microfacet Lab: native branch"

# What the artist is told the model becomes without OSL (panel, operators, the render's line).
NATIVE = {
    "cook_torrance": "Diffuse plus a Beckmann metal (Smith instead of V-cavity shadowing, "
                     "with a Glossy lobe fitted to the difference)",
    "walter_reflection": "Metallic BSDF (Physical Conductor) or Glossy: exact for GGX or "
                         "Beckmann with Height-correlated masking (metals from Blender 5.0), "
                         "scaled by a fitted factor for Separable masking",
    "walter_glass": "Glass BSDF: exact for Height-correlated masking, its colour scaled by a "
                    "fitted factor for Separable masking",
    "lee_vgroove": "Metallic or Glossy with Multiscatter GGX (Beckmann: single scattering), "
                   "plus a Glossy lobe fitted to the grooves' extra bounces",
    "heitz2016": "Metallic, Glass or Glossy with Multiscatter GGX (Beckmann: single scattering), "
                 "a metal plus a Glossy lobe fitted to the walk's extra bounces, the glass's "
                 "colour scaled by a fitted factor",
}


def approximation(model_id: str, preset_id: str | None = None) -> str:
    """What a model renders as where OSL does not run and how near it comes, for the artist:
    the numpy errors of fit() for a fitted preset, or over the model's fitted variants."""
    text = f"without OSL renders as {NATIVE[model_id]}"
    errors = fit()["presets"].get(preset_id) if preset_id else None
    # Without a preset: the worst over the fitted variants, where the model's default is one.
    fitted = FITTED.get(model_id)
    default_fitted = fitted is not None and MODELS[model_id].param(fitted.enum).default in (
        fitted.lobe + fitted.scale)
    variants = [v for k, v in fit()["variants"].items()
                if k.startswith(model_id + "/") and default_fitted and not preset_id]
    if errors is None and variants:
        errors = {name: {"mean": max(v[name]["mean"] for v in variants),
                         "worst": max(v[name]["worst"] for v in variants)}
                  for name in ("albedo", "lobe")}
    if errors:
        text += (f"; its brightness is off by {errors['albedo']['mean']:.1%} on average and "
                 f"{errors['albedo']['worst']:.0%} at most, its highlight moved by "
                 f"{errors['lobe']['mean']:.0f} degrees on average (computed against the exact "
                 "model)")
    return text


class Branch:
    """Builds nodes inside a group's frame, reading the group's inputs by catalog id."""

    def __init__(self, group, model: Model, sources: dict):
        self.group, self.model, self.sources = group, model, sources
        self.frame = group.nodes.new("NodeFrame")
        self.frame.name = self.frame.label = NATIVE_FRAME_NAME
        self._count = 0

    def node(self, kind: str, **props):
        node = self.group.nodes.new(kind)
        node.parent = self.frame
        node.location = (-250 + 180 * (self._count % 4), -400 - 160 * (self._count // 4))
        self._count += 1
        for name, value in props.items():
            setattr(node, name, value)
        return node

    def link(self, socket, target) -> None:
        """Feed `target` (an input socket) from a socket, or set it to a constant."""
        if hasattr(socket, "is_output"):
            self.group.links.new(socket, target)
        elif target.type == "RGBA" and len(socket) == 3:
            target.default_value = (*socket, 1.0)
        else:
            target.default_value = socket

    def src(self, pid: str):
        return self.sources[pid]

    def is_item(self, pid: str, item: str):
        """1 where the enum `pid` is set to `item`, else 0 (its int code compared)."""
        node = self.node("ShaderNodeMath", operation="COMPARE")
        self.link(self.src(pid), node.inputs[0])
        node.inputs[1].default_value = self.model.param(pid).index(item)
        node.inputs[2].default_value = 0.5
        return node.outputs[0]

    def mix_shader(self, factor, a, b):
        """a where factor is 0, b where it is 1; a or b None is no closure (scales the other)."""
        node = self.node("ShaderNodeMixShader")
        self.link(factor, node.inputs[0])
        for sock, shader in zip(node.inputs[1:], (a, b)):
            if shader is not None:
                self.group.links.new(shader, sock)
        return node.outputs[0]

    def add_shader(self, a, b):
        node = self.node("ShaderNodeAddShader")
        self.group.links.new(a, node.inputs[0])
        self.group.links.new(b, node.inputs[1])
        return node.outputs[0]

    def mix_vector(self, factor, a, b):
        node = self.node("ShaderNodeMix", data_type="VECTOR")
        self.link(factor, node.inputs["Factor"])
        self.link(a, node.inputs["A_Vector"] if "A_Vector" in node.inputs else node.inputs[4])
        self.link(b, node.inputs["B_Vector"] if "B_Vector" in node.inputs else node.inputs[5])
        return _output(node, "VECTOR")

    def math(self, operation: str, *inputs):
        node = self.node("ShaderNodeMath", operation=operation)
        for socket, value in zip(node.inputs, inputs):
            self.link(value, socket)
        return node.outputs[0]

    def vector_math(self, operation: str, *inputs):
        node = self.node("ShaderNodeVectorMath", operation=operation)
        for socket, value in zip(node.inputs, inputs):
            self.link(value, socket)
        return node.outputs[0]

    def facing(self):
        """1 - |n.wi| (Layer Weight's Facing at Blend 0.5)."""
        node = self.node("ShaderNodeLayerWeight")
        node.inputs["Blend"].default_value = 0.5
        return node.outputs["Facing"]

    def gray(self, value):
        """A vector (v, v, v) from a float socket."""
        node = self.node("ShaderNodeCombineXYZ")
        for sock in node.inputs:
            self.link(value, sock)
        return node.outputs[0]

    def mean(self, color):
        """The mean of a colour's channels (a scalar stand-in for a tint a closure cannot take)."""
        node = self.node("ShaderNodeVectorMath", operation="DOT_PRODUCT")
        self.link(color, node.inputs[0])
        node.inputs[1].default_value = (1 / 3, 1 / 3, 1 / 3)
        return node.outputs["Value"]

    def bsdf(self, kind: str, distribution: str = "", props: dict | None = None, **inputs):
        """A BSDF node with its properties set first (they choose which inputs exist)."""
        props = dict(props or {}, **({"distribution": distribution} if distribution else {}))
        node = self.node(kind, **props)
        for name, value in inputs.items():
            self.link(value, node.inputs[name])
        return node.outputs[0]

    def by_distribution(self, make, ggx: str = "GGX"):
        """`make(distribution)` for GGX (as `ggx`, e.g. MULTI_GGX) and Beckmann, switched by the
        model's Distribution (GGX alone where the model has none)."""
        if not any(p.id == "distribution" for p in self.model.params):
            return make(ggx)
        return self.mix_shader(self.is_item("distribution", "beckmann"), make(ggx), make("BECKMANN"))


def _output(node, socket_type: str):
    return next(s for s in node.outputs if s.type == socket_type and s.enabled)


def f0_conductor(b: Branch, n, k):
    """Reflectance at normal incidence of a conductor, ((n-1)^2 + k^2) / ((n+1)^2 + k^2)
    (Born & Wolf), per channel: the Principled metal's Base Color before Blender 4.3."""
    k2 = b.vector_math("MULTIPLY", k, k)
    minus = b.vector_math("SUBTRACT", n, (1.0, 1.0, 1.0))
    plus = b.vector_math("ADD", n, (1.0, 1.0, 1.0))
    num = b.vector_math("ADD", b.vector_math("MULTIPLY", minus, minus), k2)
    den = b.vector_math("ADD", b.vector_math("MULTIPLY", plus, plus), k2)
    return b.vector_math("DIVIDE", num, den)


def metal(b: Branch, distribution: str, n, k, roughness, anisotropy=0.0):
    """Cycles' conductor (exact Fresnel of n + ik) where Blender has the Metallic BSDF (4.3+);
    before it the Principled metal (GGX, F82 tint), coloured by its reflectance at normal
    incidence: an approximation, also for Beckmann."""
    if compat.METALLIC_BSDF:
        return b.bsdf("ShaderNodeBsdfMetallic", distribution, {"fresnel_type": "PHYSICAL_CONDUCTOR"},
                      IOR=n, Extinction=k,
                      Roughness=roughness, Anisotropy=anisotropy)
    principled = b.node("ShaderNodeBsdfPrincipled",
                        distribution="GGX" if distribution == "BECKMANN" else distribution)
    principled.inputs["Metallic"].default_value = 1.0
    b.link(f0_conductor(b, n, k), principled.inputs["Base Color"])
    b.link(roughness, principled.inputs["Roughness"])
    return principled.outputs[0]


def fresnel_metal(b: Branch, distribution: str, anisotropy=0.0):
    """The model's Fresnel as a metal: Conductor reads N and K, Dielectric is a conductor with
    n = IOR and k = 0 (the same Fresnel for real n). Fresnel None is not handled here."""
    n, k = metal_indices(b)
    return metal(b, distribution, n, k, b.src("roughness"), anisotropy)


def metal_indices(b: Branch):
    """(n, k) of the model's Fresnel as a conductor: Dielectric is n = IOR, k = 0."""
    conductor = b.is_item("fresnel_type", "conductor")
    n = b.mix_vector(conductor, b.gray(b.src("ior")), b.src("n"))
    k = b.mix_vector(conductor, (0.0, 0.0, 0.0), b.src("k"))
    return n, k


def tinted(b: Branch, shader):
    """Scale a closure that takes no colour by the tint's mean."""
    return b.mix_shader(b.mean(b.src("base_color")), None, shader)


def reflection(b: Branch, distribution: str, anisotropy=0.0):
    """A reflection with the model's Fresnel: a (tinted) metal, or for Fresnel None a Glossy
    BSDF coloured by the tint."""
    glossy = b.bsdf("ShaderNodeBsdfGlossy", distribution, Color=b.src("base_color"),
                    Roughness=b.src("roughness"), Anisotropy=anisotropy)
    metal_ = tinted(b, fresnel_metal(b, distribution, anisotropy))
    if "none" not in b.model.param("fresnel_type").items:
        return metal_
    return b.mix_shader(b.is_item("fresnel_type", "none"), metal_, glossy)


def glass(b: Branch, distribution: str):
    """A Glass BSDF coloured by the tint times the fitted scale (fitted_scale)."""
    color = b.vector_math("MULTIPLY", b.src("base_color"), fitted_scale(b, distribution))
    return b.bsdf("ShaderNodeBsdfGlass", distribution, Color=color,
                  Roughness=b.src("roughness"), IOR=b.src("ior"))


def cook_torrance(b: Branch):
    # f = (1 - s) base / pi + s R_s (docs/models.md, sec. 1): the diffuse share and the
    # specular share, a Beckmann reflection with Smith height-correlated masking.
    share = b.node("ShaderNodeMath", operation="SUBTRACT")
    share.inputs[0].default_value = 1.0
    b.link(b.src("specular"), share.inputs[1])
    diffuse_color = b.node("ShaderNodeVectorMath", operation="SCALE")
    b.link(b.src("base_color"), diffuse_color.inputs[0])
    b.link(share.outputs[0], diffuse_color.inputs["Scale"])
    diffuse = b.bsdf("ShaderNodeBsdfDiffuse", Color=diffuse_color.outputs[0])
    # The correction lobe adds what V-cavity masking keeps over Smith's at grazing incidence.
    metal_ = b.add_shader(fresnel_metal(b, "BECKMANN"), correction(b, "BECKMANN"))
    specular = b.mix_shader(b.src("specular"), None, metal_)
    return b.add_shader(diffuse, specular)


def walter_reflection(b: Branch):
    # A closure without a Color input is scaled by a Mix Shader, whose Factor (in [0, 1]) is
    # the channels' mean: Separable masking only darkens, and its ratio to Height-correlated
    # is geometric, the same for every channel but for the Fresnel's weighting.
    anisotropy = b.src("anisotropy") if compat.NATIVE_ANISOTROPY else 0.0
    return b.by_distribution(lambda d: b.mix_shader(b.mean(fitted_scale(b, d)), None,
                                                    reflection(b, d, anisotropy)))


def walter_glass(b: Branch):
    return b.by_distribution(lambda d: glass(b, d))


def lee_vgroove(b: Branch):
    # Cycles' multiscatter GGX keeps a rough metal's energy, as the grooves' bounces do; the
    # correction lobe adds what the later bounces keep where the Fresnel reflectance is low.
    return b.by_distribution(lambda d: b.add_shader(reflection(b, d), correction(b, d)),
                             ggx="MULTI_GGX")


@lru_cache(maxsize=None)
def fit() -> dict:
    """The fitted corrections (FIT_PATH), read once."""
    return json.loads(FIT_PATH.read_text(encoding="utf-8"))


class Fitted(NamedTuple):
    """Which variants of a model have a fitted polynomial C(r, x, F0) (addon/lab/fallback_fit.py)
    and how it enters the branch: the items of `enum` in `lobe` add a single-scattering Glossy
    lobe of colour max(C, 0) (it can only add light); those in `scale` multiply the native
    closure by max(C, 0) (darker or brighter); any other item keeps the plain branch."""
    enum: str
    lobe: tuple = ()
    scale: tuple = ()


# Lee: one polynomial per groove shape. Cook-Torrance: per Fresnel kind (against one polynomial
# for both, in numpy: gold_cook_torrance's worst albedo error 2.65% -> 1.57%, blue_rubber's
# 3.57% -> 3.21%; the dielectrics' worst over the training set 12.9% -> 14.3% while their mean
# falls a little). Heitz 2016: a metal's lobe as Lee's; the glass scaled, since the native Glass
# keeps the light the walk sends forward through the interface, which Cycles cannot return
# (docs/models.md, sec. 5); Fresnel None is exact (both keep all the light). Walter's
# Separable masking: the Height-correlated closure scaled (Separable shadows more).
FITTED = {
    "lee_vgroove": Fitted("groove", lobe=("symmetric", "asymmetric")),
    "cook_torrance": Fitted("fresnel_type", lobe=("conductor", "dielectric")),
    "heitz2016": Fitted("fresnel_type", lobe=("conductor",), scale=("dielectric",)),
    "walter_reflection": Fitted("masking", scale=("separable",)),
    "walter_glass": Fitted("masking", scale=("separable",)),
}


def _fitted_color(b: Branch, distribution: str, items: tuple, default):
    """max(C, 0) of the polynomial fitted for the model, distribution and the enum's item
    (FITTED), switched by the model's enum; `default` where the enum is set to another item."""
    dist = "beckmann" if distribution == "BECKMANN" else "ggx"
    f0, x = branch_f0(b), b.facing()
    pid = FITTED[b.model.id].enum

    def colour(item):
        coefficients = fit()["variants"][f"{b.model.id}/{dist}/{item}"]["coefficients"]
        return polynomial_color(b, coefficients, x, f0)

    every = set(items) == set(b.model.param(pid).items)
    value = colour(items[0]) if every else default
    for item in items[1:] if every else items:
        value = b.mix_vector(b.is_item(pid, item), value, colour(item))
    return value


def correction(b: Branch, distribution: str):
    """The model's correction lobe (addon/lab/fallback_fit.py): a single-scattering Glossy BSDF
    with the branch's distribution and roughness, of colour max(C(r, x, F0), 0) for FITTED's
    lobe items (black for the others); Lee's and Heitz's times the tint. `distribution` as
    by_distribution passes it."""
    value = _fitted_color(b, distribution, FITTED[b.model.id].lobe, (0.0, 0.0, 0.0))
    if b.model.id in ("lee_vgroove", "heitz2016"):
        value = b.vector_math("MULTIPLY", value, b.src("base_color"))
    dist = "BECKMANN" if distribution == "BECKMANN" else "GGX"
    return b.bsdf("ShaderNodeBsdfGlossy", dist, Color=value, Roughness=b.src("roughness"))


def fitted_scale(b: Branch, distribution: str):
    """The native closure's fitted scale per channel (FITTED's scale items; 1 for the others)."""
    return _fitted_color(b, distribution, FITTED[b.model.id].scale, (1.0, 1.0, 1.0))


def branch_f0(b: Branch):
    """Reflectance at normal incidence of the model's Fresnel, per channel (1 for None; a
    model without a Fresnel menu is glass, of its IOR)."""
    if not any(p.id == "fresnel_type" for p in b.model.params):
        return f0_conductor(b, b.gray(b.src("ior")), (0.0, 0.0, 0.0))
    n, k = metal_indices(b)
    f0 = f0_conductor(b, n, k)
    if "none" not in b.model.param("fresnel_type").items:
        return f0
    return b.mix_vector(b.is_item("fresnel_type", "none"), f0, (1.0, 1.0, 1.0))


def polynomial_color(b: Branch, coefficients, x, f0):
    """max(sum_ijk c_ijk r^i x^j F0^k, 0) per channel, by Horner's rule in r, then x (scalars),
    then F0 (vectors); the terms' order is fit()["terms"]."""
    terms = [tuple(t) for t in fit()["terms"]]
    c = dict(zip(terms, coefficients))
    top_i, top_j, top_k = (max(t[axis] for t in terms) for axis in range(3))

    def horner(top, coefficient, variable, op="MULTIPLY_ADD"):
        value = coefficient(top)
        for power in range(top - 1, -1, -1):
            value = b.math(op, value, variable, coefficient(power))
        return value

    def s_k(k):
        return horner(top_j, lambda j: horner(top_i, lambda i: c[(i, j, k)], b.src("roughness")),
                      x)

    value = b.gray(s_k(top_k))
    for k in range(top_k - 1, -1, -1):
        value = b.vector_math("MULTIPLY_ADD", value, f0, b.gray(s_k(k)))
    return b.vector_math("MAXIMUM", value, (0.0, 0.0, 0.0))


def heitz2016(b: Branch):
    def make(d):
        metal_ = b.add_shader(reflection(b, d), correction(b, d))
        return b.mix_shader(b.is_item("fresnel_type", "dielectric"), metal_, glass(b, d))
    return b.by_distribution(make, ggx="MULTI_GGX")


BUILDERS = {"cook_torrance": cook_torrance, "walter_reflection": walter_reflection,
            "walter_glass": walter_glass, "lee_vgroove": lee_vgroove, "heitz2016": heitz2016}
assert set(BUILDERS) == set(MODELS) == set(NATIVE), "a model without a native branch"


def build_native(group, model: Model, sources: dict):
    """Build the model's native branch in `group` (any shader node tree) from `sources`: catalog
    id -> the socket carrying that input, or a constant (enums as int codes). Returns its shader
    output socket."""
    return BUILDERS[model.id](Branch(group, model, sources))


def constant_sources(model: Model, values: dict | None = None) -> dict:
    """`sources` for build_native from catalog values (resolved and clamped by the catalog)."""
    resolved = model.resolve(values)
    return {p.id: p.index(resolved[p.id]) if p.items else resolved[p.id] for p in model.params}
