# slamcli — one command per job. The venv lives in .venv; nothing is installed globally.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: install test test-fast bench reproduce reproduce-quick lint clean-results docs docs-serve

# every extra the tests use; CHOLMOD comes with the core dependencies (CVXOPT's wheel), no system package
EXTRAS := test,gtsam,dask,parquet,dev,interval,fast,docs
PIP ?= $(BIN)/pip

install:  ## create the venv and install slamcli with every extra the tests use
	$(PY) -m venv $(VENV)
	$(PIP) install --upgrade --quiet pip
	$(PIP) install --quiet -e ".[$(EXTRAS)]"
	@$(BIN)/python -c "from slamcli.solvers.nls import cholmod_available as c; print('linear solver: ' + ('CHOLMOD (CVXOPT)' if c() else 'SciPy SuperLU (CVXOPT does not import)'))"

test:  ## the whole test suite (what CI runs)
	$(BIN)/pytest -q -n 2 --dist loadfile

test-fast:  ## everything but the tests marked slow, for the edit-test loop (tests/README.md)
	$(BIN)/pytest -q -n 2 --dist loadfile -m "not slow"

bench:  ## speed/memory benchmarks; writes benchmarks/results/*.csv and prints a table
	$(BIN)/python -m benchmarks

reproduce:  ## regenerate the papers' figures and results/reproduce/REPORT.md
	$(BIN)/slamcli reproduce --out results/reproduce

reproduce-quick:  ## a few seeds and short runs, for a smoke check of the whole pipeline
	$(BIN)/slamcli reproduce --quick --out results/reproduce-quick

docs:  ## build the documentation site into site/ (strict: any warning fails)
	$(BIN)/mkdocs build --strict

docs-serve:  ## preview the documentation site at http://127.0.0.1:8000
	$(BIN)/mkdocs serve

lint:
	$(BIN)/ruff check slamcli tests benchmarks docs

clean-results:
	rm -rf results/*/
