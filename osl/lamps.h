// Twin: addon/lab/reference/lamps.py (the residual's direct light: lamp sampling and density).
// Microfacet Lab: the residual's direct light (docs/light-sampling.md, "The residual's direct
// light").
//
// The add-on writes the scene's lamps into the table below (addon/lamps.py, slots listed
// there). A shader draws its residual's delta-lobe direction from the mixture
//   p(wo) = (1 - lam) p_model(wo) + lam sum_j pi_j p_j(wo),
// p_j uniform over lamp j's solid angle (sun cone, the cone of a sphere lamp) or over its area,
// pi_j proportional to a rough irradiance of lamp j at P, lam the shader's guess when some
// lamp can be aimed at from P (else 0; residual_guide_fraction in controls.h), and weights
// the sample r cos / p(wo) (Veach 1997, the one-sample balance heuristic). The reflected ray
// is an ordinary ray: it meets the lamp, or whatever blocks it, and Cycles adds what it finds,
// so the table only moves noise: a stale or missing lamp never biases, an occluder is never
// crossed, and no lamp is counted twice.
#ifndef MFL_LAMPS_H
#define MFL_LAMPS_H

#include "cycles.h"
#include "microfacet.h"
#include "bsdf.h"

// @lamps
#include "spots.h"
#define MFL_LAMP_SUN 0
#define MFL_LAMP_SPHERE 1
#define MFL_LAMP_RECT 2
#define MFL_LAMP_ELLIPSE 3
#define MFL_GUIDE_FRACTION 0.5
// Which lamps a function looks at (lamp_share): the ones the residual aims at and controls where
// the control variate (nee.h) is on, the ones it takes there, or every lamp where it is off.
#define MFL_LAMPS_AIMED 0
#define MFL_LAMPS_PREDICTED 1
#define MFL_LAMPS_ALL 2
// Whether the control variate (nee.h) is compiled in: only with a lamp that has a predicted
// radiance. Without one its branches fold away (they cost the Lee shader 35% of its operations
// after optimization, in every scene without a prediction).
#define MFL_PAIRED (MFL_LAMP_COUNT > 0 && MFL_PREDICTED_LAMP_COUNT > 0)
// Sampling and density use each lamp enlarged by this fraction (a cone's sin^2 and an area's
// half-extents): where a direction lies on the lamp's rim, float rounding in our cone test and
// in Cycles' hit test could disagree, and a direction Cycles sees inside the lamp that our
// density calls outside weighs r cos / ((1 - lam) p_model), a rare, heavy sample (0.5-degree
// sun: pixels up to 25 at 4096 spp, a test failing its power check). The enlarged lamp is only
// the proposal, so the estimate stays exact.
#define MFL_LAMP_MARGIN 2e-3

// Whether dir lies in the cone of sin^2(half-angle) sin2 around axis (half-angles below pi/2):
// sin^2 from the cross product, exact for tiny cones where 1 - cos rounds away.
int in_cone(vector dir, vector axis, float sin2)
{
    vector c = cross(dir, axis);
    return dot(dir, axis) > 0.0 && dot(c, c) <= sin2;
}

// The uniform density over a cone of half-angle th: 1 / (2 pi (1 - cos th)).
float cone_density(float th) { return 1.0 / (4.0 * MFL_PI * sin(0.5 * th) * sin(0.5 * th)); }

// The lamps as seen from the shading point, computed once per shader by lamp_site: what the
// functions below ask of each lamp again and again. OSL inlines every call, and each call of
// lamp_share or lamp_bounding_cone was a copy of their code (20-40 in Lee's shader: under a sun,
// a point and an area lamp its runtime compile took 9 s of 10; docs/cycles-osl.md, "Constant
// folding").
#if MFL_LAMP_COUNT > 0
#define MFL_LAMP_SLOTS MFL_LAMP_COUNT
#else
#define MFL_LAMP_SLOTS 1
#endif
struct LampSite {
    float weight[MFL_LAMP_SLOTS];    // lamp_weight with the shading normal N
    float weight_g[MFL_LAMP_SLOTS];  // lamp_weight with the geometric normal Ng
    int estimated[MFL_LAMP_SLOTS];   // lamp_estimated
    int bounded[MFL_LAMP_SLOTS];     // lamp_bounding_cone: whether there is one, its axis and th
    vector axis[MFL_LAMP_SLOTS];     // (a sun's or a sphere lamp's: lamp_cone's axis too)
    float th[MFL_LAMP_SLOTS];
    float omc[MFL_LAMP_SLOTS];       // lamp_cone's 1 - cos and sin^2 (suns and sphere lamps)
    float sin2[MFL_LAMP_SLOTS];
};

