# hopper_ros developer entry points (Python venv with the ROS 2 wheels from PyPI).
# On a machine with ROS 2 installed, `colcon build` works as well (see CMakeLists.txt).

SHELL := /bin/bash
VENV_PYTHON := .venv/bin/python

# DDS discovery stays on loopback unless the caller asked for another range.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: setup test bench demo soak clean

# Idempotent: a second run only hashes the inputs (see tools/setup.sh).
setup:
	@bash tools/setup.sh

# The node tests and, beside them at nice 19, the CPU-bound diagnosis tests (tools/test.sh).
test: setup
	@bash tools/test.sh

# BENCH_ARGS, e.g. BENCH_ARGS=--quick or BENCH_ARGS="--only messages"
bench: setup
	$(VENV_PYTHON) bench/run.py $(BENCH_ARGS)

# The whole demo graph for an hour on the simulated robot (bench/soak.py: memory, falls, late samples,
# the recording); not part of `make bench` nor `make test`. SOAK_ARGS, e.g. SOAK_ARGS="--minutes 5"
soak: setup
	$(VENV_PYTHON) bench/soak.py $(SOAK_ARGS)

# The closed-loop Fig 5.5 run on the simulated robot, the whole graph as separate processes;
# table and plot in demo_out/ (hopper_ros/cli/demo.py).
demo: setup
	$(VENV_PYTHON) -m hopper_ros.cli demo --strides 30 -o demo_out

clean:
	rm -rf .venv build install log bench/out hopper_ros.egg-info demo_out
