# lfmbench: two commands do all set-up on a fresh machine.
#   make test   create .venv, install everything (once), install libLLVM 19 (once), run the test suite
#   make demo   the same set-up, then render the demo corpus, evaluate the baselines
SHELL  := /bin/bash
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.lfmbench-installed
PIP    := $(PY) -m pip install -q
LLVM   := /usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
# a DRJIT_LIBLLVM_PATH of the caller is kept; else the recipes name Debian's libLLVM 19 once `llvm` installed it

.PHONY: setup test test-fast test-integration demo venv llvm bench clean-venv

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

# Everything `test`, `demo` and `bench` need: the Python environment and the render dependency.
setup: $(STAMP) llvm

test: setup
	DRJIT_LIBLLVM_PATH=$${DRJIT_LIBLLVM_PATH:-$$(ls $(LLVM) 2>/dev/null)} $(PY) -m pytest -q -n 2 -m "not integration" tests

# The checks of whole installs and runtimes (CI runs them after `make test`, .ci/run): the wheel installed into a
# fresh environment and used from an empty folder, the Triton kernels under Triton's interpreter, two DDP ranks.
test-integration: setup
	DRJIT_LIBLLVM_PATH=$${DRJIT_LIBLLVM_PATH:-$$(ls $(LLVM) 2>/dev/null)} $(PY) -m pytest -q -n 2 -m integration tests

# A quick subset for the edit-test loop (under a minute on 2 cores, docs/guide/extending.md): the package
# layout, the checks and registries, the flicker model, metrics, ISP, the rule-based baselines and the recipes of
# extending a registry; nothing that renders, trains or builds a corpus of many scenes. `make test` runs everything.
FAST := tests/test_layout.py tests/test_registry.py tests/test_check.py tests/test_extending.py tests/flicker \
        tests/metrics tests/isp tests/baselines/test_baselines.py tests/baselines/test_plan_merge.py \
        tests/sensor/test_plan.py tests/sensor/test_counter_rng.py tests/datasets/test_dataset_options.py \
        tests/evaluation/test_evaluation_stats.py
test-fast: setup
	DRJIT_LIBLLVM_PATH=$${DRJIT_LIBLLVM_PATH:-$$(ls $(LLVM) 2>/dev/null)} $(PY) -m pytest -q -n 2 -m "not slow" $(FAST)

# Debian's LLVM 19 for Mitsuba's llvm_* variants (the system's LLVM 15 crashes on AVX-512 CPUs; README, "System
# dependency"). Needs root (apt-get); without it the render tests skip with one line saying why (CI never skips).
llvm:
	@test -e $(LLVM) || (echo "installing Debian's libllvm19 (render dependency)"; apt-get install -y -q libllvm19 >/dev/null 2>&1 || (apt-get update -q >/dev/null 2>&1 && apt-get install -y -q libllvm19 >/dev/null 2>&1)) || echo "warning: could not install libllvm19 (needs root: sudo apt-get install libllvm19); renders need it, their tests skip"

demo: setup
	DRJIT_LIBLLVM_PATH=$${DRJIT_LIBLLVM_PATH:-$$(ls $(LLVM) 2>/dev/null)} $(PY) -m lfmbench.cli demo

# Every performance benchmark (benchmarks/bench_*.py), each rewriting its page of docs/benchmarks/ (or its section of
# one); one-off studies live in benchmarks/studies/ and run by hand. About 2-3 hours on 2 quiet cores (estimated
# from the pages' own timings, not timed as a whole; the renders and the 100,000-scene validate are most of it).
# Needs the demo's corpus and U-Net (bench_eval_sharing), so it runs `demo` first (a second demo reuses them).
# Without a GPU the device benchmarks write their "CPU figures" sections and keep the GPU ones.
RENDERENV = DRJIT_LIBLLVM_PATH=$${DRJIT_LIBLLVM_PATH:-$$(ls $(LLVM) 2>/dev/null)}
bench: setup demo
	$(PY) benchmarks/bench_flicker.py
	$(PY) benchmarks/bench_sensor.py
	$(PY) benchmarks/bench_sensor_device.py
	$(RENDERENV) $(PY) benchmarks/bench_dataset.py
	$(RENDERENV) $(PY) benchmarks/bench_architectures.py
	$(RENDERENV) $(PY) benchmarks/bench_batched_capture.py
	$(PY) benchmarks/bench_device_path.py
	$(RENDERENV) $(PY) benchmarks/bench_device_v2.py
	$(RENDERENV) $(PY) benchmarks/bench_eval_sharing.py --corpus demo_out/corpus --checkpoint demo_out/unet_fusion.pt
	$(RENDERENV) $(PY) benchmarks/bench_render.py
	$(RENDERENV) $(PY) benchmarks/bench_crop_pad.py
	$(RENDERENV) $(PY) benchmarks/bench_object_motion.py
	$(RENDERENV) $(PY) benchmarks/bench_render_scale.py
	$(RENDERENV) $(PY) benchmarks/bench_render_v2.py
	$(RENDERENV) $(PY) benchmarks/bench_render_phases.py
	$(RENDERENV) $(PY) benchmarks/bench_ray.py
	$(RENDERENV) $(PY) benchmarks/bench_protocol.py
	$(RENDERENV) $(PY) benchmarks/bench_storage.py --quick
	$(PY) benchmarks/bench_validate.py

clean-venv:
	rm -rf $(VENV)
