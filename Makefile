# pattern_locator: `make demo` and `make test` work on a fresh machine with
# Python 3.12 and the package registries. Everything goes into .venv.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

# Localhost-only DDS discovery (this network forbids multicast out of the
# machine), the venv on the ament index, and one ROS domain per invocation.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export AMENT_PREFIX_PATH := $(CURDIR)/$(VENV)$(if $(AMENT_PREFIX_PATH),:$(AMENT_PREFIX_PATH))
export PYTHONDONTWRITEBYTECODE := 1
# Room for camera images in Fast DDS's shared memory (see the file).
export FASTRTPS_DEFAULT_PROFILES_FILE ?= $(CURDIR)/config/fastdds_large_messages.xml
ROS_DOMAIN_ID ?= $(shell echo $$(( ($$$$ % 100) + 101 )))
export ROS_DOMAIN_ID

.PHONY: all venv demo test lint bench cards clean

all: test

$(STAMP): requirements.txt requirements-dev.txt setup.py setup.cfg package.xml
	@py312=$$(tools/find_python312.sh) || exit 1; \
	  if [ ! -x $(PY) ] || ! $(PY) -c 'import sys; sys.exit(sys.version_info[:2] != (3, 12))'; then \
	    rm -rf $(VENV) && $$py312 -m venv $(VENV); fi
	$(PY) -m pip install --quiet --disable-pip-version-check --upgrade pip
	@# The detector's compiled passes: built once here (about 70 s of one core)
	@# into numba's cache beside the modules, not in every test process at once.
	@# What the detector imports goes in first, so that they compile while pip
	@# installs the rest on the other core.
	$(PY) -m pip install --quiet --disable-pip-version-check \
	  $$(grep -E '^(numpy|numba|opencv-python-headless|PyYAML)==' requirements.txt)
	PYTHONPATH=$(CURDIR) $(PY) -c 'import pattern_locator.vision.detector' & kernels=$$!; \
	  $(PY) -m pip install --quiet --disable-pip-version-check \
	    -r requirements.txt -r requirements-dev.txt && \
	  $(PY) -m pip install --quiet --disable-pip-version-check --no-deps \
	    --no-build-isolation -e .; \
	  status=$$?; wait $$kernels && exit $$status
	@touch $@

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/pattern-locator demo

test: $(STAMP)
	tools/run_tests.sh $(PY)

lint: $(STAMP)
	$(PY) -m pytest -q test/test_flake8.py test/test_pep257.py

bench: $(STAMP)
	$(VENV)/bin/pattern-locator bench

clean:
	rm -rf $(VENV) build install log *.egg-info .pytest_cache
