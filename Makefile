# Two set-up commands work on a fresh machine with Python 3.11, make and pip:
#   make demo   creates .venv, installs, identifies the bundled datasets, writes demo_out/
#   make test   creates .venv if missing, installs, runs the tests
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

BENCH_VENV := .venv-bench

.PHONY: demo gallery test test-long bench bench-bd bench-realdata experiment clean

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

# The default B, D, x0 regression against the statistic-only path at 1e7 samples (issue 14).
bench-bd: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) bench/bd_pass.py --samples 10000000 --qr | tee bench/bd_pass.md

# Default calls on the bundled real records against SIPPY at its best order. SIPPY
# (sippy-unipi) is installed in the benchmark's own environment, never as a dependency.
bench-realdata:
	test -x $(BENCH_VENV)/bin/python || $(PYTHON) -m venv $(BENCH_VENV)
	$(BENCH_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(BENCH_VENV)/bin/python -m pip install --quiet -e . sippy-unipi
	OPENBLAS_NUM_THREADS=1 $(BENCH_VENV)/bin/python bench/realdata.py --out bench/realdata.md

experiment: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m subid.experiments.seed001 --runs 1000 --out results/seed001
	OPENBLAS_NUM_THREADS=1 $(PY) -m subid.experiments.seed000 --out results/seed000
	OPENBLAS_NUM_THREADS=1 $(PY) -m subid.experiments.seed002 --out results/seed002

clean:
	rm -rf $(VENV) $(BENCH_VENV) demo_out results
