# Microfacet Lab. Two set-up commands on a fresh machine: `make demo` and `make test`.
# Each Blender version gets its own pinned virtual environment, created once by scripts/venv.sh
# in a cache directory outside the clone (~/.cache/microfacet-lab), keyed by the hash of its
# requirements file, so fresh clones reuse it:
#   requirements.txt                    the current release (bpy 5.3.0, Python 3.13): demo, test,
#                                       report, package
#   tests/compat/requirements-<v>.txt   the other supported lines (4.2 LTS, 4.5 LTS, 5.0,
#                                       Python 3.11): the compatibility suite of make test
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c

VENV_SH := scripts/venv.sh
PY = $$($(VENV_SH) requirements.txt)
COMPAT ?= 4.2 4.5 5.0  # oldest first: scripts/test_lanes.sh runs its whole suite on the first
# The compatibility suite (tests marked `compat`, less those marked `release_only`; see
# tests/conftest.py): install the zip, build every node group and check it compiled, apply and
# render every preset, a white-furnace sphere against the numpy reference, the CLI; the node
# sockets, preset operator, scene specialization, a saved .blend rendered without the add-on,
# and the lamps: their hand-over, the residual aimed at them and the lamp controls against
# numpy under a large and a 0.5-degree sun (Cycles' closure cutoff), the control variate with
# the right prediction under a 4-degree sun; glass seen from inside on plane pairs (Cycles'
# back-face IOR changed in 5.3); the native branches rendered without OSL (4.2 has no Metallic
# BSDF node). On the pinned release only (the same maths on every version, and test time): the
# point and area lamps, the 4-degree sun's aimed row, Lee under the suns, the control variate
# without and with a wrong prediction and its noise, the glass ball and bowl against the traced
# twin, and the report's smoke run (the report is lab tooling). In make test, on 4.2 LTS only
# (not on the versions between it and the pinned release, whose API branches it and the pinned
# release bracket: tests/conftest.py, `oldest_only`): the lamps' maths (the residual, the
# controls, the control variate), the sun on a face's horizon, a world spot's texels read against
# Cycles' own lookup and the lab's harness.
COMPAT_PYS = $$(for v in $(COMPAT); do $(VENV_SH) tests/compat/requirements-$$v.txt; done)

.PHONY: venv venvs test test-full test-compat test-fast demo report package assets thumbnails bench-animation lee-furnace fallback-fit tables clean

venv:
	@$(VENV_SH) requirements.txt >/dev/null

venvs: venv
	@for v in $(COMPAT); do $(VENV_SH) tests/compat/requirements-$$v.txt >/dev/null; done

# Two lanes side by side on 2 cores (scripts/test_lanes.sh): the render tests on the pinned
# release; beside them the tests that do not render, then the compatibility suites (on 4.5 and
# 5.0 less the tests marked `oldest_only`: tests/conftest.py).
test: venvs
	scripts/test_lanes.sh $(PY) --compat $(COMPAT_PYS)

# The full suite on the pinned release alone (both lanes, no compatibility suite).
test-full: venv
	scripts/test_lanes.sh $(PY)

# The whole compatibility suite on every older Blender, `oldest_only` tests included.
test-compat: venvs
	@for v in $(COMPAT); do \
	  py=$$($(VENV_SH) tests/compat/requirements-$$v.txt); \
	  echo "== compatibility suite on Blender $$($$py -c 'import bpy; print(bpy.app.version_string)')"; \
	  $$py -m pytest -q -ra -p no:cacheprovider -m "compat and not release_only" tests; \
	done

test-fast: venv
	$(PY) -m pytest -q -ra -m "not render" tests

demo: venv
	$(PY) scripts/demo.py

report: venv
	$(PY) scripts/report.py $(if $(QUICK),--quick,)

package: venv
	$(PY) scripts/build_package.py

# The presets' asset library the extension ships (assets/: addon/lab/assets.py): previews
# rendered on the pinned release, the .blend written by Blender 4.2, which every later version
# reads (after a change to presets/, the catalog or a shader; about two minutes).
assets: venvs
	$(PY) scripts/build_assets.py previews
	$$($(VENV_SH) tests/compat/requirements-4.2.txt) scripts/build_assets.py library

# What the lamps' hand-over costs an animation, and the HDRI sun search's time and memory
# (addon/lab/bench_animation.py; about 10 minutes).
bench-animation: venv
	$(PY) scripts/bench_animation.py

thumbnails: venv
	$(PY) scripts/render_scene.py --all --thumbnails out/presets

lee-furnace: venv
	$(PY) scripts/lee_furnace.py

# The reference tables the repository carries (addon/lab/table_cache.py): make test, recording
# which tables it reads, then those written into addon/lab/table_seed.npz (after changing the
# numpy reference, the catalog or a test's reference inputs; about as long as make test). The
# seed is written also when a test fails (it only caches what the code computed); make tables
# then fails too.
tables: venvs
	@mkdir -p out && rm -f out/tables-used.txt
	status=0; MICROFACET_LAB_TABLE_RECORD=$(CURDIR)/out/tables-used.txt $(MAKE) test || status=$$?; \
	$(PY) scripts/seed_tables.py out/tables-used.txt; exit $$status

# The native branches' fitted corrections (addon/fallback.py, FITTED: Lee, Cook-Torrance, Heitz
# 2016, Walter's Separable masking), fitted to the numpy reference (about 6 minutes).
fallback-fit: venv
	$(PY) scripts/fallback_fit.py

clean:
	rm -rf out report dist .pytest_cache
