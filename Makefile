# Two commands do everything on a fresh clone: `make demo` and `make test`.
# Each creates .venv from nothing (pinned set in requirements.lock) and runs.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# pytest workers: both cores by default
JOBS ?= 2
# xdist hands out whole test modules, in collection order, which tests/conftest.py makes the
# longest first (tests/_support/slow_order.py): a module's shared fixture is built once, not on
# both workers (one test at a time built test_flow_bench's 94 s set twice), and the long tests
# reach both workers (xdist's default load scheduling sends the first dozen tests to one worker
# as a block: the five longest on one worker, ~20 min of the acceptance stage alone).
XDIST = -n $(JOBS) --dist loadscope --no-loadscope-reorder

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
	MPLBACKEND=Agg $(BIN)/pytest -q $(XDIST) --durations=20

test: lint typecheck imports unit

# The slow tests behind the figures in README's "Measured so far" tables (each row names its
# test); `make test` runs the fast ones. .ci/run runs both, with CI=true (missing real data or
# Chromium fails instead of skipping).
acceptance: $(STAMP)
	MPLBACKEND=Agg $(BIN)/pytest -q $(XDIST) -m 'slow and not bench' -rs --durations=0

bench: acceptance
	MPLBACKEND=Agg $(BIN)/pytest -q $(XDIST) -m bench -rs || [ $$? -eq 5 ]  # 5: none marked
	MPLBACKEND=Agg $(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) build src/*.egg-info .pytest_cache .mypy_cache .ruff_cache
