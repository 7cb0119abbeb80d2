# bearnav: `make demo` sets up .venv and plans the kitchen map; `make test` runs ruff and pytest.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.bearnav-installed

.PHONY: demo test lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/bearnav plan maps/kitchen.yaml
	$(BIN)/bearnav verify plans/kitchen/plan.npz
	$(BIN)/bearnav simulate plans/kitchen/plan.npz --fov 60
	$(BIN)/bearnav simulate plans/kitchen/plan.npz --fov 90 --dynamics unicycle -o plans/kitchen/sim_unicycle.npz
	$(BIN)/bearnav simulate plans/kitchen/plan.npz --fov 60 --starts random:100 -o plans/kitchen/sim_random.npz
	$(BIN)/bearnav plot plans/kitchen/simplified.npz --also plans/kitchen/tree.npz -o plans/kitchen/simplified.png
	$(BIN)/bearnav plot plans/kitchen/plan.npz -o plans/kitchen/plan.png
	$(BIN)/bearnav plot plans/kitchen/sim_random.npz -o plans/kitchen/sim.png
	@echo "figures: plans/kitchen/simplified.png plans/kitchen/plan.png plans/kitchen/sim.png"

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet ompl
	$(BIN)/python bench/rrtstar.py
	$(BIN)/python bench/synthesize.py --readme
	$(BIN)/python bench/simulate.py --readme

clean:
	rm -rf plans/*/ .pytest_cache
