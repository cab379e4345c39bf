// Twin: addon/lab/reference/microfacet.py (reflect_about, refract_about, Microfacet's D, lambda_,
// G1, G1_vcavity, G2 and samplers, standard_slope_radius2, beckmann_visible_slope_x).
// Microfacet Lab: distributions of normals, Smith and V-cavity masking, the samplers of
// microfacet normals, and mirror reflection and refraction about a normal; same names, same
// formulas as the twin (the Microfacet object there holds dist, ax, ay).
#ifndef MFL_MICROFACET_H
#define MFL_MICROFACET_H

#include "cycles.h"
#include "special.h"

#define MFL_SQRT_PI 1.77245385090551602730
// Below this alpha the lobe is a delta (perfect mirror): no division by a vanishing alpha.
#define MFL_ALPHA_DELTA 1e-7
// V-cavity masking is not a user choice (Cook-Torrance always uses it): code after the others.
#define MFL_MASKING_VCAVITY 2

// ---------------------------------------------------------------------------------------
// Mirror reflection and refraction about a normal m (OSL's own reflect and refract take the
// incident direction toward the surface: another convention).
vector reflect_about(vector w, vector m) { return 2.0 * dot(w, m) * m - w; }

// Refraction of wi through a facet m (wi.m > 0), eta = n_t / n_i (Walter 2007 eq. 40).
// Returns 0 on total internal reflection.
int refract_about(vector wi, vector m, float eta, output vector wt)
{
    float c = dot(wi, m);
    float cos_t2 = 1.0 - (1.0 - c * c) / (eta * eta);
    if (cos_t2 <= 0.0)
        return 0;
    wt = (c / eta - sqrt(cos_t2)) * m - wi / eta;
    return 1;
}

// ---------------------------------------------------------------------------------------
// Distributions of normals (Walter 2007 eqs. 25, 33; anisotropic form: Heitz 2014 eq. 71).
// e = tan^2(theta_m) weighted by the roughness along each axis.
float D(int dist, vector m, float ax, float ay)
{
    if (m[2] <= 0.0)
        return 0.0;
    float z2 = m[2] * m[2];
    float e = (m[0] * m[0] / (ax * ax) + m[1] * m[1] / (ay * ay)) / z2;
    if (dist == MFL_DISTRIBUTION_GGX)
        return 1.0 / (MFL_PI * ax * ay * z2 * z2 * (1.0 + e) * (1.0 + e));
    return exp(-e) / (MFL_PI * ax * ay * z2 * z2);
}

// Smith Lambda (Heitz 2014 eqs. 72, 80, 86): GGX closed form, Beckmann exact with erf;
// anisotropic through the projected roughness. Uses |w.z|: the same on both sides, as the
// transmission G2 needs.
float lambda_(int dist, vector w, float ax, float ay)
{
    float z = abs(w[2]);
    if (z <= 0.0)
        return 1e30;
    float p2 = ax * ax * w[0] * w[0] + ay * ay * w[1] * w[1];  // alpha_0^2 tan^2 cos^2
    if (p2 <= 0.0)
        return 0.0;
    if (dist == MFL_DISTRIBUTION_GGX) {
        float t2 = p2 / (z * z);
        return t2 / (2.0 * (1.0 + sqrt(1.0 + t2)));  // = (-1 + sqrt(1 + t2)) / 2, stable
    }
    float a = z / sqrt(p2);  // 1 / (alpha tan(theta))
    // (erf(a) - 1)/2 + exp(-a^2)/(2 a sqrt(pi)), written with erfc: no cancellation.
    return max(0.5 * (exp(-a * a) / (a * MFL_SQRT_PI) - erfc(a)), 0.0);
}

// Smith G1 (Walter 2007 eq. 23 / Heitz 2014 eq. 43).
float G1(int dist, vector w, vector m, float ax, float ay)
{
    if (dot(w, m) * w[2] <= 0.0)
        return 0.0;
    return 1.0 / (1.0 + lambda_(dist, w, ax, ay));
}

// V-cavity G1 (Heitz 2014 eq. 55; Torrance-Sparrow / Cook-Torrance G).
float G1_vcavity(vector w, vector m)
{
    float wm = dot(w, m);
    if (wm * w[2] <= 0.0)
        return 0.0;
    return min(1.0, 2.0 * m[2] * w[2] / wm);
}

// G2: height-correlated Smith (Heitz 2014 eq. 99), separable Smith (Walter 2007 eq. 23),
// or V-cavity min(G1(wi), G1(wo)) (Heitz 2014 eq. 57), for reflection.
float G2(int masking, int dist, vector wi, vector wo, vector m, float ax, float ay)
{
    if (masking == MFL_MASKING_VCAVITY)
        return min(G1_vcavity(wi, m), G1_vcavity(wo, m));
    if (dot(wi, m) * wi[2] <= 0.0 || dot(wo, m) * wo[2] <= 0.0)
        return 0.0;
    float li = lambda_(dist, wi, ax, ay);
    float lo = lambda_(dist, wo, ax, ay);
    if (masking == MFL_MASKING_SEPARABLE)
        return 1.0 / ((1.0 + li) * (1.0 + lo));
    return 1.0 / (1.0 + li + lo);
}

// ---------------------------------------------------------------------------------------
// Samplers. Each returns a microfacet normal m in the local frame.

