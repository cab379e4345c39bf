// Twin: addon/lab/reference/bsdf.py (sample_reflection_factor, reflection_pdf).
// Microfacet Lab: one reflection sample of a single-scattering microfacet BRDF per sampler, its
// weight without Fresnel and tint in closed form, and its density (the twin's MicrofacetBRDF:
// sample_normal, inv_pdf_factor, sample).
#ifndef MFL_BSDF_H
#define MFL_BSDF_H

#include "cycles.h"
#include "microfacet.h"

// The sampler's part of the reflection sample weight, f cos / (F G2 pdf): the normal m and
// 1 / (pdf factor) per sampler, the closed forms listed at sample_reflection (0 where the sample
// is invalid).
float sample_reflection_factor(int sampler, int dist, vector wi, float ax, float ay, vector key,
                               output vector m)
{
    m = vector(0, 0, 1);
    if (wi[2] <= 0.0)
        return 0.0;
    float u1 = rng(key, 0);
    float u2 = rng(key, 1);
    float inv_pdf_factor;
    if (sampler == MFL_SAMPLER_DCOS) {
        m = sample_dcos(dist, ax, ay, u1, u2);
        inv_pdf_factor = abs(dot(wi, m)) / (wi[2] * m[2]);
    }
    else if (sampler == MFL_SAMPLER_VNDF) {
        m = sample_vndf(dist, wi, ax, ay, u1, u2);
        float g1 = G1(dist, wi, m, ax, ay);
        inv_pdf_factor = (g1 > 0.0) ? 1.0 / g1 : 0.0;
    }
    else {
        m = sample_vcavity(dist, wi, ax, ay, u1, u2, rng(key, 2));
        float g1 = G1_vcavity(wi, m);
        inv_pdf_factor = (g1 > 0.0) ? 1.0 / g1 : 0.0;
    }
    return (dot(wi, m) > 0.0) ? inv_pdf_factor : 0.0;
}

// Density over solid angle of the reflected direction wo = reflect_about(wi, h) under each sampler:
// pdf_m(h) / (4 wi.h) (Walter 2007 eq. 14), pdf_m = D cos (Walter 2007 eq. 24), the visible
// normals G1(wi) <wi,h> D / wi.n (Heitz & d'Eon 2014 eq. 2) or the V-cavity's (Heitz 2014
// sec. 6). D / (4 wi.n pdf) is then what sample_reflection_factor returns for that h.
float reflection_pdf(int sampler, int dist, vector wi, vector h, float ax, float ay)
{
    float c = dot(wi, h);
    if (c <= 0.0 || h[2] <= 0.0 || wi[2] <= 0.0)
        return 0.0;
    float d = D(dist, h, ax, ay);
    float pdf_m;
    if (sampler == MFL_SAMPLER_DCOS)
        pdf_m = d * h[2];
    else if (sampler == MFL_SAMPLER_VNDF)
        pdf_m = G1(dist, wi, h, ax, ay) * c * d / wi[2];
    else
        pdf_m = G1_vcavity(wi, h) * c * d / wi[2];
    return pdf_m / (4.0 * c);
}

// One reflection sample of a single-scattering microfacet BRDF: returns the normal m that
// mirrors wi into wo, and the sample weight without Fresnel, f cos / (F pdf), in closed form
// per sampler (seed eq. 4-7 and fig. 12; Heitz & d'Eon 2014 eq. 8; Heitz 2014 sec. 6):
//   dcos:    G2 |wi.m| / (|wi.n| |m.n|)        (unbounded)
//   vndf:    G2 / G1(wi)                       (Smith G1 of `dist`; in [0, 1] for Smith G2)
//   vcavity: G2 / G1_vcavity(wi, m)            (in [0, 1] for V-cavity G2)
float sample_reflection(int sampler, int dist, int masking, vector wi, float ax, float ay,
                        vector key, output vector m)
{
    m = vector(0, 0, 1);
    if (wi[2] <= 0.0)
        return 0.0;
    if (max(ax, ay) < MFL_ALPHA_DELTA)
        return 1.0;  // perfect mirror: G2 = G1 = 1
    float inv_pdf_factor = sample_reflection_factor(sampler, dist, wi, ax, ay, key, m);
    vector wo = reflect_about(wi, m);
    if (inv_pdf_factor <= 0.0 || wo[2] <= 0.0)
        return 0.0;
    return G2(masking, dist, wi, wo, m, ax, ay) * inv_pdf_factor;
}

#endif  // MFL_BSDF_H