#if MFL_LAMP_COUNT > 0
vector lamp_vector(int i, int j)
{
    return vector(lamp_datum(i, j), lamp_datum(i, j + 1), lamp_datum(i, j + 2));
}

// Where every lamp in the table is of one kind (MFL_LAMP_ONE_KIND, written by the add-on; -1
// where they differ), as under one sun or one area lamp, the kind is a constant, and the shader
// optimizer drops the other kinds' code, which OSL inlines at every call. Where they differ,
// the kinds absent from the table (MFL_LAMP_KINDS: a flag per kind) still fold away: a sun and
// a point lamp leave the area lamps' code out (with it, Lee's runtime compile under the two
// took 5-8 s, five times that under either alone; 2.5 s without). Callers test
// lamp_is(i, kind) or lamp_is_area(i) itself, never a local copy (a named local of a function
// is one symbol for all the function's inlined copies, and the optimizer forgets its value
// past a branch), and put the other kinds' code in an else: the optimizer drops a folded
// branch's other side, not the code after a return.
int lamp_kind(int i)
{
#if MFL_LAMP_ONE_KIND >= 0
    return MFL_LAMP_ONE_KIND;
#else
    return int(lamp_datum(i, 0) + 0.5);
#endif
}

int lamp_is(int i, int kind)
{
    // An array, not bits: the optimizer folds a constant array's element, not a shift.
    int present[4] = {MFL_LAMP_KINDS};
    return present[kind] * (lamp_kind(i) == kind);
}

// A rectangle or an ellipse (else a sun or a sphere lamp): 0 wherever the table has neither.
int lamp_is_area(int i) { return lamp_is(i, MFL_LAMP_RECT) + lamp_is(i, MFL_LAMP_ELLIPSE); }

// An area lamp's half-extent axes, enlarged by MFL_LAMP_MARGIN for sampling and density.
vector lamp_u(int i) { return lamp_vector(i, 7) * (1.0 + MFL_LAMP_MARGIN); }
vector lamp_v(int i) { return lamp_vector(i, 10) * (1.0 + MFL_LAMP_MARGIN); }

// Cone of directions toward lamp i from P (sun; point or spot lamp, a sphere or a disk facing
// P): axis, 1 - cos and sin^2 of its half-angle. Returns 0 when P is inside the lamp's radius.
int lamp_cone(int i, point P, output vector axis, output float one_minus_cos,
              output float sin2)
{
    if (lamp_is(i, MFL_LAMP_SUN)) {
        axis = lamp_vector(i, 4);
        float omc = lamp_datum(i, 13);
        sin2 = omc * (2.0 - omc);
    }
    else {
        vector to = lamp_vector(i, 1) - P;
        float d2 = dot(to, to);
        float r = lamp_datum(i, 13);
        if (d2 <= r * r)
            return 0;
        axis = to / sqrt(d2);
        // A sphere subtends asin(r / d); a disk facing P (Soft Falloff) atan(r / d).
        sin2 = r * r / ((lamp_datum(i, 15) > 0.5) ? d2 : d2 + r * r);
    }
    sin2 = min(sin2 * (1.0 + MFL_LAMP_MARGIN), 1.0);
    one_minus_cos = sin2 / (1.0 + sqrt(1.0 - sin2));  // 1 - sqrt(1 - s2), no cancellation
    return 1;
}

