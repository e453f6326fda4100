# The README's two commands: `make demo` and `make test`. Each sets up .venv on its own.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
BASE   := $(VENV)/.installed
STAMP  := $(VENV)/.installed-dev

.PHONY: demo test test-extended test-processes test-all bench lint docs results clean

# Packages are installed by uv (from PyPI, into the venv): the same resolution as pip's, 5-7 s
# for the dev extra against pip's 50 s on this machine (docs/compile-times.md).
UV_BIN := $(VENV)/bin/uv
UV := $(UV_BIN) pip install -q --python $(PY)

$(PY):
	$(PYTHON) -m venv $(VENV)

$(UV_BIN): | $(PY)
	$(PY) -m pip install -q uv

# The demo needs only adpart itself; the tests add the dev extra (pytest, Ray, PostgreSQL driver,
# duckdb, ruff, mkdocs) and the example plugin package (docs/plugin-authoring.md), which the
# suite discovers through its entry points like any third-party plugin.
EXAMPLE_PLUGIN := examples/adpart-plugin-example

$(BASE): $(PY) $(UV_BIN) pyproject.toml
	$(UV) -e .
	touch $@

$(STAMP): $(BASE) $(EXAMPLE_PLUGIN)/pyproject.toml
	$(UV) -e ".[dev]"
	$(UV) --no-deps -e $(EXAMPLE_PLUGIN)
	touch $@

$(VENV)/.installed-bench: $(STAMP)
	$(UV) -e ".[dev,bench]"
	touch $@

ADPART := $(VENV)/bin/adpart
DEMO   := demo-output

# The main job on the embedded default knowledge base ($$ADPART_KB, else ~/.local/share/adpart/kb):
# flat Q-learning on two-rooms and three-floor (curves, policies, summaries), then
# the transfer pipeline on three-floor - learn reach-goal flat, discover subgoals, learn options,
# partition, learn reach-top-west on the decision layer vs flat - with figures in demo-output/
# and its page, demo-output/pipeline/report.html (adpart report).
# A second `make demo` reuses everything the knowledge base already holds.
demo: $(BASE)
	$(ADPART) learn two-rooms --runs 10 --episodes 300 --alpha 1 --epsilon 0.5 --eval-every 25 \
		-q --out $(DEMO)/learn-two-rooms
	$(ADPART) learn three-floor --runs 10 --episodes 500 --alpha 1 --max-steps 5000 \
		--eval-every 25 -q --out $(DEMO)/learn-three-floor
	$(ADPART) env show three-floor --task reach-goal --out $(DEMO)/three-floor-vstar.png --json
	$(ADPART) pipeline three-floor --tasks reach-goal,reach-top-west --runs 20 --episodes 500 \
		--eval-every 1 --out $(DEMO)/pipeline
	$(ADPART) report $(DEMO)/pipeline
	$(ADPART) kb info

# One BLAS thread per test worker: two workers already fill the two cores, and threaded BLAS
# spinning against each other was measured 10-50x slower on this machine.
SINGLE_THREAD := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1

# Before the suite, numba's on-disk cache is filled (tests/warm_kernels.py: the learning and the
# structure kernels in parallel, one process per core), so in a fresh clone each kernel is compiled
# once instead of once per test worker; a warm cache makes this a few seconds of loading. The
# package is byte-compiled too, so the suite's many Python processes (subprocess tests, process
# pools) do not each compile adpart's sources where PYTHONDONTWRITEBYTECODE is set.
WARM_KERNELS = $(SINGLE_THREAD) $(PY) -m tests.warm_kernels learning & warm=$$!; \
	$(PY) -m compileall -q adpart && \
	$(SINGLE_THREAD) $(PY) -m tests.warm_kernels structure && wait $$warm

test: $(STAMP)
	$(WARM_KERNELS)
	$(SINGLE_THREAD) $(PY) -m pytest -n 2 -q --durations=10

# The extended tests: the documentation run as written (every page's `$ adpart` commands, the
# README's first session, the report page in headless Chromium) and the longest end-to-end and
# property tests; minutes of full pipelines, deselected from `make test` for its speed (about
# three minutes from a fresh clone), run here, by `make test-all` and by CI.
test-extended: $(STAMP)
	$(WARM_KERNELS)
	$(SINGLE_THREAD) $(PY) -m pytest -n 2 -q -m "extended and not slow"

# The process-level robustness tests (a Ray cluster, SIGKILLed and concurrent writers, a killed
# pipeline): deselected from `make test` for its speed, run here, by `make test-all` and by CI.
test-processes: $(STAMP)
	$(WARM_KERNELS)
	$(SINGLE_THREAD) $(PY) -m pytest -n 2 -q -m processes

test-all: $(STAMP)
	$(WARM_KERNELS)
	$(SINGLE_THREAD) $(PY) -m pytest -n 2 -q -m ""

# The result tables the docs show, regenerated: the pipeline's defaults on the issue cells
# (adpart experiment comparisons, about 50 minutes on two cores), on 20 randomly moved goals
# of three-floor (adpart experiment random-goals, about 40) and on the 32 cells of toy text,
# MiniGrid and the built-in domains (adpart experiment benchmark, about 15; the field's methods on
# the same cells in both regimes, adpart experiment methods, about 60), their summaries and
# figures copied to docs/results/.
results: $(BASE)
	$(ADPART) experiment comparisons --out build/results/comparisons
	$(ADPART) experiment random-goals --out build/results/random-goals
	$(ADPART) experiment benchmark --out build/results/benchmark
	$(ADPART) experiment methods --out build/results/methods
	mkdir -p docs/results && cp build/results/comparisons/summary.md docs/results/comparisons.md
	cp build/results/random-goals/summary.md docs/results/random-goals.md
	cp build/results/benchmark/summary.md docs/results/benchmark.md
	cp build/results/benchmark/benchmark-profile.png docs/results/
	cp build/results/methods/summary.md docs/results/methods.md
	cp build/results/methods/methods-cells.md build/results/methods/methods-*.png docs/results/

bench: $(VENV)/.installed-bench
	$(PY) -m benchmarks

# The guides and the API reference (from the docstrings) as a site in build/site; warnings fail.
docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict -q

lint: $(STAMP)
	$(PY) -m ruff check adpart tests benchmarks examples

clean:
	rm -rf $(VENV) demo-output build .pytest_cache .hypothesis
