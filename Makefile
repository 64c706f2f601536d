# The README's two commands. Each does its own set-up on a fresh machine
# (a .venv with torch's CPU build and the project) and is quick when done.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)

.PHONY: demo test install clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# torch is pinned to the CPU build on this machine; installing it first keeps
# pip from resolving a CUDA wheel for stable-baselines3's torch requirement.
$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[test,ray]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	MPLBACKEND=Agg $(VENV)/bin/coloc reproduce all --quick --out results
	MPLBACKEND=Agg $(VENV)/bin/coloc train bandwidth_fusion --timesteps 20000 --seed 0 --out results/train
	MPLBACKEND=Agg $(VENV)/bin/coloc evaluate bandwidth_fusion --policy all --models results/train --episodes 100 --out results
	@echo "results: results/leaderboard.md, results/<paper>/report.md, results/train/<scenario>/seed0/learning_curve.png"

test: $(STAMP)
	$(VENV)/bin/ruff check .
	MPLBACKEND=Agg $(PY) -m pytest -q

clean:
	rm -rf $(VENV) results .pytest_cache
