# Everything runs inside .venv so a fresh machine needs only python3.
# TORCH_INSTALL installs PyTorch before the package; the default is the CPU
# build this project is tested with. For a GPU, pass the pip command for the
# CUDA build that matches your driver (see README).
PYTHON ?= python3
VENV ?= .venv
TORCH_INSTALL ?= pip install torch==2.13.0
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test docs train benchmarks clean gravomg-env

$(STAMP): setup.py
	$(PYTHON) -m venv $(VENV)
	. $(BIN)/activate && $(TORCH_INSTALL)
	$(BIN)/pip install -e ".[test]"
	$(BIN)/python -c "import torch, tg_intrinsic; print('torch', torch.__version__, '| tg_intrinsic', tg_intrinsic.__version__)"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/tg-intrinsic demo

# The documentation site, offline, warnings as errors; the examples run
# with --quick for the gallery's figures.
docs: $(STAMP)
	$(BIN)/pip install -q -e ".[docs]"
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html

train: $(STAMP)
	$(BIN)/tg-intrinsic train $(ARGS)

test: $(STAMP)
	$(BIN)/python -m pytest -q tests

# Every benchmark script, then the README's results table from their JSON.
benchmarks: $(STAMP)
	$(BIN)/pip install -e ".[benchmarks]"
	for script in benchmarks/*.py; do \
		[ $$script = benchmarks/report.py ] || $(BIN)/python $$script || exit 1; \
	done
	$(BIN)/python benchmarks/report.py

# The original Gravo MG (PyPI gravomg 0.0.4) needs numpy < 2: a separate
# environment for the oracle test and benchmark (tests skip without it).
gravomg-env:
	$(PYTHON) -m venv .gravomg-env
	.gravomg-env/bin/pip install "numpy==1.26.4" "scipy<1.14" "gravomg==0.0.4"

clean:
	rm -rf $(VENV) build *.egg-info data docs/_build docs/api/pages docs/auto_examples
