"""Glass through real geometry in numpy: a closed ball and an open bowl seen from above.

The sphere grid (grid.py) holds a refracting model on one interface, always entered from
outside. Here the numpy twin of a glass model is traced through a unit sphere centred at the
origin, so light also meets the interface from inside (back faces, eta = 1 / ior):

* `"ball"`: the whole sphere; a camera ray enters, bounces inside, leaves.
* `"bowl"`: its lower half (z <= 0) alone, seen through the open top: every camera ray meets a
  back face first (the walk starts on the dense side), reflections inside the bowl meet it
  again or leave through the opening, refractions leave below.

The view is Cycles' orthographic camera looking down -z (addon/lab/harness.py), so a pixel at
(x, y) sends the ray (x, y, +inf) -> -z, and the environment is grid.Environment. The tracer
uses the exact sphere; the renders use a fine smooth UV sphere (tests/test_render_back_faces.py
measures the difference on Cycles' own glass).

`sampler(eta)` gives, for the relative index eta = n_t / n_i seen from wi's side, a function
`(wi (N, 3) local, rng) -> (wo (N, 3) local, weight (N, 3))` drawing one scattering event of
the model, wo.z < 0 for transmission, the sample weight f |cos| / pdf (see `walter_sampler`,
`heitz_sampler`; `reflector_sampler` for an opaque model).
"""
from __future__ import annotations

import numpy as np

from .grid import Environment, GridLayout
from .reference.bsdf import make_bsdf
from .reference.glass import MicrofacetGlass
from .reference.heitz2016 import HeitzDielectric
from .reference.microfacet import Microfacet

SHAPES = ("ball", "bowl")
_EPS = 1e-7  # a hit closer than this along the ray is the surface the ray leaves


def walter_sampler(alpha: float, ior: float):
    """Walter 2007 glass (GGX, height-correlated G2, visible normals): glass.py's sampler."""
    models = {}

    def sample(eta):
        bsdf = models.setdefault(eta, MicrofacetGlass(Microfacet("ggx", alpha), ior=eta))
        return lambda wi, rng: bsdf.sample(wi, rng.random((len(wi), 3)))[:2]
    return _by_side(sample, ior)


def heitz_sampler(alpha: float, ior: float, max_order: int = 100):
    """Heitz 2016 glass (GGX), one walk per event, forward transmission dropped as
    osl/heitz2016.osl drops it."""
    models = {}

    def sample(eta):
        walk = models.setdefault(eta, HeitzDielectric(Microfacet("ggx", alpha), ior=eta,
                                                      forward_transmission=False))

        def draw(wi, rng):
            s = walk.sample(wi, rng, max_order)
            return s.wo, s.weight
        return draw
    return _by_side(sample, ior)


def reflector_sampler(model_id: str, values: dict):
    """An opaque catalog model (reflection only, e.g. Lee's V-grooves with a dielectric
    Fresnel) through its numpy BSDF (make_bsdf): the same on either side, since its IOR does not
    flip on a back face (the surface has no inside)."""
    bsdf = make_bsdf(model_id, values)
    dims = 6 if getattr(bsdf, "groove", "symmetric") == "asymmetric" else 3

    def draw(wi, rng):
        return bsdf.sample(wi, rng.random((len(wi), dims)))[:2]
    return lambda eta_is_front: draw


def _by_side(make, ior):
    front, back = make(float(ior)), make(1.0 / float(ior))
    return lambda eta_is_front: front if eta_is_front else back


def _frame(n):
    """Orthonormal tangents of unit normals n (N, 3) (Duff et al. 2017)."""
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=-1)
    s = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=-1)
    return t, s


def next_hit(shape: str, p, d):
    """Distance along unit d from p to the next hit with the surface (inf where none)."""
    b = np.einsum("ij,ij->i", p, d)
    c = np.einsum("ij,ij->i", p, p) - 1.0
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0.0))
    best = np.full(len(p), np.inf)
    for t in (-b + root, -b - root):  # the far root first, so the near one overrides it
        ok = (disc > 0.0) & (t > _EPS)
        if shape == "bowl":
            ok &= p[:, 2] + t * d[:, 2] <= 0.0
        best = np.where(ok & (t < best), t, best)
    return best


