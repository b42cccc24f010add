"""The real tendon-catheter runs against the published network, by the authors' protocol.

Data: ``../shared/real-data/tendon-catheter`` (Wang et al., ISMR 2024; ``TSM_SHARED_DIR`` if
the shared folder lives elsewhere), read in place. The pipeline runs as a user types it,
``python -m pipelines.run_all importer=tendon_catheter source=<folder>``, into a temporary
root: every family identified jointly on data_1_1..5 (each run from its own start), every
data_2 run predicted from rest. The score is the authors' own evaluation: every 10th sample,
the first 0.2 s dropped, RMSE in degrees per file, and the largest absolute error. Reference:
their LSTM's checkpoint re-scored the same way (the data's README): 2.67, 1.57, 3.31, 2.66,
2.70 deg (mean 2.58), largest error 6.85 deg.

Two more rows say what the data allows, not what the pipeline does:

* ``per_frequency``: Gamma identified on the data_1 run of the same frequency only (data_2_4
  is a 0.3 Hz run: it takes data_1_3), the configuration-per-condition way of the thesis;
* ``oracle_gamma``: Gamma identified on the five data_2 runs themselves (it sees the test
  data, so no method that identifies on data_1 only is expected to beat it): the floor of one
  rate-independent parameter set on this data;
* ``leave_one_out_gamma``: each data_2 run predicted by Gamma identified on the other four
  data_2 runs (the same excitation type as the test, decaying back to zero): what the test
  runs themselves allow a model to generalise, run to run. data_2_2's output settles about
  4 deg above the other runs after its first unloading, on the same input; no model of the
  input alone predicts that from any other run.

``python -m bench.bench_catheter`` prints the JSON.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
LSTM_RMSE_DEG = {"data_2_1": 2.67, "data_2_2": 1.57, "data_2_3": 3.31, "data_2_4": 2.66,
                 "data_2_5": 2.70}
LSTM_MAX_ABS_DEG = 6.85
#: data_2_k -> the data_1 run of the same frequency (data_2_4 is a 0.3 Hz run)
SAME_FREQUENCY = {"data_2_1": "data_1_1", "data_2_2": "data_1_2", "data_2_3": "data_1_3",
                  "data_2_4": "data_1_3", "data_2_5": "data_1_5"}


def catheter_dir() -> Path:
    shared = Path(os.environ.get("TSM_SHARED_DIR", REPO.parent / "shared"))
    folder = shared / "real-data" / "tendon-catheter"
    if not folder.is_dir():
        raise FileNotFoundError(f"the real catheter runs are not at {folder}; put the lab's "
                                "shared folder beside the repository or set TSM_SHARED_DIR")
    return folder


def protocol(t: np.ndarray, y: np.ndarray, yhat: np.ndarray) -> tuple[float, float]:
    """The authors' evaluation: every 10th sample after the first 0.2 s; (RMSE, max |e|)."""
    keep = np.flatnonzero(t >= 0.2)[::10]
    e = yhat[keep] - y[keep]
    return float(np.sqrt(np.mean(e**2))), float(np.max(np.abs(e)))


def _row(name: str, per_file: dict[str, tuple[float, float]]) -> dict[str, Any]:
    rmse = {k: v[0] for k, v in per_file.items()}
    mean = float(np.mean(list(rmse.values())))
    largest = max(v[1] for v in per_file.values())
    return {"method": name, "rmse_deg": {k: round(v, 3) for k, v in rmse.items()},
            "mean_rmse_deg": round(mean, 3), "largest_abs_error_deg": round(largest, 3),
            "lstm_over_this_mean": round(float(np.mean(list(LSTM_RMSE_DEG.values()))) / mean, 3),
            "lstm_over_this_largest": round(LSTM_MAX_ABS_DEG / largest, 3)}


