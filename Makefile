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

.PHONY: help venv data generate ingest fit validate report pipeline test test-study test-fast bench crash-test ui \
        compensate discrepancy discrepancy-study foreign-example lint typecheck clean clean-data \
        venv-team chromium postgresql cluster-check ui-check team-test bench-cluster \
        docs-figures lineage-check report-check cli-check

help:
	@echo "make pipeline    generate -> ingest -> fit -> validate -> report (virtual rig, local MLflow)"
	@echo "make test        run the test suite"
	@echo "make test-study  the study-size checks: clean-room sets through the discrepancy stage (CI runs it)"
	@echo "make cli-check   the clean-room command-line contract of every stage (CI runs it)"
	@echo "make data        write the 120-run standard virtual campaign under data/raw/virtual/"
	@echo "make ingest      raw runs -> data/processed/ (validated parquet)"
	@echo "make bench       benchmarks -> bench/results.json"
	@echo "make ui          MLflow UI on http://127.0.0.1:5000"
	@echo "make compensate  compensation experiments"
	@echo "make discrepancy RUNS=<dir> REPORT=<file.json>"
	@echo "make pipeline ARGS=\"importer=<mapping> source=<folder>\"  your own logs (docs/foreign-data.md)"
	@echo "make foreign-example  a degree-scale bending joint, one run per shape: pipeline + discrepancy"
	@echo "make discrepancy-study  detection limits and two-effect cases of the discrepancy workflow, checked (4-9 min)"
	@echo "make docs-figures  redraw the README's pictures (docs/img/)"
	@echo "make lineage-check  share of the store's runs that log their input dataset (>= 95 %)"
	@echo "make report-check  report.html in headless chromium: headline, units, no raw Markdown"

$(STAMP): requirements.lock pyproject.toml
	test -x $(PY) || $(PYTHON_BOOT) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.lock
	# The repository itself goes on sys.path through a .pth file (no build backend needed).
	$(PY) -c 'import site,sys; open(site.getsitepackages()[0]+"/tsm_hysteresis.pth","w").write(sys.argv[1]+"\n")' $(CURDIR)
	# compile the numba kernels into the cache once, not in every parallel worker later
	$(PY) -m pipelines.compile_kernels
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

# The clean-room command-line contract (48 command launches, about 95 s of CPU) runs in
# `make cli-check` and in CI's team-test (one process: the module runs its launches in a
# pool), so `make test` stays under 5 minutes on 2 cores;
# tests/pipelines/test_cli*.py check the same guard in-process here.
CLI_CONTRACT := tests/cleanroom/test_cli_contract.py

test: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadfile --no-loadscope-reorder --ignore=tests/team \
	  --ignore=$(CLI_CONTRACT) -m 'not study'

# the study-size checks (clean-room sets through the stage, the study's end-to-end case,
# two ablations; about 100 s of CPU): CI runs them after `make test`, which stays under
# 5 minutes on 2 cores
test-study: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadfile --ignore=tests/team --ignore=$(CLI_CONTRACT) -m study

cli-check: $(STAMP)
	$(PY) -m pytest -q -n 0 -p no:cacheprovider $(CLI_CONTRACT)

# the inner loop: everything but the tests marked slow (simulated campaigns, subprocess kills)
test-fast: $(STAMP)
	$(PY) -m pytest -n 2 -m 'not slow and not study' --ignore=tests/team --ignore=$(CLI_CONTRACT)

bench: $(STAMP)
	$(PY) -m bench.run --out bench/results.json

# kill -9 every stage at random moments, ROUNDS times, and check each re-run (several minutes)
ROUNDS ?= 5
crash-test: $(STAMP)
	TSM_CRASH_ROUNDS=$(ROUNDS) TSM_CRASH_KILLS=9 $(PY) -m pytest -q -n 0 \
		tests/pipelines/test_crash_recovery.py -k random

ui: $(STAMP)
	@echo "runs table: http://127.0.0.1:5000/#/experiments/1?workflowType=machine_learning"
	$(VENV)/bin/mlflow ui --backend-store-uri sqlite:///$(CURDIR)/mlflow.db --host 127.0.0.1 --port 5000

compensate: $(STAMP)
	$(PY) -m pipelines.compensate $(ARGS)

discrepancy: $(STAMP)
	$(PY) -m pipelines.discrepancy source=$(RUNS) report=$(REPORT) $(ARGS)

# the foreign-data example (docs/foreign-data.md): a bending joint logged in degrees, one sine
# run per shape starting mid-stroke, a 0.6 s output lag; nothing tuned for it
foreign-example: $(STAMP)
	$(PY) -m pipelines.run_all +experiment=bending_joint $(ARGS)
	$(PY) -m pipelines.discrepancy source=data/raw/bending \
		report=data/reports/bending/discrepancy.json $(ARGS)

