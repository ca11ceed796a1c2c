# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# every core for the tests (pytest-xdist); JOBS=1 runs them in one process
JOBS ?= auto

.PHONY: demo test quick warm lint docs venv clean browser

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install -e '.[dev,dask]' --config-settings editable_mode=compat
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	rm -rf runs/quick
	$(BIN)/hexapod-bench run quick --out runs/quick --workers 2

# the viewer test drives a real headless browser: found, installed, or a clear message
browser:
	@bash tests/ensure_browser.sh

# compile every C kernel the built-in scenarios use, once, as one visible step
warm: $(STAMP)
	$(BIN)/hexapod-bench warm

# the whole suite on every core (the wall-clock tests alone, after), then the linters:
# CI's command
test: $(STAMP) browser warm
	$(BIN)/python -m pytest -q -n $(JOBS) --dist worksteal --durations=10 -m "not realtime"
	$(BIN)/python -m pytest -q -m realtime
	$(BIN)/ruff check hexapod vision controllers benchmarks tests
	$(BIN)/mypy

# the inner loop of a change: every test not marked slow (nor realtime), under a minute on
# a warm kernel cache (run `make warm` or `make test` once first); an unmarked test over
# 2 s fails it
quick: $(STAMP)
	$(BIN)/python -m pytest -q -n $(JOBS) --dist worksteal -m "not slow and not realtime" \
		--unmarked-budget 2

lint: $(STAMP)
	$(BIN)/ruff check hexapod vision controllers benchmarks tests
	$(BIN)/mypy

docs: $(STAMP)
	$(BIN)/sphinx-build -W --keep-going -b html docs/api docs/_build/html

clean:
	rm -rf $(VENV) build *.egg-info
