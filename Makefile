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

# Lint, format and type checks first (pyproject.toml [tool.ruff], [tool.mypy]). One BLAS thread per test worker: two workers on
# two cores must not oversubscribe them. The 25 slowest tests are listed at the end, so CI's log shows where
# the suite's time goes.
test: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) -m pytest -q -n 2 --dist worksteal --durations=25 tests

# Benchmark-time peers live in their own environment: sysidentpy (the local dynamic model's peer, issue 21)
# pins numpy <= 2.3.5, older than the project's.
PEERS      := .venv-peers
PEER_STAMP := $(PEERS)/.installed-stamp

$(PEER_STAMP): benchmarks/peers/requirements.txt
	$(PYTHON) -m venv $(PEERS)
	$(PEERS)/bin/python -m pip install --quiet -r benchmarks/peers/requirements.txt
	touch $(PEER_STAMP)

# Writes benchmarks/RESULTS-table.md (the figures, their peers and ratios; see benchmarks/run.py).
bench: $(STAMP) $(PEER_STAMP)
	$(PY) benchmarks/run.py

# The whole conformance suite against every mutant of conformance/mutants/catalogue/ (spec §16.8.3):
# prints caught/total, writes conformance/mutants/results.json, exits 1 when a mutant escapes.
mutants: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) -m haptify_mutants.run --workers 2

clean:
	rm -rf $(VENV) $(PEERS) $(OUT) build *.egg-info