float lamp_area(int i)
{
    float a = length(lamp_u(i)) * length(lamp_v(i));
    return lamp_is(i, MFL_LAMP_ELLIPSE) ? MFL_PI * a : 4.0 * a;
}

// Guiding weight of lamp i at P with normal Ng: a rough irradiance; 0 when the lamp is behind
// the surface, P is inside it or behind an area lamp. Any choice is exact (only the noise
// depends on it), as long as sampling and density use the same one.
float lamp_weight(int i, point P, normal Ng)
{
    float power = lamp_datum(i, 14);
    if (lamp_is(i, MFL_LAMP_SUN)) {
        float omc = lamp_datum(i, 13);
        return (dot(Ng, lamp_vector(i, 4)) > -sqrt(omc * (2.0 - omc))) ? power : 0.0;
    }
    else {  // an else, for the optimizer: see lamp_kind
        vector to = lamp_vector(i, 1) - P;
        float d2 = dot(to, to);
        if (!lamp_is_area(i)) {  // a sphere lamp
            float r = lamp_datum(i, 13);
            if (d2 <= r * r || dot(Ng, to) < -r)
                return 0.0;
            return power / (4.0 * MFL_PI * d2);
        }
        else {  // an area lamp
            float front = -dot(lamp_vector(i, 4), to);  // P's distance in front of its plane
            float extent = length(lamp_vector(i, 7)) + length(lamp_vector(i, 10));
            if (front <= 0.0 || dot(Ng, to) < -extent)
                return 0.0;
            return power * front / (MFL_PI * sqrt(d2) * max(d2, lamp_area(i)));
        }
    }
}

// Uniform direction in the cone around axis with the given 1 - cos(half-angle).
vector sample_cone(vector axis, float one_minus_cos, float u1, float u2)
{
    float s = u1 * one_minus_cos;  // 1 - cos(theta)
    float cos_t = 1.0 - s;
    float sin_t = sqrt(max(s * (2.0 - s), 0.0));
    float phi = 2.0 * MFL_PI * u2;
    vector t, b;
    make_frame(normal(axis), t, b);
    return (sin_t * cos(phi)) * t + (sin_t * sin(phi)) * b + cos_t * axis;
}

// The offset of a world spot's texels in the spot table (addon/lamps.py, slot 15 of a sun),
// where the shaders read them, else -1.
int lamp_texels(int i)
{
#if MFL_SPOT_TEXELS
    if (lamp_is(i, MFL_LAMP_SUN))
        return int(lamp_datum(i, 15) + 0.5) - 1;
#endif
    return -1;
}

// A direction toward lamp i from P (world space), drawn from p_i: over a world spot's texels by
// their light (spots.h) where the shaders read them.
vector sample_lamp(LampSite site, int i, float u1, float u2)
{
#if MFL_SPOT_TEXELS
    int texels = lamp_texels(i);
    if (texels >= 0)
        return spot_sample(texels, u1, u2);
#endif
    if (!lamp_is_area(i)) {
        if (!site.bounded[i])
            return vector(0, 0, 1);
        return sample_cone(site.axis[i], site.omc[i], u1, u2);
    }
    else {
        float s, t;
        if (lamp_is(i, MFL_LAMP_ELLIPSE)) {  // uniform over the disk, then stretched
            float r = sqrt(u1);
            s = r * cos(2.0 * MFL_PI * u2);
            t = r * sin(2.0 * MFL_PI * u2);
        }
        else {
            s = 2.0 * u1 - 1.0;
            t = 2.0 * u2 - 1.0;
        }
        point q = lamp_vector(i, 1) + s * lamp_u(i) + t * lamp_v(i);
        return normalize(q - P);
    }
}

