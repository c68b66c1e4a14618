# Two entry points (see README):  make demo  |  make test
# Each sets everything up first (libLLVM, .venv, the package) and is safe to repeat.
VENV := .venv
BIN := $(VENV)/bin
PYTEST_ARGS ?=
# the suite runs in this many processes (pytest-xdist; a test module stays in one process, so
# its module fixtures are made once): much of a test is single-threaded Python
TEST_WORKERS ?= 2

.PHONY: setup demo test test-gpu test-all bench docs docs-html docs-examples clean

setup:
	bash scripts/setup.sh

demo: setup
	$(BIN)/mitsuba-veg demo --out out/demo

test: setup
	$(BIN)/python -m pytest -m "not slow and not docs" -q --nbmake -n $(TEST_WORKERS) \
		--dist loadscope tests notebooks $(PYTEST_ARGS)

# The documentation: the HTML site (warnings are errors; the API reference, the command line,
# the plugin pages and the benchmark tables are generated; the gallery's examples run), then
# every code block of the README and the docs (tests/test_doc_examples.py).
docs: docs-html docs-examples

docs-html:
	bash scripts/setup.sh docs
	$(BIN)/python -m sphinx -b html -W --keep-going -j 1 docs docs/_build/html
	@echo "docs: open docs/_build/html/index.html"

docs-examples:
	bash scripts/setup.sh docs
	$(BIN)/python -m pytest -m docs -q -p no:xdist tests/test_doc_examples.py

# the light, world, sensor and render tests on cuda_ad_spectral (a machine with a CUDA GPU)
test-gpu: setup
	PY=$(BIN)/python bash scripts/test-gpu.sh $(PYTEST_ARGS)

test-all: setup
	$(BIN)/python -m pytest -q --nbmake -m "not docs" tests notebooks $(PYTEST_ARGS)

bench: setup
	$(BIN)/python benchmarks/photon_throughput.py
	$(BIN)/python benchmarks/photon_vs_path.py
	$(BIN)/python benchmarks/moss_run.py
	$(BIN)/python benchmarks/trees_growth.py
	$(BIN)/python benchmarks/trees_nongrowth.py
	$(BIN)/python benchmarks/weber_penn_generation.py
	$(BIN)/python benchmarks/autumn_insolation.py
	$(BIN)/python benchmarks/world_day.py
	$(BIN)/python benchmarks/world_year.py
	$(BIN)/python benchmarks/animate_daily_light.py
	$(BIN)/python benchmarks/validation_page.py
	$(BIN)/python benchmarks/sweep_throughput.py

clean:
	rm -rf out build *.egg-info .pytest_cache docs/_build docs/_gen docs/gallery docs/reference/api \
		docs/reference/plugins
