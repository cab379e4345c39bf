// Microfacet Lab: shared OSL maths, the twin of addon/lab/reference/{fresnel,microfacet}.py.
// The add-on inlines this header into each shader's text block (Cycles compiles INTERNAL
// scripts from a temporary file, so a local #include cannot be found; docs/cycles-osl.md).
//
// Conventions (docs/models.md): local frame n = (0,0,1); wi points from the surface
// toward the viewer (Cycles' I); wo points away from the surface; eta = n_t / n_i.
// Enum codes (MFL_DISTRIBUTION_GGX, MFL_SAMPLER_VNDF, ...) are #defines the add-on generates
// from addon/catalog.py ENUMS and places before this header.

#define MFL_PI 3.14159265358979323846
#define MFL_SQRT_PI 1.77245385090551602730
// Below this alpha the lobe is a delta (perfect mirror): no division by a vanishing alpha.
#define MFL_ALPHA_DELTA 1e-7
// V-cavity masking is not a user choice (Cook-Torrance always uses it): code after the others.
#define MFL_MASKING_VCAVITY 2

// ---------------------------------------------------------------------------------------
// Random numbers. Cycles exposes no per-sample random number to surface shaders, so hash
// values that change every sample (hit point, direction, ray length), decorrelated per
// dimension (docs/cycles-osl.md).
vector rng_key()
{
    float ray_length = 0.0;
    getattribute("path:ray_length", ray_length);
    return vector(hashnoise(P, ray_length),
                  hashnoise(I, ray_length + 0.5),
                  hashnoise(P + I, ray_length * 1.7 + 0.25));
}

float rng(vector key, int dimension) { return hashnoise(key, float(dimension) + 0.5); }

// ---------------------------------------------------------------------------------------
// Local shading frame around the normal; the tangent follows dPdu where it is defined.
void make_frame(normal n, output vector t, output vector b)
{
    vector u = dPdu - n * dot(n, dPdu);
    if (length(u) < 1e-6) {
        u = (abs(n[2]) < 0.9) ? cross(vector(0, 0, 1), n) : cross(vector(1, 0, 0), n);
    }
    t = normalize(u);
    b = cross(n, t);
}

vector to_local(vector v, vector t, vector b, normal n)
{
    return vector(dot(v, t), dot(v, b), dot(v, n));
}

vector to_world(vector v, vector t, vector b, normal n) { return v[0] * t + v[1] * b + v[2] * n; }

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

// Cycles bends a closure normal whose mirror reflection of wi would dip below the geometric
// surface (ensure_valid_specular_reflection), which would turn a refraction lobe through a
// steep microfacet into a wrong direction. Every normal in the plane of wi and wo refracts wi
// into wo for a suitable ratio eta': m' = +-normalize(wi + eta' wo) (Walter 2007 eq. 16),
// oriented toward wi. Return the first m' that Cycles leaves alone, in world space, so the
// lobe points exactly along wo: eta' = eta, else eta' = c/2, c/4, ... with c = -wi.wo > 0
// (a real refraction has wi.wo < 0). For eta' < c the pair is a valid refraction (wo.m' < 0,
// no total internal reflection: Snell holds by construction), and as eta' -> 0, m' -> wi,
// whose mirror reflection is wi itself, which Cycles always accepts; the first halving
// usually does. (Doubling eta' instead, tried first, left 12% of the samples bent at eta 3,
// alpha 1: a 3% error in the gradient.) Arguments in world space; Cycles' threshold.
normal refraction_closure_normal(vector wi, vector wo, float eta, output float eta_closure)
{
    float threshold = min(0.9 * dot(wi, Ng), 0.01) + 1e-4;
    float c = -dot(wi, wo);
    float e = eta;
    for (int i = 0; i < 24; ++i) {
        vector m = normalize(wi + e * wo);
        if (dot(wi, m) < 0.0)
            m = -m;
        if (dot(wo, m) < 0.0 && dot(reflect_about(wi, m), Ng) >= threshold) {
            eta_closure = e;
            return m;
        }
        e = (i == 0) ? 0.5 * c : 0.5 * e;
    }
    eta_closure = eta;
    vector m = normalize(wi + eta * wo);
    return (dot(wi, m) < 0.0) ? -m : m;
}

