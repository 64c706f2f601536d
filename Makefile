# The README's two commands. Each does its own set-up on a fresh machine
# (a .venv with torch's CPU build and the project) and is quick when done.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)

.PHONY: demo test install clean test-clients rllib-example docs stress

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# torch comes first, from TORCH_INDEX, so that pip does not resolve stable-baselines3's torch requirement
# to PyPI's default Linux wheel (a CUDA build of several GB). TORCH_VERSION is pyproject.toml's pin
# (tests/test_docs.py checks that it, this Makefile and the README agree). TORCH_INDEX:
#   default                    PyTorch's CPU index: what an ordinary machine needs;
#   make test TORCH_INDEX=     pip's own configuration: a machine whose pip already serves a CPU wheel
#                              (a mirror, a wheel cache), or macOS, where PyPI's wheel is the CPU build;
#   TORCH_INDEX=https://download.pytorch.org/whl/cu128   a CUDA build instead.
# A machine that cannot reach the CPU index still installs with the default from its own configured
# sources (pip's extra indexes and find-links stay active); --retries 1 keeps an unreachable index from
# costing a minute of retries there (TORCH_INDEX= skips it altogether).
# An installed torch==$(TORCH_VERSION) is kept as it is: pip does not query any index for it.
TORCH_VERSION := 2.13.0
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu
TORCH_INDEX_OPTION := $(if $(strip $(TORCH_INDEX)),--index-url $(TORCH_INDEX))

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet --retries 1 torch==$(TORCH_VERSION) $(TORCH_INDEX_OPTION)
	$(PY) -m pip install --quiet -e '.[test,ray]'
	touch $(STAMP)

install: $(STAMP)

# The demo's stages run in two lanes, one per core, each single-threaded (train/demo.py: the stages, their
# reduced budgets, each preset's DEMO_RUN in train/hyperparams, and why); its stage times go to results/.demo_times, each lane's output to
# results/.demo_lane<N>.log, and the summary (train/demo_summary.py) ends it.
demo: $(STAMP)
	$(PY) -m train.demo --out results --coloc $(VENV)/bin/coloc

# Two pytest workers, one per core, each with single-threaded BLAS and torch: a worker's BLAS threads would
# otherwise compete with the other worker for the same two cores. Work stealing: a worker that runs out takes
# queued tests from the other, so the run does not end on one worker's tail of long tests. Bytecode caches
# on (PYTHONDONTWRITEBYTECODE emptied): every `coloc` subprocess a test starts, and each worker's collection
# (pytest's assertion rewriting), would otherwise compile the sources again.
test: $(STAMP)
	$(VENV)/bin/ruff check .
	PYTHONDONTWRITEBYTECODE= OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 MPLBACKEND=Agg \
		$(PY) -m pytest -q -n 2 --dist worksteal

# The documentation site (mkdocs.yml) into site/, strictly: a warning (a broken link or reference) is an error.
# tests/test_docs.py runs the same build in `make test`. NO_MKDOCS_2_WARNING=1 is Material's own switch for its
# end-of-life notice (printed on every build; it says nothing about this site).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --quiet

# Numerical health at every documented extreme (tests/test_covariance_health.py): each numeric field of each preset
# and part at its documented minimum and maximum, one at a time, plus all noise fields at their maximum together,
# 1000 steps each (or the episode) from seeds 0 and 1 with random actions. `make test` runs the same cases with
# 30 steps; STRESS_STEPS sets another length.
STRESS_STEPS ?= 1000
stress: $(STAMP)
	COLOC_STRESS=1 COLOC_STRESS_STEPS=$(STRESS_STEPS) MPLBACKEND=Agg $(PY) -m pytest -q -n 2 tests/test_covariance_health.py \
		-k extreme --durations=20

# The client checks alone (they are part of `make test` too): PettingZoo's module convention, TorchRL's
# check_env_specs on every preset and some compositions, and the SB3 / TorchRL examples of docs/clients.
test-clients: $(STAMP)
	MPLBACKEND=Agg $(PY) -m pytest -q -p no:xdist tests/test_clients.py

# RLlib pins an older gymnasium (ray[rllib] 2.60: gymnasium==1.2.2) than the main venv's: its example
# runs in its own venv, with the same torch CPU build first (TORCH_INDEX as above). The stamp (as the main
# venv's, from pyproject.toml) is written only once the install has passed `pip check` with no CUDA
# package (nvidia-*) pulled in, so a failed install is retried by the next `make rllib-example`.
# RLLIB_ARGS: e.g. make rllib-example RLLIB_ARGS='--preset bandwidth_fusion --iterations 5'.
# PYTHONHASHSEED=0: RLlib's MultiAgentEpisode orders agents through sets of their names, so without a
# fixed hash seed the sampled actions (and returns) change from run to run whatever PPO's seed.
RLLIB_VENV := .venv-rllib
RLLIB_PY := $(RLLIB_VENV)/bin/python
RLLIB_STAMP := $(RLLIB_VENV)/$(notdir $(STAMP))
RLLIB_ARGS ?=
$(RLLIB_PY):
	$(PYTHON) -m venv $(RLLIB_VENV)
	$(RLLIB_PY) -m pip install --quiet --upgrade pip

$(RLLIB_STAMP): $(RLLIB_PY) pyproject.toml
	$(RLLIB_PY) -m pip install --quiet --retries 1 torch==$(TORCH_VERSION) $(TORCH_INDEX_OPTION)
	$(RLLIB_PY) -m pip install --quiet -e '.[rllib]'
	$(RLLIB_PY) -m pip check
	! $(RLLIB_PY) -m pip list 2>/dev/null | grep -i '^nvidia-'
	touch $(RLLIB_STAMP)

rllib-example: $(RLLIB_STAMP)
	PYTHONHASHSEED=0 MPLBACKEND=Agg $(RLLIB_PY) docs/clients/rllib_ppo.py $(RLLIB_ARGS)

clean:
	rm -rf $(VENV) $(RLLIB_VENV) results site .pytest_cache
