# Two entry points for a fresh machine (README): `make demo` and `make test`.
# Both create the virtual environment and install what they need themselves.
PY      ?= python3
VENV    ?= .venv
BIN     := $(VENV)/bin
PYTEST_ARGS ?= -m "not slow and not gpu"
# Test processes (pytest-xdist): compiling a kernel and most CUDA-simulator tests use one core, so two processes use
# both of a 2-core CI machine; 0 runs the tests in the pytest process itself. Tests that share a costly module fixture
# (a model stepped on the CUDA simulator) carry one xdist_group and run in one process.
PYTEST_WORKERS ?= 2

.PHONY: demo test venv bench clean

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -q -e ".[test,gpu,mpi]"
	touch $@

venv: $(VENV)/.installed

demo: venv
	$(BIN)/python -m iceresist demo

test: venv
	NUMBA_ENABLE_CUDASIM=$${NUMBA_ENABLE_CUDASIM-1} $(BIN)/python -m pytest -n $(PYTEST_WORKERS) --dist loadgroup $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