// Slopes of the alpha = 1 distribution, radius^2 from the inverse radial CDF of P22.
float standard_slope_radius2(int dist, float u)
{
    float v = min(u, 0.99999994);
    if (dist == MFL_DISTRIBUTION_GGX)
        return v / (1.0 - v);  // Walter 2007 eq. 35
    return -log(1.0 - v);      // Walter 2007 eq. 28
}

// m ~ D(m)(m.n) (Walter 2007 sec. 5.3): stretch standard slopes by (ax, ay).
vector sample_dcos(int dist, float ax, float ay, float u1, float u2)
{
    float r = sqrt(standard_slope_radius2(dist, u1));
    float phi = 2.0 * MFL_PI * u2;
    return normalize(vector(-r * cos(phi) * ax, -r * sin(phi) * ay, 1.0));
}

// Beckmann visible slope x for alpha = 1 (Heitz & d'Eon 2014 sec. 4 eq. 12): x solves
// C(x) = [(1 + erf x)/2 + tan(t) exp(-x^2)/(2 sqrt(pi))] / (1 + Lambda) = u1 on (-inf, cot t].
// As Jakob 2014 the unknown is b = erf(x) in [-1, erf(cot t)], where dC/db is bounded:
// safeguarded Newton-bisection from Jakob's fitted initial guess, a fixed number of steps
// (5 reach |dx| < 1e-9 in the numpy twin; y = erfinv_giles(2 u2 - 1) in sample_vndf). No special
// case at normal incidence: tan t = 0 reduces C to the Gaussian CDF.
float beckmann_visible_slope_x(float cos_t_in, float sin_t, float u1)
{
    float cos_t = max(cos_t_in, 1e-7);
    float tan_t = sin_t / cos_t;
    float cot_t = min(cos_t / max(sin_t, 1e-30), 6.0);  // slope mass beyond 6 is below 1e-16
    float theta = atan(tan_t);
    float hi = erf(cot_t);
    float lo = -1.0;
    float two_norm = 1.0 + hi + tan_t * exp(-cot_t * cot_t) / MFL_SQRT_PI;  // 2 (1 + Lambda)
    float p = 1.0 + theta * (-0.876 + theta * (0.4265 - 0.0594 * theta));
    float b = hi - (1.0 + hi) * pow(1.0 - u1, p);
    for (int i = 0; i < 8; ++i) {
        if (!(b >= lo && b <= hi))
            b = 0.5 * (lo + hi);
        float x = erfinv_giles(b);
        float f = (1.0 + b + tan_t * exp(-x * x) / MFL_SQRT_PI) / two_norm - u1;
        float df = (1.0 - x * tan_t) / two_norm;
        if (f > 0.0)
            hi = b;
        else
            lo = b;
        b -= f / max(df, 1e-30);
    }
    if (!(b >= lo && b <= hi))
        b = 0.5 * (lo + hi);
    return erfinv_giles(b);
}

// m ~ D_wi(m) = G1(wi,m) <wi,m>+ D(m) / (wi.n) (Heitz & d'Eon 2014 eq. 2).
// GGX: spherical caps (Dupuy & Benyoub 2023, listing 3). Beckmann: slope inversion above.
vector sample_vndf(int dist, vector wi, float ax, float ay, float u1, float u2)
{
    vector wi_std = normalize(vector(ax * wi[0], ay * wi[1], wi[2]));
    if (dist == MFL_DISTRIBUTION_GGX) {
        float phi = 2.0 * MFL_PI * u1;
        float z = (1.0 - u2) * (1.0 + wi_std[2]) - wi_std[2];
        float sin_t = sqrt(clamp(1.0 - z * z, 0.0, 1.0));
        vector h = vector(sin_t * cos(phi), sin_t * sin(phi), z) + wi_std;
        return normalize(vector(ax * h[0], ay * h[1], max(h[2], 0.0)));
    }
    // sin(theta) from the components, not from cos: exact near normal incidence.
    float rxy = sqrt(wi_std[0] * wi_std[0] + wi_std[1] * wi_std[1]);
    float sx = beckmann_visible_slope_x(wi_std[2], rxy, u1);
    float sy = erfinv_giles(2.0 * u2 - 1.0);
    // Rotate the slopes to the azimuth of wi, then unstretch (Heitz & d'Eon 2014 alg. 1).
    float cphi = (rxy > 0.0) ? wi_std[0] / rxy : 1.0;
    float sphi = (rxy > 0.0) ? wi_std[1] / rxy : 0.0;
    float tx = cphi * sx - sphi * sy;
    float ty = sphi * sx + cphi * sy;
    return normalize(vector(-tx * ax, -ty * ay, 1.0));
}

// V-cavity visible normals (Heitz 2014 sec. 6 / seed fig. 14): m ~ D cos, then its mirror
// m' = (-m.x, -m.y, m.z) with probability <wi,m'>+ / (<wi,m>+ + <wi,m'>+).
vector sample_vcavity(int dist, vector wi, float ax, float ay, float u1, float u2, float u3)
{
    vector m = sample_dcos(dist, ax, ay, u1, u2);
    vector m_mirror = vector(-m[0], -m[1], m[2]);
    float a = max(dot(wi, m), 0.0);
    float b = max(dot(wi, m_mirror), 0.0);
    return (u3 * (a + b) < b) ? m_mirror : m;
}

#endif  // MFL_MICROFACET_H
