# tactile_descriptors_ros: one-command set-up, tests and demo on a machine with
# no ROS installed (pinned ROS 2 Kilted wheels from PyPI into a venv).
#
#   make setup    the venv as a ROS 2 prefix: wheels, messages, this package in the
#                 ament index, ros2 launch/CLI when ../shared/ros2-cli is there, and
#                 .venv/setup.bash (source it, like a workspace's install/setup.bash)
#   make test     set everything up, then run the tests
#   make demo     set everything up, then run a simulated robot through the live graph
#   make report   regenerate lab/docs/results.md and its plots from the real recordings
#   make report-length  only its touch-length sections (minutes, not an hour)
#   make report-headline  only its headline table (the figures the README quotes first)
#   make report-datasets  only its table across data sets (other labs' layouts, the simulated NAO)
#   make report-convolutions  only its section on the convolution group (1 s SVM, 2 s online)
#   make protocols  the paper's protocols on simulated robots (lab/docs/simulated.md)
#   make bench    time the descriptor path against a naive baseline
#   make clean    remove the venv and build products

SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
BUILD ?= build
SHARED ?= $(abspath ../shared)
# the upstream launch system and ros2 CLI, built as wheels (not on PyPI)
ROS2_CLI ?= $(SHARED)/ros2-cli
PKG := tactile_descriptors_ros
# ROS 2 distribution of the wheels: kilted (default) or jazzy (LTS; Python 3.11),
# e.g. `make test ROS_DISTRO=jazzy VENV=.venv-jazzy BUILD=build/jazzy`
ROS_DISTRO ?= kilted
ROS_REQUIREMENTS := requirements/$(if $(filter jazzy,$(ROS_DISTRO)),ros-jazzy,ros).txt
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
# the pip-installed wheels set no ament prefix; the venv is this checkout's prefix
export AMENT_PREFIX_PATH := $(VIRTUAL_ENV)$(if $(AMENT_PREFIX_PATH),:$(AMENT_PREFIX_PATH))

PIP := $(VPY) -m pip --disable-pip-version-check -q

.PHONY: setup test browser demo demo-nao report report-length report-headline report-datasets report-convolutions protocols bench fuzz clean

setup: $(VENV)/.installed $(VENV)/.ament $(VENV)/setup.bash $(VENV)/.ros2cli $(VENV)/.kernel

# Set-up takes minutes on 2 cores: every step says what it does and about how
# long it takes, and pip lists the packages as it installs them.
STEP = @printf '==> [%s] %s\n' "$$(date +%H:%M:%S)"
PIP_LIST := $(VPY) -m pip --disable-pip-version-check

$(VENV)/.venv-created:
	$(STEP) "setup 1/7: virtual environment $(VENV) (a few seconds)"
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --upgrade "pip>=23" "setuptools>=68" wheel
	touch $@

$(VENV)/.deps: $(VENV)/.venv-created $(ROS_REQUIREMENTS) requirements/base.txt requirements/lab.txt requirements/test.txt
	$(STEP) "setup 2/7: ROS 2 wheels and libraries (3-5 minutes; each package is listed as it comes)"
	set -o pipefail; $(PIP_LIST) install --progress-bar off -r $(ROS_REQUIREMENTS) -r requirements/base.txt \
	  -r requirements/lab.txt -r requirements/test.txt \
	  2>&1 | sed -u -n -E 's/^(Collecting|Installing|Successfully|ERROR|error)/    \1/p'
	touch $@