// The ratio to hand Cycles' refraction() and dielectric_bsdf() for a ratio eta seen from wi's
// side. From Blender 5.3 Cycles inverts the ratio on a back face itself (the add-on says so:
// MFL_CYCLES_INVERTS_BACKFACE_IOR, addon/compat.py), so it gets the inverse there, which it
// inverts back. Handed 1/1.5 unchanged, a 5.3 back face refracted as 1.5 does: rough glass
// seen from inside (bowls, the far side of balls) was several percent off.
float cycles_ior(float eta)
{
    return (MFL_CYCLES_INVERTS_BACKFACE_IOR && backfacing()) ? 1.0 / eta : eta;
}

// A delta refraction lobe along wo (world space) for wi refracted with ratio eta: the normal
// and ratio of refraction_closure_normal.
closure color refraction_toward(vector wi, vector wo, float eta)
{
    float eta_closure;
    normal m = refraction_closure_normal(wi, wo, eta, eta_closure);
    return refraction(m, cycles_ior(eta_closure));
}

float safe_nan(float x, float fallback) { return isnan(x) ? fallback : x; }

// ---------------------------------------------------------------------------------------
// Fresnel. Exact unpolarised dielectric (Cook & Torrance 1982 eq. 9; seed eq. 2-6):
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
    float rs = (t1 - t2) / (t1 + t2);
    float t3 = c2 * a2b2 + s2 * s2;
    float t4 = t2 * s2;
    float rp = rs * (t3 - t4) / (t3 + t4);
    return 0.5 * (rp + rs);
}

color fresnel_conductor(float cos_i, color n, color k)
{
    return color(fresnel_conductor(cos_i, n[0], k[0]),
                 fresnel_conductor(cos_i, n[1], k[1]),
                 fresnel_conductor(cos_i, n[2], k[2]));
}

// The Fresnel factor of a model's Fresnel choice, per channel (1 for none).
color fresnel_color(int fresnel_type, float cos_i, float ior, color n, color k)
{
    if (fresnel_type == MFL_FRESNEL_TYPE_CONDUCTOR)
        return fresnel_conductor(cos_i, n, k);
    if (fresnel_type == MFL_FRESNEL_TYPE_DIELECTRIC)
        return color(fresnel_dielectric(cos_i, ior));
    return color(1.0);
}

