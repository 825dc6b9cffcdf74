# lfmbench: two commands do all set-up on a fresh machine.
#   make test   create .venv, install everything (once), run the test suite
#   make demo   set up the fast render path, render the demo corpus, evaluate the baselines
SHELL  := /bin/bash
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.lfmbench-installed
PIP    := $(PY) -m pip install -q
LLVM   := /usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
export DRJIT_LIBLLVM_PATH ?= $(wildcard /usr/lib/x86_64-linux-gnu/libLLVM.so.19.1)

.PHONY: test demo venv llvm bench clean-venv

venv: $(STAMP)

# Re-installs only when the dependency list changes. PyTorch goes in first from the local CPU wheel and is
# held by constraints.txt, so nothing can swap it for a multi-GB CUDA build.
$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@echo "installing into $(VENV) (log: $(VENV)/pip.log)"
	$(PIP) --upgrade pip > $(VENV)/pip.log 2>&1 || (cat $(VENV)/pip.log; exit 1)
	$(PIP) -c constraints.txt "torch==2.13.0" >> $(VENV)/pip.log 2>&1 || (cat $(VENV)/pip.log; exit 1)
	$(PIP) -c constraints.txt -e ".[all]" >> $(VENV)/pip.log 2>&1 || (cat $(VENV)/pip.log; exit 1)
	$(PY) -c "import torch; assert torch.__version__.startswith('2.13.0'), torch.__version__"
	touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q -n 2 tests

# Debian's LLVM 19 for Mitsuba's llvm_* variants (LLVM 15 crashes on these CPUs; see docs/rendering.md).
llvm: 
	@test -e $(LLVM) || (apt-get install -y -q libllvm19 >/dev/null 2>&1 || (apt-get update -q >/dev/null && apt-get install -y -q libllvm19 >/dev/null)) || echo "warning: libllvm19 not installed; rendering falls back to scalar_spectral"

demo: $(STAMP) llvm
	DRJIT_LIBLLVM_PATH=$(wildcard /usr/lib/x86_64-linux-gnu/libLLVM.so.19.1) $(PY) -m lfmbench.cli demo

# Every benchmark behind the tables and plots in docs/ (about 25 minutes on 2 cores; each script also runs alone).
bench: $(STAMP) llvm
	$(PY) benchmarks/bench_flicker.py
	$(PY) benchmarks/bench_sensor.py
	DRJIT_LIBLLVM_PATH=$(wildcard $(LLVM)) $(PY) benchmarks/bench_dataset.py
	DRJIT_LIBLLVM_PATH=$(wildcard $(LLVM)) $(PY) benchmarks/bench_render.py
	DRJIT_LIBLLVM_PATH=$(wildcard $(LLVM)) $(PY) benchmarks/bench_crop_pad.py
	DRJIT_LIBLLVM_PATH=$(wildcard $(LLVM)) $(PY) benchmarks/bench_object_motion.py

clean-venv:
	rm -rf $(VENV)
