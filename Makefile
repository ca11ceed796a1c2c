# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint docs venv clean browser

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

test: $(STAMP) browser
	$(BIN)/python -m pytest -q
	$(BIN)/ruff check hexapod vision controllers benchmarks tests
	$(BIN)/mypy

lint: $(STAMP)
	$(BIN)/ruff check hexapod vision controllers benchmarks tests
	$(BIN)/mypy

docs: $(STAMP)
	$(BIN)/sphinx-build -W --keep-going -b html docs/api docs/_build/html

clean:
	rm -rf $(VENV) build *.egg-info