// p_i(dir) over solid angle: uniform over a cone, or area density dist^2 / (A |cos|); a world
// spot's over its texels (spots.h) where the shaders read them.
float lamp_pdf(LampSite site, int i, vector dir)
{
#if MFL_SPOT_TEXELS
    int texels = lamp_texels(i);
    if (texels >= 0)
        return spot_pdf(texels, dir);
#endif
    if (!lamp_is_area(i)) {
        if (!site.bounded[i])
            return 0.0;
        return in_cone(dir, site.axis[i], site.sin2[i]) ? 1.0 / (2.0 * MFL_PI * site.omc[i])
                                                        : 0.0;
    }
    else {
        vector n = lamp_vector(i, 4);
        float cos_l = -dot(dir, n);
        if (cos_l <= 0.0)
            return 0.0;
        vector u = lamp_u(i);
        vector v = lamp_v(i);
        point c = lamp_vector(i, 1);
        float dist = dot(P - c, n) / cos_l;
        if (dist <= 0.0)
            return 0.0;
        vector q = P + dist * dir - c;
        float s = dot(q, u) / dot(u, u);
        float t = dot(q, v) / dot(v, v);
        int inside = lamp_is(i, MFL_LAMP_ELLIPSE) ? (s * s + t * t <= 1.0)
                                                  : (abs(s) <= 1.0 && abs(t) <= 1.0);
        return inside ? dist * dist / (lamp_area(i) * cos_l) : 0.0;
    }
}

// A cone holding every direction toward lamp i from P: lamp_cone for suns and sphere lamps;
// about the centre out to the farthest corner of the rectangle for area lamps (an ellipse's
// bounding rectangle). Returns 0 where there is none.
int lamp_bounding_cone(int i, point P, output vector axis, output float th)
{
    if (!lamp_is_area(i)) {
        float omc, sin2;
        if (!lamp_cone(i, P, axis, omc, sin2))
            return 0;
        th = lamp_is(i, MFL_LAMP_SUN) ? 2.0 * asin(sqrt(0.5 * omc))
                                      : asin(sqrt(clamp(sin2, 0.0, 1.0)));
        return 1;
    }
    else {
        vector to = lamp_vector(i, 1) - P;
        float d = length(to);
        if (d <= 0.0)
            return 0;
        axis = to / d;
        th = 0.0;
        vector u = lamp_u(i);
        vector v = lamp_v(i);
        for (int c = 0; c < 4; c++) {
            vector corner = normalize(to + ((c & 1) ? u : -u) + ((c & 2) ? v : -v));
            th = max(th, acos(clamp(dot(corner, axis), -1.0, 1.0)));
        }
        return 1;
    }
}
// The lamp's radiance as the hand-over predicts it (slots 16-18), 0 where it does not.
color lamp_predicted(int i)
{
    return color(lamp_datum(i, 16), lamp_datum(i, 17), lamp_datum(i, 18));
}

// Whether nee.h estimates the predicted lamps' light at this shading point: on the camera's hits
// only (path:ray_depth 0), where a path's throughput is known (nee.h).
int lamps_estimated_here()
{
    int depth = 1;
    getattribute("path:ray_depth", depth);
    return depth == 0;
}

// The sine of the least elevation over the geometric surface at which a delta leaves as drawn:
// Cycles turns a reflection below min(0.9 I.Ng, 0.01) onto that line (cycles.h clears_surface),
// plus a margin for rounding (nee.h lamps_light).
#define MFL_NEE_HORIZON_MARGIN 2e-3
float nee_horizon() { return min(0.9 * dot(I, Ng), 0.01) + MFL_NEE_HORIZON_MARGIN; }

// A lamp at least this wide (its bounding cone's half-angle, radians) is estimated even where it
// reaches below nee_horizon (lamp_estimated).
#define MFL_NEE_WIDE_LAMP 0.1

