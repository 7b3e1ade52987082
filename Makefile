# Two commands do all set-up: `make test` and `make repro` (see README.md).
VENV ?= .venv
PY := $(VENV)/bin/python
PROFILE ?=

.PHONY: setup test test-fast repro smoke lint clean-data

setup:
	@bash scripts/setup.sh

## run the test suite (unit tests + papermill smoke runs of every notebook)
test: setup
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" $(PY) -m pytest -q

## unit tests only, no notebooks
test-fast: setup
	$(PY) -m pytest -q -m "not notebooks"

## regenerate every table and figure: dvc repro (profile from params.yaml; PROFILE=smoke to override)
repro: setup
	@if [ -n "$(PROFILE)" ]; then $(PY) -m semmatch.experiments set-profile $(PROFILE); fi
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" $(VENV)/bin/dvc repro
	$(PY) -m semmatch.experiments readme

lint: setup
	$(VENV)/bin/ruff check semmatch tests

clean-data:
	rm -rf data/smoke data/full reports
