# heliotwin — the two commands a new user needs: `make run` and `make test`.
# Every target creates .venv and installs the project into it when missing or stale.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test bench lint clean

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

run: $(STAMP)  ## start the service: API + dashboard on :8000, 3D twin on :8080, demo logger
	$(BIN)/heliotwin serve

test: $(STAMP)  ## run the whole test suite
	$(BIN)/python -m pytest

bench: $(STAMP)  ## measure the speed figures and write benchmarks/RESULTS.md
	$(BIN)/python benchmarks/run.py

lint: $(STAMP)  ## ruff and mypy, both clean on main
	$(BIN)/ruff check backend sim vision tests benchmarks
	$(BIN)/mypy backend sim vision

clean:
	rm -rf $(VENV) build *.egg-info
