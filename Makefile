# Two entry points for a fresh machine (see README):
#   make demo   installs everything and runs the main job end to end on the embedded default
#   make test   installs everything and runs lint + the default test suite
# Both install into the active virtualenv when make runs inside one, else into ./.venv (made on first use
# with python3, which must be >= 3.11); afterwards `. .venv/bin/activate` puts gttdata/gttnet on the PATH.
# Versions come from constraints.txt; `make lock` regenerates it (see scripts/lock.sh).
VENV ?= .venv
BASE_PYTHON ?= python3

# The interpreter: PYTHON=... on the command line wins; else the active virtualenv's; else .venv's.
ifeq ($(origin PYTHON),undefined)
  ifneq ($(VIRTUAL_ENV),)
    PYTHON := $(VIRTUAL_ENV)/bin/python
  else ifeq ($(shell $(BASE_PYTHON) -c 'import sys; print(sys.prefix != sys.base_prefix)' 2>/dev/null),True)
    PYTHON := $(BASE_PYTHON)
  else
    PYTHON := $(VENV)/bin/python
  endif
endif
ifeq ($(PYTHON),$(VENV)/bin/python)
  VENV_TARGET := $(PYTHON)
endif
# Scripts (demo.sh, system_deps.sh) call gttdata/gttnet: the interpreter's bin/ goes first on their PATH.
ifneq ($(findstring /,$(PYTHON)),)
  export PATH := $(abspath $(dir $(PYTHON))):$(PATH)
endif
PIP := $(PYTHON) -m pip
CONSTRAINTS := constraints.txt
EXTRAS := train,preview,dev,formats

.PHONY: install system-deps demo test lint pytest lock

$(VENV)/bin/python:
	bash scripts/make_venv.sh $(BASE_PYTHON) $(VENV)

install: $(VENV_TARGET)
	$(PIP) install -q -c $(CONSTRAINTS) -e ".[$(EXTRAS)]"

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

# Regenerate constraints.txt from the newest releases (a deliberate upgrade: review the diff, `make test`).
lock: $(VENV_TARGET)
	PYTHON=$(PYTHON) EXTRAS=$(EXTRAS) bash scripts/lock.sh
