# semlab: one entry point for setting up, running the workbench and testing.
#   make lab    - create .venv, install semlab with its extras, register the kernel, start JupyterLab
#   make test   - same set-up, then the whole test suite (notebooks and the browser test included)
# Second runs reinstall nothing unless pyproject.toml or etc/constraints.txt changed. Releases are those of
# etc/constraints.txt (the ones CI last passed with); make constraints renews it from the .venv.

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.semlab-installed
ARGS   ?=
# Jupyter refuses to run as root unless told: containers and fresh VMs often are root.
ROOT_FLAG := $(shell [ "$$(id -u)" = 0 ] && echo --allow-root)
# Two test workers (pytest-xdist): the suite is CPU-bound and the machines have 2 cores.
PYTEST_ARGS ?= -n 2

.PHONY: constraints setup lab test test-fast bench bench-servo bench-corpus bench-all chromium strip lint clean mutate

setup: $(STAMP)

# JupyterLab settings of this .venv: save the widgets' state in a notebook when it is saved (ipywidgets'
# default is not to), so a saved notebook reopens with its widgets, not "Error displaying widget: model not found".
LAB_OVERRIDES := $(VENV)/share/jupyter/lab/settings/overrides.d

$(STAMP): pyproject.toml etc/constraints.txt etc/jupyterlab/semlab.json
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -c etc/constraints.txt -e '.[dev,fibsem]'
	$(BIN)/python -m ipykernel install --sys-prefix --name python3 --display-name "Python 3 (semlab)" >/dev/null
	@mkdir -p $(LAB_OVERRIDES) && cp etc/jupyterlab/semlab.json $(LAB_OVERRIDES)/semlab.json
	@touch $(STAMP)

lab: $(STAMP)
	$(BIN)/jupyter lab --notebook-dir=notebooks --ServerApp.ip=127.0.0.1 $(ROOT_FLAG) $(ARGS)

# Debian's chromium drives the browser test; install it when missing and we may (root or sudo).
chromium:
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; elif command -v sudo >/dev/null 2>&1; then SUDO=sudo; else \
	    echo "chromium is missing and cannot be installed without root: the browser test will be skipped"; exit 0; fi; \
	  echo "installing Debian's chromium for the browser test"; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq chromium >/dev/null; }

test: $(STAMP) chromium
	SEMLAB_FAST=1 $(BIN)/python -m pytest $(PYTEST_ARGS)

# The unit tests alone (no notebooks, no browser): the quick loop while developing.
test-fast: $(STAMP)
	$(BIN)/python -m pytest -m "not notebooks and not browser" $(PYTEST_ARGS)

# A few minutes each; the long servo and corpus runs have their own targets (bench-all: every benchmark).
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_sim.py
	$(BIN)/python benchmarks/bench_tracking.py
	$(BIN)/python benchmarks/bench_tracking_seeds.py
	$(BIN)/python benchmarks/bench_fibsem_demo.py
	$(BIN)/python benchmarks/bench_four_probes.py

bench-servo: $(STAMP)
	$(BIN)/python benchmarks/bench_servo.py

bench-corpus: $(STAMP)
	nice -n 10 $(BIN)/python benchmarks/bench_corpus.py

bench-all: bench bench-servo bench-corpus

# Mutation testing of the core modules ([tool.mutmut] in pyproject.toml; slow, not in CI: the fixed
# sample in tests/test_mutants.py is). Niced, 2 workers; `make mutate ARGS='semlab.control.*'` runs a subset.
# The table per module: $(BIN)/python benchmarks/mutation_report.py (reads mutants/).
mutate: $(STAMP)
	nice -n 10 $(BIN)/mutmut run --max-children 2 $(ARGS)
	$(BIN)/python benchmarks/mutation_report.py

strip: $(STAMP)
	$(BIN)/nbstripout --keep-id notebooks/*.ipynb

# The .venv's releases become the constraints make setup installs with (run after a green make test on
# newer releases; the file's comment lines are kept).
constraints: $(STAMP)
	@{ grep '^#' etc/constraints.txt; $(BIN)/python -m pip freeze --exclude-editable | grep -v '^semlab=='; } > etc/constraints.txt.new
	@mv etc/constraints.txt.new etc/constraints.txt

lint: $(STAMP)
	$(BIN)/ruff check semlab tests benchmarks

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
