# Hysteresis pipeline for tendon-sheath mechanisms.
# Every target bootstraps .venv from the pinned requirements.lock on first use.

SHELL := /bin/bash
PYTHON_BOOT ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export PYTHONHASHSEED := 0
# numba caches compiled kernels beside the sources; keep them out of the tree.
export NUMBA_CACHE_DIR := $(CURDIR)/.venv/numba-cache
export MPLBACKEND := Agg

# Extra Hydra overrides for any stage target: make fit ARGS="family=gamma"
ARGS ?=
RUNS ?= data/raw/virtual
REPORT ?= data/reports/discrepancy.json

.PHONY: help venv data generate ingest fit validate report pipeline test bench crash-test ui \
        compensate discrepancy discrepancy-study lint typecheck clean clean-data

help:
	@echo "make pipeline    generate -> ingest -> fit -> validate -> report (virtual rig, local MLflow)"
	@echo "make test        run the test suite"
	@echo "make data        write the 72-run standard virtual campaign under data/raw/virtual/"
	@echo "make ingest      raw runs -> data/processed/ (validated parquet)"
	@echo "make bench       benchmarks -> bench/results.json"
	@echo "make ui          MLflow UI on http://127.0.0.1:5000"
	@echo "make compensate  compensation experiments"
	@echo "make discrepancy RUNS=<dir> REPORT=<file.json>"
	@echo "make discrepancy-study  detection limits and two-effect cases of the discrepancy workflow (~1 h)"

$(STAMP): requirements.lock pyproject.toml
	test -x $(PY) || $(PYTHON_BOOT) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.lock
	# The repository itself goes on sys.path through a .pth file (no build backend needed).
	$(PY) -c 'import site,sys; open(site.getsitepackages()[0]+"/tsm_hysteresis.pth","w").write(sys.argv[1]+"\n")' $(CURDIR)
	touch $(STAMP)

venv: $(STAMP)

data generate: $(STAMP)
	$(PY) -m pipelines.generate $(ARGS)

ingest: $(STAMP)
	$(PY) -m pipelines.ingest $(ARGS)

fit: $(STAMP)
	$(PY) -m pipelines.fit $(ARGS)

validate: $(STAMP)
	$(PY) -m pipelines.validate $(ARGS)

report: $(STAMP)
	$(PY) -m pipelines.report $(ARGS)

pipeline: $(STAMP)
	$(PY) -m pipelines.run_all $(ARGS)

test: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadfile

bench: $(STAMP)
	$(PY) -m bench.run --out bench/results.json

# kill -9 every stage at random moments, ROUNDS times, and check each re-run (several minutes)
ROUNDS ?= 5
crash-test: $(STAMP)
	TSM_CRASH_ROUNDS=$(ROUNDS) TSM_CRASH_KILLS=5 $(PY) -m pytest -q -n 0 \
		tests/pipelines/test_crash_recovery.py -k random

ui: $(STAMP)
	$(VENV)/bin/mlflow ui --backend-store-uri sqlite:///$(CURDIR)/mlflow.db --host 127.0.0.1 --port 5000

compensate: $(STAMP)
	$(PY) -m pipelines.compensate $(ARGS)

discrepancy: $(STAMP)
	$(PY) -m pipelines.discrepancy source=$(RUNS) report=$(REPORT) $(ARGS)

discrepancy-study: $(STAMP)
	$(PY) -m pipelines.discrepancy_study $(ARGS)

lint: $(STAMP)
	$(VENV)/bin/ruff check hysteresis rig_io pipelines tests bench

typecheck: $(STAMP)
	$(VENV)/bin/mypy

clean-data:
	rm -rf data/raw/virtual data/processed data/reports data/interim mlflow.db mlartifacts

clean: clean-data
	rm -rf $(VENV) outputs multirun .pytest_cache
