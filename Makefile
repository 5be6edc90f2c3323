# The two commands of the README's quick start use these targets. Each creates .venv
# (if missing), installs what it needs into it, and runs.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip -q --disable-pip-version-check

.PHONY: demo test lint bench clean

$(VENV)/.core:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade pip
	$(PIP) install -e .
	touch $@

$(VENV)/.dev: $(VENV)/.core pyproject.toml
	$(PIP) install -e ".[dev]"
	touch $@

# Main job: the RGB-D plane tracker on the built-in synthetic scene -> robopercept-out/
demo: $(VENV)/.core
	$(VENV)/bin/robopercept demo --out robopercept-out

# Every test, with the reference libraries installed.
test: $(VENV)/.dev
	$(PY) -m ruff check src tests benchmarks
	$(PY) -m ruff format --check src tests benchmarks
	$(PY) tools/typecheck.py
	$(PY) -m pytest -p no:cacheprovider

bench: $(VENV)/.dev
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) robopercept-out
