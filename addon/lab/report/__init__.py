"""`make report`: error against render time, the samplers' weights, the reference's cost and
numerical stability, written to report/ as a Markdown page with PNG plots and results.json.

Sections, one module each; a section's `compute(cfg, rows, tables, progress, notes, out)` measures
and draws its plots, its `page(cfg, rows, results)` returns its Markdown lines:
1. `convergence`: every model x sampler (catalog driven) and Cycles' native closure where one
   exists, rendered on sphere grids (one row of roughness values per model variant) under the
   white furnace, the smooth gradient and a small sun over a dim uniform world, at sample counts
   from 1 up; relative RMSE against the numpy reference against wall-clock render time.
   Timing: one scene per environment holding every row; each row is rendered alone through a
   render border with Cycles' persistent data on, so the one-off scene sync and OSL JIT (reported
   separately) are not in the per-render time, which is the wall clock of the render call.
2. `samplers`: Walter D cos against visible normals (Smith) against V-cavity visible normals in
   numpy: variance and maximum of the sample weight against incidence and roughness; and a
   firefly picture (`samplers.fireflies`).
3. `reference_cost`: time and accuracy of the reference image against quadrature order.
4. `stability_section`: the numpy sweep and the OSL stress grid of addon/lab/stability.py.
5. `lee`: the Lee 2018 V-groove model (addon/lab/bench_lee.py): white-furnace grid over alpha
   against single scattering and Cycles' multi-GGX (table and picture), render cost per sample
   against the Cook-Torrance shader measured side by side, the closed-form albedo against the
   brute-force tracer at equal error, and the accuracy of the moment rules.
6. `specialization`, `multiple_scattering` ("comparisons"), `fallback`: what a scene's
   specialization saves, the seed's comparisons of multiple-scattering models, the native
   branches against the exact models.
7. `lookdev_noise` ("lookdev"): samples and time for equal noise against Cycles' closest
   closure on the look-dev scene, per preset and light.
8. `optix`: the OptiX comparison, only where bpy reports an OptiX device (untested without one);
   run with section 1, stated in the page header.

Shared modules: `config` (modes, constants, progress), `rows` (model variants x samplers,
native twins), `lights` (the lights as numbers: directions, radiance, lamp geometry),
`references` (moment tables, the sun-disk term, the reference image), `scenes` (Blender scenes,
the sun lamp, GPU devices), `plotting` (matplotlib), `machine` (machine,
versions, the page header), `page` (`write_page` assembles the header and the sections' lines)
and `runner` (`run`: the sections in order, the page, results.json, the README figures).
Nothing here imports bpy or matplotlib at import time.
"""
from .config import SUN_ANGLE_DEG
from .convergence import time_to_target
from .lights import sun_unit
from .references import sun_cone_nodes
from .runner import run

__all__ = ["SUN_ANGLE_DEG", "run", "sun_cone_nodes", "sun_unit", "time_to_target"]
