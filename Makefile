# Two entry points for a fresh machine (see README): `make demo` and `make test`.
# Both build .venv first: the pinned wheels from requirements.txt, then this package installed by colcon
# with .venv as a merged ament prefix (lib/veg_area_ros/<node>, share/ament_index/...), as on ROS 2.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
SOURCES := $(shell find veg_area_ros veg_area_msgs -type f -not -name "*.pyc")

.PHONY: demo test install build-tools browser lint bench clean

demo: install
	$(VENV)/bin/veg-area demo

test: install browser
	$(PY) -m ruff check .
	VEG_AREA_REQUIRE_INSTALL=1 $(PY) -m pytest -n auto --dist loadfile --no-loadscope-reorder

install: $(VENV)/.deps-installed $(VENV)/.package-installed

$(VENV)/.deps-installed: requirements.txt
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.txt
	touch $@

# both packages (veg_area_msgs with CMake and the rosidl generators from the wheels, then veg_area_ros), with
# .venv as the only prefix; the wheels' CMake files first get this machine's Python and NumPy include folders
$(VENV)/.package-installed: $(VENV)/.deps-installed $(SOURCES) tools/wheel_cmake.py | build-tools
	$(PY) tools/wheel_cmake.py $(VENV)
	mkdir -p build
	PATH="$(abspath $(VENV))/bin:$$PATH" AMENT_PREFIX_PATH="$(abspath $(VENV))" CMAKE_PREFIX_PATH="$(abspath $(VENV))" \
	    $(VENV)/bin/colcon --log-base build/log build --base-paths veg_area_msgs veg_area_ros --build-base build \
	    --install-base $(VENV) --merge-install \
	    --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$(abspath $(PY))" >build/colcon.out 2>&1 \
	    || { cat build/colcon.out; tail -n 40 build/log/latest_build/veg_area_msgs/stdout_stderr.log 2>/dev/null; exit 1; }
	ln -sf ../lib/veg_area_ros/veg-area $(VENV)/bin/veg-area
	touch $@

# veg_area_msgs is compiled (C and C++ type support), as any ROS message package
build-tools:
	@command -v cmake >/dev/null && command -v c++ >/dev/null || { \
	    if [ "$$(id -u)" != 0 ]; then echo "building veg_area_msgs needs cmake and a C++ compiler: sudo apt-get install cmake g++"; exit 1; fi; \
	    echo "installing Debian's cmake and g++ to build veg_area_msgs"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq cmake g++ >/dev/null; }

# the console's tests drive Debian's chromium (Playwright uses it; no browser is downloaded)
browser:
	@command -v chromium >/dev/null || { \
	    if [ "$$(id -u)" != 0 ]; then echo "the console's tests need Debian's chromium: sudo apt-get install chromium"; exit 1; fi; \
	    echo "installing Debian's chromium for the console's tests"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; }

lint: install
	$(PY) -m ruff check .

bench: install
	$(PY) bench/calibration_speed.py
	$(PY) bench/area_speed.py
	$(PY) bench/ros_transport.py
	$(PY) bench/ros_pipeline.py

clean:
	rm -rf $(VENV) build .pytest_cache
