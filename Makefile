# Two commands do all set-up on a fresh machine:
#   make demo   - install into .venv and run the nightly job on generated demo data
#   make test   - install into .venv (with test extras) and run the test suite
#   make docs   - build the manual (docs/, mkdocs.yml) into site/
PY ?= python3.11
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-$(shell cat pyproject.toml constraints.txt | sha1sum | cut -c1-12)
export PREFECT_HOME ?= $(CURDIR)/.prefect
export PREFECT_LOGGING_LEVEL ?= WARNING
export PREFECT_SERVER_ANALYTICS_ENABLED ?= false

.PHONY: install demo test test-fast lint typecheck docs bench clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -c constraints.txt -e '.[test]'
	rm -f $(VENV)/.installed-* && touch $@

# then compile the routing kernels into numba's cache (pipeline/__pycache__/numba/jitroute-<digest of the sources>,
# see pipeline/compile_cache.py), so the first run does not pay it
install: $(STAMP)
	$(BIN)/jitroute warm

demo: install
	$(BIN)/jitroute demo

test: install
	$(BIN)/python -m pytest -n auto

# before every commit: every test not marked slow (unit tests of every package on tiny cases), one process
test-fast: install
	$(BIN)/python -m pytest -m "not slow"

lint: install
	$(BIN)/ruff check .

# the packages' interfaces checked by mypy (configured in pyproject.toml, [tool.mypy])
typecheck: install
	$(BIN)/python -m mypy

# the manual's second layer; --strict: a broken link or a missing page fails the build. The test extras hold mkdocs.
docs: $(STAMP)
	$(BIN)/python -m mkdocs build --strict --site-dir site

bench: install
	$(BIN)/python bench/ingest.py
	$(BIN)/python bench/refit.py
	$(BIN)/python bench/models.py
	$(BIN)/python bench/fleet.py
	$(BIN)/python bench/routing.py
	$(BIN)/python bench/cli.py
	$(BIN)/python bench/planning.py

clean:
	rm -rf data .prefect site
