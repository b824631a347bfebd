# slamcli — one command per job. The venv lives in .venv; nothing is installed globally.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: install test bench reproduce reproduce-quick lint clean-results

install:  ## create the venv and install slamcli with every extra the tests use
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --upgrade --quiet pip
	@# scikit-sparse (extra "cholmod") compiles against SuiteSparse's headers: Debian's libsuitesparse-dev
	@dpkg -s libsuitesparse-dev >/dev/null 2>&1 || { apt-get update -qq && apt-get install -y -qq libsuitesparse-dev; }
	$(BIN)/pip install --quiet -e ".[test,gtsam,dask,parquet,dev,interval,cholmod]"

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
