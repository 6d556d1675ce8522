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

# Every tier (tests/conftest.py names them): what CI runs, after `make check`.  One run of every tier
# but the `alone` tests, two tests at a time (WORKERS, one per core), dearest tier first (tests/conftest.py
# orders them) so that the short in-process tests fill the end; then, one at a time, the tests marked
# `alone`, which assert a wall-clock bound of the product that a test beside them could break.
# tests/conftest.py keeps a module's shared fixture (a planner, say) on one worker, and
# tests/zenoh_util.py gives each worker its own ports.  Each run names its slowest tests, so a CI log
# shows where the time went.
WORKERS ?= 2
XDIST = -n $(WORKERS) --dist loadgroup
# The planner's own warm-up, once, before the workers start: on a fresh clone it compiles the shared
# numba kernels into the cache in one process, not in both workers at once (seconds when they are cached).
WARM_KERNELS = $(BIN)/python -c "from pfp_service.node.previews import warm_up; warm_up(None)"
test: $(STAMP)
	@sh .ci/ensure-chromium
	@sh .ci/ensure-gdal
	$(WARM_KERNELS)
	$(BIN)/python -m pytest -q -m "not alone" $(XDIST) --durations=20
	$(BIN)/python -m pytest -q -m alone --durations=10

# The in-process tiers (unit and net): under a minute on 2 cores; run it on every change.  Their shared
# fixtures are in-process and cheap, so the tests go to either worker in batches (`--dist load`):
# loadgroup hands ~2,800 short tests out one at a time, 67 s against 47 s on 2026-12-06.  One worker more
# than cores (FAST_WORKERS): the net tier waits on sockets and sleeps, and a third worker fills those
# waits; 2,929 tests took 52.7 s with 3 against 70.0 s with 2 (2026-12-06, load 1.4-2.9, 2 cores).
FAST_WORKERS ?= 3
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "unit or net" -n $(FAST_WORKERS) --dist load

# The tiers that start processes but no browser: run before a commit that touches the service or a client.
test-proc: $(STAMP)
	@sh .ci/ensure-gdal
	$(BIN)/python -m pytest -q -m "proc and not alone" $(XDIST)
	$(BIN)/python -m pytest -q -m "multi and not alone" $(XDIST)
	$(BIN)/python -m pytest -q -m "(proc or multi) and alone"

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
