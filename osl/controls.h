// Twin: addon/lab/reference/controls.py (lamp controls: the residual's light-sampled part).
// Microfacet Lab: lamp controls (docs/light-sampling.md, "Lamp controls"). Toward each of up to
// MFL_CONTROL_SLOTS lamps, a cone K holding the lamp's directions from P carries w_K t_K: Cycles'
// glossy_toon about normalize(wi + a) (so that its reflected axis is the cone's axis a), size th /
// (pi/2), no smooth, whose value times cos t_K is 1 / (2 pi (1 - cos th)) inside K and 0 outside
// (kernel/closure/bsdf_toon.h), and w_K = 2 pi (1 - cos th) times a lower bound of the residual's r
// cos over K (cone_value_lo). Cycles evaluates the toon toward its lamps with multiple importance
// sampling, so the lamp's light through K gets next-event estimation on every sample; the delta
// residual keeps r - sum w_K t_K >= 0. Exact for any cone (a stale table only moves noise). Left
// out: cones that reach a horizon (Cycles' toon sampler rejects directions below Ng), overlap a
// cone chosen before (two controls could sum above r), are narrower than MFL_CONTROL_MIN_HALF_ANGLE
// (Cycles clamps a toon's size at 1e-5; and a needle-sharp toon beside the delta residual meets
// Cycles' 1e6 stand-in pdf for deltas), or weigh less than MFL_CONTROL_MIN_WEIGHT even after
// widening (Cycles drops closures below 1e-5: a Mix Shader factor down to 0.1 keeps every control,
// as it keeps every delta lobe, MFL_MIN_DELTA_WEIGHT; 1e-3 left most controls out under a
// 0.5-degree sun, whose cones hold 6e-5 sr: a rough Beckmann sphere 3.5 times noisier). A small
// lamp's cone is widened once (control_cone) where its weight, about the lobe's value times the
// cone's solid angle, would fall below that; weights are lowered by MFL_CONTROL_MARGIN against
// float rounding in r.
#ifndef MFL_CONTROLS_H
#define MFL_CONTROLS_H

#include "cycles.h"
#include "fresnel.h"
#include "microfacet.h"
#include "split.h"
#include "lamps.h"

#define MFL_CONTROL_SLOTS 4
#define MFL_CONTROL_MIN_WEIGHT 1e-4
#define MFL_CONTROL_MARGIN 1e-3
#define MFL_CONTROL_GROW_CAP 0.5
#define MFL_CONTROL_GROW_MAX 0.1
#define MFL_CONTROL_MIN_HALF_ANGLE 2e-3
#define MFL_CONTROL_HORIZON_MARGIN 0.01
#define MFL_GUIDE_AMBIENT 1.0
#define MFL_GUIDE_MIN 0.05
#define MFL_GUIDE_MAX 0.95

// ---------------------------------------------------------------------------------------
// The bound of r cos = F D G / (4 wi.n) over a cone of directions wo (axis a, half-angle th).
// Every half vector of the cone lies within beta = asin(sin(th/2) / wi.h_a) of
// h_a = normalize(wi + a) (|wo - a| <= 2 sin(th/2), |wi + a| = 2 wi.h_a), every wo within th of
// a; each factor is bounded on those ranges.

// Least masking factor of r cos over the cone (lam_o: the largest Lambda(wo) there): G2 with no
// native part, G2 - c G2_hc = (1 - c) G1(wo) G2_hc for separable masking beside one (a Beckmann
// split's G2 - c G2_native is at least that: split.h MFL_BECKMANN_LAMBDA_GAP).
float residual_masking_lo(int masking, int split, float lam_i, float lam_o, float cos_h_max,
                          float cos_o_min, float wi_z, float u_hi)
{
    if (masking == MFL_MASKING_VCAVITY)
        return min(1.0, 2.0 * cos_h_max * min(wi_z, cos_o_min) / u_hi);
    if (masking == MFL_MASKING_SEPARABLE) {
        if (split)
            return (lam_i / (1.0 + lam_i)) / ((1.0 + lam_o) * (1.0 + lam_i + lam_o));
        return 1.0 / ((1.0 + lam_i) * (1.0 + lam_o));
    }
    return split ? 0.0 : 1.0 / (1.0 + lam_i + lam_o);
}

