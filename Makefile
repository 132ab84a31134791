# Two commands for a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench lint docs clean install

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install -q -e '.[test]'
	# MAVProxy for the SITL interoperability test, installed lean (its GUI deps are not needed).
	$(PY) -m pip install -q --no-deps 'MAVProxy==1.8.75'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/navig8-stability --plots out/stability
	$(VENV)/bin/navig8-sitl --scenario paper --speed 0 --until-done --defaults --log-dir out/logs \
		--state-dir out/state --summary out/summary.json
	$(VENV)/bin/navig8-plot $$(ls -t out/logs/*.mcap | head -1) --out out/figures

test: $(STAMP)
	$(VENV)/bin/ruff check navig8_fc sim_bridge tools tests
	# Fast lane (unit, integration) on both cores; then the SITL lane alone (real processes, wall-clock pacing).
	# tests/conftest.py warms numba's cache once before xdist starts its workers. Exit 5 (no tests) fails.
	$(PY) -m pytest -q -m 'not slow' -n 2; rc=$$?; if [ $$rc -eq 5 ]; then echo 'make test: fast lane collected no tests' >&2; fi; [ $$rc -eq 0 ] || exit $$rc
	$(PY) -m pytest -q -m slow; rc=$$?; if [ $$rc -eq 5 ]; then echo 'make test: SITL lane collected no tests' >&2; fi; exit $$rc

bench: $(STAMP)
	$(VENV)/bin/navig8-bench

docs: $(STAMP)
	$(VENV)/bin/navig8-params-doc --write docs/params.md
	$(VENV)/bin/navig8-urdf --write
	$(VENV)/bin/navig8-foxglove-layout --write

clean:
	rm -rf $(VENV) out build *.egg-info
