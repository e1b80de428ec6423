# Set-up is part of every target: a fresh clone needs nothing but python3 (and apt for chromium).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: run test check bench lint chromium clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

chromium:
	@command -v chromium >/dev/null 2>&1 || { $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq chromium; }

run: $(STAMP)
	$(VENV)/bin/skyring serve

test: $(STAMP) chromium
	$(PY) -m pytest -q -ra -n auto --durations=15

# The fast part: no closed-loop runs, browser or end-to-end tests (they run in `make test` and CI).
check: $(STAMP)
	$(PY) -m pytest -q -ra -n auto -m "not slow and not browser and not e2e"

bench: $(STAMP)
	$(VENV)/bin/skyring bench all

lint: $(STAMP)
	$(VENV)/bin/ruff check controller vehicles server webui tests
	$(VENV)/bin/ruff format --check controller vehicles server webui tests
	$(VENV)/bin/pyright

clean:
	rm -rf $(VENV) .pytest_cache
