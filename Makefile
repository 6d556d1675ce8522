# One entry point for people and CI.  `make test` is what the README says and
# what .ci/run calls; it builds the virtualenv on first use.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
DEMO_STAMP := $(VENV)/.demo-stamp

.PHONY: install test test-fast test-proc check demo bench format clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

# The test targets write bytecode even where the shell says not to (PYTHONDONTWRITEBYTECODE):
# without it pytest rewrites the asserts of every test module again on each run, 6 s of a
# test-fast run's CPU, and every `pfp` a test starts compiles the package again.
test test-fast test-proc: export PYTHONDONTWRITEBYTECODE =

# Every tier (tests/conftest.py names them): what CI runs, after `make check`.  Three runs, cheapest
# first: the in-process tiers in one process (they also fill a fresh clone's kernel cache before any
# planner starts); then the proc tier two at a time, as its tests mostly wait on the processes they
# start (tests/conftest.py keeps a module's shared planner on one worker, tests/zenoh_util.py gives
# each worker its own ports); then the multi and browser tiers one at a time, as each test already
# runs several processes at once.
PROC_WORKERS ?= 2
test: $(STAMP)
	@sh .ci/ensure-chromium
	@sh .ci/ensure-gdal
	$(BIN)/python -m pytest -q -m "unit or net"
	$(BIN)/python -m pytest -q -m proc -n $(PROC_WORKERS) --dist loadgroup
	$(BIN)/python -m pytest -q -m "multi or browser"

# The in-process tiers (unit and net): about a minute on 2 cores; run it on every change.
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "unit or net"

# The tiers that start processes but no browser: run before a commit that touches the service or a client.
test-proc: $(STAMP)
	@sh .ci/ensure-gdal
	$(BIN)/python -m pytest -q -m proc -n $(PROC_WORKERS) --dist loadgroup
	$(BIN)/python -m pytest -q -m multi

check: $(STAMP)
	$(BIN)/ruff format --check .
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/lint-imports

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# The demo needs a plain install plus matplotlib (the `demo` extra), not the dev tools;
# a full dev install (make test) already has it.
$(DEMO_STAMP): pyproject.toml
	@if [ -f $(STAMP) ] && [ $(STAMP) -nt pyproject.toml ]; then touch $(DEMO_STAMP); else \
	  $(PYTHON) -m venv $(VENV) && \
	  $(BIN)/python -m pip install --quiet --upgrade pip && \
	  $(BIN)/python -m pip install --quiet -e '.[demo]' && \
	  touch $(DEMO_STAMP); fi

demo: $(DEMO_STAMP)
	$(BIN)/pfp demo --out demo.png

bench: $(STAMP)
	$(BIN)/pfp bench engine

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .hypothesis demo.png
