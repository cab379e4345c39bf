"""The report's settings per mode (full, quick, smoke), its constants and its progress log."""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

TARGET = 0.01  # relative RMSE for the time-to-target table
MU_MIN_RMSE = 0.05  # the rim beyond is left out of the RMSE (see grid.MU_BANDS)
SUN_DIRECTION = (0.6, 0.48, 0.64)  # toward the sun, world space (same as the gradient's)
SUN_ANGLE_DEG = 4.0  # angular diameter
SUN_STRENGTH = 1.0  # irradiance at normal incidence, W/m^2
SUN_WORLD = 0.05  # the dim uniform world under the sun
# Lights that are a uniform cone over the dim world, by environment key: (kind, angular
# diameter in degrees). "lamp": a Cycles sun lamp (radiance calibrated on a mirror sphere);
# "world": a bright spot painted into the world shader, no lamp (radiance exact, SPOT_STRENGTH
# of irradiance at normal incidence), found by Cycles' world importance sampling and not read
# by the add-on; "image": the same spot drawn in the pixels of an equirectangular image (an
# HDRI's sun, Closest interpolation, HDRI_SIZE pixels), found and handed over by the add-on.
CONE_LIGHTS = {"sun": ("lamp", SUN_ANGLE_DEG), "sun05": ("lamp", 0.5), "spot": ("world", 4.0),
               "hdri": ("image", 4.0)}
HDRI_SIZE = (512, 256)
SPOT_STRENGTH = 1.0
# "point": a point lamp (Blender's defaults: Soft Falloff, so a disk facing the shading point)
# above the grid's centre, over the dim world; power for an irradiance of 1 W/m^2 at the
# distance of the spheres' tops below it.
POINT_LAMP = {"height": 6.0, "radius": 0.25}
POINT_LAMP["power"] = 4.0 * 3.141592653589793 * (POINT_LAMP["height"] - 1.0) ** 2
# "area": a rectangular area lamp (1 x 0.5, tilted 0.3 rad about x) at the same height, its
# power for about the same irradiance below it.
AREA_LAMP = {"height": 6.0, "size": (1.0, 0.5), "tilt": 0.3}
AREA_LAMP["power"] = 3.141592653589793 * (AREA_LAMP["height"] - 1.0) ** 2
LAMP_ENVS = tuple(CONE_LIGHTS) + ("point", "area")  # lights with a numpy quadrature reference
GOLD = {"fresnel_type": "conductor"}  # catalog default n, k (gold)
CONVERGENCE_ROUGHNESS = (0.2, 0.5, 0.8)  # the spheres of each convergence row
# --sections
SECTIONS = ("convergence", "share", "samplers", "refcost", "stability", "lee", "specialization",
            "comparisons", "fallback", "lookdev")


@dataclass
class LeeConfig:
    """Settings of the Lee section (defaults: the full run)."""
    furnace_samples: int = 256
    furnace_px: int = 48
    cost_samples: tuple = (16, 384)  # the two sample counts whose time difference is taken
    cost_px: int = 32
    cost_repeats: int = 5
    tracer_n: int = 1 << 20
    tracer_cases: tuple = (("ggx", 0.5, 60.0), ("ggx", 1.0, 0.0), ("beckmann", 1.0, 80.0))
    quad_orders: tuple = (32, 64, 128, 256, 512)
    quad_ref: int = 1024
    target: float = 1e-4  # albedo error for the time-to-error comparison
    moment_mus: tuple = (1.0, 0.5, 0.2, 0.05, 0.01)
    moment_alphas: tuple = (0.09, 1.0)
    moment_grooves: tuple = ("symmetric", "asymmetric")
    moment_distributions: tuple = ("ggx", "beckmann")


@dataclass
class Config:
    mode: str
    samples: tuple
    cell_px: int
    roughness: tuple
    envs: tuple
    sweep_stride: int
    albedo_samples: int
    stress: str  # "full", "quick" or "none"
    study_samples: int
    study_thetas: tuple
    study_roughness: tuple
    fireflies_px: int
    ref_orders: tuple
    ref_high_order: int
    ref_cell_px: int
    sun_nodes: tuple  # (radial, azimuthal) of the sun-disk quadrature; the check uses half
    moment_order: int = 6
    walk_moments: int | None = None  # walks per incidence of a Monte Carlo table (None: 200,000)
    seed: int = 0
    combo_seconds: float = 20.0  # stability sweep: per parameter combination
    model_seconds: float = 240.0  # stability sweep: per model
    lee: LeeConfig = field(default_factory=LeeConfig)


def config(mode: str) -> Config:
    theta_full = tuple(np.round(np.concatenate([np.linspace(0, 80, 9), [84, 87, 88.5, 89.5, 89.9]]), 3))
    if mode == "full":
        return Config("full", tuple(2 ** k for k in range(11)), 20, CONVERGENCE_ROUGHNESS,
                      ("white", "gradient", "sun", "sun05", "spot", "hdri", "point", "area"), 1, 1024,
                      "full",
                      40000,
                      theta_full,
                      (0.1, 0.3, 0.6, 1.0), 96, (2, 3, 4, 6, 8), 14, 32, (24, 48))
    if mode == "quick":
        return Config("quick", (1, 4, 16, 64, 256), 16, CONVERGENCE_ROUGHNESS,
                      ("white", "gradient", "sun", "sun05", "spot", "hdri", "point", "area"), 8, 256,
                      "quick",
                      8000,
                      (0.0, 30.0, 60.0, 80.0, 87.0, 89.0, 89.9), (0.1, 0.3, 1.0), 64,
                      (2, 4, 6), 10, 16, (16, 32), combo_seconds=5.0, model_seconds=30.0,
                      lee=LeeConfig(furnace_samples=64, furnace_px=32, cost_samples=(16, 256),
                                    cost_px=24, cost_repeats=3, tracer_n=1 << 16,
                                    quad_orders=(32, 64, 128, 256), quad_ref=512,
                                    moment_mus=(1.0, 0.2, 0.01)))
    if mode == "smoke":
        return Config("smoke", (1, 8), 10, (0.3, 1.0), ("gradient",), 200, 64, "none", 500,
                      (0.0, 60.0, 89.9), (0.3,), 32, (2,), 4, 8, (8, 16), moment_order=4,
                      walk_moments=20_000,
                      combo_seconds=1.0, model_seconds=3.0,
                      lee=LeeConfig(furnace_samples=16, furnace_px=16, cost_samples=(4, 32),
                                    cost_px=12, cost_repeats=2, tracer_n=1 << 14,
                                    tracer_cases=(("beckmann", 1.0, 80.0),),
                                    quad_orders=(32, 64, 128), quad_ref=256,
                                    moment_mus=(1.0, 0.01), moment_alphas=(1.0,),
                                    moment_distributions=("ggx",)))
    raise ValueError(f"unknown mode {mode!r}")


class Progress:
    def __init__(self, stream=None):
        self.start = time.perf_counter()
        self.stream = stream or sys.stdout

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def __call__(self, message: str, i: int | None = None, n: int | None = None):
        count = f"({i}/{n}) " if i is not None else ""
        self.stream.write(f"[report {self.elapsed():6.1f} s] {count}{message}\n")
        self.stream.flush()
