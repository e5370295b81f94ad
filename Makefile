# The README's two commands: `make demo` and `make test`. Both set up a local
# virtual environment on first use (only python3 and make are needed).
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
BENCH_STAMP := $(VENV)/.installed-bench
PYTEST_WORKERS ?= 2

.PHONY: setup setup-bench demo test lint typecheck pytest bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,viz,robots,lsl]'
	@echo "compiling the numba kernels once (about a minute on 2 cores)"
	$(BIN)/mocapkit demo --warm-up
	@touch $(STAMP)

# The peers (vqf, imufusion, ahrs, opensim) and Ray (mocapkit batch --engine ray): the
# benchmarks and the tests that run them. CI installs them (.ci/run); on a user's machine
# those tests skip without them.
setup-bench: $(BENCH_STAMP)

$(BENCH_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[dev,viz,robots,lsl,bench,corpus,ros]'
	@touch $(BENCH_STAMP)

demo: $(STAMP)
	$(BIN)/mocapkit demo

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/ruff format --check src tests benchmarks

typecheck: $(STAMP)
	$(BIN)/mypy

# Tests against the clock (live processes, sockets, a browser) run serially after the
# rest, so they never compete with each other for the two cores.
pytest: $(STAMP)
	HYPOTHESIS_PROFILE=ci $(BIN)/python -m pytest -n $(PYTEST_WORKERS) -q -m "not realtime"
	HYPOTHESIS_PROFILE=ci $(BIN)/python -m pytest -q -m realtime

test: lint typecheck pytest

bench: $(BENCH_STAMP)
	$(BIN)/python -m benchmarks.run_all

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .hypothesis
	find src tests benchmarks -name '*.nbi' -delete -o -name '*.nbc' -delete
