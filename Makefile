# Two commands set up and run everything on a fresh machine:
#   make demo   - create .venv, install the package, run the main job on built-in data
#   make test   - the same set-up plus a virtual display, then the whole test suite, the tests of
#                 the benchmark scripts, and the built wheel installed into a fresh virtual
#                 environment and smoke-tested
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip install --disable-pip-version-check -q -c constraints.txt
DEMO_OUT ?= demo_out
# a fresh virtual environment for the built wheel (no napari, no Qt)
WHEEL_VENV ?= .venv-wheel
# system packages for Qt under a virtual X display (Debian/Ubuntu names)
APT_PACKAGES := xvfb libxcb-icccm4 libxcb-keysyms1 libxcb-xinerama0 libxcb-cursor0 \
	libxkbcommon-x11-0 libegl1 libgl1 libfontconfig1 libdbus-1-3
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: demo test wheel-test install install-test system-deps benchmarks clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: $(PY) pyproject.toml constraints.txt
	$(PIP) -e .
	touch $@

$(VENV)/.installed-testing: $(VENV)/.installed
	$(PIP) -e ".[testing]"
	touch $@

install: $(VENV)/.installed

install-test: $(VENV)/.installed-testing system-deps

system-deps:
	@if ! dpkg -s $(APT_PACKAGES) >/dev/null 2>&1; then \
		echo "installing system packages for a virtual display: $(APT_PACKAGES)"; \
		$(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq $(APT_PACKAGES); \
	fi

demo: $(VENV)/.installed
	$(VENV)/bin/lfdeblur demo --out $(DEMO_OUT)

test: install-test
	xvfb-run -a $(PY) -m pytest
	$(PY) -m pytest -q benchmarks/tests
	$(MAKE) wheel-test

# build the sdist and the wheel, install the wheel (not editable) into a fresh environment, smoke-test it
wheel-test: $(VENV)/.installed-testing
	rm -rf dist $(WHEEL_VENV)
	$(PY) -m build --outdir dist .
	$(PYTHON) -m venv $(WHEEL_VENV)
	$(WHEEL_VENV)/bin/python -m pip install --disable-pip-version-check -q -c constraints.txt dist/*.whl npe2
	cd "$$(mktemp -d)" && $(CURDIR)/$(WHEEL_VENV)/bin/python $(CURDIR)/tests/wheel_smoke.py

benchmarks: $(VENV)/.installed
	$(PY) benchmarks/bench_forward.py

clean:
	rm -rf $(VENV) $(WHEEL_VENV) $(DEMO_OUT) dist .pytest_cache
