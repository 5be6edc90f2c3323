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

# Main job. Until the plane tracker lands: edges and blobs of the bundled sample image.
demo: $(VENV)/.core
	mkdir -p robopercept-out
	$(VENV)/bin/robopercept edges -o robopercept-out/edges.png
	$(VENV)/bin/robopercept blobs -o robopercept-out/blobs.png

# Every test, with the reference libraries installed.
test: $(VENV)/.dev
	$(PY) -m ruff check src tests benchmarks
	$(PY) -m ruff format --check src tests benchmarks
	$(PY) -m pytest -p no:cacheprovider

bench: $(VENV)/.dev
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) robopercept-out
