# hmocap_ros: `make demo` and `make test` set everything up if needed, then run.
# DDS stays on this machine (loopback only) with its own domain: in a real
# multi-host room, run the nodes without these two variables (see docs/network.md).
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export ROS_DOMAIN_ID ?= 42
# Fast DDS profile: a shared-memory segment that carries full-size frames whole (Fast DDS 2
# reads the first variable, Fast DDS 3 the second).
export FASTRTPS_DEFAULT_PROFILES_FILE ?= $(CURDIR)/config/fastdds_local.xml
export FASTDDS_DEFAULT_PROFILES_FILE ?= $(FASTRTPS_DEFAULT_PROFILES_FILE)
export PYTHONUNBUFFERED = 1

VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: setup demo test lint test-fresh test-jazzy test-slow test-mutants test-faults test-multihost bench clean help
help:
	@echo "make demo       set up if needed, run the demo on the shipped data"
	@echo "make test       set up if needed, run the test suite"
	@echo "make lint       ruff (pyflakes, pycodestyle, import order, bugbear) and mypy"
	@echo "make test-fresh what CI runs: a clean clone of HEAD, set up from nothing, then make test"
	@echo "                (HMOCAP_FRESH_LOAD=1: one core busy; HMOCAP_FRESH_OTHER_CPU=1: an AVX2 CPU's rounding)"
	@echo "make test-jazzy the test suite with ROS 2 Jazzy's numpy 1.26, OpenCV 4.6, SciPy 1.11 (.venv-jazzy)"
	@echo "make test-slow  long evaluations (marked slow)"
	@echo "make test-mutants  deliberate breakages the accuracy tests must catch"
	@echo "make test-faults   nodes killed, a camera gone, stamps back, memory soak (HMOCAP_SOAK_MINUTES, default 30)"
	@echo "make test-multihost  a pipeline split over network namespaces (root, iproute2)"
	@echo "make bench      benchmark scripts"
	@echo "make setup      only set up .venv (idempotent)"

setup:
	@HMOCAP_VENV=$(VENV) bash tools/setup_env.sh

demo: setup
	$(VENV)/bin/hmocap demo --out out/demo

test: setup
	$(PY) -m pytest -q -p no:cacheprovider

lint: setup
	@$(PY) -m pip install -q -r requirements-lint.txt
	$(PY) -m ruff check .
	$(PY) -m mypy

test-fresh:
	@bash tools/test_fresh.sh

# The quick suite in a second venv holding the versions a ROS 2 Jazzy install on Ubuntu 24.04
# has (requirements-jazzy.txt in place of the lock's pins).
JAZZY_VENV ?= .venv-jazzy
test-jazzy:
	@HMOCAP_VENV=$(JAZZY_VENV) HMOCAP_PINS=requirements-jazzy.txt bash tools/setup_env.sh
	$(JAZZY_VENV)/bin/python -m pytest -q -p no:cacheprovider

test-slow: setup
	$(PY) -m pytest -q -p no:cacheprovider -m slow

test-mutants: setup
	$(PY) -m pytest -q -p no:cacheprovider -m mutants test/test_mutants.py

test-faults: setup
	$(PY) -m pytest -q -p no:cacheprovider -m faults test/test_faults.py

test-multihost: setup
	$(PY) -m pytest -q -p no:cacheprovider -m multihost test/test_multi_host.py

bench: setup
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

clean:
	rm -rf out msg_defs/build msg_defs_tf2/build msg_defs_hri/build build *.egg-info
