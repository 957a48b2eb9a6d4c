# Two commands do everything on a fresh clone: `make demo` and `make test`.
# Each creates .venv from nothing (pinned set in requirements.lock) and runs.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# pytest workers: both cores by default
JOBS ?= 2
# The slow tests (make acceptance): xdist hands each worker one test at a time, longest first
# (its default sends the first dozen in one block: with the longest first that put the five
# longest on one worker, tests/_support/slow_order.py).
XDIST_SLOW = -n $(JOBS) --maxschedchunk 1
# The fast ones (make unit): whole test modules per worker, in collection order (the heaviest
# first, tests/_support/slow_order.py), so a module's shared fixture is built once, not on both
# workers (one test at a time rendered test_flow_bench's 94 s set twice).
XDIST_FAST = -n $(JOBS) --dist loadscope --no-loadscope-reorder

.PHONY: all install demo test lint typecheck imports unit acceptance bench clean

all: test

$(STAMP): requirements.lock pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade "pip>=24"
	$(BIN)/python -m pip install --quiet -r requirements.lock
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/phonestereo demo --force  # replaces the previous demo_out set

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

typecheck: $(STAMP)
	$(BIN)/mypy

imports: $(STAMP)
	$(BIN)/lint-imports

unit: $(STAMP)
	MPLBACKEND=Agg $(BIN)/pytest -q $(XDIST_FAST) --durations=20

test: lint typecheck imports unit

# The slow tests behind the figures in README's "Measured so far" tables (each row names its
# test); `make test` runs the fast ones. .ci/run runs both, with CI=true (missing real data or
# Chromium fails instead of skipping).
acceptance: $(STAMP)
	MPLBACKEND=Agg $(BIN)/pytest -q $(XDIST_SLOW) -m 'slow and not bench' -rs --durations=0

bench: acceptance
	MPLBACKEND=Agg $(BIN)/pytest -q $(XDIST_SLOW) -m bench -rs || [ $$? -eq 5 ]  # 5: none marked
	MPLBACKEND=Agg $(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) build src/*.egg-info .pytest_cache .mypy_cache .ruff_cache
