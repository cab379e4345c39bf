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
  the walk tests went back). Set below by module.

A test that uses a fixture which renders is a render test whatever its own marks say, so the
two lanes never both pay for one fixture (the report's smoke run is two minutes).
"""
import pytest

RENDERING_FIXTURES = {"smoke"}  # tests/test_report.py: the report's smoke run
RENDER_LANE_MODULES = {"test_stability.py", "test_fallback_fit.py"}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    for item in items:
        if RENDERING_FIXTURES & set(item.fixturenames):
            item.add_marker(pytest.mark.render)
        if item.path.name in RENDER_LANE_MODULES:
            item.add_marker(pytest.mark.render_lane)
