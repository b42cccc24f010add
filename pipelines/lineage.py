"""Dataset lineage in MLflow: every model run names the data it was fitted and scored on.

Each child run (one fitted model) gets MLflow dataset inputs (``MlflowClient.log_inputs``,
what ``mlflow.log_input`` writes), shown in the UI's *Dataset* column and on the run page:

* ``training``: the processed identification run(s) of its configuration,
* ``validation``: the processed held-out runs it was scored on (when validated).

A dataset's **name** says what it is (``<configuration>:<excitations>``, e.g.
``tsm-bench_phi090_r030:sine_decay``); its **digest** is a hash over, per run, the processed
file's content hash and the raw source hash that ingest recorded in ``runs.json``: a run
whose raw data changed is a dataset with the same name and a different digest. Its
**source** is the raw run folder (or bag) it came from; the input tags list the run ids and
their raw hashes, so any metric traces back to the raw runs it was computed from.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pipelines import cache
from pipelines.tracking import finite_or_none as _num

log = logging.getLogger(__name__)

#: MLflow's input-tag key for a dataset's role (shown as the dataset's context in the UI).
CONTEXT_TAG = "mlflow.data.context"
_MAX_TAG = 500  # MLflow's limit on an input tag value


@dataclass(frozen=True)
class RunLineage:
    """Where one processed run came from."""

    run_id: str
    rig: str
    curve_angle_deg: float | None
    radius_mm: float | None
    excitation: str
    n_samples: int
    processed_hash: str
    raw_hash: str
    raw_source: str


def run_lineage(processed: Path, dataset: pd.DataFrame | None = None, *,
                labels: set[str] | None = None) -> dict[str, RunLineage]:
    """Per processed run: configuration, excitation, processed and raw content hashes.

    The processed hash is the hash of the run's parquet file (``samples/<run_id>.parquet``)
    or, for a dataset not in that layout, of its rows; the raw hash and source come from the
    ingest's ``runs.json`` (``unknown`` / the processed folder without one). ``labels``
    limits it to those configurations (a sweep job hashes only its own runs).
    """
    processed = Path(processed)
    index: dict[str, Any] = {}
    runs_json = processed / "runs.json"
    if runs_json.is_file():
        index = dict(json.loads(runs_json.read_text(encoding="utf-8")).get("runs") or {})
    samples = processed / "samples"
    cols = ["run_id", "rig", "curve_angle_deg", "radius_mm", "excitation"]
    if dataset is None:  # per-run files hash themselves; otherwise the rows are hashed
        if samples.is_dir():
            dataset = pd.read_parquet(samples, columns=cols)
        else:
            dataset = pd.read_parquet(processed) if processed.exists() else pd.DataFrame(
                columns=cols)
    out: dict[str, RunLineage] = {}
    for run_id, rows in dataset.groupby("run_id", sort=True, observed=True):
        rid = str(run_id)
        first = rows.iloc[0]
        if labels is not None and _label(str(first["rig"]), _num(first["curve_angle_deg"]),
                                         _num(first["radius_mm"])) not in labels:
            continue
        file = samples / f"{rid}.parquet"
        p_hash = (cache.hash_files([file]) if file.is_file()
                  else cache.hash_frame(rows.reset_index(drop=True)))
        meta = index.get(rid) or {}
        out[rid] = RunLineage(
            run_id=rid, rig=str(first["rig"]), curve_angle_deg=_num(first["curve_angle_deg"]),
            radius_mm=_num(first["radius_mm"]), excitation=str(first["excitation"]),
            n_samples=len(rows), processed_hash=p_hash,
            raw_hash=str(meta.get("source_hash") or "unknown"),
            raw_source=str(meta.get("source_path") or processed))
    return out


def _label(rig: str, phi: float | None, r: float | None) -> str:
    from pipelines.stages import Configuration

    return Configuration(rig, phi, r).label


def dataset_input(runs: Sequence[RunLineage], *, context: str, processed: Path) -> Any:
    """One MLflow ``DatasetInput`` for a set of processed runs of one configuration."""
    from mlflow.entities import Dataset, DatasetInput, InputTag

    runs = sorted(runs, key=lambda r: r.run_id)
    first = runs[0]
    excitations = sorted({r.excitation for r in runs})
    name = f"{_label(first.rig, first.curve_angle_deg, first.radius_mm)}:{'+'.join(excitations)}"
    digest = cache.hash_json([[r.run_id, r.processed_hash, r.raw_hash] for r in runs])
    sources = sorted({r.raw_source for r in runs})
    uri = sources[0] if len(sources) == 1 else _common_parent(sources)
    profile = {"runs": len(runs), "samples": sum(r.n_samples for r in runs),
               "processed": str(processed), "raw_sources": sources[:20]}
    entity = Dataset(name=name, digest=digest, source_type="local",
                     source=json.dumps({"uri": uri}), profile=json.dumps(profile))
    tags = [InputTag(CONTEXT_TAG, context),
            InputTag("run_ids", _fit(",".join(r.run_id for r in runs))),
            InputTag("raw_hashes",
                     _fit(",".join(f"{r.run_id}={r.raw_hash[:16]}" for r in runs))),
            InputTag("processed_hashes",
                     _fit(",".join(f"{r.run_id}={r.processed_hash}" for r in runs)))]
    return DatasetInput(dataset=entity, tags=tags)


def _fit(text: str) -> str:
    return text if len(text) <= _MAX_TAG else text[:_MAX_TAG - 12] + f"...(+{len(text)})"


def _common_parent(paths: Iterable[str]) -> str:
    import os

    try:
        return os.path.commonpath(list(paths))
    except ValueError:
        return ";".join(paths)[:1000]


def log_model_inputs(tracker: Any, run_ids: Sequence[str], fits: pd.DataFrame,
                     metrics: pd.DataFrame | None, *, processed: Path,
                     dataset: pd.DataFrame | None = None,
                     lineage: Mapping[str, RunLineage] | None = None) -> int:
    """Log the training (and, with ``metrics``, validation) datasets of each child run.

    ``run_ids[i]`` is the run logged for ``fits.iloc[i]`` (what ``log_model_runs`` returns).
    Returns the number of dataset inputs logged.
    """
    from pipelines.tracking import retry

    if not run_ids:
        return 0
    if lineage is None:
        wanted = {_label(str(f["rig"]), _num(f["curve_angle_deg"]), _num(f["radius_mm"]))
                  for f in fits.to_dict("records")}
        lineage = run_lineage(processed, dataset, labels=wanted)
    runs = dict(lineage)
    n = 0
    for run_id, fit in zip(run_ids, fits.to_dict("records"), strict=True):
        inputs = []
        train = [runs[r] for r in str(fit.get("fit_run_ids") or "").split(",") if r in runs]
        if train:
            inputs.append(dataset_input(train, context="training", processed=processed))
        held_exc = _heldout_excitations(metrics, fit)
        if held_exc:
            phi, r = _num(fit["curve_angle_deg"]), _num(fit["radius_mm"])
            held = [x for x in runs.values()
                    if x.rig == str(fit["rig"]) and _same(x.curve_angle_deg, phi)
                    and _same(x.radius_mm, r) and x.excitation in held_exc]
            if held:
                inputs.append(dataset_input(held, context="validation", processed=processed))
        if inputs:
            retry(tracker.client.log_inputs, run_id, datasets=inputs)
            n += len(inputs)
    return n


def _same(a: float | None, b: float | None) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and abs(a - b) < 1e-9)


def _heldout_excitations(metrics: pd.DataFrame | None, fit: Mapping[str, Any]) -> set[str]:
    if metrics is None or metrics.empty:
        return set()
    sel = metrics[(metrics["split"] == "heldout") & (metrics["family"] == fit["family"])
                  & (metrics["rig"] == fit["rig"])
                  & (metrics["fit_excitation"] == fit["fit_excitation"])]
    phi, r = _num(fit["curve_angle_deg"]), _num(fit["radius_mm"])
    keep = [_same(_num(a), phi) and _same(_num(b), r)
            for a, b in zip(sel["curve_angle_deg"], sel["radius_mm"], strict=True)]
    return {str(x) for x in sel.loc[keep, "eval_excitation"]}


def log_stage_inputs(tracker: Any, run_id: str, metrics: pd.DataFrame, *, processed: Path,
                     dataset: pd.DataFrame | None = None) -> int:
    """A validate stage's run: per configuration in ``metrics``, the identification data of
    its models (``training``) and the held-out data they were scored on (``validation``)."""
    from pipelines.tracking import retry

    if metrics.empty:
        return 0
    keys = metrics[["rig", "curve_angle_deg", "radius_mm", "fit_excitation"]].drop_duplicates()
    labels = {_label(str(k["rig"]), _num(k["curve_angle_deg"]), _num(k["radius_mm"]))
              for k in keys.to_dict("records")}
    runs = run_lineage(processed, dataset, labels=labels)
    inputs = []
    for k in keys.to_dict("records"):
        phi, r = _num(k["curve_angle_deg"]), _num(k["radius_mm"])
        mine = [x for x in runs.values() if x.rig == str(k["rig"])
                and _same(x.curve_angle_deg, phi) and _same(x.radius_mm, r)]
        sel = metrics[(metrics["split"] == "heldout") & (metrics["rig"] == k["rig"])
                      & (metrics["fit_excitation"] == k["fit_excitation"])]
        held_exc = {str(x) for a, b, x in zip(sel["curve_angle_deg"], sel["radius_mm"],
                                              sel["eval_excitation"], strict=True)
                    if _same(_num(a), phi) and _same(_num(b), r)}
        train = [x for x in mine if x.excitation == str(k["fit_excitation"])]
        held = [x for x in mine if x.excitation in held_exc]
        if train:
            inputs.append(dataset_input(train, context="training", processed=processed))
        if held:
            inputs.append(dataset_input(held, context="validation", processed=processed))
    for i in range(0, len(inputs), 500):
        retry(tracker.client.log_inputs, run_id, datasets=inputs[i:i + 500])
    return len(inputs)


# --------------------------------------------------------------------------------------
# whole-dataset inputs: the pipeline's parent, the discrepancy and compensation runs
# --------------------------------------------------------------------------------------


def processed_input(processed: Path, *, context: str) -> Any:
    """The whole processed dataset at ``processed`` as one ``DatasetInput`` (the pipeline's
    parent run: the unseen-shape study and the report read every run of it). Digest: the
    dataset's content hash; input tags: the run count and the raw folders."""
    from mlflow.entities import Dataset, DatasetInput, InputTag

    from pipelines.common import dataset_hash
    from rig_io.dataset import read_runs

    processed = Path(processed)
    index = read_runs(processed) if processed.is_dir() else {}
    sources = sorted({str(Path(str(m.get("source_path"))).parent) for m in index.values()
                      if m.get("source_path")})
    profile = {"runs": len(index), "processed": str(processed), "raw_folders": sources[:20]}
    entity = Dataset(name=f"{processed.name}:all runs", digest=dataset_hash(processed),
                     source_type="local", source=json.dumps({"uri": str(processed)}),
                     profile=json.dumps(profile))
    return DatasetInput(dataset=entity, tags=[InputTag(CONTEXT_TAG, context),
                                              InputTag("runs", str(len(index))),
                                              InputTag("raw_folders", _fit(",".join(sources)))])


