# bearnav: `make demo` sets up .venv with bearnav alone (its runtime dependencies) and plans the kitchen map;
# `make test` installs the test extra too (OpenCV, rosbags, ruff, pytest) and runs ruff (lint, format) and pytest (a worker per CPU);
# `make reproduce` redraws the papers' figures in docs/figures/ (only those whose inputs changed);
# `make runtime-wheel` writes the robot's numpy-only wheel into dist/.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
# bearnav with the test extra (make test, bench, reproduce); it holds the runtime dependencies too
STAMP := $(VENV)/.bearnav-installed
# bearnav alone, its runtime dependencies only (make demo): no OpenCV, rosbags or ruff
RUNTIME_STAMP := $(VENV)/.bearnav-runtime

.PHONY: demo install test lint bench clean reproduce runtime-wheel

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# an editable install leaves bearnav's own modules uncompiled: where Python may not write byte-code
# (PYTHONDONTWRITEBYTECODE) every start would compile them again (45 ms of `bearnav rrtstar`), so the
# install compiles them once, as pip does for an installed wheel
$(RUNTIME_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	$(BIN)/python -m compileall -q bearnav_cli
	touch $(RUNTIME_STAMP)

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	$(BIN)/python -m compileall -q bearnav_cli
	touch $(STAMP) $(RUNTIME_STAMP)

install: $(RUNTIME_STAMP)

demo: $(RUNTIME_STAMP)
	$(BIN)/bearnav plan maps/kitchen.yaml
	$(BIN)/bearnav verify plans/kitchen/plan.npz
	$(BIN)/bearnav simulate plans/kitchen/plan.npz --fov 60
	$(BIN)/bearnav simulate plans/kitchen/plan.npz --fov 90 --dynamics unicycle -o plans/kitchen/sim_demo_unicycle.npz
	$(BIN)/bearnav simulate plans/kitchen/plan.npz --fov 60 --starts random:100 -o plans/kitchen/sim_random.npz
	$(BIN)/bearnav plot plans/kitchen/simplified.npz --also plans/kitchen/tree.npz
	$(BIN)/bearnav plot plans/kitchen/plan.npz
	$(BIN)/bearnav plot plans/kitchen/sim_random.npz
	@echo "figures: plans/kitchen/simplified.png plans/kitchen/plan.png plans/kitchen/sim_random.png; run bearnav yourself: . .venv/bin/activate"

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/python -m pytest -n auto

# the benchmarks import the repository's tests/mapgen.py (the maps nobody tuned): the root on the path
BENCH := PYTHONPATH=. $(BIN)/python

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet ompl
	# the byte-code of what changed since the install: a whole process measured in the inherited environment
	# (bench/rrtstar_process.py, bench/plan.py) would compile it again at every start
	$(BIN)/python -m compileall -q bearnav_cli
	$(BENCH) bench/rrtstar.py
	$(BENCH) bench/rrtstar_process.py --readme
	$(BENCH) bench/synthesize.py --readme
	$(BENCH) bench/simulate.py --readme
	$(BENCH) bench/plan.py --readme
	$(BENCH) bench/tolerance.py --readme
	$(BENCH) bench/bounded.py --readme --maps kitchen
	$(BENCH) bench/sweep.py --readme

# The robot's distribution, bearnav-runtime (numpy only): dist/bearnav_runtime-VERSION-py3-none-any.whl
# (docs/runtime.md). Standard library only: no venv, build backend or network needed.
runtime-wheel:
	$(PYTHON) tools/build_runtime.py -o dist

clean:
	rm -rf plans/*/ sweeps/ .pytest_cache dist/

# --------------------------------------------------------------------------- reproduce (repro/)
FIGURES := docs/figures
REPRO_FIGURES := $(FIGURES)/kitchen_paper.png $(FIGURES)/kitchen_unicycle.png $(FIGURES)/paper_b.png \
	$(FIGURES)/kitchen_sets.png $(FIGURES)/robustness.png
PLAN_SRC := $(wildcard bearnav_cli/*.py bearnav_cli/*/*.py)
# What every figure script runs besides its own file: a change to the closed loop, the simulated
# world (wheel slip, camera) or the drawing code redraws every figure.
REPRO_LIB := repro/common.py bearnav_cli/stages/simulate.py $(wildcard bearnav_cli/runtime/*.py) \
	$(wildcard bearnav_cli/world/*.py) $(wildcard bearnav_cli/geometry/*.py) $(wildcard bearnav_cli/plot/*.py) bearnav_cli/palette.py

reproduce: $(STAMP) $(REPRO_FIGURES)
	@echo "figures: $(REPRO_FIGURES) (numbers next to each as .json, .csv, .md)"

# `bearnav plan` writes every artifact of plans/NAME/ but rewrites only the stages whose inputs,
# parameters or versions changed, so an artifact's date changes only with its content; the stamp
# records that the plan was brought up to date, and each figure below is redrawn only when its
# script or an artifact it reads changed.
plans/%/.planned: maps/%.yaml $(STAMP) $(PLAN_SRC)
	$(BIN)/bearnav plan $<
	@touch $@
plans/%/tree.npz plans/%/simplified.npz plans/%/plan.npz: plans/%/.planned ;
.PRECIOUS: plans/%/.planned

$(FIGURES)/kitchen_paper.png: repro/kitchen_figure.py $(REPRO_LIB) \
		plans/kitchen/tree.npz plans/kitchen/simplified.npz plans/kitchen/plan.npz
	$(BIN)/python $< $(filter %.npz,$^) -o $@

$(FIGURES)/kitchen_unicycle.png: repro/kitchen_unicycle.py $(REPRO_LIB) plans/kitchen/plan.npz
	$(BIN)/python $< $(filter %.npz,$^) -o $@

$(FIGURES)/kitchen_sets.png: repro/kitchen_sets.py $(REPRO_LIB) plans/kitchen/plan.npz
	$(BIN)/python $< $(filter %.npz,$^) -o $@

$(FIGURES)/paper_b.png: repro/paper_b.py $(REPRO_LIB) plans/paper_b_circles/plan.npz
	$(BIN)/python $< $(filter %.npz,$^) -o $@

# The robustness figure is a sweep (repro/robustness.yaml, docs/sweeps.md): every example map × both tag sets ×
# 4 fields of view × 4 noises × 2 dynamics, 200 random starts, one job each, on every CPU (bearnav sweep --jobs N
# for fewer). The store sweeps/robustness/ keeps every finished job (a job's file is named by the hash of its map,
# seed, parameters and stage versions), so an interrupted `make reproduce` resumes where it stopped. 30
# minutes of CPU on the 2-core development machine, 17 on both of its cores (bench/README.md "Sweep").
ROBUSTNESS_MAPS := kitchen paper_sim_circles paper_b_circles storeroom
$(FIGURES)/robustness.png: repro/robustness.yaml $(STAMP) $(PLAN_SRC) $(foreach m,$(ROBUSTNESS_MAPS),maps/$(m).yaml)
	$(BIN)/bearnav sweep $< -o sweeps/robustness --figure $@
	cp sweeps/robustness/results.csv $(FIGURES)/robustness.csv
	cp sweeps/robustness/results.md $(FIGURES)/robustness.md