$(VENV)/.msgs: $(VENV)/.deps $(wildcard msg/msg/*.msg) $(wildcard msg/srv/*.srv) msg/CMakeLists.txt msg/package.xml
	$(STEP) "setup 3/7: building the messages (tactile_descriptors_msgs, about 1 minute)"
	mkdir -p $(BUILD)
	cmake -S msg -B $(BUILD)/tactile_descriptors_msgs -DCMAKE_INSTALL_PREFIX="$(VIRTUAL_ENV)" \
	  -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$(VPY)" > $(BUILD)/msgs-configure.log 2>&1 \
	  || { cat $(BUILD)/msgs-configure.log; exit 1; }
	cmake --build $(BUILD)/tactile_descriptors_msgs -j2 > $(BUILD)/msgs-build.log 2>&1 \
	  || { tail -50 $(BUILD)/msgs-build.log; exit 1; }
	cmake --install $(BUILD)/tactile_descriptors_msgs > $(BUILD)/msgs-install.log 2>&1 \
	  || { tail -50 $(BUILD)/msgs-install.log; exit 1; }
	touch $@

$(VENV)/.installed: $(VENV)/.msgs setup.py setup.cfg lab/pyproject.toml
	$(STEP) "setup 4/7: installing tactile_descriptors_ros and the lab beside it, tactile_descriptors_lab (a few seconds)"
	$(PIP) install --no-deps --no-build-isolation -e .
	$(PIP) install --no-deps --no-build-isolation -e lab
	touch $@

# The ament index entries an editable install does not make (pip installs no
# data_files, and puts console scripts in bin/): the package marker, share/$(PKG)
# (package.xml, launch/, config/: each file a link into this checkout, like colcon's
# --symlink-install; ros2 launch does not follow linked folders) and
# lib/$(PKG)/<executable> for `ros2 run` and launch_ros.
SHARE_FILES := package.xml $(wildcard launch/*.launch.py config/*.yaml config/*.xml config/scenes/*.yaml config/rviz/*.rviz)
$(VENV)/.ament: Makefile $(VENV)/.installed resource/$(PKG) $(SHARE_FILES)
	$(STEP) "setup 5/7: ament index entries of the venv prefix (a few seconds)"
	rm -rf $(VENV)/share/$(PKG) $(VENV)/lib/$(PKG)
	mkdir -p $(VENV)/share/ament_index/resource_index/packages $(VENV)/lib/$(PKG)
	cp resource/$(PKG) $(VENV)/share/ament_index/resource_index/packages/$(PKG)
	for f in $(SHARE_FILES); do mkdir -p $(VENV)/share/$(PKG)/$$(dirname $$f); \
	  ln -sfn $(CURDIR)/$$f $(VENV)/share/$(PKG)/$$f; done
	for exe in $$($(VPY) -I -c "import importlib.metadata as m; \
	    print(*sorted(e.name for e in m.distribution('$(PKG)').entry_points if e.group == 'console_scripts'))"); do \
	  ln -sfn ../../bin/$$exe $(VENV)/lib/$(PKG)/$$exe; done
	touch $@

# One line to source in a shell, like a ROS workspace's install/setup.bash: the
# venv's bin/ and its ament prefix, discovery kept on this machine unless the
# shell says otherwise, and a domain id chosen once per checkout (every shell that
# sources it sees the others; other checkouts do not).
$(VENV)/setup.bash: Makefile $(VENV)/.venv-created
	printf '%s\n' \
	  '# $(PKG): the environment of the ROS 2 prefix $(VIRTUAL_ENV) (written by make setup)' \
	  'export VIRTUAL_ENV=$(VIRTUAL_ENV)' \
	  'case ":$$PATH:" in *":$$VIRTUAL_ENV/bin:"*) ;; *) export PATH="$$VIRTUAL_ENV/bin:$$PATH" ;; esac' \
	  'case ":$${AMENT_PREFIX_PATH:-}:" in *":$$VIRTUAL_ENV:"*) ;; *) export AMENT_PREFIX_PATH="$$VIRTUAL_ENV$${AMENT_PREFIX_PATH:+:$$AMENT_PREFIX_PATH}" ;; esac' \
	  'export RMW_IMPLEMENTATION="$${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"' \
	  'export ROS_AUTOMATIC_DISCOVERY_RANGE="$${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"' \
	  'export ROS_DOMAIN_ID="$${ROS_DOMAIN_ID:-$(shell shuf -i 1-100 -n 1)}"' \
	  > $@

# ros2 launch / run / topic / param / service / lifecycle and launch_testing, and the interface
# packages not on PyPI (tf2_msgs for /tf_static): a venv set up before install.sh built one gets it.
$(VENV)/.ros2cli: $(VENV)/.deps $(wildcard $(ROS2_CLI)/install.sh)
	$(STEP) "setup 6/7: ros2 CLI and launch system (1-3 minutes)"
	@if [ -x "$(ROS2_CLI)/install.sh" ]; then \
	  echo "installing the ros2 CLI and launch system from $(ROS2_CLI) (about a minute)"; \
	  "$(ROS2_CLI)/install.sh" $(VENV) && touch $@; \
	else echo "note: $(ROS2_CLI) not found: no ros2 CLI in the venv (ros2 launch needs a ROS 2 install)"; fi

# The nodes find the compiled descriptor kernel in the venv's cache instead of
# compiling it for about 30 s at their first start (docs/nodes.md, window_node).
$(VENV)/.kernel: $(VENV)/.installed tactile_descriptors_ros/core/numba_kernel.py tactile_descriptors_ros/core/fast.py
	$(STEP) "setup 7/7: compiling the descriptor kernel into $(VENV)/var/cache (about 30-60 s)"
	$(VPY) -c "import sys; from tactile_descriptors_ros.core.fast import main; sys.exit(main())"
	touch $@

# Headless Chromium for the browser view's tests (Debian's package, installed with apt-get as root, as
# CI runs; idempotent).  Where it cannot be installed the tests that need it are skipped, saying why.
browser:
	@if command -v chromium >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  printf '==> [%s] %s\n' "$$(date +%H:%M:%S)" "headless Chromium for the browser tests (apt-get install chromium, 1-3 minutes)"; \
	  { DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null 2>&1 \
	    || { apt-get update -q >/dev/null 2>&1 && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null 2>&1; }; } \
	  || echo "note: chromium could not be installed: the browser tests will be skipped"; \
	else echo "note: no chromium, and no apt-get as root to install it: the browser tests will be skipped"; fi

test: setup browser
	mkdir -p $(ROS_LOG_DIR)
	$(VPY) -m pytest $(PYTEST_ARGS)

demo: setup
	mkdir -p $(ROS_LOG_DIR)
	$(VENV)/bin/tactile demo shadow_hand $(DEMO_ARGS)

demo-nao: setup
	mkdir -p $(ROS_LOG_DIR)
	$(VENV)/bin/tactile demo nao $(DEMO_ARGS)

report: setup
	$(VENV)/bin/tactile report --data $(SHARED)/data/biotac_slide_20_50 --out lab/docs --readme README.md

report-headline: setup
	$(VENV)/bin/tactile report --data $(SHARED)/data/biotac_slide_20_50 --out lab/docs --only headline --readme README.md

report-length: setup
	$(VENV)/bin/tactile report --data $(SHARED)/data/biotac_slide_20_50 --out lab/docs --only length --readme README.md

report-datasets: setup
	$(VENV)/bin/tactile report --data $(SHARED)/data/biotac_slide_20_50 --out lab/docs --only datasets --readme README.md

report-convolutions: setup
	$(VENV)/bin/tactile report --data $(SHARED)/data/biotac_slide_20_50 --out lab/docs --only convolutions --readme README.md

protocols: setup
	$(VENV)/bin/tactile protocols --out lab/docs

bench: setup
	$(VENV)/bin/tactile bench

fuzz: setup
	$(VENV)/bin/tactile fuzz --inputs 1000000

clean:
	rm -rf $(VENV) $(BUILD) *.egg-info
