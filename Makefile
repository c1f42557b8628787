# Everything runs inside .venv so a fresh machine needs only python3.
# TORCH_INSTALL installs PyTorch before the package; the default is the CPU
# build this project is tested with, from PyTorch's index of CPU builds (on
# Linux the default index's torch==2.13.0 is the CUDA build, several GB).
# Where that index cannot be reached within 5 s (a machine whose only package
# source is a mirror), the default index is used, with a note. For a GPU,
# pass the pip command for the CUDA build that matches your driver (README).
PYTHON ?= python3
VENV ?= .venv
TORCH_VERSION := 2.13.0
TORCH_CPU_INDEX ?= https://download.pytorch.org/whl/cpu
TORCH_INSTALL ?= if python -c "import sys, urllib.request; \
	urllib.request.urlopen(sys.argv[1].rstrip('/') + '/torch/', timeout=5)" \
	"$(TORCH_CPU_INDEX)" 2>/dev/null; then \
	pip install --timeout 15 --index-url "$(TORCH_CPU_INDEX)" torch==$(TORCH_VERSION); \
	else echo "note: $(TORCH_CPU_INDEX) cannot be reached; installing torch==$(TORCH_VERSION) from pip's default index (on Linux that may be the CUDA build)"; \
	pip install torch==$(TORCH_VERSION); fi
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install install-torch demo test docs train benchmarks clean gravomg-env

$(STAMP): setup.py
	$(PYTHON) -m venv $(VENV)
	. $(BIN)/activate && $(TORCH_INSTALL)
	$(BIN)/pip install -e ".[test]"
	$(BIN)/python -c "import torch, tg_intrinsic; print('torch', torch.__version__, '| tg_intrinsic', tg_intrinsic.__version__)"
	touch $(STAMP)

install: $(STAMP)

# PyTorch alone, into an existing .venv (as the first install does).
install-torch:
	. $(BIN)/activate && $(TORCH_INSTALL)

demo: $(STAMP)
	$(BIN)/tg-intrinsic demo

# The documentation site, offline, warnings as errors; the examples run
# with --quick for the gallery's figures.
docs: $(STAMP)
	$(BIN)/pip install -q -e ".[docs]"
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html
	$(BIN)/python docs/check_site.py docs/_build/html

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
	rm -rf $(VENV) build *.egg-info data docs/_build docs/api/pages docs/results/pages docs/results/summary.md docs/auto_examples
