# Two commands do everything: `make demo` and `make test` (both run `make setup` first).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# The ROS 2 Jazzy packages of package.xml, as PyPI wheels standing in for a ROS installation
# (a colcon user has them from ROS, not from pip). Everything else comes from setup.py:
# install_requires and the 'test' extra.
ROS_WHEELS := "ros-jazzy-rclpy[fastrtps]" ros-jazzy-visualization-msgs ros-jazzy-sensor-msgs \
	ros-jazzy-geometry-msgs ros-jazzy-std-srvs ros-jazzy-diagnostic-msgs

.PHONY: setup demo test bench clean

setup: $(VENV)/.installed

$(VENV)/.installed: setup.py package.xml Makefile
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(ROS_WHEELS)
	$(PY) -m pip install -q -e '.[test]'
	$(PY) -m paper_sim_ros.warmup
	touch $@

demo: setup
	$(PY) -m paper_sim_ros.demo

test: setup
	$(PY) -m pytest -q test

bench: setup
	$(PY) bench/benchmark.py

clean:
	rm -rf $(VENV) build install log out
