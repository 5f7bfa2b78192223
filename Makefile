# whitted: set-up, the main job and the tests. Needs python3 (3.11+), pip and make;
# everything else is installed here (a virtual environment in .venv).

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: setup report report-quick test browser lint bench bench-mesh bench-speed clean

## setup: the virtual environment with whitted, its pinned dependencies and the LuxCore
## extra (whitted[luxcore], the third renderer), plus Chromium
setup: $(STAMP) browser

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,luxcore]'
	@# byte-code for the project's own modules, which an editable install leaves out: a
	@# `whitted` process then starts without compiling them (read even where
	@# PYTHONDONTWRITEBYTECODE keeps Python from writing them itself)
	$(BIN)/python -m compileall -q tracer reference scenes >/dev/null
	@touch $(STAMP)

## browser: Debian's chromium for the report's browser test, where it is missing
browser:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || { \
	  echo "installing Debian's chromium (for the report's browser test)"; \
	  if [ "$$(id -u)" = 0 ]; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	  elif command -v sudo >/dev/null 2>&1; then \
	    sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	  else echo "cannot install chromium here (not root, no sudo): its test will be skipped"; fi; }

## report: the main job, the full accuracy report of every built-in scene -> reports/
report: $(STAMP)
	$(BIN)/whitted report -o reports

## report-quick: the same, smaller and faster (what CI leaves under reports/)
report-quick: $(STAMP)
	$(BIN)/whitted report --quick -o reports

## test: the test suite (includes real cross-renders against Mitsuba)
test: setup
	$(BIN)/python -m pytest

lint: $(STAMP)
	$(BIN)/ruff check .

## bench: tracer against Mitsuba's direct integrator, timed in one run
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_direct.py

## bench-mesh: the BVH against Mitsuba's Embree on a 144,000-triangle mesh
bench-mesh: $(STAMP)
	$(BIN)/python benchmarks/bench_mesh.py

## bench-speed: every speed target against Mitsuba and minray, each a ratio from one run
## (SPEED=direct|mesh|recursion|quality|memory|report picks one; default all, ~25 min on 2 cores)
SPEED ?= all
bench-speed: $(STAMP)
	$(BIN)/python benchmarks/bench_speed.py $(SPEED)

clean:
	rm -rf $(VENV) reports/*.html reports/*.md reports/*.json reports/*.png reports/scenes out