def source_input(source: str | Path, runs: Mapping[str, Mapping[str, Any]], *,
                 context: str) -> Any:
    """The raw runs a stage read straight from ``source`` (the discrepancy workflow ingests
    its source itself): ``runs`` is ingest's run index (``runs.json``) of that source.
    Digest: a hash over (run id, raw source hash) per run, so re-recorded runs differ."""
    from mlflow.entities import Dataset, DatasetInput, InputTag

    src = Path(source).resolve()
    ids = sorted(runs)
    digest = cache.hash_json([[r, str(runs[r].get("source_hash") or "unknown")] for r in ids])
    kinds = sorted({_excitation_name(runs[r].get("excitation")) for r in ids})
    profile = {"runs": len(ids), "excitations": kinds, "source": str(src)}
    entity = Dataset(name=f"{src.name}:{len(ids)} runs", digest=digest, source_type="local",
                     source=json.dumps({"uri": str(src)}), profile=json.dumps(profile))
    tags = [InputTag(CONTEXT_TAG, context), InputTag("run_ids", _fit(",".join(ids))),
            InputTag("raw_hashes", _fit(",".join(
                f"{r}={str(runs[r].get('source_hash') or 'unknown')[:16]}" for r in ids)))]
    return DatasetInput(dataset=entity, tags=tags)


