// Twin: addon/lab/reference/fresnel.py (fresnel_dielectric, fresnel_conductor, fresnel_color).
// Microfacet Lab: exact unpolarised Fresnel factors, and fresnel_color, the one dispatcher on a
// model's Fresnel choice that every shader uses.
#ifndef MFL_FRESNEL_H
#define MFL_FRESNEL_H

// Exact unpolarised dielectric (Cook & Torrance 1982 eq. 9; seed eq. 2-6):
// c = |wi.m|, g^2 = eta^2 - 1 + c^2; total internal reflection (g^2 < 0) gives 1.
float fresnel_dielectric(float cos_i, float eta)
{
    float c = min(abs(cos_i), 1.0);
    float g2 = eta * eta - 1.0 + c * c;
    if (g2 < 0.0)
        return 1.0;
    float g = sqrt(g2);
    float a = (g - c) / (g + c);
    float b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    return 0.5 * a * a * (1.0 + b * b);
}

// Exact conductor Fresnel for complex IOR n + ik seen from vacuum (Born & Wolf sec. 14.2;
// the closed form of Rs, Rp without complex arithmetic). n >= 0.001 keeps it finite at c = 0.
float fresnel_conductor(float cos_i, float n, float k)
{
    float c = min(abs(cos_i), 1.0);
    float c2 = c * c;
    float s2 = 1.0 - c2;
    float t0 = n * n - k * k - s2;
    float a2b2 = sqrt(t0 * t0 + 4.0 * n * n * k * k);
    float a = sqrt(max(0.5 * (a2b2 + t0), 0.0));
    float t1 = a2b2 + c2;
    float t2 = 2.0 * a * c;
    if (t1 + t2 <= 0.0)
        return 1.0;  // grazing on an index-matched medium: 0/0, take the grazing limit (twin)
    // R_s is a squared modulus: where a = c (an index-matched medium) t1 - t2 cancels to a
    // few ulps either side of 0, and a negative one would make F negative (twin).
    float rs = max((t1 - t2) / (t1 + t2), 0.0);
    float t3 = c2 * a2b2 + s2 * s2;
    float t4 = t2 * s2;
    float rp = rs * (t3 - t4) / (t3 + t4);
    return 0.5 * (rp + rs);
}

// Per channel through one call site: OSL inlines every call (docs/cycles-osl.md).
color fresnel_conductor(float cos_i, color n, color k)
{
    color F = 0;
    for (int c = 0; c < 3; ++c)
        F[c] = fresnel_conductor(cos_i, n[c], k[c]);
    return F;
}

// The Fresnel factor of a model's Fresnel choice (MFL_FRESNEL_TYPE_*), per channel (1 for
// none): the one dispatcher (numpy fresnel_color).
color fresnel_color(int fresnel_type, float cos_i, float ior, color n, color k)
{
    if (fresnel_type == MFL_FRESNEL_TYPE_CONDUCTOR)
        return fresnel_conductor(cos_i, n, k);
    if (fresnel_type == MFL_FRESNEL_TYPE_DIELECTRIC)
        return color(fresnel_dielectric(cos_i, ior));
    return color(1.0);
}

#endif  // MFL_FRESNEL_H
