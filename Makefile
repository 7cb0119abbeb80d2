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
	$(BIN)/bearnav plot plans/kitchen/simplified.npz --also plans/kitchen/tree.npz -o plans/kitchen/simplified.png
	$(BIN)/bearnav plot plans/kitchen/plan.npz -o plans/kitchen/plan.png
	@echo "figures: plans/kitchen/simplified.png plans/kitchen/plan.png"

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet ompl
	$(BIN)/python bench/rrtstar.py
	$(BIN)/python bench/synthesize.py

clean:
	rm -rf plans/*/ .pytest_cache