// Inverse error function: Giles 2010, "Approximating the erfinv function" (single precision).
float erfinv(float x_in)
{
    float x = clamp(x_in, -0.99999994, 0.99999994);
    float w = -log((1.0 - x) * (1.0 + x));
    float p;
    if (w < 5.0) {
        w = w - 2.5;
        p = 2.81022636e-08;
        p = 3.43273939e-07 + p * w;
        p = -3.5233877e-06 + p * w;
        p = -4.39150654e-06 + p * w;
        p = 0.00021858087 + p * w;
        p = -0.00125372503 + p * w;
        p = -0.00417768164 + p * w;
        p = 0.246640727 + p * w;
        p = 1.50140941 + p * w;
    }
    else {
        w = sqrt(w) - 3.0;
        p = -0.000200214257;
        p = 0.000100950558 + p * w;
        p = 0.00134934322 + p * w;
        p = -0.00367342844 + p * w;
        p = 0.00573950773 + p * w;
        p = -0.0076224613 + p * w;
        p = 0.00943887047 + p * w;
        p = 1.00167406 + p * w;
        p = 2.83297682 + p * w;
    }
    return p * x;
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

// Beckmann visible slopes for alpha = 1 (Heitz & d'Eon 2014 sec. 4 eq. 12): x solves
// C(x) = [(1 + erf x)/2 + tan(t) exp(-x^2)/(2 sqrt(pi))] / (1 + Lambda) = u1 on (-inf, cot t].
// As Jakob 2014 the unknown is b = erf(x) in [-1, erf(cot t)], where dC/db is bounded:
// safeguarded Newton-bisection from Jakob's fitted initial guess, a fixed number of steps
// (5 reach |dx| < 1e-9 in the numpy twin). y = erfinv(2 u2 - 1). No special case at normal
// incidence: tan t = 0 reduces C to the Gaussian CDF.
void sample_beckmann_visible_slopes(float cos_t_in, float sin_t, float u1, float u2,
                                    output float sx, output float sy)
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
        float x = erfinv(b);
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
    sx = erfinv(b);
    sy = erfinv(2.0 * u2 - 1.0);
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
    float sx, sy;
    sample_beckmann_visible_slopes(wi_std[2], rxy, u1, u2, sx, sy);
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

// ---------------------------------------------------------------------------------------
// The sampler's part of the reflection sample weight, f cos / (F G2 pdf): the normal m and
// 1 / (pdf factor) per sampler, as listed above (0 where the sample is invalid).
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

// Density over solid angle of the reflected direction wo = reflect(wi, h) under each sampler:
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

// ---------------------------------------------------------------------------------------
// The light-sampled split (docs/light-sampling.md; twin: addon/lab/reference/split.py):
//   f = c(wi) F f_ggx + r,   r >= 0,
// F f_ggx Cycles' native closure (height-correlated Smith GGX with the model's alphas and
// Fresnel factor F), which Cycles light-samples, and r the model's own stochastic lobe.
// c = tint G_lo is a lower bound of f / (F f_ggx) over every wo, so r is never negative (Cycles
// drops negative weights): G_lo the least ratio G2 / G2_hc (height-correlated 1, separable
// 1 / (1 + Lambda(wi)); Heitz 2014 eqs. 98, 99).

// Below this alpha the lobe is nearly a mirror: stay stochastic (split.ALPHA_SPLIT_MIN).
#define MFL_ALPHA_SPLIT_MIN 1e-3

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

float fresnel_of(int fresnel_type, float x, float ior, float n, float k)
{
    if (fresnel_type == MFL_FRESNEL_TYPE_CONDUCTOR)
        return fresnel_conductor(x, n, k);
    if (fresnel_type == MFL_FRESNEL_TYPE_DIELECTRIC)
        return fresnel_dielectric(x, ior);
    return 1.0;
}

// x = origin + sign t^2, clamped to [lo, hi]: the search variable of fresnel_min.
float fresnel_at(int fresnel_type, float t, float origin, float sign, float lo, float hi,
                 float ior, float n, float k)
{
    return fresnel_of(fresnel_type, clamp(origin + sign * t * t, lo, hi), ior, n, k);
}

// Golden-section minimum of the (unimodal) Fresnel factor over x in [lo, hi], searched in
// t = sqrt(|x - origin|), origin the critical angle's cosine at one end of the interval, where
// F has a square-root cusp that t makes smooth: the least value visited, lowered by the margin
// (split.fresnel_min, the same steps).
float fresnel_min(int fresnel_type, float lo, float hi, float origin, float ior, float n, float k)
{
    float sign = (abs(hi - origin) >= abs(lo - origin)) ? 1.0 : -1.0;
    float a = sqrt(abs(((sign > 0.0) ? lo : hi) - origin));
    float b = sqrt(abs(((sign > 0.0) ? hi : lo) - origin));
    float x1 = b - MFL_GOLDEN * (b - a), x2 = a + MFL_GOLDEN * (b - a);
    float f1 = fresnel_at(fresnel_type, x1, origin, sign, lo, hi, ior, n, k);
    float f2 = fresnel_at(fresnel_type, x2, origin, sign, lo, hi, ior, n, k);
    float best = min(fresnel_at(fresnel_type, a, origin, sign, lo, hi, ior, n, k),
                     fresnel_at(fresnel_type, b, origin, sign, lo, hi, ior, n, k));
    for (int i = 0; i < MFL_MIN_SEARCH_STEPS; ++i) {
        best = min(best, min(f1, f2));
        if (f1 < f2) {  // the minimum lies in [a, x2]
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - MFL_GOLDEN * (b - a);
            f1 = fresnel_at(fresnel_type, x1, origin, sign, lo, hi, ior, n, k);
        }
        else {  // in [x1, b]
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + MFL_GOLDEN * (b - a);
            f2 = fresnel_at(fresnel_type, x2, origin, sign, lo, hi, ior, n, k);
        }
    }
    return min(best, min(f1, f2)) * (1.0 - MFL_FRESNEL_MARGIN);
}

// Least conductor Fresnel over [lo, hi] (split.conductor_min): with n < 1 and k < MFL_CUSP_K, F
// has a (near-)plateau left of the critical angle and a cusp and narrow dip right of it, so the
// two sides are searched apart; otherwise one search covers [lo, 1].
float conductor_min(float lo, float hi, float n, float k)
{
    float xc = (k < MFL_CUSP_K) ? critical_cos(n) : 0.0;
    float split_at = min(max(lo, xc), hi);
    float right = fresnel_min(MFL_FRESNEL_TYPE_CONDUCTOR, split_at, hi, xc, 0.0, n, k);
    if (k <= 0.0 || xc <= lo)
        return right;
    return min(right, fresnel_min(MFL_FRESNEL_TYPE_CONDUCTOR, lo, split_at, xc, 0.0, n, k));
}

// F_lo per channel, the least conductor Fresnel a reflection from wi can meet.
color conductor_lower_bound(vector wi, color n, color k)
{
    float lo = reachable_cos_lo(wi);
    return color(conductor_min(lo, 1.0, n[0], k[0]), conductor_min(lo, 1.0, n[1], k[1]),
                 conductor_min(lo, 1.0, n[2], k[2]));
}

// ---------------------------------------------------------------------------------------
// Lamp controls (docs/light-sampling.md, "Lamp controls"; twin: reference/controls.py): a lower
// bound of the residual's r cos = F D G / (4 wi.n) over a cone of directions wo (axis a,
// half-angle th), for the glossy_toon closure that carries it with Cycles' light sampling
// (lamps.h lamp_controls). Every half vector of the cone lies within beta = asin(sin(th/2) /
// wi.h_a) of h_a = normalize(wi + a) (|wo - a| <= 2 sin(th/2), |wi + a| = 2 wi.h_a), every wo
// within th of a; each factor is bounded on those ranges.

// Least masking factor of r cos over the cone (lam_o: the largest Lambda(wo) there): G2 with no
// native part, G2 - c G2_hc = (1 - c) G1(wo) G2_hc for separable masking beside one.
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
        return color(conductor_min(u_lo, u_hi, n[0], k[0]), conductor_min(u_lo, u_hi, n[1], k[1]),
                     conductor_min(u_lo, u_hi, n[2], k[2]));
    return color(1.0);
}

