"""A small processed-format dataset for the pipeline tests (no rig, no ingest needed).

The plant is a smooth backlash: the output creeps towards ``u -/+ b`` with a first-order
approach in input travel, gain ``g``; the backlash half-width ``b`` grows with the curve
angle and, at large angles, with a smaller radius (seed 001 section 3.2.3). It is close to
but not inside the model families, so fits leave a realistic, non-zero error.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

KINDS = ("sine_decay", "triangle_decay", "trapezoid_decay")
AMPS = (6.0, 4.5, 3.0, 1.5)


def excitation(kind: str, *, dt: float, periods: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """(t_s, command) of the seed 001 excitations, shortened to ``periods`` per amplitude."""
    if kind == "sine_decay":
        f = 0.25
        n = int(round(periods / f / dt))
        u = np.concatenate([a * np.sin(2 * np.pi * f * np.arange(n) * dt) for a in AMPS])
    elif kind in ("triangle_decay", "trapezoid_decay"):
        slope, dwell = 6.0, (0.5 if kind == "trapezoid_decay" else 0.0)
        knots_t, knots_u, t = [0.0], [0.0], 0.0
        for a in AMPS:
            for _ in range(periods):
                for target in (a, -a, 0.0):
                    t += abs(target - knots_u[-1]) / slope
                    knots_t.append(t)
                    knots_u.append(target)
                    if dwell and target != 0.0:
                        t += dwell
                        knots_t.append(t)
                        knots_u.append(target)
        tt = np.arange(0.0, t, dt)
        u = np.interp(tt, knots_t, knots_u)
    else:
        raise ValueError(kind)
    return np.arange(u.size) * dt, u


def smooth_backlash(u: np.ndarray, *, half_width: float, gain: float = 0.95,
                    sharpness: float = 4.0) -> np.ndarray:
    y = np.zeros_like(u)
    for k in range(1, u.size):
        du = u[k] - u[k - 1]
        target = gain * (u[k] - np.sign(du) * half_width) if du != 0 else y[k - 1]
        frac = 1.0 - np.exp(-sharpness * abs(du) / max(half_width, 1e-6))
        y[k] = y[k - 1] + frac * (target - y[k - 1]) if du != 0 else y[k - 1]
    return y


def half_width(curve_angle_deg: float, radius_mm: float) -> float:
    return 0.1 + 0.6 * curve_angle_deg / 90.0 + (0.2 * (75.0 - radius_mm) / 45.0
                                                 if curve_angle_deg >= 60 else 0.0)


def make_dataset(
    *,
    angles: Iterable[float] = (15, 90),
    radii: Iterable[float] = (30, 75),
    kinds: Iterable[str] = KINDS,
    dt: float = 0.05,
    periods: int = 2,
    noise: float = 0.005,
    rig: str = "tsm-bench",
    seed: int = 0,
) -> pd.DataFrame:
    """One row per sample with the processed-dataset columns of the ingest contract."""
    rng = np.random.default_rng(seed)
    frames = []
    for phi in angles:
        for r in radii:
            b = half_width(float(phi), float(r))
            for kind in kinds:
                t, u = excitation(kind, dt=dt, periods=periods)
                y = smooth_backlash(u, half_width=b) + noise * rng.normal(size=u.size)
                amp = float(np.max(np.abs(u)))
                run_id = f"phi{int(phi):03d}_r{int(r):03d}_{kind}_0001"
                frames.append(pd.DataFrame({
                    "run_id": run_id, "rig": rig, "curve_angle_deg": float(phi),
                    "radius_mm": float(r), "excitation": kind, "t_s": t, "input": u,
                    "output": y, "input_norm": u / amp, "output_norm": y / amp,
                    "tension_in_n": 5.0 + 0.1 * u, "tension_out_n": 4.0 + 0.05 * y,
                }))
    return pd.concat(frames, ignore_index=True)


def write_dataset(frame: pd.DataFrame, root: Path) -> Path:
    """Write ``frame`` where the stages look for it (``<root>/data/processed/virtual``)."""
    out = root / "data" / "processed" / "virtual"
    out.mkdir(parents=True, exist_ok=True)
    frame.to_parquet(out / "part-0.parquet", index=False)
    return out


def stage_cfg(root: Path, **extra: Any) -> dict[str, Any]:
    """A plain stage config rooted at ``root`` (what Hydra would compose), for tests."""
    paths = {"root": str(root), "raw": f"{root}/data/raw/virtual",
             "processed": f"{root}/data/processed/virtual", "interim": f"{root}/data/interim",
             "models": f"{root}/data/interim/models",
             "predictions": f"{root}/data/interim/predictions", "reports": f"{root}/data/reports"}
    return {"paths": paths, "families": ["linear", "gamma"], "family_overrides": {},
            "config": {"rig": None, "curve_angle_deg": None, "radius_mm": None},
            "fit_excitations": ["sine_decay"], "signals": {"input": "input", "output": "output"},
            "n_jobs": 1, "cache": True, "progress": False, **extra}


def mlflow_store(root: Path) -> Path:
    """An initialised (empty) MLflow SQLite store at ``<root>/mlflow.db``.

    Creating the schema runs every MLflow migration (seconds); tests copy a template made
    once per machine and MLflow version instead.
    """
    import os
    import shutil
    import tempfile

    import mlflow
    from mlflow import MlflowClient

    template = Path(tempfile.gettempdir()) / f"tsm-mlflow-template-{mlflow.__version__}.db"
    if not template.exists():
        fd, tmp_name = tempfile.mkstemp(suffix=".db", dir=template.parent)
        os.close(fd)
        os.unlink(tmp_name)
        MlflowClient(f"sqlite:///{tmp_name}").search_experiments()  # creates the schema
        os.replace(tmp_name, template)
    root.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(template, root / "mlflow.db")
    return root / "mlflow.db"


#: The quick campaign made shorter still: two periods per amplitude, 10 s evaluation runs.
SHORT_CAMPAIGN = [*(f"campaign.excitations.{i}.periods_per_amplitude=2" for i in range(3)),
                  *(f"campaign.excitations.{i}.duration_s=10.0" for i in (3, 4))]


def listed(stage: str, overrides: list[str]) -> str:
    """``overrides.<stage>=['a=1','b=2']`` (each stage override quoted for Hydra's grammar)."""
    return f"overrides.{stage}=[{','.join(repr(o) for o in overrides)}]"


def small_pipeline(root: Path) -> list[str]:
    """``make pipeline``'s overrides for a small run in ``root``: the shortened quick campaign,
    linear and gamma only, small figures."""
    return [f"paths.root={root}", "n_jobs=1", "progress=false",
            listed("generate", ["campaign=quick", "n_jobs=1", "progress=false",
                                *SHORT_CAMPAIGN]),
            listed("ingest", ["progress=false"]),
            listed("fit", ["families=[linear,gamma]"]),
            listed("report", ["plots.dpi=40"])]
