"""Lee, Jarabo, Jeon, Gutierrez, Kim 2018 "Practical multiple scattering for rough surfaces":
the kaleidoscopic closed form of multiple mirror reflection in V-grooves (numpy reference).

Derivation (own geometry, no code of the authors) in docs/lee-asymmetric-grooves.md; ground
truth: addon/lab/reference/vgroove.py (brute-force tracing). Conventions: docs/models.md (n = (0,0,1),
wi toward the viewer, wo away from the surface, vectors (..., 3)).

The package, by topic; each module imports only those before it (no circles):
  fresnel_table       FresnelTable, the tabulated Fresnel callable of every inner loop;
  geometry            the kaleidoscope (2D angles, bounce count, exit angle, Fresnel product,
                      seed eqs. 5-1, 5-2) and the bounce bound (max_bounces, tail_ratio, kmax_for);
  sampler             the analytic sampler (sample, sample_partner, sample_albedo);
  symmetric           the symmetric BRDF in closed form (eval, G_k_symmetric; seed eqs. 5-3, 5-7);
  asymmetric          the asymmetric BRDF, the integral over the partner wall (eval_asymmetric);
  directional_albedo  the closed-form albedo by deterministic quadrature (albedo);
  directional_moments the moments (E, Vn, Vt) of the sphere-grid reference (moments);
  model               LeeBRDF and its catalog builder (lee_vgroove, registered with bsdf.builds
                      when this package is imported);
  light_sampling      the Native + Residual light-sampling twin of osl/lee_vgroove.osl.
This __init__ re-exports the public names, so `from addon.lab.reference import lee` then
`lee.albedo(...)`, `lee.LeeBRDF`, ... work as they did when the package was one module.

Max Bounces (the catalog's max_bounces, LeeBRDF.kmax; 0 = the derived bound max_bounces()):
the first kmax bounces of a path get their Fresnel factor, later bounces F = 1, and every path
is followed to its exact exit. One meaning in sample, eval / eval_asymmetric (fresnel_bounces;
their kmax is the number of terms summed, which LeeBRDF sets to the derived bound), albedo,
moments and the OSL shader (doc sec. 4): energy-conserving (F = 1: exactly 1 at any limit).
"""
from ..vgroove import fresnel_fn  # re-exported: report/multiple_scattering.py uses lee.fresnel_fn
from .asymmetric import eval_asymmetric, partner_norm
from .directional_albedo import GAUSS_PANEL, albedo
from .directional_moments import MOMENT_NODES, moments
from .fresnel_table import FresnelTable
from .geometry import (BECKMANN_Y_MAX, PI, TRUNCATION, bounce_count, bounce_count_symmetric,
                       exit_angle, fresnel_product, kmax_for, max_bounces, max_bounces_closed_form,
                       tail_ratio)
from .light_sampling import (AIMED_ORDERS, PARTNER_DIM, control_cones, first_order, low_orders,
                             sample_light_sampled, uniforms_needed)
from .model import LeeBRDF
from .sampler import local_angles, sample, sample_albedo, sample_partner
from .symmetric import G_k_symmetric, eval

__all__ = [
    "PI", "TRUNCATION", "BECKMANN_Y_MAX", "GAUSS_PANEL", "MOMENT_NODES", "AIMED_ORDERS",
    "PARTNER_DIM", "FresnelTable", "LeeBRDF", "fresnel_fn",
    "max_bounces", "max_bounces_closed_form", "tail_ratio", "kmax_for",
    "bounce_count_symmetric", "bounce_count", "exit_angle", "fresnel_product",
    "local_angles", "sample_partner", "sample", "sample_albedo",
    "G_k_symmetric", "eval", "partner_norm", "eval_asymmetric", "albedo", "moments",
    "uniforms_needed", "first_order", "control_cones", "low_orders", "sample_light_sampled",
]