def pipeline_rows(root: Path, source: Path) -> tuple[list[dict[str, Any]], float]:
    cmd = [sys.executable, "-m", "pipelines.run_all", "importer=tendon_catheter",
           f"source={source}", f"paths.root={root}", "tracking.enabled=false", "progress=false",
           f"hydra.run.dir={root}/outputs"]
    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=1800, cwd=REPO)
    seconds = time.perf_counter() - start
    preds = pd.read_parquet(root / "data" / "interim" / "tendon_catheter" / "predictions"
                            / "bending-joint.parquet")
    rows = []
    for family, g in preds.groupby("family", observed=True):
        per_file = {}
        for run_id, r in g.groupby("run_id", observed=True):
            name = str(run_id).removeprefix("catheter_")
            if name in LSTM_RMSE_DEG:
                per_file[name] = protocol(r["t_s"].to_numpy(), r["output"].to_numpy(),
                                          r["predicted"].to_numpy())
        if len(per_file) == len(LSTM_RMSE_DEG):
            rows.append(_row(f"pipeline default {family} (joint on data_1_*)", per_file))
    return sorted(rows, key=lambda r: r["mean_rmse_deg"]), seconds


def _load(folder: Path, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = pd.read_csv(folder / f"{name}.txt")
    return (d["Time"].to_numpy(float), d["Tendon Disp."].to_numpy(float),
            d["Angle x"].to_numpy(float))


def reference_rows(folder: Path) -> list[dict[str, Any]]:
    from hysteresis import make_family

    held = {k: _load(folder, k) for k in LSTM_RMSE_DEG}
    ident = {k: _load(folder, k) for k in sorted(set(SAME_FREQUENCY.values()))}
    per_freq = {}
    for k, (t, u, y) in held.items():
        _, ui, yi = ident[SAME_FREQUENCY[k]]
        per_freq[k] = protocol(t, y, make_family("gamma").fit(ui, yi).predict(u))
    oracle = make_family("gamma").fit([v[1] for v in held.values()],
                                      [v[2] for v in held.values()])
    floor = {k: protocol(t, y, oracle.predict(u)) for k, (t, u, y) in held.items()}
    loo = {}
    for k, (t, u, y) in held.items():
        rest = [v for j, v in held.items() if j != k]
        model = make_family("gamma").fit([v[1] for v in rest], [v[2] for v in rest])
        loo[k] = protocol(t, y, model.predict(u))
    return [_row("per_frequency gamma (data_1 run of the same frequency)", per_freq),
            _row("oracle_gamma (identified on the data_2 runs themselves)", floor),
            _row("leave_one_out_gamma (identified on the other four data_2 runs)", loo)]


def run() -> dict[str, Any]:
    source = catheter_dir()
    with tempfile.TemporaryDirectory(prefix="tsm-bench-catheter-") as tmp:
        rows, seconds = pipeline_rows(Path(tmp), source)
    ref = reference_rows(source)
    lstm = {"method": "published LSTM (Wang et al. 2024, re-scored)",
            "rmse_deg": LSTM_RMSE_DEG,
            "mean_rmse_deg": round(float(np.mean(list(LSTM_RMSE_DEG.values()))), 3),
            "largest_abs_error_deg": LSTM_MAX_ABS_DEG}
    best = rows[0]
    return {
        "protocol": "identify on data_1_*, test on data_2_*; every 10th sample, first 0.2 s "
                    "dropped; RMSE in deg per file",
        "command": "python -m pipelines.run_all importer=tendon_catheter source=<folder>",
        "pipeline_seconds": round(seconds, 1),
        "rows": [lstm, *rows, *ref],
        "best_default": best["method"],
        "best_default_mean_rmse_deg": best["mean_rmse_deg"],
        "best_default_vs_lstm_mean": best["lstm_over_this_mean"],
        "best_default_vs_lstm_largest": best["lstm_over_this_largest"],
        "target_mean_rmse_deg": 1.29,
    }


if __name__ == "__main__":
    print(json.dumps(run(), indent=1))