// Lower bound of r cos over the cone, without the tint; 0 where the cone reaches a horizon or no
// bound holds (split: whether the GGX native part c F f_ggx is returned beside the residual).
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

// c / tint (split.native_factor): G_lo, the least G2 / G2_hc over wo (1 for height-correlated
// masking, 1 / (1 + Lambda(wi)) for separable). The native closure carries the model's own
// Fresnel factor (native_ggx), so c needs no Fresnel bound.
float native_factor(int masking, int dist, vector wi, float ax, float ay)
{
    return (masking == MFL_MASKING_SEPARABLE) ? 1.0 / (1.0 + lambda_(dist, wi, ax, ay)) : 1.0;
}

// Whether Cycles has a native closure equal to the model's single scattering (GGX): always,
// but for a conductor only where its conductor_bsdf is exact (MFL_EXACT_CONDUCTOR, Blender 5.0
// on, defined by the add-on from addon/compat.py; 4.x approximates the conductor Fresnel).
int has_native(int fresnel_type)
{
    return fresnel_type != MFL_FRESNEL_TYPE_CONDUCTOR || MFL_EXACT_CONDUCTOR;
}

// Cycles' native height-correlated GGX reflection closure of a split, carrying the model's own
// Fresnel factor (fresnel_color): conductor_bsdf for a conductor, dielectric_bsdf with no
// transmission for a dielectric (the same closed forms; tests/test_reference_split.py),
// microfacet("ggx") with no Fresnel for none. `ior` is seen from wi's side (cycles_ior).
closure color native_ggx(int fresnel_type, vector t, float ax, float ay, float ior, color n,
                         color k)
{
    if (fresnel_type == MFL_FRESNEL_TYPE_CONDUCTOR)
        return conductor_bsdf(N, t, ax, ay, n, k, "ggx");
    if (fresnel_type == MFL_FRESNEL_TYPE_DIELECTRIC)
        return dielectric_bsdf(N, t, color(1.0), color(0.0), ax, ay, cycles_ior(ior), "ggx");
    return microfacet("ggx", N, t, ax, ay, 0.0, 0);
}

