# `make demo` and `make test` each build .venv from nothing on a fresh machine, then run.
# Torch is pinned to a CPU build that installs from local disk here; override with
#   make test TORCH_SPEC="torch==2.13.0 --index-url https://download.pytorch.org/whl/cu128"
PYTHON ?= python3
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
PY := $(VENV)/bin/python
PYTEST_ARGS ?=

.PHONY: demo test bench clean

$(VENV)/.installed: setup.cfg setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet $(TORCH_SPEC)
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $@

demo: $(VENV)/.installed
	$(PY) examples/cantilever.py

test: $(VENV)/.installed
	$(PY) -m pytest -q $(PYTEST_ARGS) tests

bench: $(VENV)/.installed
	$(PY) -m anisofem bench

clean:
	rm -rf $(VENV) build *.egg-info
