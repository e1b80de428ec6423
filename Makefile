# Set-up is part of every target: a fresh clone needs nothing but python3 (and apt for chromium).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# The pose model's own environment (MediaPipe 0.10.21 needs numpy < 2 and Python <= 3.12): docs/detection.md.
POSE_VENV := .venv-pose
POSE_STAMP := $(POSE_VENV)/.installed
POSE_REQS := vehicles/detect/pose-requirements.txt
POSE_PYTHON ?= $(shell for p in python3.12 python3.11; do command -v $$p >/dev/null 2>&1 && $$p -c 'import venv' 2>/dev/null && { echo $$p; break; }; done)
FOOTAGE := /usr/share/doc/opencv-doc/examples/data/vtest.avi

# Python keeps compiled modules, and pytest its assertion-rewritten modules (tests and plugins), in __pycache__
# (ignored by git). Where the machine sets PYTHONDONTWRITEBYTECODE (ours does), every process compiled them
# again: each pytest process spent 5.5 s of its 11.5 s collection rewriting them (docs/fast-core.md).
export PYTHONDONTWRITEBYTECODE :=

.PHONY: run test test-px4 check bench lint chromium footage pose-env environments clean kernels kernels-fresh

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

$(POSE_STAMP): $(POSE_REQS)
	@test -n "$(POSE_PYTHON)" || { echo "pose-env needs python3.12 or python3.11 (MediaPipe 0.10.21 has no wheel for newer)"; exit 1; }
	rm -rf $(POSE_VENV)
	$(POSE_PYTHON) -m venv $(POSE_VENV)
	$(POSE_VENV)/bin/python -m pip install -q --no-deps -r $(POSE_REQS)
	$(POSE_VENV)/bin/python -c "import mediapipe as mp; mp.solutions.pose.Pose; from ai_edge_litert.interpreter import Interpreter"
	touch $(POSE_STAMP)

pose-env: $(POSE_STAMP)

# The two virtual environments install side by side: on a fresh clone about 50 s and 17 s one after the other.
environments:
	@$(MAKE) --no-print-directory -j2 $(STAMP) $(POSE_STAMP)

# Real test footage (vtest.avi, basketball1.png, messi5.jpg) from Debian's opencv-doc.
footage:
	@test -f $(FOOTAGE) || { $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq opencv-doc; }

chromium:
	@command -v chromium >/dev/null 2>&1 || { $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq chromium; }

run: $(STAMP)
	$(VENV)/bin/skyring serve

# The controller's numba kernels are compiled (first run after an install) or loaded once before the tests,
# so that no timed test pays for the compile (docs/fast-core.md).
kernels: $(STAMP)
	$(PY) -c "from controller.warmup import warm_up; warm_up()"

# numba checks a kernel's cache against the kernel's own module only, not against the kernels it calls in
# other modules (qp, sparse_rows, dual_active_set, scalar_kernels, teammates): after editing one of those, the
# callers' cached code is stale until it is compiled again. This drops every cached kernel and compiles them
# afresh.
kernels-fresh: $(STAMP)
	find controller -name '*.nbi' -delete -o -name '*.nbc' -delete
	$(PY) -c "from controller.warmup import warm_up; warm_up()"

# Two xdist workers more than there are cores: many tests wait on real-time peers (PX4 test peers, browsers,
# spawned agents) with the CPU idle, e.g. the PX4 link tests take 69 s of wall time for 5 s of CPU. Measured on
# 2 cores with the safety sample's whole flights (2026-12-02): 425 s on 4 workers, the CPU busy to the last
# minute, against 529 s on 3 (147 % of 200 % CPU); earlier, 560-583 s with 3 workers against 605-648 s with 2.
WORKERS := $(shell echo $$(( $$(nproc) + 2 )))

# Three passes, all always run: the suite without the browser on the workers; then the browser tests on two
# workers, away from the suite's simulations and experiment pools (beside them a software-rendered page starved
# for minutes on CI: two of its experiment fixtures run 2 processes each, on 3 workers and 2 cores); then the
# tests marked `alone` one at a time with the machine to themselves (they bound wall-clock time: latency, or a
# detector keeping up with real-time footage, which the parallel passes' load would decide).
PAGE_WORKERS := 2

test: environments chromium footage kernels
	@$(PY) -m pytest -q -ra -n $(WORKERS) --dist loadgroup --durations=15 -m "not px4_sitl and not alone and not browser"; \
	parallel=$$?; \
	$(PY) -m pytest -q -ra -n $(PAGE_WORKERS) --dist loadgroup --durations=5 -m "browser and not px4_sitl and not alone"; \
	pages=$$?; \
	$(PY) -m pytest -q -ra -p no:xdist --durations=5 -m "alone and not px4_sitl"; \
	alone=$$?; \
	[ $$parallel -eq 0 ] && [ $$pages -eq 0 ] && [ $$alone -eq 0 ]

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

# The fast part: no closed-loop runs, browser or end-to-end tests (they run in `make test` and CI).
check: environments footage kernels
	$(PY) -m pytest -q -ra -n auto --dist loadgroup -m "not slow and not browser and not e2e"

bench: $(STAMP)
	$(VENV)/bin/skyring bench all

lint: $(STAMP)
	$(VENV)/bin/ruff check controller vehicles server webui tests
	$(VENV)/bin/ruff format --check controller vehicles server webui tests
	$(VENV)/bin/pyright

clean:
	rm -rf $(VENV) $(POSE_VENV) .pytest_cache
