# Set-up is part of every target: a fresh clone needs nothing but python3 (and apt for chromium).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: run test test-px4 bench lint chromium clean

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
	$(PY) -m pytest -q -ra -n auto --durations=15 -m "not px4_sitl"

# The PX4 scenarios against real PX4 SITL (SIH): PX4_SITL=path/to/build/px4_sitl_default/bin/px4 (docs/px4.md
# says how to build it). One scenario at a time: each starts and stops its own PX4 instances.
test-px4: $(STAMP)
	@if [ -z "$(PX4_SITL)" ]; then \
		echo "make test-px4 needs a PX4 SITL build: make test-px4 PX4_SITL=path/to/build/px4_sitl_default/bin/px4"; \
		echo "(PX4 v1.16.0, SIH; docs/px4.md, 'Testing against real PX4', says how to build one)"; \
		exit 2; \
	fi
	@[ -x "$(PX4_SITL)" ] || { echo "PX4_SITL=$(PX4_SITL) is not an executable PX4 binary"; exit 2; }
	PX4_SITL="$(abspath $(PX4_SITL))" $(PY) -m pytest -q -rP -p no:xdist -m px4_sitl --durations=0 tests/vehicles/px4

bench: $(STAMP)
	$(VENV)/bin/skyring bench all

lint: $(STAMP)
	$(VENV)/bin/ruff check controller vehicles server webui tests
	$(VENV)/bin/ruff format --check controller vehicles server webui tests

clean:
	rm -rf $(VENV) .pytest_cache
