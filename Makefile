# Two set-up commands work on a fresh machine with Python 3.11, make and pip:
#   make demo   creates .venv, installs, identifies the bundled datasets, writes demo_out/
#   make test   creates .venv if missing, installs, runs the tests
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo gallery test test-long bench experiment clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/subid demo --out demo_out

gallery: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/subid gallery --out docs/gallery.md

test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -m "not long" tests

# Long profile: every test, hypothesis/fuzzers with large budgets, long runs.
test-long: $(STAMP)
	OPENBLAS_NUM_THREADS=1 SUBID_HYPOTHESIS_PROFILE=long $(PY) -m pytest -q tests

bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) bench/run.py --out bench/results.md

experiment: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m subid.experiments.seed001 --runs 1000 --out results/seed001
	OPENBLAS_NUM_THREADS=1 $(PY) -m subid.experiments.seed000 --out results/seed000
	OPENBLAS_NUM_THREADS=1 $(PY) -m subid.experiments.seed002 --out results/seed002

clean:
	rm -rf $(VENV) demo_out results
