# The two commands: `make demo` (the benchmark) and `make test` (the test suite).
# Each builds .venv from nothing the first time, and again whenever pyproject.toml changes.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
RESULTS ?= results

.PHONY: demo test lint format bench-speed docs warmup wheel clean

# constraints.txt pins torch to the CPU build on this kind of machine (no CUDA packages);
# the package itself does not pin it.
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[rl,onnx,bench,zoo,ray,dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/machining-bench benchmark --quick --out $(RESULTS)

# The suite runs on every core, at most four (pytest-xdist; each worker holds about 1 GB),
# the long tests shared out as workers free up.
test: $(STAMP)
	$(BIN)/python -m pytest -m "not slow" -q -n auto --maxprocesses 4 --dist worksteal

lint: $(STAMP)
	$(BIN)/lint-imports
	$(BIN)/ruff check machining_envs agents tests benchmarks
	$(BIN)/ruff format --check machining_envs agents tests benchmarks

format: $(STAMP)
	$(BIN)/ruff format machining_envs agents tests benchmarks
	$(BIN)/ruff check --fix machining_envs agents tests benchmarks

# The documentation site (mkdocs.yml) into site/; --strict: a broken link or reference fails.
docs: $(STAMP)
	$(BIN)/mkdocs build --strict --site-dir site

bench-speed: $(STAMP)
	$(BIN)/python benchmarks/throughput.py

# Compile every env's numba kernels now (cached on disk) instead of at their first use.
warmup: $(STAMP)
	$(BIN)/machining-bench warmup

# Build the wheel (python -m build), install it in a clean venv and run the README's example there.
wheel: $(STAMP)
	PYTHON=$(BIN)/python .ci/wheel

clean:
	rm -rf $(VENV) $(RESULTS) site .pytest_cache .ruff_cache
