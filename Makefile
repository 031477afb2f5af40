# Two entry points for a fresh machine (see README):
#   make demo   installs everything and runs the main job end to end on the embedded default
#   make test   installs everything and runs lint + the default test suite
PYTHON ?= python3
PIP := $(PYTHON) -m pip

.PHONY: install system-deps demo test lint pytest

install:
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e ".[train,preview,dev,formats]"

system-deps:
	bash scripts/system_deps.sh

demo: install system-deps
	bash scripts/demo.sh

lint:
	$(PYTHON) -m ruff check gttdata gttnet tests benchmarks
	$(PYTHON) -m ruff format --check gttdata gttnet tests benchmarks
	$(PYTHON) -m mypy

pytest:
	$(PYTHON) -m pytest -q; rc=$$?; if [ $$rc -eq 5 ]; then echo "pytest: no tests collected"; exit 0; fi; exit $$rc

test: install system-deps lint pytest
