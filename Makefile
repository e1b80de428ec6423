# Set-up is part of every target: a fresh clone needs nothing but python3 (and apt for chromium).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: run test bench lint chromium clean kernels

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

chromium:
	@command -v chromium >/dev/null 2>&1 || { $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq chromium; }

run: $(STAMP)
	$(VENV)/bin/skyring serve

# The controller's numba kernels are compiled (first run after an install) or loaded once before the tests,
# so that no timed test pays for the compile (docs/fast-core.md).
kernels: $(STAMP)
	$(PY) -c "from controller.warmup import warm_up; warm_up()"

test: $(STAMP) chromium kernels
	$(PY) -m pytest -q -ra -n auto --durations=15

bench: $(STAMP)
	$(VENV)/bin/skyring bench all

lint: $(STAMP)
	$(VENV)/bin/ruff check controller vehicles server webui tests
	$(VENV)/bin/ruff format --check controller vehicles server webui tests

clean:
	rm -rf $(VENV) .pytest_cache
