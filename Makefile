# The two commands of the README's quick start use these targets. Each creates .venv
# (if missing), installs what it needs into it, and runs.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip -q --disable-pip-version-check

.PHONY: demo test lint bench fuzz clean syslibs

# Installing ends with `robopercept warmup`: numba compiles every command's kernels once,
# in parallel, into its on-disk cache (a few minutes on 2 cores), so no command's first
# run waits for the compiler. It runs again only when the sources change.
$(VENV)/.core:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade pip
	$(PIP) install -e .
	touch $@

$(VENV)/.warm: $(VENV)/.core $(shell find src -name '*.py' 2>/dev/null)
	@echo "make: compiling every command's kernels ahead of time (robopercept warmup; once per install, a few minutes on 2 cores)"
	$(VENV)/bin/robopercept warmup
	touch $@

# Open3D and pyrealsense2 (test references) load the system library libusb-1.0; install it
# with apt-get (through sudo when not root) when the dynamic linker cannot find it.
syslibs:
	@if ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then :; \
	elif command -v apt-get >/dev/null 2>&1; then \
	  SUDO=; [ "$$(id -u)" -ne 0 ] && SUDO=sudo; \
	  echo "make: installing the system library libusb-1.0-0 (needed by Open3D and pyrealsense2) with $${SUDO:+sudo }apt-get"; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq libusb-1.0-0; \
	else \
	  echo "make: libusb-1.0 is missing and apt-get is not available: install libusb-1.0 with your package manager" >&2; exit 1; \
	fi

# torch is installed first, pinned by constraints.txt (the CPU build, no CUDA packages),
# then the dev and deep extras under the same constraints.
$(VENV)/.dev: $(VENV)/.core pyproject.toml constraints.txt | syslibs
	$(PIP) install -c constraints.txt "torch==2.13.0"
	$(PIP) install -c constraints.txt -e ".[dev,deep]"
	touch $@

# Main job: the RGB-D plane tracker on the built-in synthetic scene -> robopercept-out/
demo: $(VENV)/.warm
	$(VENV)/bin/robopercept demo --out robopercept-out

# Every test, with the reference libraries installed.
test: $(VENV)/.dev syslibs
	$(PY) -m ruff check src tests benchmarks
	$(PY) -m ruff format --check src tests benchmarks
	$(PY) tools/typecheck.py
	$(PY) -m pytest -p no:cacheprovider -n 2 --dist loadfile

bench: $(VENV)/.dev
	$(PY) -m benchmarks

# The long fuzz campaign (tests/fuzz, docs/reliability.md): hostile arguments for every
# public callable and mutated files for every reader, each call in a sandboxed worker;
# prints the summary table, writes benchmarks/results/fuzz.json, fails on any untyped
# error, crash, hang or over-bound allocation. `make fuzz FUZZ_BUDGET=300` for a short one.
FUZZ_BUDGET ?= 1800
fuzz: $(VENV)/.dev
	$(PY) -m tests.fuzz --budget $(FUZZ_BUDGET)

clean:
	rm -rf $(VENV) robopercept-out
