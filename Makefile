# pneumatic_unload: the two commands of README.md are `make demo` and `make test`.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: setup demo test lint docs bench lock bags clean

setup:
	@bash scripts/setup_venv.sh

demo: setup
	@$(PY) -m pneumatic_unload.app.demo

# the tests not marked serial on every core, then the serial ones (node processes in real
# time, servers: test/conftest.py) alone
# (the PostgreSQL tests may install Debian's postgresql: test/pgserver.py)
test: export PNEUMATIC_UNLOAD_TEST_INSTALL_POSTGRES = 1
test: setup
	@$(VENV)/bin/ruff check .
	@$(PY) -m pytest -q -n auto --dist worksteal -m "not serial" --durations=10 pneumatic_unload/test
	@$(PY) -m pytest -q -m serial --durations=10 pneumatic_unload/test

lint: setup
	@$(VENV)/bin/ruff check .

# the documentation site (docs/_build/html/index.html); its reference pages are generated
# from the code at each build; a warning fails the build
docs: setup
	@$(PY) -m sphinx -W --keep-going -q -b html docs docs/_build/html
	@echo "docs/_build/html/index.html"

bench: setup
	@for b in bench/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

bags: setup
	@$(PY) pneumatic_unload/bags/regenerate.py

lock:
	@bash scripts/lock.sh

clean:
	rm -rf build install log runs docs/_build docs/_generated
