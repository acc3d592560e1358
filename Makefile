# Two commands do everything: `make demo` and `make test` (both run `make setup` first).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
ROS_WHEELS := "ros-jazzy-rclpy[fastrtps]" ros-jazzy-visualization-msgs ros-jazzy-sensor-msgs \
	ros-jazzy-geometry-msgs ros-jazzy-std-srvs ros-jazzy-diagnostic-msgs
PY_DEPS := numpy numba rerun-sdk==0.41.* pyyaml scipy pytest pillow colcon-core colcon-ros colcon-python-setup-py colcon-package-selection colcon-output colcon-library-path

.PHONY: setup demo test bench clean

setup: $(VENV)/.installed

$(VENV)/.installed: setup.py package.xml Makefile
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(ROS_WHEELS) $(PY_DEPS)
	$(PY) -m pip install -q --no-deps -e .
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
