// Twin: none. trace() and Cycles' emission() have no numpy counterpart; the estimator's mean is
// the delta's by construction (below), held by tests/test_render_nee.py.
// Microfacet Lab: the residual's lamp light as a control variate (docs/light-sampling.md, "The
// lamps' light as a control variate").
//
// The delta residual meets a lamp only by chance (aimed or not), a rare and heavy sample. Let
// g(wo) = r(wo) cos L_pred(wo) V(wo): the residual's light from the lamps as the hand-over
// predicts it (radiance L_pred, slots 16-18 of the lamp table; V from trace()). The shader adds,
// as a signed emission(),
//   E = g(w_n) / p_n(w_n)  -  W_d L_pred(w_d) V(w_d),
// w_n a direction drawn toward the predicted lamps (p_n, lamps.h), W_d and w_d the delta's own
// weight and direction (0 where the delta carries a part that g does not count). Both terms
// are unbiased estimates of the same integral of g, so E has mean 0 whatever L_pred and V are:
// a stale, wrong or missing prediction, a trace() that finds nothing (OptiX), light linking or
// a lamp with nodes change the noise, never the image. Where the prediction is right the delta's
// lamp light (W_d L) and its subtraction cancel, and the lamp's light comes from the first term,
// drawn over the lamp like Cycles' own next-event estimation.
#ifndef MFL_NEE_H
#define MFL_NEE_H

#include "cycles.h"
#include "lamps.h"

// The pair's signed emission. Compiled out without a predicted lamp: Cycles takes a shader whose
// bytecode names emission() for a lamp (Emission Sampling Auto), so a shader without one keeps
// none.
closure color nee_emission(color weight)
{
    closure color lobe = 0;
#if MFL_PAIRED
    lobe = weight * emission();
#endif
    return lobe;
}

#if MFL_LAMP_COUNT > 0
// Lamp i's predicted radiance toward dir from P: 0 outside the lamp itself (no sampling
// margin: the margin's directions see what lies beyond the lamp). dist receives the distance
// to the lamp (1e30 for a sun).
color lamp_radiance(int i, point P, vector dir, output float dist)
{
    color L = lamp_predicted(i);
    dist = 1e30;
    if (L[0] + L[1] + L[2] <= 0.0)
        return color(0.0);
    if (lamp_is(i, MFL_LAMP_SUN)) {
        float omc = lamp_datum(i, 13);
        if (!in_cone(dir, lamp_vector(i, 4), omc * (2.0 - omc)))
            return color(0.0);
#if MFL_SPOT_TEXELS
        int texels = lamp_texels(i);
        if (texels >= 0)
            return spot_radiance(texels, dir);
#endif
        return L;
    }
    else if (!lamp_is_area(i)) {  // a sphere lamp; else: lamps.h lamp_is
        vector to = lamp_vector(i, 1) - P;
        float d2 = dot(to, to);
        float r = lamp_datum(i, 13);
        if (d2 <= r * r)
            return color(0.0);
        float sin2 = r * r / ((lamp_datum(i, 15) > 0.5) ? d2 : d2 + r * r);
        dist = sqrt(d2) - r;
        return in_cone(dir, to / sqrt(d2), sin2) ? L : color(0.0);
    }
    else {
        vector n = lamp_vector(i, 4);
        float cos_l = -dot(dir, n);
        if (cos_l <= 0.0)
            return color(0.0);
        point c = lamp_vector(i, 1);
        dist = dot(P - c, n) / cos_l;
        if (dist <= 0.0)
            return color(0.0);
        vector u = lamp_vector(i, 7);
        vector v = lamp_vector(i, 10);
        vector q = P + dist * dir - c;
        float s = dot(q, u) / dot(u, u);
        float t = dot(q, v) / dot(v, v);
        int inside = lamp_is(i, MFL_LAMP_ELLIPSE) ? (s * s + t * t <= 1.0)
                                                  : (abs(s) <= 1.0 && abs(t) <= 1.0);
        return inside ? L : color(0.0);
    }
}
#endif

