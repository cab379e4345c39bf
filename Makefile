# Microfacet Lab. Two set-up commands on a fresh machine: `make demo` and `make test`.
# Both create (once) a pinned Python 3.11 virtual environment in a cache directory outside the
# clone, keyed by the hash of requirements.txt, so fresh clones reuse it.
SHELL := /bin/bash
PYTHON_BASE ?= python3.11
REQ_HASH := $(shell sha256sum requirements.txt | cut -c1-12)
VENV ?= $(HOME)/.cache/microfacet-lab/venv-$(REQ_HASH)
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: venv test test-fast demo report package thumbnails clean

venv: $(STAMP)

$(STAMP): requirements.txt
	@command -v $(PYTHON_BASE) >/dev/null || { echo "error: $(PYTHON_BASE) not found (bpy 5.0.1 needs Python 3.11)"; exit 1; }
	@test -x $(PY) || $(PYTHON_BASE) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -r requirements.txt
	@touch $(STAMP)

test: venv
	$(PY) -m pytest -q -ra --durations=15 tests

test-fast: venv
	$(PY) -m pytest -q -ra -m "not render" tests

demo: venv
	$(PY) scripts/demo.py

report: venv
	$(PY) scripts/report.py $(if $(QUICK),--quick,)

package: venv
	$(PY) scripts/build_package.py

thumbnails: venv
	$(PY) scripts/render_scene.py --all --thumbnails out/presets

clean:
	rm -rf out report dist .pytest_cache
