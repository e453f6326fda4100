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

ADPART := $(VENV)/bin/adpart
DEMO   := demo-output

# The main job on the embedded default knowledge base ($$ADPART_KB, else ~/.local/share/adpart/kb):
# exact solutions rendered as maps, then Q-learning on two-rooms and three-floor, recorded in the KB.
demo: $(STAMP)
	$(ADPART) env show two-rooms --task reach-goal --out $(DEMO)/two-rooms-vstar.png --json
	$(ADPART) env show three-floor --task reach-goal --out $(DEMO)/three-floor-vstar.png --json
	$(ADPART) learn two-rooms --task reach-goal --runs 10 --episodes 500 --alpha 1 --epsilon 0.5 \
		--out $(DEMO)/two-rooms --json
	$(ADPART) learn three-floor --task reach-goal --runs 10 --episodes 500 --eval-every 25 \
		--alpha 1 --max-steps 5000 --out $(DEMO)/three-floor --json
	$(ADPART) kb info

# One BLAS thread per test worker: two workers already fill the two cores, and threaded BLAS
# spinning against each other was measured 10-50x slower on this machine.
SINGLE_THREAD := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1

test: $(STAMP)
	$(SINGLE_THREAD) $(PY) -m pytest -n 2 -q

test-all: $(STAMP)
	$(SINGLE_THREAD) $(PY) -m pytest -n 2 -q -m ""

bench: $(VENV)/.installed-bench
	$(PY) -m benchmarks

lint: $(STAMP)
	$(PY) -m ruff check adpart tests benchmarks

clean:
	rm -rf $(VENV) demo-output .pytest_cache .hypothesis
