# The README's two commands: `make demo` and `make test`. Each sets up .venv on its own.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-dev

.PHONY: demo test test-all bench lint clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install -q -e ".[dev]"
	touch $@

$(VENV)/.installed-bench: $(STAMP)
	$(PY) -m pip install -q -e ".[dev,bench]"
	touch $@

demo: $(STAMP)
	$(PY) -m adpart.demo demo-output

test: $(STAMP)
	$(PY) -m pytest -n 2 -q

test-all: $(STAMP)
	$(PY) -m pytest -n 2 -q -m ""

bench: $(VENV)/.installed-bench
	$(PY) -m benchmarks

lint: $(STAMP)
	$(PY) -m ruff check adpart tests benchmarks

clean:
	rm -rf $(VENV) demo-output .pytest_cache .hypothesis
