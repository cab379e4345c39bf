"""What the Heitz 2016 reference tests share (tests/test_reference_heitz2016_*.py): the seed of
their generators, gold's complex index, directions by mu or by polar angles, random directions,
and the z statistic of two Monte Carlo estimates."""
import math
import zlib

import numpy as np

from addon.lab.reference.microfacet import normalize

SEED = 2016
GOLD_N = (0.143, 0.374, 1.442)
GOLD_K = (3.983, 2.385, 1.603)


def rng_for(*key):
    """A Generator seeded by SEED and the key: a test's streams do not depend on its file."""
    return np.random.default_rng([SEED] + [zlib.crc32(repr(k).encode()) for k in key])


def mu_dir(mu):
    """The direction at cos theta = mu in the xz plane."""
    return np.array([math.sqrt(max(1.0 - mu * mu, 0.0)), 0.0, mu])


def polar(theta_deg, phi=0.3):
    """The direction at polar angle theta_deg (degrees), azimuth phi (radians)."""
    t = math.radians(theta_deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


def rand_dirs(rng, n, lower=False, zmin=0.0):
    """n random upper directions (lower: mirrored below); where |z| < zmin, z gets zmin added
    before normalizing (not uniform then)."""
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    z = np.abs(v[:, 2])
    v[:, 2] = np.where(z < zmin, zmin + z, z)
    v = normalize(v)
    if lower:
        v[:, 2] = -v[:, 2]
    return v


def z_of(a, a_se, b, b_se):
    """(a - b) in units of the combined standard error of two independent estimates."""
    return (a - b) / np.maximum(np.hypot(a_se, b_se), 1e-300)  # hypot: se may be ~1e-176
