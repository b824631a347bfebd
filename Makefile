# slamcli — one command per job. The venv lives in .venv; nothing is installed globally.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: install test bench reproduce reproduce-quick lint clean-results

# CHOLMOD (extra "cholmod", scikit-sparse) is an opt-in accelerator: it compiles against SuiteSparse's headers,
# so it is installed only when cholmod.h is found (override: make install SUITESPARSE_H=/path/to/cholmod.h, or
# SUITESPARSE_H= to skip it). Without it the graph optimiser uses SciPy's SuperLU. No system package manager is run.
COMMA := ,
INCLUDE_DIRS ?= /usr/include /usr/local/include /opt/homebrew/include $(CONDA_PREFIX)/include
SUITESPARSE_H ?= $(firstword $(wildcard $(addsuffix /suitesparse/cholmod.h,$(INCLUDE_DIRS))))
EXTRAS := test,gtsam,dask,parquet,dev,interval,fast$(if $(strip $(SUITESPARSE_H)),$(COMMA)cholmod)
PIP ?= $(BIN)/pip

install:  ## create the venv and install slamcli with every extra the tests use (cholmod only if its headers exist)
	$(PY) -m venv $(VENV)
	$(PIP) install --upgrade --quiet pip
	$(PIP) install --quiet -e ".[$(EXTRAS)]"
	@$(BIN)/python -c "from slamcli.solvers.nls import cholmod_available as c; print('linear solver: ' + ('CHOLMOD (scikit-sparse, extra cholmod)' if c() else 'SciPy SuperLU (no SuiteSparse headers found: extra cholmod skipped)'))"

test:  ## the whole test suite (what CI runs)
	$(BIN)/pytest -q -n 2 --dist loadfile

bench:  ## speed/memory benchmarks; writes benchmarks/results/*.csv and prints a table
	$(BIN)/python -m benchmarks

reproduce:  ## regenerate the papers' figures and results/reproduce/REPORT.md
	$(BIN)/slamcli reproduce --out results/reproduce

reproduce-quick:  ## a few seeds and short runs, for a smoke check of the whole pipeline
	$(BIN)/slamcli reproduce --quick --out results/reproduce-quick

lint:
	$(BIN)/ruff check slamcli tests benchmarks

clean-results:
	rm -rf results/*/