// Least Fresnel factor over wi.h in [u_lo, u_hi]: a dielectric's falls as wi.h grows; a
// conductor's is searched per channel.
color fresnel_lo(int fresnel_type, float u_lo, float u_hi, float ior, color n, color k)
{
    if (fresnel_type == MFL_FRESNEL_TYPE_DIELECTRIC)
        return color(fresnel_dielectric(u_hi, ior));
    if (fresnel_type == MFL_FRESNEL_TYPE_CONDUCTOR)
        return conductor_min(u_lo, u_hi, n, k);
    return color(1.0);
}

// Lower bound of r cos over the cone, without the tint; 0 where the cone reaches a horizon or no
// bound holds (split: whether the native part c F f_native is returned beside the residual).
color cone_value_lo(int masking, int dist, int fresnel_type, int split, vector wi, vector a,
                    float th, float ax, float ay, float ior, color n, color k)
{
    vector h = normalize(wi + a);
    float wh = dot(wi, h);
    float s = sin(0.5 * th) / max(wh, 1e-30);
    if (s >= 1.0 || wi[2] <= 0.0)
        return color(0.0);
    float beta = asin(s);
    float theta_o = acos(clamp(a[2], -1.0, 1.0)) + th;
    float theta_h = acos(clamp(h[2], -1.0, 1.0));
    float h_max = theta_h + beta;
    float gamma = acos(clamp(wh, -1.0, 1.0));
    float u_lo = cos(gamma + beta);
    float u_hi = cos(max(gamma - beta, 0.0));
    if (theta_o >= 0.5 * MFL_PI || h_max >= 0.5 * MFL_PI || u_lo <= 0.0)
        return color(0.0);
    // D = g(e) / (pi ax ay cos^4): g falls with the stretched slope e <= tan^2 / alpha_min^2,
    // 1 / cos^4 grows with theta_m >= theta_h - beta (Walter 2007 eqs. 25, 33).
    float a_min = min(ax, ay);
    float a_max = max(ax, ay);
    float tan_h = tan(h_max);
    float e = tan_h * tan_h / (a_min * a_min);
    float g = (dist == MFL_DISTRIBUTION_GGX) ? 1.0 / ((1.0 + e) * (1.0 + e)) : exp(-e);
    float c_min = cos(max(theta_h - beta, 0.0));
    float d_lo = g / (MFL_PI * ax * ay * c_min * c_min * c_min * c_min);
    // Lambda grows with theta and with the projected roughness (at most alpha_max).
    float lam_o = lambda_(dist, vector(sin(theta_o), 0.0, cos(theta_o)), a_max, a_max);
    float lam_i = lambda_(dist, wi, ax, ay);
    float g_lo = residual_masking_lo(masking, split, lam_i, lam_o, cos(h_max), cos(theta_o),
                                     wi[2], u_hi);
    color F = fresnel_lo(fresnel_type, u_lo, u_hi, ior, n, k);
    return max(F * (d_lo * g_lo / (4.0 * wi[2])), color(0.0));
}

// ---------------------------------------------------------------------------------------
// The controls.

// The chosen cones (table order, brightest first): lamps with weight at P (site: lamps.h
// lamp_site) whose cone, widened as far as control_cone may (MFL_CONTROL_GROW_MAX), clears the
// horizons of N and Ng and every cone chosen before; returns how many.
int select_cones(LampSite site, int set, output vector axes[MFL_CONTROL_SLOTS],
                 output float ths[MFL_CONTROL_SLOTS])
{
    int count = 0;
#if MFL_LAMP_COUNT > 0
    for (int i = 0; i < MFL_LAMP_COUNT && count < MFL_CONTROL_SLOTS; i++) {
        if (lamp_share(site, i, set, 1) <= 0.0 || !site.bounded[i])
            continue;
        vector a = site.axis[i];
        float th = site.th[i];
        float reach = max(th, MFL_CONTROL_GROW_MAX);
        float clear = sin(reach) + MFL_CONTROL_HORIZON_MARGIN;
        if (th < MFL_CONTROL_MIN_HALF_ANGLE || th >= 0.5 * MFL_PI || dot(a, Ng) <= clear ||
            dot(a, N) <= clear)
            continue;
        int apart = 1;
        for (int j = 0; j < count; j++)
            if (acos(clamp(dot(a, axes[j]), -1.0, 1.0)) <=
                reach + max(ths[j], MFL_CONTROL_GROW_MAX))
                apart = 0;
        if (!apart)
            continue;
        axes[count] = a;
        ths[count] = th;
        count += 1;
    }
#endif
    return count;
}

