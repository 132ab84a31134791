# Two commands for a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-hil test-clients bench lint docs clean install

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): $(PY) pyproject.toml
	# pip byte-compiles ~7,000 files one at a time (~50 s); compileall does the same on every core (half of that);
	# a file that does not compile is left to compile when imported, as pip leaves it.
	$(PY) -m pip install -q --no-compile -e '.[test]'
	# MAVProxy for the SITL interoperability test, installed lean (its GUI deps are not needed).
	$(PY) -m pip install -q --no-compile --no-deps 'MAVProxy==1.8.75'
	# The packages' own test folders (a third of the files) are never imported here: not compiled. Nor are the 36 of
	# pymavlink's 40 generated dialect modules that no process of make test imports (31 of its 42 MB; an import hook
	# over every process of the three lanes, MAVProxy's included, saw only v10.all, v20.all, v20.common and
	# v20.development): one imported uncompiled would be compiled again in each process that imports it.
	$(PY) -m compileall -q -j 0 -x '/tests/|/pymavlink/dialects/(v10/(?!(__init__|all)\.py$$)|v20/(?!(__init__|all|common|development)\.py$$))[^/]+\.py$$' \
		$$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])') >/dev/null || true
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/navig8-stability --plots out/stability
	# the paper's scenario flown twice over SITL: with the defaults (the robust controller) and with the paper's method
	$(VENV)/bin/navig8-sitl --scenario paper --speed 0 --until-done --defaults --log-dir out/logs \
		--state-dir out/state --summary out/summary.json
	$(VENV)/bin/navig8-plot $$(ls -t out/logs/*.mcap | head -1) --out out/figures
	$(VENV)/bin/navig8-sitl --scenario paper --speed 0 --until-done --defaults --params params/presets/paper.parm \
		--instance 1 --log-dir out/logs_paper --state-dir out/state --summary out/summary_paper.json
	$(VENV)/bin/navig8-compare defaults=out/summary.json paper.parm=out/summary_paper.json

test: $(STAMP)
	$(VENV)/bin/ruff check navig8_fc sim_bridge tools tests
	# Our own modules byte-compiled once (only the changed ones): with PYTHONDONTWRITEBYTECODE (CI) every SITL process
	# would compile them again at import (~0.15 s of CPU each, a few hundred processes).
	$(PY) -m compileall -q -j 0 navig8_fc sim_bridge tools params tests/sitl tests/clients/*.py >/dev/null || true
	# Fast lane (unit, integration) on both cores; then the SITL lane (real processes) on four workers: a test spends
	# most of its time waiting on flights and replies, and on three workers the lane used 1.5 of the 2 cores, so a
	# fourth worker fills them (docs/results.md, "Test suite time"); --dist loadfile keeps a module's shared pair in
	# one worker. tests/conftest.py warms numba's cache in the fast lane, on both cores, while xdist's workers start
	# (they wait for it before their first test). The slow and real-time lanes collect only tests/sitl and tests/clients,
	# where every slow test lives (their conftests add the marker; tests/conftest.py fails the fast lane on a slow
	# test elsewhere): each worker imports every module it collects. Exit 5 fails. The later lanes do not warm it again:
	# the fast lane's warm-up compiled every kernel it reaches (a failed one fails that lane, and make stops there);
	# NAVIG8_TEST_WARM_DONE names an existing file, and tests/conftest.py skips the warm-up (~7 s of a plain run's wall).
	# The SITL lane's FC and bridge processes are forked from a pre-imported fork server in each worker
	# (tests/sitl/prefork.py): ~0.6 s of CPU a pair instead of ~2.3 s as two new interpreters.
	$(PY) -m pytest -q -m 'not slow' -n 2; rc=$$?; if [ $$rc -eq 5 ]; then echo 'make test: fast lane collected no tests' >&2; fi; [ $$rc -eq 0 ] || exit $$rc
	NAVIG8_TEST_WARM_DONE=$(STAMP) $(PY) -m pytest -q -m 'slow and not clients_all and not realtime' -n 4 --dist loadfile tests/sitl tests/clients; rc=$$?; if [ $$rc -eq 5 ]; then echo 'make test: SITL lane collected no tests' >&2; fi; [ $$rc -eq 0 ] || exit $$rc
	# The real-time tests (the FC on its own clock, the bridge free-running) alone: beside a second worker their
	# wall-clock loop is starved and the hover leaves its band (docs/hil.md). With them the MAVFTP flood test, whose
	# p99 control-step spacing is a wall-clock figure. Their processes start as interpreters of their own, not forked
	# (tests/sitl/prefork.py): the lane waits on the wall clock, so forking would save it ~15 s of CPU and no wall.
	NAVIG8_TEST_PREFORK=0 NAVIG8_TEST_WARM_DONE=$(STAMP) $(PY) -m pytest -q -m 'realtime' -p no:xdist tests/sitl tests/clients; rc=$$?; if [ $$rc -eq 5 ]; then echo 'make test: real-time lane collected no tests' >&2; fi; exit $$rc

# MAVSDK-Python's own examples, all of them (tests/clients; make test runs the quick ones), both identities: about 10 min on 2 workers.
test-clients: $(STAMP)
	$(PY) -m pytest -q tests/clients -n 2; rc=$$?; if [ $$rc -eq 5 ]; then echo 'make test-clients: no tests' >&2; fi; exit $$rc

# The MAVLink-only SITL tests against an FC running elsewhere, by connection string (docs/hil.md); without FC the
# local pairs (one per module); `python tests/sitl/hil_pair.py` runs it against a pair started outside pytest:
#   make test-hil FC=udpin:0.0.0.0:14550 FC_API=udpin:0.0.0.0:14540 BRIDGE=tcpin:0.0.0.0:4560   (BRIDGE=none: no sim)
# FC is also make's built-in Fortran compiler (f77): take it only when given on the command line or in the environment.
FC_GCS ?= $(if $(filter command line environment,$(origin FC)),$(FC))
# The MAVLink-only SITL tests (docs/hil.md, "A test suite for any FC"); pointed elsewhere, their local-only tests skip.
HIL_TESTS := tests/sitl/test_hil_interop.py tests/sitl/test_sitl_gcs.py tests/sitl/test_sitl_set_mode.py \
	tests/sitl/test_sitl_params_interop.py tests/sitl/test_sitl_param_metadata.py tests/sitl/test_sitl_link_health.py \
	tests/sitl/test_sitl_mission.py tests/sitl/test_sitl_offboard.py tests/sitl/test_sitl_arm_gripper.py \
	tests/sitl/test_sitl_mavsdk.py tests/sitl/test_sitl_mavsdk_guided.py tests/sitl/test_sitl_failsafe.py
test-hil: $(STAMP)
	$(PY) -m pytest -q -rs $(HIL_TESTS) $(if $(FC_GCS),--fc-gcs=$(FC_GCS)) \
		$(if $(FC_API),--fc-api=$(FC_API)) $(if $(BRIDGE),--bridge=$(BRIDGE)) $(if $(FC_SYSID),--fc-sysid=$(FC_SYSID)) \
		$(PYTEST_ARGS)

bench: $(STAMP)
	$(VENV)/bin/navig8-bench

docs: $(STAMP)
	$(VENV)/bin/navig8-params-doc --write docs/params.md
	$(VENV)/bin/navig8-urdf --write
	$(VENV)/bin/navig8-foxglove-layout --write

clean:
	rm -rf $(VENV) out build *.egg-info