discrepancy-study: $(STAMP)
	$(PY) -m pipelines.discrepancy_study $(ARGS)

# the README's pictures, drawn from the project's own code (small, deterministic, committed)
docs-figures: $(STAMP)
	$(PY) -m pipelines.docs_figures --out docs/img

# share of the local store's runs that log their input dataset; exits 1 below 95 %
lineage-check: $(STAMP)
	$(PY) -m pipelines.lineage --store sqlite:///$(CURDIR)/mlflow.db $(ARGS)

lint: $(STAMP)
	$(VENV)/bin/ruff check hysteresis rig_io pipelines tests bench

typecheck: $(STAMP)
	$(VENV)/bin/mypy

# --- team scale: registry browser check, PostgreSQL + MLflow server + Ray cluster -------------
# Heavy extras (ray, hydra-ray-launcher, psycopg2, playwright) live in requirements-team.lock and
# in their own venv, so .venv and `make test` do not grow. Debian's postgresql and chromium are
# installed with apt-get when missing (playwright drives the system chromium: no browser download).
TEAM_VENV := .venv-team
TEAM_PY := $(TEAM_VENV)/bin/python
TEAM_STAMP := $(TEAM_VENV)/.installed

$(TEAM_STAMP): requirements.lock requirements-team.lock pyproject.toml
	test -x $(TEAM_PY) || $(PYTHON_BOOT) -m venv $(TEAM_VENV)
	$(TEAM_PY) -m pip install --quiet --upgrade pip
	$(TEAM_PY) -m pip install --quiet -r requirements.lock
	$(TEAM_PY) -m pip install --quiet -r requirements-team.lock
	$(TEAM_PY) -m pip check
	$(TEAM_PY) -c 'import site,sys; open(site.getsitepackages()[0]+"/tsm_hysteresis.pth","w").write(sys.argv[1]+"\n")' $(CURDIR)
	touch $(TEAM_STAMP)

venv-team: $(TEAM_STAMP)

chromium:
	@command -v chromium >/dev/null || command -v chromium-browser >/dev/null || \
	  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium; }

postgresql:
	@test -n "$$(ls /usr/lib/postgresql/*/bin/initdb 2>/dev/null)" || command -v initdb >/dev/null || \
	  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends postgresql; }

# The MLflow UI in headless chromium: runs table and a run page of a small pipeline's store;
# screenshot to data/reports/ui/.
ui-check: $(TEAM_STAMP) chromium
	TSM_CHROMIUM="$$(command -v chromium || command -v chromium-browser)" \
	  $(TEAM_PY) -m pytest -q -n 0 -p no:cacheprovider tests/team/test_ui_browser.py

# report.html of a small pipeline in headless chromium: headline, units in every table header,
# thumbnails, no raw Markdown (a part of ui-check)
report-check: $(TEAM_STAMP) chromium
	TSM_CHROMIUM="$$(command -v chromium || command -v chromium-browser)" \
	  $(TEAM_PY) -m pytest -q -n 0 -p no:cacheprovider tests/team/test_ui_browser.py -k report

# The tests that need the team extras: the UI check above and tracking=server against a
# throwaway PostgreSQL + MLflow server (tests/team/test_tracking_server.py). CI runs it.
team-test: $(STAMP) $(TEAM_STAMP) chromium postgresql
	TSM_CHROMIUM="$$(command -v chromium || command -v chromium-browser)" \
	  $(TEAM_PY) -m pytest -q -n 0 -p no:cacheprovider tests/team/test_ui_browser.py \
	  tests/team/test_tracking_server.py
	$(PY) -m pytest -q -n 0 -p no:cacheprovider $(CLI_CONTRACT)

# Throwaway PostgreSQL + MLflow server + Ray head on 127.0.0.1, a 24-job fit sweep through
# hydra's Ray launcher, runs counted in the server: prints `lost N`, exits 0 only for lost 0.
cluster-check: $(TEAM_STAMP) postgresql
	$(TEAM_PY) -m pipelines.cluster_check $(ARGS)

# The same sweep machinery at 100 jobs: Ray launcher vs joblib launcher wall time.
bench-cluster: $(TEAM_STAMP) postgresql
	$(TEAM_PY) -m bench.bench_cluster --out bench/results_cluster.json $(ARGS)

clean-data:
	rm -rf data/raw/virtual data/processed data/reports data/interim mlflow.db mlartifacts

clean: clean-data
	rm -rf $(VENV) $(TEAM_VENV) outputs multirun .pytest_cache
