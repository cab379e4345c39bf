// Twin: addon/lab/reference/split.py (the light-sampled split: native part and residual).
// Microfacet Lab: the light-sampled split (docs/light-sampling.md):
//   f = c(wi) F f_native + r,   r >= 0,
// F f_native Cycles' native closure (height-correlated Smith GGX or Beckmann with the model's
// alphas and Fresnel factor F), which Cycles light-samples, and r the model's own stochastic
// lobe. c = tint G_lo is a lower bound of f / (F f_native) over every wo, so r is never negative
// (Cycles drops negative weights): G_lo the least ratio G2 / G2_native (height-correlated 1,
// separable 1 / (1 + Lambda(wi)); Heitz 2014 eqs. 98, 99; Beckmann times 1 - 2
// MFL_BECKMANN_LAMBDA_GAP, see lambda_native). Which part a sample returns: split_closures
// (cycles.h).
#ifndef MFL_SPLIT_H
#define MFL_SPLIT_H

#include "cycles.h"
#include "fresnel.h"
#include "microfacet.h"

// Below this alpha the lobe is nearly a mirror: stay stochastic (split.ALPHA_SPLIT_MIN).
#define MFL_ALPHA_SPLIT_MIN 1e-3

// ---------------------------------------------------------------------------------------
// Blender 4.x only (MFL_EXACT_CONDUCTOR 0): Cycles' conductor_bsdf approximates the conductor
// Fresnel there, so a conductor's native part is microfacet("ggx") times F_lo, the least
// conductor Fresnel over the reachable wi.h, found by a golden-section search
// (split.conductor_lower_bound; tests/test_reference_split.py checks it on dense grids).
#define MFL_MIN_SEARCH_STEPS 16
#define MFL_FRESNEL_MARGIN 1e-4
#define MFL_CUSP_K 1.0
#define MFL_GOLDEN 0.61803398874989485

// Least wi.h over reflected directions: wo on the horizon opposite wi, cos(pi/4 + theta_i/2).
float reachable_cos_lo(vector wi)
{
    return max(cos(0.25 * MFL_PI + 0.5 * acos(clamp(wi[2], -1.0, 1.0))), 0.0);
}

// cos of the critical angle (0 for eta >= 1): F is a plateau at 1 left of it.
float critical_cos(float eta) { return sqrt(max(1.0 - eta * eta, 0.0)); }

// x = origin + sign t^2, clamped to [lo, hi]: the cosine wi.h at fresnel_min's search variable t.
float search_x(float t, float origin, float sign, float lo, float hi)
{
    return clamp(origin + sign * t * t, lo, hi);
}

// Golden-section minimum of the (unimodal) conductor Fresnel factor over x in [lo, hi], searched
// in t = sqrt(|x - origin|), origin the critical angle's cosine at one end of the interval, where
// F has a square-root cusp that t makes smooth: the least value visited, lowered by the margin
// (split.fresnel_min with F the conductor's, the same steps; OSL passes no functions).
float fresnel_min(float lo, float hi, float origin, float n, float k)
{
    float sign = (abs(hi - origin) >= abs(lo - origin)) ? 1.0 : -1.0;
    float a = sqrt(abs(((sign > 0.0) ? lo : hi) - origin));
    float b = sqrt(abs(((sign > 0.0) ? hi : lo) - origin));
    float x1 = b - MFL_GOLDEN * (b - a), x2 = a + MFL_GOLDEN * (b - a);
    float f1 = fresnel_conductor(search_x(x1, origin, sign, lo, hi), n, k);
    float f2 = fresnel_conductor(search_x(x2, origin, sign, lo, hi), n, k);
    float best = min(fresnel_conductor(search_x(a, origin, sign, lo, hi), n, k),
                     fresnel_conductor(search_x(b, origin, sign, lo, hi), n, k));
    for (int i = 0; i < MFL_MIN_SEARCH_STEPS; ++i) {
        best = min(best, min(f1, f2));
        if (f1 < f2) {  // the minimum lies in [a, x2]
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - MFL_GOLDEN * (b - a);
            f1 = fresnel_conductor(search_x(x1, origin, sign, lo, hi), n, k);
        }
        else {  // in [x1, b]
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + MFL_GOLDEN * (b - a);
            f2 = fresnel_conductor(search_x(x2, origin, sign, lo, hi), n, k);
        }
    }
    return min(best, min(f1, f2)) * (1.0 - MFL_FRESNEL_MARGIN);
}

