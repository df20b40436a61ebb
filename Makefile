# The two commands a lab needs: `make demo` and `make test`. Everything else is installed here.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: venv demo demo-coils test test-fast lint build bench bench-model campaign clean

venv: $(STAMP)

$(STAMP): requirements.txt
	$(PYTHON) -m venv $(VENV) || { echo 'make: $(PYTHON) -m venv failed; on Debian: apt-get install python3-venv'; exit 1; }
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.txt
	$(PY) scripts/build_kernels.py
	touch $(STAMP)

# The main job: plan the pancreatic duct, play it on the simulated rig open loop, closed
# loop and tip-driven, write out/ (schedule.yaml, report.json, report.md, PNGs, recordings).
demo: $(STAMP)
	$(PY) scripts/demo_navigation.py

# Bring up three emulated supplies and the coils node, command a rotating field,
# print per axis what the supplies were told and what they measured.
demo-coils: $(STAMP)
	$(PY) scripts/demo_coils.py

# Unit tests, cross-process tests over DDS and the colcon layout check.
test: $(STAMP)
	$(PY) -m pytest -q --durations=20

# Only the tests that need no ROS process (fast inner loop).
test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not ros"

lint: $(STAMP)
	$(PY) -m pytest -q tests/test_lint.py

build: $(STAMP)
	cd ros_ws && ../$(VENV)/bin/colcon build --symlink-install

bench: $(STAMP)
	$(PY) bench/coils_rate.py

# The coil driver's reliability campaign: every fault and signal, timed, what reached the wire.
campaign: $(STAMP)
	$(PY) tests/fault_campaign.py

# The statics speed/accuracy trade against the PyElastica peer, in a bench-only venv.
VENV_BENCH := .venv-bench
$(VENV_BENCH)/.installed: bench/requirements-peer.txt
	$(PYTHON) -m venv $(VENV_BENCH)
	$(VENV_BENCH)/bin/python -m pip install --quiet -r bench/requirements-peer.txt
	$(VENV_BENCH)/bin/python -m pip install --quiet --no-deps --ignore-requires-python magneto-pyelastica==0.0.1.post2
	touch $@

bench-model: $(VENV_BENCH)/.installed
	$(VENV_BENCH)/bin/python bench/model_tradeoff.py

clean:
	rm -rf ros_ws/build ros_ws/install ros_ws/log
