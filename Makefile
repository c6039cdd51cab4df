# Two commands from a fresh clone: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
LINKED := $(VENV)/.linked
# The editable install is a link tree (editable_mode=strict) that type checkers and IDEs can follow;
# it links files, so adding or removing a source file (a folder's mtime changes) relinks it.
SOURCE_DIRS := $(shell find host protocol device_sim tools -type d -not -name __pycache__)

.PHONY: demo test lint measure bench soak stability clean

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

# Bytecode caching on even where the environment turns it off (PYTHONDONTWRITEBYTECODE): each worker,
# and every CLI or simulator the tests start in a child process, would otherwise compile the package
# (and pytest re-rewrite every test module) from source again.
# The matching kernels are compiled (or loaded from numba's disk cache) once before the workers start:
# on a fresh clone or after a kernel change, two workers and the simulators they start would each
# compile them at once, and a busy machine then misses the first frames' deadlines.
test: lint
	env -u PYTHONDONTWRITEBYTECODE $(PY) -c 'from stereocam.stereo.engines import warm_up; print(f"matching kernels ready in {warm_up():.1f} s")'
	env -u PYTHONDONTWRITEBYTECODE $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadgroup -m "not measurement"

# Tests that measure a target whose result varies run to run (e.g. a simulated wide-angle unit's
# device-mode calibration against its truth): reported, not part of `make test`.
measure: $(LINKED)
	env -u PYTHONDONTWRITEBYTECODE $(PY) -m pytest -q -m measurement -p no:randomly

# The suite's stability on a busy machine: RUNS full runs of `make test`, one after another, with two
# busy-loop processes beside them; each run's output in out/stability-N.log, a line per run.
RUNS ?= 5
stability: $(LINKED)
	@mkdir -p out; $(PY) -c 'while True: pass' & b1=$$!; $(PY) -c 'while True: pass' & b2=$$!; \
	trap 'kill $$b1 $$b2' EXIT; failed=0; \
	for i in $$(seq $(RUNS)); do \
	  start=$$(date +%s); load=$$(cut -d' ' -f1-3 /proc/loadavg); \
	  $(MAKE) --no-print-directory test > out/stability-$$i.log 2>&1 || failed=$$((failed + 1)); \
	  echo "run $$i: $$(( $$(date +%s) - start )) s, load $$load at start: $$(grep -E '[0-9]+ (passed|failed)' out/stability-$$i.log | tail -1)"; \
	done; echo "$$failed of $(RUNS) runs failed"; test $$failed = 0

bench: $(LINKED)
	$(VENV)/bin/stereocam bench

soak: $(LINKED)
	$(VENV)/bin/stereocam soak 'sim://?seed=1'

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache .import_linter_cache build
