"""Heitz, Hanika, d'Eon & Dachsbacher 2016, "Multiple-scattering microfacet BSDFs with the Smith
model" (SIGGRAPH 2016): the numpy twin of osl/heitz2016.osl (catalog model `heitz2016`).

    bsdf = HeitzConductor(Microfacet("ggx", 0.25), fresnel="conductor", n=..., k=...)
    bsdf = HeitzDielectric(Microfacet("ggx", 0.25), ior=1.5)
    s = bsdf.sample(wi, rng)                  # WalkSample(wo, weight, order, lost), one per row
    est = bsdf.eval(wi, wo, rng)              # one unbiased estimate of f(wi, wo) |wo.n| per row
    mean, se = bsdf.eval_mean(wi, wo, 4096, rng)
    bsdf.eval_single(wi, wo)                  # closed-form first order, f_1 |wo.n|
    bsdf.albedo(wi, 10**5, rng)               # Albedo(E, E_se, R, T, R_se, T_se, lost,
                                              #        mean_order)
    directional_moments_mc(bsdf, mu, 10**5, rng)   # (E, Vn, Vt) and their standard errors

Conventions (docs/models.md): local frame n = (0,0,1); wi.z > 0 points from the surface to the
viewer; wo points away from the surface, wo.z < 0 is transmission; eta = n_t / n_i seen from wi's
side (the upper medium has index 1, the lower one eta); Cycles' transport convention for the
dielectric: a refraction carries weight 1 (no 1/eta^2 radiance factor), as in glass.py. Directions
are arrays (N, 3) (any (..., 3) is flattened), one random walk per row; RGB results (N, 3).
`rng` is a numpy Generator or any object with a `random(shape)` method returning uniforms in
[0, 1) (a stream of prepared numbers): every scattering step draws `rng.random((n_alive, 4))`
(column 0 the next height, 1-2 the visible normal, 3 the Fresnel choice of the dielectric), and
the downward visible-normal samplers draw extra numbers for their rejection loops.

The model (Heitz et al. 2016). The paper's equation, section and algorithm numbers are NOT
cited here: I could not check them against the paper's text, so each quantity is described
instead; where it helps, the name of the corresponding function of the authors' published
supplemental code is given (sampleHeight, G_1(w, h0), evalPhaseFunction, samplePhaseFunction,
evalSingleScattering), whose structure was checked against a public port of that code (libbsdf's
MultipleScatteringSmith); no code was copied, this is an independent vectorised derivation.
Each module's doc describes its part of the model:

    medium          the Smith microsurface as a random medium: heights, masking at a height,
                    the free path in height, visible normals from either side, phase functions
    walk            the random walk both materials share (SmithWalk): sampling, stochastic
                    evaluation, albedo, and the variance measured
    conductor       HeitzConductor, and the first order in closed form (reflection)
    dielectric      HeitzDielectric: the walk on both sides of the interface, the first order's
                    transmission
    moments         Monte Carlo directional moments (directional_moments_mc)
    model           the catalog model HeitzBSDF (registered with reference.bsdf.builds) and its
                    moment tables for the sphere grid
    light_sampling  the aimed residual of Light Sampling (eval_residual, sample_aimed_residual)

Each imports only those above it. This package re-exports every public name, so
`heitz2016.X` reads as it did when the model was one module; importing it registers the
builder of `heitz2016` with make_bsdf.
"""
from .medium import (C1, D_wi, G1_height, beta_function, invC1, lambda_signed, phase_dielectric,
                     phase_reflection, projected_area, sample_height, sample_visible,
                     sample_vndf_below)
from .walk import MAX_ORDER, Albedo, SmithWalk, WalkSample, flip
from .conductor import HeitzConductor
from .dielectric import HeitzDielectric
from .moments import MCMoments, directional_moments_mc
from .model import HeitzBSDF, moment_tables, table_nodes
from .light_sampling import eval_residual, sample_aimed_residual

__all__ = [
    "C1", "invC1", "lambda_signed", "projected_area", "D_wi", "G1_height", "sample_height",
    "sample_vndf_below", "sample_visible", "phase_reflection", "phase_dielectric",
    "beta_function", "MAX_ORDER", "WalkSample", "Albedo", "SmithWalk", "flip", "HeitzConductor",
    "HeitzDielectric", "MCMoments", "directional_moments_mc", "HeitzBSDF", "moment_tables",
    "table_nodes", "eval_residual", "sample_aimed_residual"]