def _excitation_name(value: Any) -> str:
    if isinstance(value, Mapping):
        return str(value.get("name") or value.get("kind") or "?")
    return str(value or "?")


def measured_input(name: str, tables: Mapping[str, pd.DataFrame], *, source: str,
                   context: str, tags: Mapping[str, str] | None = None) -> Any:
    """Data a stage measured itself (the compensation experiments record their closed loops
    on the rig behind ``source``): one ``DatasetInput`` whose digest hashes the recorded
    tables, so a run with other measurements shows another digest."""
    from mlflow.entities import Dataset, DatasetInput, InputTag

    digest = cache.hash_json({k: cache.hash_frame(v.reset_index(drop=True))
                              for k, v in sorted(tables.items())})
    profile = {"tables": {k: len(v) for k, v in sorted(tables.items())}}
    entity = Dataset(name=name, digest=digest, source_type="code",
                     source=json.dumps({"uri": source}), profile=json.dumps(profile))
    return DatasetInput(dataset=entity, tags=[InputTag(CONTEXT_TAG, context),
                                              *(InputTag(k, _fit(str(v)))
                                                for k, v in (tags or {}).items())])


def log_input(tracker: Any, run_ids: Iterable[str | None], dataset: Any) -> None:
    """Log one ``DatasetInput`` on each of ``run_ids`` (what ``mlflow.log_input`` writes)."""
    from pipelines.tracking import retry

    for run_id in run_ids:
        if run_id:
            retry(tracker.client.log_inputs, run_id, datasets=[dataset])