// Whether nee.h may estimate lamp i from P (bounded, axis, th: its bounding cone), over the
// geometric surface (Ng; the weights also have one with N, lamp_site): where every direction
// toward it rises above nee_horizon, or where it is wide. The directions above a line at a
// positive height form a convex cone, so an area lamp lies in it where its four corners do (an
// ellipse's bounding rectangle's); a sun or a sphere lamp where its cone does. Below the line
// the estimate counts nothing either way (nee.h lamps_light); what the rule keeps out is a
// small lamp there: the deltas Cycles turns onto the line from under it meet it unaimed, rare
// and heavy (a point lamp on Suzanne's horizon: pixels of +12 at 64 samples). A wide lamp meets
// them often and lightly, and the estimate above the line is worth more
// (docs/noise-measurements.md, sec. 16).
int lamp_estimable(int i, point P, int bounded, vector axis, float th)
{
    if (!bounded)
        return 0;
    if (th >= MFL_NEE_WIDE_LAMP)
        return 1;
    if (lamp_is_area(i)) {
        float horizon = max(nee_horizon(), 0.0);  // a convex cone
        vector to = lamp_vector(i, 1) - P;
        vector u = lamp_u(i);
        vector v = lamp_v(i);
        for (int c = 0; c < 4; c++) {
            vector corner = to + ((c & 1) ? u : -u) + ((c & 2) ? v : -v);
            float d = length(corner);
            if (d <= 0.0 || dot(corner, Ng) <= horizon * d)
                return 0;
        }
        return 1;
    }
    else {
        float lowest = asin(clamp(dot(axis, Ng), -1.0, 1.0)) - th;
        return lowest > 0.0 && sin(lowest) > nee_horizon();
    }
}

// Whether nee.h estimates lamp i's light here: a predicted radiance, on the camera's hits, and
// the lamp wholly above nee_horizon or wide (lamp_estimable; bounded, axis, th: its bounding
// cone, lamp_bounding_cone). The estimate and its subtraction count only directions above the
// line (nee.h lamps_light): Cycles turns the deltas drawn under it onto it, in or out of the
// lamp, so a subtraction there would not pair with them (under a 1-degree sun: pixels of -260).
// A small lamp reaching below it stays aimed at.
int lamp_estimated(int i, point P, int bounded, vector axis, float th)
{
    color L = lamp_predicted(i);
    return L[0] + L[1] + L[2] > 0.0 && lamps_estimated_here() &&
           lamp_estimable(i, P, bounded, axis, th);
}
#endif

// Fills the LampSite of the shading point P (its normals N and Ng).
void lamp_site(output LampSite site)
{
#if MFL_LAMP_COUNT > 0
    for (int i = 0; i < MFL_LAMP_COUNT; i++) {
        site.weight[i] = lamp_weight(i, P, N);
        site.weight_g[i] = lamp_weight(i, P, Ng);
        vector axis = vector(0, 0, 1);
        float th = 0.0;
        int bounded = lamp_bounding_cone(i, P, axis, th);
        float omc = 0.0;
        float sin2 = 0.0;
        if (!lamp_is_area(i)) {
            vector cone_axis;
            lamp_cone(i, P, cone_axis, omc, sin2);
        }
        site.bounded[i] = bounded;
        site.axis[i] = axis;
        site.th[i] = th;
        site.omc[i] = omc;
        site.sin2[i] = sin2;
        site.estimated[i] = lamp_estimated(i, P, bounded, axis, th);
    }
#endif
}

#if MFL_LAMP_COUNT > 0
// Lamp i's weight in a set: MFL_LAMPS_PREDICTED the lamps nee.h estimates here
// (lamp_estimated), MFL_LAMPS_AIMED the others, which the residual aims at, MFL_LAMPS_ALL every
// lamp; lamp_weight with the shading normal N, or with Ng where geometric.
float lamp_share(LampSite site, int i, int set, int geometric)
{
    float w = geometric ? site.weight_g[i] : site.weight[i];
    if (set == MFL_LAMPS_ALL)
        return w;
    return (site.estimated[i] == (set == MFL_LAMPS_PREDICTED)) ? w : 0.0;
}

float lamps_total_weight(LampSite site, int set)
{
    float total = 0.0;
    for (int i = 0; i < MFL_LAMP_COUNT; i++)
        total += lamp_share(site, i, set, 0);
    return total;
}

// sum_j pi_j p_j(dir) over a set, pi_j = weight_j / total.
float lamps_pdf(LampSite site, float total, vector dir, int set)
{
    if (total <= 0.0)
        return 0.0;
    float pdf = 0.0;
    for (int i = 0; i < MFL_LAMP_COUNT; i++) {
        float w = lamp_share(site, i, set, 0);
        if (w > 0.0)
            pdf += w * lamp_pdf(site, i, dir);
    }
    return pdf / total;
}