def trace(shape: str, sampler, xy, env: Environment, rng, max_bounces: int = 64):
    """Radiance (N, 3) of one path per camera ray through pixel centres xy (N, 2), the unit
    sphere in world units. A path still hitting the surface after `max_bounces` events counts
    0, as Cycles' bounce limit does."""
    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {SHAPES}, not {shape!r}")
    n = len(xy)
    p = np.column_stack([xy, np.full(n, 10.0)])
    d = np.tile([0.0, 0.0, -1.0], (n, 1))
    throughput = np.ones((n, 3))
    radiance = np.zeros((n, 3))
    alive = np.arange(n)
    for _ in range(max_bounces + 1):
        t = next_hit(shape, p[alive], d[alive])
        escaped = ~np.isfinite(t)
        gone = alive[escaped]
        radiance[gone] = throughput[gone] * env.radiance(d[gone])[:, None]
        alive, t = alive[~escaped], t[~escaped]
        if not len(alive):
            break
        hit = p[alive] + t[:, None] * d[alive]
        outward = hit / np.linalg.norm(hit, axis=-1, keepdims=True)
        front = np.einsum("ij,ij->i", d[alive], outward) < 0.0
        normal = np.where(front[:, None], outward, -outward)  # toward the viewer, as Cycles' N
        tangent, bitangent = _frame(normal)
        wi = -d[alive]
        wi_local = np.stack([np.einsum("ij,ij->i", wi, v) for v in (tangent, bitangent, normal)],
                            axis=-1)
        wo_local = np.zeros_like(wi_local)
        weight = np.zeros((len(alive), 3))
        for side in (True, False):
            sel = front == side
            if sel.any():
                wo_local[sel], weight[sel] = sampler(side)(wi_local[sel], rng)
        wo = (wo_local[:, :1] * tangent + wo_local[:, 1:2] * bitangent
              + wo_local[:, 2:] * normal)
        throughput[alive] *= weight
        p[alive], d[alive] = hit, wo / np.maximum(np.linalg.norm(wo, axis=-1, keepdims=True),
                                                  1e-300)
        alive = alive[weight.max(axis=-1) > 0.0]
    return radiance


# Radial bands of the image around the sphere's centre, in units of its radius: centre,
# middle, rim and edge, of about equal area (so equal noise); the edge stops short of the
# silhouette, where pixels straddle it.
BANDS = ((0.0, 0.45), (0.45, 0.67), (0.67, 0.82), (0.82, 0.95))
BAND_NAMES = ("centre", "middle", "rim", "edge")


def layout(size_px: int) -> GridLayout:
    """The view: one unit sphere in a square image of size_px pixels (the grid's camera)."""
    return GridLayout(rows=1, cols=1, cell_px=size_px)


def band_pixels(view: GridLayout, bands=BANDS):
    """Per band: a boolean mask over the image and the world (x, y) of its pixel centres."""
    xy = view.pixel_world_xy()
    rho = np.linalg.norm(xy, axis=-1) / view.radius
    masks = [(rho >= lo) & (rho < hi) for lo, hi in bands]
    return masks, [xy[m] for m in masks]


def band_means(shape: str, sampler, pixels_by_band, env: Environment, paths: int, seed: int,
               max_bounces: int = 64):
    """Per band (a list of pixel-centre arrays (n_b, 2)): the mean radiance over `paths`
    camera rays through its pixels drawn uniformly, and its standard error, (bands, 3) each."""
    rng = np.random.default_rng(seed)
    means, errors = [], []
    for pixels in pixels_by_band:
        xy = pixels[rng.integers(len(pixels), size=paths)]
        radiance = trace(shape, sampler, xy, env, rng, max_bounces)
        means.append(radiance.mean(axis=0))
        errors.append(radiance.std(axis=0, ddof=1) / np.sqrt(paths))
    return np.array(means), np.array(errors)
