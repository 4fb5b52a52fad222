# fleetlink — two commands do everything on a fresh machine:
#   make demo   install, start the local stack and run the demo
#   make test   install, lint, type-check and run every test against real services
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
DEMO_STAMP := $(VENV)/.installed-demo
STAMP := $(VENV)/.installed

.PHONY: install demo test lint typecheck unit integration fault bench clean

$(BIN)/python:
	@$(PY) -c 'import sys; assert sys.version_info >= (3, 11), "fleetlink needs Python 3.11+"' \
		|| { echo "fleetlink needs Python 3.11 or newer as '$(PY)'; set PY=python3.11"; exit 2; }
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

# the native extension (native/) is built by pip install: a change to its sources installs again
NATIVE := native/Cargo.toml native/Cargo.lock $(wildcard native/src/*.rs)

# the demo needs fleetlink with its demo extra (the stream app, the console); the checks need the dev
# extra (the demo's and the test tools); an edge device needs neither: `pip install fleetlink`
$(DEMO_STAMP): pyproject.toml $(NATIVE) | $(BIN)/python
	$(BIN)/pip install --quiet -e '.[demo]'
	@touch $(DEMO_STAMP)

$(STAMP): pyproject.toml $(NATIVE) | $(BIN)/python
	$(BIN)/pip install --quiet -e '.[dev]'
	@touch $(STAMP) $(DEMO_STAMP)

install: $(STAMP)

demo: $(DEMO_STAMP)
	$(BIN)/fleetlink demo

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

unit: $(STAMP)
	$(BIN)/pytest -m unit -q

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/pytest -q -n 2 --dist worksteal --durations=15

bench: $(STAMP)
	@for b in bench/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) var .mypy_cache .ruff_cache .pytest_cache
