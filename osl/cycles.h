// Twin: none. Cycles and OSL plumbing: numpy has no closures, hash stream or shading frame.
// Microfacet Lab: what the shaders need from Cycles (random numbers, the shading frame, closure
// helpers and their traps, the parameter clamp), none of which the numpy reference models: its
// frame is the local one and its samples numpy's.
// The add-on inlines the headers into each shader's text block, each once, a header after those
// it includes (Cycles compiles INTERNAL scripts from a temporary file, so a local #include
// cannot be found; addon/shaders.py, docs/cycles-osl.md).
//
// Conventions (docs/models.md): local frame n = (0,0,1); wi points from the surface
// toward the viewer (Cycles' I); wo points away from the surface; eta = n_t / n_i.
// Enum codes (MFL_DISTRIBUTION_GGX, MFL_SAMPLER_VNDF, ...) and the Blender version facts
// (MFL_EXACT_CONDUCTOR, MFL_CYCLES_INVERTS_BACKFACE_IOR) are #defines the add-on generates from
// addon/catalog.py ENUMS and addon/compat.py and places before every header.
#ifndef MFL_CYCLES_H
#define MFL_CYCLES_H

#define MFL_PI 3.14159265358979323846

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

// x, or fallback where x is NaN (the one value for which abs(x) >= 0 is false). Not isnan(x),
// which the shader optimizer does not fold: every clamped parameter, and all the code that
// depends on it, would stay in the compiled shader (docs/cycles-osl.md, "Constant folding").
float safe_nan(float x, float fallback) { return (abs(x) >= 0.0) ? x : fallback; }

// ---------------------------------------------------------------------------------------
// Refraction closures.

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
// alpha 1: a 3% error in the gradient.) Arguments in world space; Cycles' threshold. The mirror
// reflection is microfacet.h's reflect_about written out (this header comes before that one).
normal refraction_closure_normal(vector wi, vector wo, float eta, output float eta_closure)
{
    float threshold = min(0.9 * dot(wi, Ng), 0.01) + 1e-4;
    float c = -dot(wi, wo);
    float e = eta;
    for (int i = 0; i < 24; ++i) {
        vector m = normalize(wi + e * wo);
        if (dot(wi, m) < 0.0)
            m = -m;
        if (dot(wo, m) < 0.0 && dot(2.0 * dot(wi, m) * m - wi, Ng) >= threshold) {
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

// Cycles turns a reflection closure's normal so that its mirror direction rises at least
// min(0.9 I.Ng, 0.01) above the geometric surface (ensure_valid_specular_reflection in
// kernel/closure/bsdf_util.h, under the material's bump map correction, on by default; always
// applied to ours, whose normal m is not Ng), and without it rejects a direction below Ng. A
// delta drawn under the geometric surface would leave along that line with the weight of the
// direction drawn and find a lamp sitting there: a rare, heavy sample (Suzanne's smooth-shaded
// brow with a point lamp on its faces' horizon: single samples over 1,000 times the pixel's
// mean).
// So such a delta is not returned: the lobe loses the directions under the geometric surface,
// as Cycles' own closures do (their sampler rejects them), and stays exact above it. A
// direction between the surface and the line is moved onto the line, as before (on a sphere,
// Ng = N, those are all there is: a white furnace stays exactly 1 at grazing incidence).
int clears_surface(normal m)
{
    return dot(Ng, 2.0 * dot(m, I) * m - I) >= 0.0;
}

// The delta reflection about the microfacet normal m (world space) where its direction clears
// the geometric surface, else none.
closure color delta_reflection(normal m)
{
    closure color lobe = 0;
    if (clears_surface(m))
        lobe = reflection(m);
    return lobe;
}

// ---------------------------------------------------------------------------------------
// Cycles' native closures beside our delta lobes (docs/light-sampling.md).

// Whether Cycles has a native closure for the model's single scattering (GGX, Beckmann): always,
// but for a conductor only where its conductor_bsdf is exact (MFL_EXACT_CONDUCTOR, Blender 5.0
// on, defined by the add-on from addon/compat.py; 4.x approximates the conductor Fresnel).
int has_native(int fresnel_type)
{
    return fresnel_type != MFL_FRESNEL_TYPE_CONDUCTOR || MFL_EXACT_CONDUCTOR;
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
// The probability without the choice weights is reference/split.py selection_probability.
// The probability q of the native part (split_closures); 1 where the residual is 0, 0 where
// the native part is.
float split_probability(color w_native, color a_choice, color w_residual, color w_choice)
{
    float a_sum = max(w_native[0] + w_native[1] + w_native[2], 0.0);
    float r = max(w_residual[0] + w_residual[1] + w_residual[2], 0.0);
    if (r <= 0.0)
        return 1.0;
    if (a_sum <= 0.0)
        return 0.0;
    // Never 0 where the native part has weight (an index-matched conductor's F(1) is 0).
    float a = max(a_choice[0] + a_choice[1] + a_choice[2], 1e-4 * a_sum);
    return a / (a + max(w_choice[0] + w_choice[1] + w_choice[2], r));
}

closure color split_closures(color w_native, color a_choice, closure color native,
                             color w_residual, color w_choice, closure color residual, float u)
{
    float q = split_probability(w_native, a_choice, w_residual, w_choice);
    if (u < q)
        return (w_native / q) * native;
    return (w_residual / (1.0 - q)) * residual;
}

#endif  // MFL_CYCLES_H
