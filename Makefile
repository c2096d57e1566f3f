# The two commands of the README. Each creates .venv if it is missing.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
SCENE ?= geometry_precompute/scenes/09_mug_behind_two.toml

.PHONY: demo test test-all lint bench clean notebooks docs

$(BIN)/shacc: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e ".[test]"
	touch $(BIN)/shacc

demo: $(BIN)/shacc
	$(BIN)/shacc evaluate $(SCENE)

# `make test` leaves out the tests marked slow: each is a heavier case of what a faster
# test also checks (tests/test_slow_twins.py holds them to that); `make test-all` runs
# every test.
# Two processes (CI has two cores), a file each: its module fixtures run once.
PYTEST := $(BIN)/python -m pytest -q -n 2 --dist loadfile --durations=25

test: $(BIN)/shacc
	$(BIN)/ruff check .
	$(BIN)/mypy  # the three packages, as pyproject's [tool.mypy] says
	$(PYTEST) -m "not slow"

test-all: $(BIN)/shacc
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(PYTEST)

bench: $(BIN)/shacc
	$(BIN)/python benchmarks/bench_precompute.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .mypy_cache

# Executed copies of the notebooks and their figures, in build/notebooks (git-ignored);
# `make notebooks FIGURES=docs/notebooks` refreshes the README's pictures instead.
NOTEBOOKS_OUT ?= build/notebooks
FIGURES ?= $(NOTEBOOKS_OUT)
notebooks: $(BIN)/shacc
	mkdir -p $(NOTEBOOKS_OUT) $(FIGURES)
	$(BIN)/python -m sweeps.app.notebook_runner --out $(NOTEBOOKS_OUT) -p FIGURES=$(abspath $(FIGURES))

# The reference as a site in build/site (warnings are errors); its generated tables first.
docs: $(BIN)/shacc
	$(BIN)/python -m sweeps.app.reference
	$(BIN)/mkdocs build --strict
