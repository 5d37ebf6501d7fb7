# stationbed - everything installs into a local virtual environment (.venv) on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SCENE  ?= scenarios/power_tower_free_drift.toml
OUT    ?= out/power_tower_free_drift
# pytest workers: both cores of the CI machine
JOBS   ?= 2

.PHONY: run test test-fast bench bench-smoke check install clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,plot]"
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(VENV)/bin/stationbed run $(SCENE) --out $(OUT) --rrd $(OUT)/recording.rrd

test: $(STAMP)
	$(PY) -m pytest -n $(JOBS) -q

# the fast subset: everything but whole-scenario, sweep and multi-orbit runs (marked slow)
test-fast: $(STAMP)
	$(PY) -m pytest -n $(JOBS) -q -m "not slow"

check: $(STAMP)
	@for s in scenarios/*.toml; do $(VENV)/bin/stationbed check $$s || exit 1; done

bench: $(STAMP)
	$(PY) benchmarks/bench_core.py
	$(PY) benchmarks/bench_orbit.py
	$(PY) benchmarks/bench_control.py
	$(PY) benchmarks/bench_estimated.py $(if $(SMOKE),--smoke)
	$(PY) benchmarks/bench_batch.py
	$(PY) benchmarks/bench_environment.py
	$(PY) benchmarks/bench_linearize.py
	$(PY) benchmarks/bench_montecarlo.py
	$(PY) benchmarks/bench_lockstep.py
	$(PY) benchmarks/bench_fmu.py  # optional: says so when FMPy is not installed
	$(PY) benchmarks/bench_plan.py $(if $(SMOKE),--smoke)
	$(PY) benchmarks/bench_basilisk.py  # optional: says so when bsk is not installed

# every benchmark with tiny sizes, one repeat, no target judged: they all still run (CI does this
# through tests/test_benchmarks_smoke.py)
bench-smoke: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b --smoke > /dev/null || { echo "$$b failed"; exit 1; }; done

clean:
	rm -rf $(VENV) out .pytest_cache