// Cycles drops a closure whose mean weight is below 1e-5 (CLOSURE_WEIGHT_CUTOFF, kernel/closure/
// alloc.h). A delta lobe aimed at a small lamp weighs r cos / p with p up to 1 / (the lamp's
// solid angle) and still carries that lamp's light (radiance up to 1 / solid angle): a residual
// ray aimed at a 0.5-degree sun from where the lobe is faint weighs about 1e-6 and was dropped,
// 32% of a rough Beckmann sphere's sun light with it. Below MFL_MIN_DELTA_WEIGHT the lobe is
// kept with probability mean / MFL_MIN_DELTA_WEIGHT and scaled up to it (Russian roulette:
// unbiased, and a Mix Shader factor down to 0.1 still clears the cutoff).
#define MFL_MIN_DELTA_WEIGHT 1e-4

// w, or its roulette, where the closure's weight will be scale * w.
color delta_weight(color w, color scale, vector key)
{
    color final = scale * w;
    float mean = (final[0] + final[1] + final[2]) / 3.0;
    if (mean >= MFL_MIN_DELTA_WEIGHT || mean <= 0.0)
        return w;
    if (rng(key, -1) * MFL_MIN_DELTA_WEIGHT < mean)
        return w * (MFL_MIN_DELTA_WEIGHT / mean);
    return color(0.0);
}

// One of the two parts per shading sample, never both: when Cycles samples a singular closure
// it adds every other closure's value in that direction with the balance heuristic, taking
// 1e6 for the singular pdf, which biases a sharp native lobe beside a delta residual (gold at
// roughness 0.05: +1.4% red, -1.9% blue near the rim). Chosen with probability q = a / (a + r),
// a the channel sum of a_choice (the native weight times the Fresnel factor the closure
// carries itself, at the mirror direction) and r that of w_choice, the residual's weight as the
// model's sampler alone would give its direction, and divided by it: exact for any q (q = 1
// where the residual is 0), and the two choices then carry about the same total weight, so the
// choice adds little noise. r is not the aimed weight itself: a residual ray aimed at a lamp has
// a small weight, so it would be chosen rarely and then carry the whole a + r into the lamp, a
// rare and heavy sample (a separable gold sphere under a 4-degree sun: pixels +1.0 at 512 spp).
closure color split_closures(color w_native, color a_choice, closure color native,
                             color w_residual, color w_choice, closure color residual, float u)
{
    float a_sum = max(w_native[0] + w_native[1] + w_native[2], 0.0);
    float r = max(w_residual[0] + w_residual[1] + w_residual[2], 0.0);
    if (r <= 0.0)
        return w_native * native;
    if (a_sum <= 0.0)
        return w_residual * residual;
    // Never 0 where the native part has weight (an index-matched conductor's F(1) is 0).
    float a = max(a_choice[0] + a_choice[1] + a_choice[2], 1e-4 * a_sum);
    float q = a / (a + max(w_choice[0] + w_choice[1] + w_choice[2], r));
    if (u < q)
        return (w_native / q) * native;
    return (w_residual / (1.0 - q)) * residual;
}