// w_K without the tint: 2 pi (1 - cos th) cone_value_lo (1 - margin).
color control_weight(int masking, int dist, int fresnel_type, int split, vector wi, vector a,
                     float th, float ax, float ay, float ior, color n, color k)
{
    float omc = 2.0 * sin(0.5 * th) * sin(0.5 * th);
    return cone_value_lo(masking, dist, fresnel_type, split, wi, a, th, ax, ay, ior, n, k) *
           (2.0 * MFL_PI * omc * (1.0 - MFL_CONTROL_MARGIN));
}

// The control's half-angle th (in: the lamp's) and weight w_K without the tint (0 where left
// out): where the lamp cone's weight would fall below MFL_CONTROL_MIN_WEIGHT, the cone is widened
// once, to the solid angle that would give twice that at the lamp cone's bound, at most
// MFL_CONTROL_GROW_CAP alpha_min (the lobe stays nearly constant across it) and GROW_MAX.
color control_cone(int masking, int dist, int fresnel_type, int split, vector wi, vector a,
                   output float th, float ax, float ay, float ior, color n, color k, color tint)
{
    color w = control_weight(masking, dist, fresnel_type, split, wi, a, th, ax, ay, ior, n, k);
    color tw = tint * w;
    float mean = (tw[0] + tw[1] + tw[2]) / 3.0;
    if (mean < MFL_CONTROL_MIN_WEIGHT && mean > 0.0) {
        float omc = 2.0 * sin(0.5 * th) * sin(0.5 * th);
        float target = omc * 2.0 * MFL_CONTROL_MIN_WEIGHT / mean;
        float cap = max(th, min(MFL_CONTROL_GROW_MAX, MFL_CONTROL_GROW_CAP * min(ax, ay)));
        float grown = min(2.0 * asin(sqrt(min(0.5 * target, 1.0))), cap);
        if (grown > th) {
            th = grown;
            w = control_weight(masking, dist, fresnel_type, split, wi, a, th, ax, ay, ior, n, k);
            tw = tint * w;
            mean = (tw[0] + tw[1] + tw[2]) / 3.0;
        }
    }
    return (mean >= MFL_CONTROL_MIN_WEIGHT) ? w : color(0.0);
}

// The controls of a reflection residual (masking, dist, ... as cone_value_lo; split: whether the
// GGX native part is returned beside it): their closures, tint times w_K times the toon;
// weights[j] = w_K without the tint (0 where left out) and ths[j] its cone, for controls_value;
// lamp_ths[j] the lamp's own cone within it. set, in and out: the lamps controlled (lamp_share;
// site: lamps.h lamp_site).
// From MFL_LAMPS_AIMED (the control variate of nee.h takes the predicted lamps), a control for
// another lamp turns the pair off: then every lamp is controlled and aimed at (MFL_LAMPS_ALL).
// The second pass is a loop, not a second call: OSL inlines every call, and two calls made the
// Lee shader 40% larger after optimization.
closure color control_terms(LampSite site, int masking, int dist, int fresnel_type, int split,
                            output int set, vector wi, vector t, vector b, float ax, float ay,
                            float ior, color n, color k,
                            color tint, output vector axes[MFL_CONTROL_SLOTS],
                            output float ths[MFL_CONTROL_SLOTS],
                            output float lamp_ths[MFL_CONTROL_SLOTS],
                            output color weights[MFL_CONTROL_SLOTS], output int count)
{
    closure color controls = 0;
    for (int pass = 0; pass < 2; pass++) {
        controls = 0;
        count = select_cones(site, set, axes, ths);
        for (int j = 0; j < count; j++) {
            float th = ths[j];
            lamp_ths[j] = th;
            color w = control_cone(masking, dist, fresnel_type, split, wi,
                                   to_local(axes[j], t, b, N), th, ax, ay, ior, n, k, tint);
            if (w[0] + w[1] + w[2] > 0.0)  // a cone left without a control stays the lamp's
                ths[j] = th;
            weights[j] = w;
            if (w[0] + w[1] + w[2] > 0.0)
                controls += (tint * w) * glossy_toon(normalize(I + axes[j]), th / (0.5 * MFL_PI),
                                                     0.0);
        }
        if (!MFL_PAIRED || set == MFL_LAMPS_ALL || count == 0)
            break;
        set = MFL_LAMPS_ALL;
    }
    return controls;
}

