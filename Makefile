# skymesh: `make demo` and `make test` bootstrap .venv from nothing (Python >= 3.11 on PATH).
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast lint clean

$(STAMP): pyproject.toml
	$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "skymesh needs Python >= 3.11")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	# MAVProxy, headless, as a ground station in the autopilot tests: its declared dependencies (opencv-python,
	# vtk: ~565 MB, for its map and console) would clash with opencv-python-headless, and headless needs none
	$(BIN)/python -m pip install -q --no-deps mavproxy==1.8.75
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/skymesh demo

test: $(STAMP)
	$(BIN)/ruff check agent fusion perception tasking mesh_sim tests
	$(BIN)/python -m pytest -q

# the inner loop: everything but the tests marked slow (live multi-process runs, benchmarks, golden runs)
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow"

lint: $(STAMP)
	$(BIN)/ruff check agent fusion perception tasking mesh_sim tests

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
