"""What every test shares: the marks that choose where a test runs (pytest.ini lists them).

- `render`: renders with Cycles through bpy. `make test` runs these in one lane and the rest
  beside them (scripts/test_lanes.sh).
- `compat`: also run by the compatibility suite on every older supported Blender (a module
  marks itself); `release_only` takes a test of such a module out of it, where it checks
  the same maths on every version and the pinned release's run is enough.

- `render_lane`: does not render, but `make test` runs it in the render lane to balance the two
  lanes (in two fresh clones the other lane finished 74 and 77 s after the render lane; these
  modules took about 30 s; on 2026-12-04 the other lane again finished 44 s after the render
  lane, and the native branches' fit, 24 s alone, joined them; on 2026-12-05, 31 s after it,
  and Heitz 2016's walk tests, 23 s alone, joined them; later that day the render lane ran 1008 s
  and the other 988, and the compatibility suites lost more renders than the render lane, so
  the walk tests went back; on 2026-12-06, with the compatibility suites between the oldest and
  the pinned release shortened (`oldest_only`), the stability sweep's numpy tests went back
  too; its OSL stress grids render, so stay in the render lane). Set below by module.

- `oldest_only`: in a compat module, run by the compatibility suite on the oldest supported
  Blender (4.2 LTS) and not on the versions between it and the pinned release: Cycles' maths
  under lamps (the shaders' split, the aimed residual, the controls), the shaders' reading of
  a world spot's texels against Cycles' own lookup (tests/test_world_handover.py) and the lab's
  own harness.
  Each of addon/compat.py's differences that these reach (the conductor's Fresnel, the
  back-face IOR) takes on 4.5 and 5.0 the way it takes on one of the two ends, and the two ends
  run them; the versions between keep everything that calls Blender's API (install, node
  groups, presets, assets, CLI, hand-over of lamps and world, native branches). Set below by
  module, or on the test.

A test that uses a fixture which renders is a render test whatever its own marks say, so the
two lanes never both pay for one fixture (the report's smoke run is two minutes).
"""
import pytest

RENDERING_FIXTURES = {"smoke"}  # tests/test_report.py: the report's smoke run
RENDER_LANE_MODULES = {"test_fallback_fit.py"}
OLDEST_ONLY_MODULES = {"test_render_lights.py", "test_harness.py", "test_render_terminator.py"}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    for item in items:
        if RENDERING_FIXTURES & set(item.fixturenames):
            item.add_marker(pytest.mark.render)
        if item.path.name in RENDER_LANE_MODULES:
            item.add_marker(pytest.mark.render_lane)
        if item.path.name in OLDEST_ONLY_MODULES:
            item.add_marker(pytest.mark.oldest_only)
