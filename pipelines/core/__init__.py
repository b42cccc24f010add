"""The stages' cores: typed settings in, tables and figures out (no Hydra, no MLflow).

Each module holds one stage's Hydra-free work (``run``, or ``generate`` / ``ingest``); the
stage's command (``python -m pipelines.<stage>``) is the thin edge beside it, built by
:class:`pipelines.skeleton.Stage`. ``run_all`` drives these cores, never the commands, so no
module imports a stage module (tests/hysteresis/test_import_graph.py).
"""