def input_coverage(client: Any, experiment_ids: Sequence[str]) -> tuple[int, int]:
    """(runs that log at least one input dataset, all runs) in ``experiment_ids``."""
    from pipelines.tracking import retry

    runs = list(retry(client.search_runs, list(experiment_ids), max_results=50000))
    with_inputs = sum(1 for r in runs if r.inputs is not None and r.inputs.dataset_inputs)
    return with_inputs, len(runs)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m pipelines.lineage [--store <uri>] [--experiment tsm-hysteresis] [--min 95]``:
    how many runs of the experiment log their input dataset; exit 1 below ``--min`` %."""
    import argparse

    from mlflow import MlflowClient

    ap = argparse.ArgumentParser(prog="python -m pipelines.lineage", description=main.__doc__)
    ap.add_argument("--store", default="sqlite:///mlflow.db", help="tracking URI")
    ap.add_argument("--experiment", default="tsm-hysteresis")
    ap.add_argument("--min", type=float, default=95.0, help="lowest acceptable share in %%")
    args = ap.parse_args(argv)
    client = MlflowClient(tracking_uri=args.store)
    exp = client.get_experiment_by_name(args.experiment)
    if exp is None:
        print(f"no experiment {args.experiment!r} in {args.store}")
        return 1
    n, total = input_coverage(client, [exp.experiment_id])
    share = 100.0 * n / total if total else 0.0
    print(f"{n} of {total} runs log an input dataset ({share:.1f} %)")
    return 0 if share >= args.min else 1


if __name__ == "__main__":
    raise SystemExit(main())