// Least conductor Fresnel over [lo, hi] (split.conductor_min): with n < 1 and k < MFL_CUSP_K, F
// has a (near-)plateau left of the critical angle and a cusp and narrow dip right of it, so the
// two sides are searched apart; otherwise one search covers [lo, hi]. The sides, and the channels
// below, loop through one call site: OSL inlines every call, and fresnel_min's six calls of F,
// copied for each side and channel, were a fifth of a shader's code after optimization
// (docs/cycles-osl.md). Its own steps keep their two calls: one call site there, behind a chain
// of branches, made Cook-Torrance's conductor 50% slower per sample.
float conductor_min(float lo, float hi, float n, float k)
{
    float xc = (k < MFL_CUSP_K) ? critical_cos(n) : 0.0;
    float split_at = min(max(lo, xc), hi);
    int sides = (k <= 0.0 || xc <= lo) ? 1 : 2;
    float best = 1.0e30;
    for (int side = 0; side < sides; ++side)
        best = min(best, fresnel_min(side == 0 ? split_at : lo, side == 0 ? hi : split_at, xc,
                                     n, k));
    return best;
}

// Per channel, one call site.
color conductor_min(float lo, float hi, color n, color k)
{
    color F = 0;
    for (int c = 0; c < 3; ++c)
        F[c] = conductor_min(lo, hi, n[c], k[c]);
    return F;
}

// F_lo per channel, the least conductor Fresnel a reflection from wi can meet.
color conductor_lower_bound(vector wi, color n, color k)
{
    return conductor_min(reachable_cos_lo(wi), 1.0, n, k);
}

// ---------------------------------------------------------------------------------------
// The native part.

// Cycles' Smith Lambda for its native closure: GGX exact (lambda_); Beckmann the rational
// approximation of Walter 2007 eq. 27 (G1 = (3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2)
// for a < 1.6, else 1), which is what Cycles' Beckmann closure evaluates.
float lambda_native(int dist, vector w, float ax, float ay)
{
    if (dist == MFL_DISTRIBUTION_GGX)
        return lambda_(dist, w, ax, ay);
    float z = abs(w[2]);
    float p2 = (ax * ax * w[0] * w[0] + ay * ay * w[1] * w[1]) / max(z * z, 1e-30);
    if (p2 < 0.39)  // a = 1 / sqrt(p2) > 1.6
        return 0.0;
    float a = 1.0 / sqrt(p2);
    return ((0.396 * a - 1.259) * a + 1.0) / ((2.181 * a + 3.535) * a);
}

// G2 of Cycles' native closure: height-correlated, with lambda_native (Heitz 2014 eq. 99).
float G2_native(int dist, vector wi, vector wo, vector m, float ax, float ay)
{
    if (dot(wi, m) * wi[2] <= 0.0 || dot(wo, m) * wo[2] <= 0.0)
        return 0.0;
    return 1.0 / (1.0 + lambda_native(dist, wi, ax, ay) + lambda_native(dist, wo, ax, ay));
}