// The predicted radiance toward dir of the lamps estimated here (lamps.h lamp_estimated: all
// above the line under which Cycles turns a delta, so a delta toward them leaves as drawn),
// times V (trace(): nothing in between; each lamp's ray stops short of it), summed (site: lamps.h
// lamp_site).
color lamps_light(LampSite site, vector dir)
{
    color sum = 0;
#if MFL_LAMP_COUNT > 0
    if (dot(Ng, dir) < nee_horizon())
        return sum;
    for (int i = 0; i < MFL_LAMP_COUNT; i++) {
        if (!site.estimated[i])
            continue;
        float dist;
        color L = lamp_radiance(i, P, dir, dist);
        if (L[0] + L[1] + L[2] > 0.0 && !trace(P, dir, "maxdist", dist))
            sum += L;
    }
#endif
    return sum;
}

// The first term's directions per camera hit: a jittered grid x grid over the lamp's two sampling
// dimensions, grid = MFL_NEE_GRID where a lamp it estimates is wide (lamps.h MFL_NEE_WIDE_LAMP),
// or wide against the lobe (its half-angle at least MFL_NEE_LOBE_SHARE times the lobe's alpha:
// the model's value then varies across it; alpha 0 where the estimate carries a small part of
// the lobe, which four directions would not repay), or the model's value toward it is itself an
// estimate (stochastic: Heitz 2016's walk, Lee's asymmetric grooves), else 1. The shader's random
// numbers are white noise (cycles.h rng), where Cycles stratifies its own light samples over a
// pixel's samples: on the look-dev Suzanne's area lamp a Lambertian's light through this
// estimate, one direction per sample, had 8.8 times the variance of Cycles' Diffuse BSDF
// (docs/noise-measurements.md, sec. 16). Across a lamp narrow against both a closed
// form hardly changes, and more directions would only cost.
#define MFL_NEE_GRID 2
// A 4-degree sun on a roughness-0.2 Cook-Torrance sphere (alpha 0.04): one direction per hit
// left its highlight's pixels about 0.6 relative noise per sample
// (docs/noise-measurements.md, sec. 19).
#define MFL_NEE_LOBE_SHARE 0.5

int nee_grid(LampSite site, int stochastic, float alpha)
{
    if (stochastic)
        return MFL_NEE_GRID;
#if MFL_LAMP_COUNT > 0
    for (int i = 0; i < MFL_LAMP_COUNT; i++) {
        float th = site.th[i];
        if (lamp_share(site, i, 1, 0) > 0.0 && site.bounded[i] &&
            (th >= MFL_NEE_WIDE_LAMP || (alpha > 0.0 && th >= MFL_NEE_LOBE_SHARE * alpha)))
            return MFL_NEE_GRID;
    }
#endif
    return 1;
}

// Direction j (0 <= j < grid^2) of the first term: a lamp with a predicted radiance by its
// guiding weight at P (lamps.h lamp_share, set 1), then over its cone or area (lamps.h
// sample_lamp) from cell j of the grid. The mean over j is an unbiased estimate: each cell is
// drawn from uniformly and the cells tile the square. Returns 0 when no such lamp has weight;
// else pdf receives p_n(w_n), the density of the cells' mixture (lamps_pdf), and light
// lamps_light(site, w_n).
int nee_sample(LampSite site, vector key, int j, int grid, output vector dir, output float pdf,
               output color light)
{
    pdf = 0.0;
    light = 0;
#if MFL_LAMP_COUNT > 0
    float total = lamps_total_weight(site, 1);
    if (total <= 0.0)
        return 0;
    int dim = -10 - 3 * j;  // three per direction, clear of delta_weight's -1 and the roulette's -5
    float u1 = (float(j % grid) + rng(key, dim - 1)) / float(grid);
    float u2 = (float(j / grid) + rng(key, dim - 2)) / float(grid);
    dir = sample_lamps(site, total, rng(key, dim), u1, u2, 1);
    pdf = lamps_pdf(site, total, dir, 1);
    if (pdf <= 0.0)
        return 0;
    light = lamps_light(site, dir);
    return 1;
#else
    return 0;
#endif
}

