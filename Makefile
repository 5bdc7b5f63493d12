# heliotwin — the two commands a new user needs: `make run` and `make test`.
# Every target creates .venv and installs the project into it when missing or stale,
# with the versions CI tested (constraints.txt; `make lock` refreshes it).

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test bench fuzz lint lock clean

$(STAMP): pyproject.toml constraints.txt
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[dev]'
	@touch $(STAMP)

run: $(STAMP)  ## start the service: API + dashboard on :8000, 3D twin on :8080, demo logger
	$(BIN)/heliotwin serve

# the suite over both cores (pytest-xdist); a module's tests stay on one worker, so its
# in-process service starts once, and the browser modules (tests/e2e/) stay together, so
# their served dashboard and Chromium start once. Modules go out in collection order, which
# tests/conftest.py starts with the browser modules, then those holding slow tests (xdist's
# own reorder, by number of tests, would leave those long modules for last).
# `make test PYTEST_WORKERS=0` runs it in one process. --durations prints the 15 slowest
# steps, so a CI log says where the 8-minute budget goes.
# The schema fuzzing (marker one_process) runs after it in a plain pytest: xdist would
# run one case per operation group (schemathesis' cases share a node id). That run collects
# only the test modules naming the marker (collecting the whole suite again cost 10 s); the
# xdist run does not import the modules marked one_process whole (schemathesis: 4 s a worker).
PYTEST_WORKERS ?= 2
ONE_PROCESS_MODULES = $(shell grep -rl --include='test_*.py' one_process tests)
ONE_PROCESS_ONLY = $(shell grep -rlx --include='test_*.py' 'pytestmark = pytest.mark.one_process' tests)

test: $(STAMP)  ## run the whole test suite
	$(BIN)/python -m pytest -n $(PYTEST_WORKERS) --dist loadfile --no-loadscope-reorder \
		--durations=15 -m "not one_process" $(addprefix --ignore=,$(ONE_PROCESS_ONLY))
	$(BIN)/python -m pytest -m one_process $(ONE_PROCESS_MODULES)

bench: $(STAMP)  ## measure the speed figures and write benchmarks/RESULTS.md
	$(BIN)/python benchmarks/run.py

fuzz: $(STAMP)  ## schema fuzzing of every operation, long: 300 examples each and the coverage phase
	HELIOTWIN_FUZZ_EXAMPLES=300 HELIOTWIN_FUZZ_COVERAGE=1 \
		$(BIN)/python -m pytest tests/backend/test_schema_fuzz.py -q

lint: $(STAMP)  ## ruff and mypy, both clean on main
	$(BIN)/ruff check backend sim vision tests benchmarks
	$(BIN)/mypy backend sim vision

lock:  ## resolve pyproject.toml's ranges afresh in a scratch venv and pin them in constraints.txt
	@# --all keeps setuptools (the packaging test builds the wheel with it, no network)
	rm -rf build/lock-venv
	$(PYTHON) -m venv build/lock-venv
	build/lock-venv/bin/python -m pip install --quiet --upgrade pip
	build/lock-venv/bin/python -m pip install --quiet -e '.[dev]'
	( echo "# pip constraints: the versions CI tested (make lock writes this file)"; \
	  build/lock-venv/bin/python -m pip freeze --all --exclude pip --exclude-editable ) > constraints.txt
	rm -rf build/lock-venv

clean:
	rm -rf $(VENV) build *.egg-info