// The most (Lambda - lambda_native) / (1 + Lambda) reaches for Beckmann over every direction
// (split.BECKMANN_LAMBDA_GAP: 0.003117 at a = 1.34, rounded up). Then 1 + L_i' + L_o' >=
// (1 - 2 gap) (1 + L_i + L_o), so G2_native <= G2_hc / (1 - 2 gap), and c = (1 - 2 gap) G_lo
// keeps c G2_native <= G_lo G2_hc: the residual stays >= 0 and keeps the GGX form's bounds
// (controls.h residual_masking_lo).
#define MFL_BECKMANN_LAMBDA_GAP 0.0032
// Cycles samples Beckmann's visible normals exactly but divides by its own G1(wi), so its
// BSDF-sampled estimates carry (1 + lambda_native(wi)) / (1 + Lambda(wi)), -0.31% to +0.30%
// (split.BECKMANN_SAMPLING_TOLERANCE). A Beckmann native part is used only where Lambda(wi)
// <= this: then lambda_native(wi) = 0 (a > 1.6) and the factor is within 2.5e-4 of 1, the
// tolerance of the float32 Fresnel transcriptions (a >= 2: theta_i <= 63 degrees at alpha 0.25).
#define MFL_BECKMANN_SAMPLING_TOLERANCE 2.5e-4

// c / tint (split.native_factor): G_lo, the least G2 / G2_native over wo (1 for
// height-correlated masking, 1 / (1 + Lambda(wi)) for separable; Beckmann times 1 - 2
// MFL_BECKMANN_LAMBDA_GAP, and 0 where Lambda(wi) exceeds MFL_BECKMANN_SAMPLING_TOLERANCE).
// The native closure carries the model's own Fresnel factor (native_closure), so c needs no
// Fresnel bound.
float native_factor(int masking, int dist, vector wi, float ax, float ay)
{
    float lam_i = lambda_(dist, wi, ax, ay);
    float g_lo = (masking == MFL_MASKING_SEPARABLE) ? 1.0 / (1.0 + lam_i) : 1.0;
    if (dist == MFL_DISTRIBUTION_GGX)
        return g_lo;
    return (lam_i <= MFL_BECKMANN_SAMPLING_TOLERANCE) ? g_lo * (1.0 - 2.0 * MFL_BECKMANN_LAMBDA_GAP)
                                                      : 0.0;
}

// The residual's value per unit of D / (4 wi.n), without the tint: F G2 - c F_n G2_native,
// where F_n = F if the native part carries the model's Fresnel (exact), else 1 (Blender 4.x: c
// holds a Fresnel bound). Not clamped: a caller subtracts the controls first.
color residual_factor(int masking, int dist, int fresnel_type, color c, int exact, vector wi,
                      vector wo, vector m, float ax, float ay, float ior, color n, color k)
{
    color F = fresnel_color(fresnel_type, dot(wi, m), ior, n, k);
    float g2_n = (c[0] + c[1] + c[2] > 0.0) ? G2_native(dist, wi, wo, m, ax, ay) : 0.0;
    return F * G2(masking, dist, wi, wo, m, ax, ay) - c * (exact ? F : color(1.0)) * g2_n;
}

// Cycles' native height-correlated GGX or Beckmann reflection closure of a split, carrying the
// model's own Fresnel factor (fresnel_color): conductor_bsdf for a conductor, dielectric_bsdf
// with no transmission for a dielectric (the same closed forms; tests/test_reference_split.py),
// microfacet with no Fresnel for none. `ior` is seen from wi's side (cycles_ior).
closure color native_closure(int dist, int fresnel_type, vector t, float ax, float ay, float ior,
                             color n, color k)
{
    string name = (dist == MFL_DISTRIBUTION_GGX) ? "ggx" : "beckmann";
    if (fresnel_type == MFL_FRESNEL_TYPE_CONDUCTOR)
        return conductor_bsdf(N, t, ax, ay, n, k, name);
    if (fresnel_type == MFL_FRESNEL_TYPE_DIELECTRIC)
        return dielectric_bsdf(N, t, color(1.0), color(0.0), ax, ay, cycles_ior(ior), name);
    return microfacet(name, N, t, ax, ay, 0.0, 0);
}

#endif  // MFL_SPLIT_H
