"""Special functions (erf, erfinv, chi-square tail) and the Fresnel spot values of docs/models.md."""
import math

import numpy as np
import pytest

from addon.lab.reference.fresnel import fresnel_conductor, fresnel_dielectric
from addon.lab.reference.special import chi2_sf, erf, erfc, erfinv, erfinv_giles


def test_erfc_relative_accuracy():
    x = np.linspace(-6.0, 9.0, 30001)
    ref = np.array([math.erfc(v) for v in x])
    assert np.max(np.abs(erfc(x) / ref - 1.0)) < 1.2e-7


def test_erf_accuracy():
    x = np.concatenate([np.linspace(-6.0, 6.0, 30001), [1e-12, -1e-9, 0.0]])
    ref = np.array([math.erf(v) for v in x])
    err = np.abs(erf(x) - ref)
    assert np.max(err) < 6e-8
    small = np.abs(x) < 0.5
    assert np.max(err[small] / np.maximum(np.abs(ref[small]), 1e-300)) < 1e-13


def test_erfinv_inverts_erf():
    u = np.concatenate([np.linspace(-1.0, 1.0, 20001)[1:-1], [1 - 1e-12, -1 + 1e-12]])
    y = erfinv(u)
    assert np.all(np.isfinite(y))
    assert np.max(np.abs(np.array([math.erf(v) for v in y]) - u)) < 5e-8
    tail = u > 0.99
    rel = np.abs(np.array([math.erfc(v) for v in y[tail]]) / (1.0 - u[tail]) - 1.0)
    assert np.max(rel) < 2e-7
    assert np.max(np.abs(np.array([math.erf(v) for v in erfinv_giles(u)]) - u)) < 1e-7
    assert np.all(np.isfinite(erfinv(np.array([-1.0, 1.0]))))


@pytest.mark.parametrize("x, dof, p", [(3.841458820694124, 1, 0.05), (18.307038053275146, 10, 0.05),
                                       (124.34211340400407, 100, 0.05), (0.0, 5, 1.0),
                                       (6.634896601021214, 1, 0.01), (1.6448536269514722**2, 1, 0.1)])
def test_chi2_sf(x, dof, p):
    assert chi2_sf(x, dof) == pytest.approx(p, rel=1e-9)


def test_fresnel_dielectric_spot_values():
    assert fresnel_dielectric(1.0, 1.5) == pytest.approx(0.04, abs=1e-12)
    c = np.linspace(0.0, 1.0, 101)
    assert np.all(fresnel_dielectric(c, 1.0) == 0.0)  # eta = 1: exactly 0, also at c = 0
    assert fresnel_dielectric(0.0, 1.5) == pytest.approx(1.0)  # grazing
    crit = math.degrees(math.asin(1.0 / 1.5))
    assert crit == pytest.approx(41.81, abs=0.005)
    before, after = fresnel_dielectric(np.cos(np.radians([crit - 0.01, crit + 0.01])), 1 / 1.5)
    assert before < 1.0 and after == 1.0
    assert np.all(fresnel_dielectric(np.cos(np.radians(np.linspace(crit + 1e-6, 90, 50))),
                                     1 / 1.5) == 1.0)
    # Symmetric in the sign of cos_i (|cos_i| is used) and bounded.
    F = fresnel_dielectric(np.linspace(-1, 1, 201), np.array([[0.5], [1.33], [2.4]]))
    assert np.all((F >= 0) & (F <= 1)) and np.allclose(F, F[:, ::-1])


def test_fresnel_conductor_spot_values():
    assert fresnel_conductor(1.0, 2.0, 4.0) == pytest.approx(0.68, abs=0.005)
    # Normal incidence closed form, per channel.
    n, k = np.array([0.166, 0.429, 1.38]), np.array([3.15, 2.45, 1.83])
    F0 = ((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2)
    assert np.allclose(fresnel_conductor(np.ones((4, 1)), n, k), F0, atol=1e-12)
    # Grazing -> 1, k = 0 reduces to the dielectric formula.
    assert np.allclose(fresnel_conductor(0.0, n, k), 1.0)
    c = np.linspace(0.0, 1.0, 51)
    assert np.allclose(fresnel_conductor(c, 1.5, 0.0), fresnel_dielectric(c, 1.5), atol=1e-12)


def _fresnel_complex(c, n, k):
    """The Fresnel equations with complex arithmetic (Born & Wolf sec. 14.2; pbrt-v4
    FrComplex), the independent form the closed form must equal: cos_t = sqrt(1 - s^2/eta^2),
    r_s = (c - eta cos_t)/(c + eta cos_t), r_p = (eta c - cos_t)/(eta c + cos_t)."""
    eta = n + 1j * k
    cos_t = np.sqrt(1.0 - (1.0 - c * c) / (eta * eta))
    r_s = (c - eta * cos_t) / (c + eta * cos_t)
    r_p = (eta * c - cos_t) / (eta * c + cos_t)
    return 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)


def test_fresnel_conductor_closed_form_is_the_complex_fresnel_equations():
    """What this catches: a wrong sign or term in the closed form (the dielectric and normal-
    incidence checks above see only k = 0 or c = 1)."""
    c = np.linspace(1e-6, 1.0, 400)[:, None, None]
    n = np.geomspace(0.01, 50.0, 37)[None, :, None]
    k = np.concatenate([[0.0], np.geomspace(1e-3, 20.0, 30)])[None, None, :]
    closed, exact = fresnel_conductor(c, n, k), _fresnel_complex(c, n, k)
    np.testing.assert_allclose(closed, exact, rtol=1e-9, atol=1e-12)


def test_reference_imports_without_bpy():
    """addon.lab.reference loads with numpy alone (no bpy import, no scipy)."""
    import subprocess
    import sys
    code = ("import sys, addon.lab.reference, addon.lab.reference.quadrature; "
            "assert 'bpy' not in sys.modules and 'scipy' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=str(
        __import__("pathlib").Path(__file__).resolve().parents[1]))
