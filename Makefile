# stationbed - everything installs into a local virtual environment (.venv) on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SCENE  ?= scenarios/power_tower_free_drift.toml
OUT    ?= out/power_tower_free_drift
# pytest workers: both cores of the CI machine
JOBS   ?= 2

.PHONY: run test test-fast bench bench-smoke check install clean screenshots docs

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
	$(PY) benchmarks/bench_thrusters.py
	$(PY) benchmarks/bench_docking.py  # issue 35: a docking fused against the same run without it
	$(PY) benchmarks/bench_full_loop.py  # issue 33: the full flight loop fused against truth-fed pd
	$(PY) benchmarks/bench_socket.py --realtime-duration 60  # the 10-minute drift figure: --realtime-duration 600
	$(PY) benchmarks/bench_fmu.py  # optional: says so when FMPy is not installed
	$(PY) benchmarks/bench_plan.py $(if $(SMOKE),--smoke)
	$(PY) benchmarks/bench_basilisk.py  # optional: says so when bsk is not installed

# every benchmark with tiny sizes, one repeat, no target judged: they all still run (CI does this
# through tests/test_benchmarks_smoke.py)
bench-smoke: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b --smoke > /dev/null || { echo "$$b failed"; exit 1; }; done

# the README's rerun images (issue 24): recordings rendered by the web viewer in headless Chromium
# (stationbed screenshot); installs the Debian package chromium first when no browser is found
SHOTS ?= out/screenshots
screenshots: $(STAMP)
	@command -v chromium >/dev/null || command -v chromium-browser >/dev/null || command -v google-chrome >/dev/null \
	  || { echo "installing chromium (apt-get)"; apt-get update -qq && apt-get install -y -qq chromium; }
	$(VENV)/bin/stationbed run scenarios/iss_lvlh_hold.toml --duration 6000 --out $(SHOTS)/hold --rrd $(SHOTS)/hold/recording.rrd
	$(VENV)/bin/stationbed screenshot $(SHOTS)/hold/recording.rrd --out docs/img/rerun_iss_lvlh_hold.png
	$(VENV)/bin/stationbed run scenarios/power_tower_free_drift.toml --out $(SHOTS)/tower --rrd $(SHOTS)/tower/recording.rrd
	$(VENV)/bin/stationbed screenshot $(SHOTS)/tower/recording.rrd --out docs/img/rerun_power_tower.png
	rm -rf $(SHOTS)/mc
	$(VENV)/bin/stationbed montecarlo scenarios/iss_lvlh_hold_montecarlo.toml --n 40 --set simulation.duration=2000.0 --out $(SHOTS)/mc --exit-zero -q
	$(VENV)/bin/stationbed screenshot $(SHOTS)/mc/montecarlo.rrd --out docs/img/rerun_montecarlo.png

# the documentation site (mkdocs.yml): the `docs` extra, then a strict build into site/ (a broken
# link or anchor, or a docstring mkdocstrings cannot read, fails it); tests/test_docs.py runs the
# same build in CI and every command and Python block of the pages
DOCS_STAMP := $(VENV)/.docs-installed
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(PY) -m pip install --quiet -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

clean:
	rm -rf $(VENV) out .pytest_cache site
