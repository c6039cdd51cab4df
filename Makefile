# Two commands from a fresh clone: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
LINKED := $(VENV)/.linked
# The editable install is a link tree (editable_mode=strict) that type checkers and IDEs can follow;
# it links files, so adding or removing a source file (a folder's mtime changes) relinks it.
SOURCE_DIRS := $(shell find host protocol device_sim tools -type d -not -name __pycache__)

.PHONY: demo test lint bench soak clean

$(STAMP): pyproject.toml setup.py
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install -e '.[all,test]' --config-settings editable_mode=strict
	touch $(STAMP) $(LINKED)

$(LINKED): $(STAMP) $(SOURCE_DIRS)
	$(PY) -m pip install --no-deps -q -e . --config-settings editable_mode=strict
	touch $(LINKED)

demo: $(LINKED)
	$(VENV)/bin/stereocam demo --out out

# ruff, mypy (through the installed link tree, so stereocam.* resolves) and the import contracts.
lint: $(LINKED)
	$(PY) -m ruff check .
	$(PY) -m mypy
	$(PY) -c 'import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())'

# Tests run on one worker process per core (pytest-xdist); TEST_WORKERS=0 runs them in this process.
TEST_WORKERS ?= auto

test: lint
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist load

bench: $(LINKED)
	$(VENV)/bin/stereocam bench

soak: $(LINKED)
	$(VENV)/bin/stereocam soak 'sim://?seed=1'

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache .import_linter_cache build