// The first term's share of a direction, h = p_n^2 / (p_n^2 + p_d^2): Veach's power heuristic
// (1997, sec. 9.2.4) with any stand-in p_d for the delta's density. Any h in [0, 1] fixed by the
// direction keeps the pair exact; the power heuristic leaves the delta's rare lamp hits a share
// that falls as the square of p_d / p_n where the lamp is the narrower.
float nee_share(float pn, float pd)
{
    if (pn <= 0.0)
        return 0.0;
    float ratio = pd / pn;
    return 1.0 / (1.0 + ratio * ratio);
}

// One direction's first term, weighted by nee_share: rv the residual's r cos toward w_n (what the
// delta carries there), pd the stand-in for the delta's density, the same as nee_cancel's. The
// caller sums it over the grid's directions and divides by their number.
color nee_estimate(color rv, color light, float pn, float pd)
{
    return (pn > 0.0) ? rv * light * (nee_share(pn, pd) / pn) : color(0.0);
}

// The same where the directions came from several strategies (lee_vgroove.osl
// nee_sample_spike): p_all, the sum over the strategies of their direction counts times their
// densities, divides; the share stays nee_share(pn, pd), a function of the direction, as
// nee_cancel's. Not divided by the count.
color nee_estimate_mixed(color rv, color light, float pn, float pd, float p_all)
{
    return (p_all > 0.0) ? rv * light * (nee_share(pn, pd) / p_all) : color(0.0);
}

// The delta's weight W toward a direction where light (lamps_light) is not 0: Cycles' own
// roulette continues a path with probability sqrt(max throughput), and a path it ends would
// leave its subtraction unpaired (an unbounded negative sample: W L for a sun of radiance
// 16,720). So the shader plays the roulette first, keeping the delta with probability max(W)
// and scaling it to a largest channel of 1: on the camera's hit (throughput 1) Cycles then always
// continues it, and the delta's lamp light and its subtraction always come together.
color nee_roulette(color W, color light, vector key)
{
    float m = max(W[0], max(W[1], W[2]));
    if (light[0] + light[1] + light[2] <= 0.0 || m >= 1.0 || m <= 0.0)
        return W;
    return (rng(key, -5) < m) ? W / m : color(0.0);
}

// The subtraction: the delta's weight W_d toward dir times light = lamps_light(site, dir),
// weighted by the same share, nee_share(p_n, pd).
color nee_cancel(LampSite site, vector dir, color weight, color light, float pd)
{
#if MFL_LAMP_COUNT > 0
    if (light[0] + light[1] + light[2] <= 0.0)
        return color(0.0);
    float pn = lamps_pdf(site, lamps_total_weight(site, 1), dir, 1);
    return weight * light * nee_share(pn, pd);
#else
    return color(0.0);
#endif
}

// The density of the guided residual's directions (lamps.h sample_guided_residual) toward wo
// (shading frame): (1 - lam) p_model + lam p_lamps where some aimed lamp has weight at P.
float guided_residual_pdf(LampSite site, int sampler, int dist, vector wi, vector wo, float ax,
                          float ay, vector t, vector b, normal n, float lam_hint, int set)
{
    if (wo[2] <= 0.0)
        return 0.0;
    vector m = normalize(wi + wo);
    float total;
    float lam = (guide_fraction(site, set, total) > 0.0) ? lam_hint : 0.0;
    float p = (1.0 - lam) * reflection_pdf(sampler, dist, wi, m, ax, ay);
    return (lam > 0.0) ? p + lam * lamps_density_local(site, total, wo, t, b, n, set) : p;
}

// The delta residual with weight W about the microfacet normal m (world space) toward dir, on
// a shading point where the control variate is on (on), with its subtraction: pd the stand-in
// for the delta's density the first term used (nee_estimate).
closure color nee_delta(LampSite site, color W, normal m, vector dir, float pd, vector key,
                        int on)
{
    color light = (on && W != color(0.0)) ? lamps_light(site, dir) : color(0.0);
    color Wr = nee_roulette(W, light, key);
    closure color lobe = Wr * delta_reflection(m);
    if (light != color(0.0))
        lobe += nee_emission(-nee_cancel(site, dir, Wr, light, pd));
    return lobe;
}

#endif  // MFL_NEE_H
