# The two commands of the README: `make run` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
OUT ?= outputs

.PHONY: run test test-slow lint bench clean

# torch is pinned to the CPU build that the project's machines hold; a looser
# pin would download gigabytes of CUDA packages.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/tactile-braille data
	$(VENV)/bin/tactile-braille show --output $(OUT)/gallery.png
	$(VENV)/bin/tactile-braille show grid-alphabet --output $(OUT)/grid-alphabet.png

test: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

lint: $(STAMP)
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check .

bench: $(STAMP)
	$(PY) benchmarks/activation_map.py
	$(PY) benchmarks/render.py
	$(PY) benchmarks/collect.py
	$(PY) benchmarks/separability.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache
