// Twin: addon/lab/reference/special.py (erfinv_giles).
// Microfacet Lab: special functions OSL lacks. OSL has erf and erfc; the inverse error function
// is Giles's single-precision fit, which numpy's erfinv refines with Newton steps (special.py).
#ifndef MFL_SPECIAL_H
#define MFL_SPECIAL_H

// Inverse error function: Giles 2010, "Approximating the erfinv function" (single precision).
float erfinv_giles(float x_in)
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

#endif  // MFL_SPECIAL_H
