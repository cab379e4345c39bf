"""The GPU comparison, only where bpy reports an OptiX device (untested without one): the
white-furnace grid on the CPU and with OptiX, and its line in the page header."""
from __future__ import annotations

from .config import MU_MIN_RMSE
from .references import reference_image, relative_rmse
from .rows import self_referenced, specs_for
from .scenes import build_env_scene, optix_devices


def compare_if_available(cfg, rows, tables, progress, notes):
    """`optix_comparison` where bpy reports an OptiX device, else None (a failure: a note)."""
    if not optix_devices():
        progress("no OptiX device reported by bpy: the GPU comparison is not run")
        return None
    try:
        return optix_comparison(cfg, rows, tables, progress)
    except Exception as exc:  # noqa: BLE001 - report it rather than lose the page
        notes.append(f"OptiX comparison failed: {type(exc).__name__}: {exc}")
        return None


def optix_comparison(cfg, rows, tables, progress) -> dict:
    """UNTESTED here (no NVIDIA GPU): the white-furnace gallery at the largest sample count on
    the CPU and with OptiX; times, and agreement of the two images (relative RMSE of their
    difference against each one's own error to the reference)."""
    from .. import harness

    rows = [row for row in rows if not self_referenced(row)]  # no reference image to share
    spp = cfg.samples[-1]
    result = {}
    for device in ("CPU", "OPTIX"):
        progress(f"OptiX comparison: {device}, {spp} samples")
        scene, layout = build_env_scene(rows, cfg, "white", device)
        scene.render.use_border = False
        harness.render(scene)
        scene.cycles.samples = spp
        image, seconds = harness.render(scene)
        result[device] = (image, seconds)
    specs = [s for row in rows for s in specs_for(row, cfg.roughness)]
    reference, _ = reference_image(layout, specs, "white", tables)
    index, _, mu = layout.pixel_geometry()
    sel = (index >= 0) & (mu > MU_MIN_RMSE)
    cpu, gpu = result["CPU"][0], result["OPTIX"][0]
    return {"devices": optix_devices(), "samples": spp, "cpu_seconds": result["CPU"][1],
            "gpu_seconds": result["OPTIX"][1],
            "cpu_vs_gpu_rel_rmse": relative_rmse(cpu, gpu[..., :3], sel),
            "cpu_rel_rmse": relative_rmse(cpu, reference, sel),
            "gpu_rel_rmse": relative_rmse(gpu, reference, sel)}


def gpu_line(gpu) -> str:
    """The page header's GPU line: the comparison, or the plain statement that it was not run."""
    if gpu is None:
        return ("- GPU: **the OptiX comparison was not run: no NVIDIA GPU (no OptiX device "
                "reported by bpy) on this machine.** The code path "
                "(`addon/lab/report/optix.py: optix_comparison`) runs when bpy reports an OptiX "
                "device; it has not been tested.")
    return (f"- GPU: OptiX on {', '.join(gpu['devices'])}: white-furnace grid at {gpu['samples']} "
            f"samples, CPU {gpu['cpu_seconds']:.2f} s vs OptiX {gpu['gpu_seconds']:.2f} s "
            f"(x{gpu['cpu_seconds'] / max(gpu['gpu_seconds'], 1e-9):.1f}); relative RMSE CPU vs "
            f"GPU {gpu['cpu_vs_gpu_rel_rmse']:.4f}, against the reference CPU "
            f"{gpu['cpu_rel_rmse']:.4f}, GPU {gpu['gpu_rel_rmse']:.4f}.")