// sum_K w_K t_K(wo) (no tint) at the world direction wo: what the controls carry there.
color controls_value(vector wo, int count, vector axes[MFL_CONTROL_SLOTS],
                     float ths[MFL_CONTROL_SLOTS], color weights[MFL_CONTROL_SLOTS])
{
    color value = color(0.0);
    for (int j = 0; j < count; j++) {
        if (in_cone(wo, axes[j], sin(ths[j]) * sin(ths[j])))
            value += weights[j] * cone_density(ths[j]);
    }
    return value;
}

// ---------------------------------------------------------------------------------------
// How often to aim (docs/light-sampling.md, "How often to aim").

// The direction of the cone (a, th) nearest to R: R where the cone holds it, else a turned
// toward R by th.
vector nearest_in_cone(vector a, float th, vector R)
{
    vector perp = R - dot(R, a) * a;
    float angle = acos(clamp(dot(a, R), -1.0, 1.0));
    if (angle <= th)
        return R;
    if (dot(perp, perp) <= 1e-18)
        return a;
    return cos(th) * a + sin(th) * normalize(perp);
}

// lam, the share of a residual's samples aimed at the lamps (lamps.h), for one shading point:
// U / (U + A MFL_GUIDE_AMBIENT) within [MFL_GUIDE_MIN, MFL_GUIDE_MAX]. U = sum_j E_j min(u_j,
// A / Omega_j) guesses the lamps' light that the delta carries: E_j lamp j's rough irradiance
// (lamp_weight), u_j the residual's r cos less the controls toward the lamp's direction nearest
// the mirror direction, A / Omega_j the most a lamp wider than the lobe passes (A: the residual's
// albedo, at most tint (1 - c)); A MFL_GUIDE_AMBIENT guesses the light from everywhere else
// (an ambient radiance of 1). Aiming where the lobe misses the lamps only starves the rest, and
// a lamp the controls carry needs no aim. Any lam in (0, 1) keeps the one-sample balance
// heuristic exact (Veach 1997, sec. 9.2.4): sampling and density use the same (masking, ...:
// as cone_value_lo; c, exact: the native part's factor and whether its Fresnel is the model's).
float residual_guide_fraction(LampSite site, int masking, int dist, int fresnel_type, color c,
                              int exact, int set, vector wi, vector t, vector b, float ax,
                              float ay, float ior, color n, color k, color tint, int count,
                              vector axes[MFL_CONTROL_SLOTS], float ths[MFL_CONTROL_SLOTS],
                              color weights[MFL_CONTROL_SLOTS])
{
    float A = (tint[0] * (1.0 - c[0]) + tint[1] * (1.0 - c[1]) + tint[2] * (1.0 - c[2])) / 3.0;
    float U = 0.0;
#if MFL_LAMP_COUNT > 0
    vector R = reflect(-I, N);
    for (int i = 0; i < MFL_LAMP_COUNT; i++) {
        float E = lamp_share(site, i, set, 1);
        if (E <= 0.0 || !site.bounded[i])
            continue;
        float th = site.th[i];
        vector d = nearest_in_cone(site.axis[i], th, R);
        vector wo = to_local(d, t, b, N);
        if (wo[2] <= 0.0 || wi[2] <= 0.0)
            continue;
        vector m = normalize(wi + wo);
        color r = residual_factor(masking, dist, fresnel_type, c, exact, wi, wo, m, ax, ay, ior,
                                  n, k) * (D(dist, m, ax, ay) / (4.0 * wi[2]));
        color v = tint * r - tint * controls_value(d, count, axes, ths, weights);
        float u = max((v[0] + v[1] + v[2]) / 3.0, 0.0);
        float omega = 4.0 * MFL_PI * sin(0.5 * th) * sin(0.5 * th);
        U += E * min(u, A / max(omega, 1e-12));
    }
#endif
    if (U <= 0.0)
        return MFL_GUIDE_MIN;
    return clamp(U / (U + A * MFL_GUIDE_AMBIENT), MFL_GUIDE_MIN, MFL_GUIDE_MAX);
}

#endif  // MFL_CONTROLS_H
