# Two commands do all set-up: `make test` and `make repro` (see README.md).
VENV ?= .venv
PY := $(VENV)/bin/python
PROFILE ?=
TRAIN ?=
SEEDS ?=
NAME ?=

.PHONY: setup test test-fast repro confirm in-home real-diagnostics smoke lint clean-data

setup:
	@bash scripts/setup.sh

## run the test suite (unit tests + papermill smoke runs of every notebook)
test: setup
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" $(PY) -m pytest -q

## unit tests only, no notebooks
test-fast: setup
	$(PY) -m pytest -q -m "not notebooks"

## regenerate every table and figure: dvc repro (profile from params.yaml; PROFILE=smoke to override)
## with the shipped networks (models/<profile>/); TRAIN=1 reruns every stage and trains every network
repro: setup
	@if [ -n "$(PROFILE)" ]; then $(PY) -m semmatch.experiments set-profile $(PROFILE); fi
ifeq ($(TRAIN),1)
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" SEMMATCH_TRAIN=1 $(VENV)/bin/dvc repro --force
else
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" $(VENV)/bin/dvc repro
endif
	$(PY) -m semmatch.experiments readme

## confirmatory run: every evaluation study of the full profile on scenes of fresh seeds, with the
## shipped networks -> figures/confirm/NAME/ (docs/confirm.md); e.g. make confirm SEEDS="9111 9112 9113"
## (IN_HOME=1: the in-home adaptation study in the run's homes too; NOTEBOOKS="...": only these
## notebooks, added to an existing run of the same seeds; the "when transfer pays" study runs too,
## docs/when_transfer_pays.md, unless NOTEBOOKS is given or WHEN_TRANSFER_PAYS=0)
WHEN_TRANSFER_PAYS ?= 1
confirm: setup
	@if [ -z "$(SEEDS)" ]; then echo 'usage: make confirm SEEDS="9111 9112 9113" [NAME=mine] [IN_HOME=1] [NOTEBOOKS="09_adapt_robot_view"] [WHEN_TRANSFER_PAYS=0]' >&2; exit 2; fi
	PATH="$(CURDIR)/$(VENV)/bin:$$PATH" $(PY) -m semmatch.experiments confirm --seeds $(SEEDS) $(if $(NAME),--name $(NAME),) $(if $(IN_HOME),--in-home,) $(if $(NOTEBOOKS),--notebooks $(NOTEBOOKS),$(if $(filter 1,$(WHEN_TRANSFER_PAYS)),--when-transfer-pays,))

## the in-home adaptation study (its plan: semmatch/experiments/in_home_plan.yaml; docs/adapt.md)
in-home: setup
	$(PY) -m semmatch.experiments.in_home $(if $(JOBS),--jobs $(JOBS),)

## diagnostics of the real-like chain on the full profile's development scenes (docs/protocol.md)
real-diagnostics: setup
	$(PY) -m semmatch.experiments.real_diagnostics --profile full $(if $(JOBS),--jobs $(JOBS),)

lint: setup
	$(VENV)/bin/ruff check semmatch tests

clean-data:
	rm -rf data/smoke data/full reports
