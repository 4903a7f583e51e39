# The two commands a user needs: `make demo` and `make test`. Each sets itself up.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
OUT    ?= demo-out

.PHONY: demo test bench mutants install clean

$(PY):
	$(PYTHON) -m venv $(VENV)

# Re-install only when pyproject.toml changed.
$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) -m haptify_tools.demo --out $(OUT)

# One BLAS thread per test worker: two workers on two cores must not oversubscribe them.
test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) -m pytest -q -n 2 tests

bench: $(STAMP)
	$(PY) benchmarks/run.py

# The whole conformance suite against every mutant of conformance/mutants/catalogue.py (spec §16.8.3):
# prints caught/total, writes conformance/mutants/results.json, exits 1 when a mutant escapes.
mutants: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) -m haptify_mutants.run --workers 2

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info