// Lamp j of a set with probability pi_j, then a direction from p_j.
vector sample_lamps(LampSite site, float total, float u0, float u1, float u2, int set)
{
    float target = u0 * total;
    int chosen = -1;
    for (int i = 0; i < MFL_LAMP_COUNT; i++) {
        float w = lamp_share(site, i, set, 0);
        if (w > 0.0) {
            chosen = i;  // the last lamp with weight catches rounding at u0 near 1
            if (target < w)
                break;
            target -= w;
        }
    }
    return (chosen >= 0) ? sample_lamp(site, chosen, u1, u2) : vector(0, 0, 1);
}
#endif

// lam for a shading point: MFL_GUIDE_FRACTION when some lamp of the set has weight there, else
// 0; total receives the sum of their weights.
float guide_fraction(LampSite site, int set, output float total)
{
    total = 0.0;
#if MFL_LAMP_COUNT > 0
    total = lamps_total_weight(site, set);
    if (total > 0.0)
        return MFL_GUIDE_FRACTION;
#endif
    return 0.0;
}

vector sample_lamps_local(LampSite site, float total, vector t, vector b, normal n, vector key,
                          int set)
{
#if MFL_LAMP_COUNT > 0
    vector dir = sample_lamps(site, total, rng(key, 7), rng(key, 8), rng(key, 9), set);
    return to_local(dir, t, b, n);
#else
    return vector(0, 0, 1);
#endif
}

float lamps_density_local(LampSite site, float total, vector wo, vector t, vector b, normal n,
                          int set)
{
#if MFL_LAMP_COUNT > 0
    return lamps_pdf(site, total, to_world(wo, t, b, n), set);
#else
    return 0.0;
#endif
}

// One direction for a reflection residual, from the mixture above when some lamp can be aimed
// at from P (lam = lam_hint there: residual_guide_fraction in controls.h), else from the
// model's sampler alone. Returns the factor that multiplies the
// residual's F G2 - c G2_hc in its sample weight, D(m) / (4 wi.n p(wo)) (with the model's
// sampler alone this is sample_reflection_factor's closed form), and the half vector m of wi
// and wo; pdf receives p(wo) where some lamp has weight (else 0). model_share receives
// (1 - lam) p_model(wo) / p(wo), 1 without lamps: the weight over it is what the model's
// sampler alone would give wo, which split_closures chooses with (a choice made from the
// guided weight itself would undo the aiming: see split_closures). set: the lamps aimed at
// (lamp_share). 0 for an invalid sample.
float sample_guided_residual(LampSite site, int sampler, int dist, vector wi, float ax,
                             float ay, vector t, vector b, normal n, vector key, float lam_hint,
                             int set, output vector m, output vector wo, output float model_share,
                             output float pdf)
{
    model_share = 1.0;
    pdf = 0.0;
    float total;
    float lam = (guide_fraction(site, set, total) > 0.0) ? lam_hint : 0.0;
    if (lam <= 0.0 || rng(key, 6) >= lam) {
        float factor = sample_reflection_factor(sampler, dist, wi, ax, ay, key, m);
        wo = reflect_about(wi, m);
        if (lam <= 0.0 || factor <= 0.0)
            return factor;
    }
    else {
        wo = sample_lamps_local(site, total, t, b, n, key, set);
        m = normalize(wi + wo);
    }
    if (wi[2] <= 0.0 || wo[2] <= 0.0)
        return 0.0;
    float p_model = (1.0 - lam) * reflection_pdf(sampler, dist, wi, m, ax, ay);
    pdf = p_model + lam * lamps_density_local(site, total, wo, t, b, n, set);
    if (pdf <= 0.0)
        return 0.0;
    model_share = p_model / pdf;
    return D(dist, m, ax, ay) / (4.0 * wi[2] * pdf);
}

#endif  // MFL_LAMPS_H
