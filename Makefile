# Two set-up commands work on a fresh machine with Python 3.11, make and pip:
#   make demo   creates .venv, installs, identifies the bundled datasets, writes demo_out/
#   make test   creates .venv if missing, installs, type-checks src/ (mypy), runs the tests
#               (make test-fast: the quick tier)
#   make docs   creates .venv-docs, builds the documentation site into site/ (warnings are errors)
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# The demo needs only the plotting extra; the tests need the test extras.
DEMO_STAMP := $(VENV)/.installed-plot
DOCS_VENV := .venv-docs
DOCS_STAMP := $(DOCS_VENV)/.installed

BENCH_VENV := .venv-bench

.PHONY: demo gallery test test-fast test-long bench bench-bd bench-ct bench-startup bench-realdata experiment docs clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	# compile the numba kernels into their cache now, not on a user's first call
	OPENBLAS_NUM_THREADS=1 $(PY) -m subid.warmup --quiet
	touch $(STAMP)

$(DEMO_STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[plot]"
	OPENBLAS_NUM_THREADS=1 $(PY) -m subid.warmup --quiet
	touch $(DEMO_STAMP)

$(DOCS_VENV)/bin/python:
	$(PYTHON) -m venv $(DOCS_VENV)

$(DOCS_STAMP): $(DOCS_VENV)/bin/python pyproject.toml
	$(DOCS_VENV)/bin/python -m pip install --quiet --upgrade pip
	# the docs extra only: mkdocstrings reads src/ statically, so numpy & co. are not needed
	$(DOCS_VENV)/bin/python -m pip install --quiet $$($(DOCS_VENV)/bin/python -c \
	  "import tomllib; print(' '.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['optional-dependencies']['docs']))")
	touch $(DOCS_STAMP)

demo: $(DEMO_STAMP)
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/subid demo --out demo_out

gallery: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/subid gallery --out docs/gallery.md

# The default tier (what CI runs): the static type check of src/ (mypy, configured in
# pyproject.toml), then every test but the long ones, and the docstring examples, on one
# pytest-xdist worker per core (-n auto; each worker single-threaded BLAS).
test: $(STAMP)
	$(PY) -m mypy
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n auto -m "not long" --doctest-modules src tests

# While working: the default tier without the tests marked slow (under 2 minutes on 2 cores).
test-fast: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n auto -m "not long and not slow" --doctest-modules src tests

# Long profile: every test, hypothesis/fuzzers with large budgets, long runs.
test-long: $(STAMP)
	OPENBLAS_NUM_THREADS=1 SUBID_HYPOTHESIS_PROFILE=long $(PY) -m pytest -q -n auto --doctest-modules src tests

bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) bench/run.py --out bench/results.md

# Start-up, first-call compile, one-sample update and report/identification ratio (issue 14).
bench-startup: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) bench/startup.py --repeat 5
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) bench/demo_ratio.py

# The default B, D, x0 regression against the statistic-only path at 1e7 samples (issue 14).
bench-bd: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) bench/bd_pass.py --samples 10000000 --qr | tee bench/bd_pass.md

# ct_subspace on jittered grids against the uniform grid (issue 14).
bench-ct: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) bench/ct_nonuniform.py | tee bench/ct_nonuniform.md

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

# HTML documentation from docs/ and the docstrings; --strict turns every warning into an error,
# then every name in subid.__all__ must appear in the API reference.
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(DOCS_VENV)/bin/mkdocs build --strict --site-dir site
	$(DOCS_VENV)/bin/python docs/check_api.py site

clean:
	rm -rf $(VENV) $(BENCH_VENV) $(DOCS_VENV) demo_out results site .mypy_cache
