"""MLflow Model Registry: the best family of each configuration, loadable by name.

After ``make pipeline`` every configuration (rig x curve angle x radius) has one registered
model, ``<prefix>.<configuration label>`` (e.g. ``tsm.tsm-bench_phi090_r030``), whose alias
``champion`` points at the version holding the family with the lowest held-out RMSE. Each
version wraps an MLflow 3 *logged model* (:func:`log_pyfunc`: a pyfunc from code,
``pipelines/pyfunc_model.py``, with a signature whose units are in its metadata and an input
example), the output of the child run of the model it wraps (so the registry links back to
the run, its metrics and its dataset), tagged with the family, the configuration, the
held-out score and metrics, the model key and the processed data hash:

    import mlflow, pandas as pd
    model = mlflow.pyfunc.load_model("models:/tsm.tsm-bench_phi090_r030@champion")
    y = model.predict(pd.DataFrame({"input": u}))["output"].to_numpy()

``predict`` takes a DataFrame with an ``input`` column (optional ``state``: the start state in
its first row, as written by :func:`encode_state`) and returns a DataFrame with ``output``,
exactly the family's own ``predict``. A controller that needs the model object itself (e.g.
its ``invert``) gets it with :func:`load_champion`.

Everything goes through :class:`mlflow.MlflowClient`, so the same code registers into the
local SQLite store and into a shared tracking server.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import json
import logging
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mlflow.pyfunc
import numpy as np
import pandas as pd
from mlflow.pyfunc.model import PythonModel

from hysteresis.base import HysteresisModel, _decode, _encode

log = logging.getLogger(__name__)

ALIAS = "champion"
DEFAULT_PREFIX = "tsm"
#: Held-out metrics copied onto a model version as tags (``heldout.<m>``).
TAG_METRICS = ("rmse", "mean_abs_error", "std_error", "error_range", "sse")


class RegistryError(Exception):
    """No champion where one was asked for, or a model that cannot be registered."""


# --------------------------------------------------------------------------------------
# the pyfunc wrapper
# --------------------------------------------------------------------------------------


def encode_state(state: Any) -> str:
    """A family's state (dataclass, array, tuple, float) as JSON for the ``state`` column."""
    def enc(obj: Any) -> Any:
        if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
            cls = type(obj)
            return {"__state__": f"{cls.__module__}:{cls.__qualname__}",
                    "fields": {f.name: enc(getattr(obj, f.name))
                               for f in dataclasses.fields(obj)}}
        if isinstance(obj, tuple):
            return {"__tuple__": [enc(v) for v in obj]}
        return _encode(obj)

    return json.dumps(enc(state))


def decode_state(text: str) -> Any:
    """The inverse of :func:`encode_state`."""
    def dec(obj: Any) -> Any:
        if isinstance(obj, dict) and "__state__" in obj:
            module, qualname = str(obj["__state__"]).split(":")
            cls: Any = importlib.import_module(module)
            for part in qualname.split("."):
                cls = getattr(cls, part)
            return cls(**{k: dec(v) for k, v in obj["fields"].items()})
        if isinstance(obj, dict) and "__tuple__" in obj:
            return tuple(dec(v) for v in obj["__tuple__"])
        if isinstance(obj, dict) and "__ndarray__" in obj:
            return _decode(obj)
        if isinstance(obj, dict):
            return {k: dec(v) for k, v in obj.items()}
        if isinstance(obj, list):
            return [dec(v) for v in obj]
        return obj

    return dec(json.loads(text))


def predict_frame(model: HysteresisModel, frame: pd.DataFrame) -> pd.DataFrame:
    """What the registered pyfunc's ``predict`` does: ``input`` (+ optional ``state``) in,
    ``output`` out, through the family's own ``predict``."""
    if "input" not in frame.columns:
        raise RegistryError(f"the model input needs an 'input' column, got {list(frame.columns)}")
    u = frame["input"].to_numpy(dtype=np.float64)
    state = None
    if "state" in frame.columns and len(frame) and isinstance(frame["state"].iloc[0], str) \
            and frame["state"].iloc[0]:
        state = decode_state(str(frame["state"].iloc[0]))
    y = model.predict(u) if state is None else model.predict(u, state=state)
    return pd.DataFrame({"output": np.asarray(y, dtype=np.float64)}, index=frame.index)


class HysteresisPyfunc(PythonModel):
    """The registered pyfunc: the model JSON is its one artifact."""

    def load_context(self, context: Any) -> None:
        text = Path(context.artifacts["model_json"]).read_text(encoding="utf-8")
        self.model = HysteresisModel.from_json(text)

    def predict(self, context: Any, model_input: pd.DataFrame,
                params: dict[str, Any] | None = None) -> pd.DataFrame:
        return predict_frame(self.model, pd.DataFrame(model_input))


#: MLflow's switch for its artifact download progress bar.
BAR = "MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR"
#: The models-from-code file MLflow runs to load the pyfunc (``set_model``).
MODEL_CODE = Path(__file__).with_name("pyfunc_model.py")


def model_signature() -> Any:
    """``input`` (and the optional ``state``) in, ``output`` out; the units travel in the
    model's metadata (:func:`signature_metadata`), since a column spec has no unit field."""
    from mlflow.models import ModelSignature
    from mlflow.types import ColSpec, Schema

    return ModelSignature(
        inputs=Schema([ColSpec("double", "input"), ColSpec("string", "state", required=False)]),
        outputs=Schema([ColSpec("double", "output")]))


def signature_metadata(units: tuple[str, str]) -> dict[str, Any]:
    """What each signature column means and its unit (the MLmodel file's ``metadata``)."""
    return {"signature_units": {"input": units[0], "output": units[1], "state": "JSON"},
            "signature_meaning": {
                "input": "proximal (actuator) displacement, one row per sample at the rig rate",
                "state": "optional start state in the first row (encode_state)",
                "output": "predicted distal displacement"}}


def input_example(u: np.ndarray | None = None, n: int = 40) -> pd.DataFrame:
    """A short input for the model's page: ``n`` samples spread over ``u`` (the model's own
    identification input), or a unit triangle when no data is at hand."""
    if u is None or len(u) < 2:
        u = np.concatenate([np.linspace(0, 1, n // 2), np.linspace(1, -1, n - n // 2)])
    idx = np.linspace(0, len(u) - 1, min(n, len(u))).round().astype(int)
    return pd.DataFrame({"input": np.asarray(u, dtype=np.float64)[idx]})


@contextlib.contextmanager
def _store(uri: str) -> Any:
    """MLflow's fluent model logging reads the global tracking URI: point it at ``uri`` for
    the block, then put back what was there (the variable and the environment, which
    ``set_tracking_uri`` also writes)."""
    import os

    from mlflow.tracking._tracking_service import utils

    keys = ("MLFLOW_TRACKING_URI", BAR)
    before, env = utils._tracking_uri, {k: os.environ.get(k) for k in keys}
    mlflow.set_tracking_uri(uri)
    # 24 models each validating its input example would print 24 download bars in the log
    os.environ[BAR] = "false"
    try:
        yield
    finally:
        if before is not None:
            mlflow.set_tracking_uri(before)
        utils._tracking_uri = before
        for key, value in env.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def log_pyfunc(tracker: Any, run_id: str, model_json: str, *, name: str,
               units: tuple[str, str] = ("?", "?"), example: np.ndarray | None = None,
               tags: Mapping[str, str] | None = None, params: Mapping[str, str] | None = None,
               metrics: Mapping[str, float] | None = None) -> str:
    """Log the model as an MLflow 3 *logged model* of ``run_id`` (models-from-code, a
    signature whose units are in the metadata, an input example) and return its model id.

    The logged model is the run's output (the run page and the experiment's *Models* tab
    list it) and carries ``metrics`` (e.g. the held-out RMSE) as its own.
    """
    from mlflow.entities import LoggedModelOutput, Metric

    from pipelines.tracking import retry

    client = tracker.client
    model = retry(client.create_logged_model, tracker.experiment_id, name=name,
                  source_run_id=run_id, tags=dict(tags or {}), params=dict(params or {}),
                  model_type="hysteresis")
    with tempfile.TemporaryDirectory(prefix="tsm-pyfunc-") as tmp, \
            _store(tracker.settings.tracking_uri):
        src = Path(tmp) / "model.json"
        src.write_text(model_json, encoding="utf-8")
        # Explicit requirements: inferring them would load the model in a subprocess.
        retry(mlflow.pyfunc.log_model, name=name, python_model=str(MODEL_CODE),
              artifacts={"model_json": str(src)}, signature=model_signature(),
              input_example=input_example(example), metadata=signature_metadata(units),
              pip_requirements=_requirements(), model_id=model.model_id)
    retry(client.log_outputs, run_id, [LoggedModelOutput(model.model_id, step=0)])
    ts = int(time.time() * 1000)
    values = [Metric(k, float(v), ts, 0, model_id=model.model_id, run_id=run_id)
              for k, v in (metrics or {}).items() if v == v]
    if values:
        retry(client.log_batch, run_id, metrics=values)
    return str(model.model_id)


def _requirements() -> list[str]:
    from importlib.metadata import PackageNotFoundError, version

    out = []
    for dist in ("mlflow", "numpy", "pandas", "scipy", "numba"):
        try:
            out.append(f"{dist}=={version(dist)}")
        except PackageNotFoundError:  # pragma: no cover - all are in requirements.lock
            continue
    return out


# --------------------------------------------------------------------------------------
# choosing and registering champions
# --------------------------------------------------------------------------------------


def registered_name(rig: str, curve_angle_deg: float | None, radius_mm: float | None, *,
                    prefix: str = DEFAULT_PREFIX) -> str:
    """``<prefix>.<configuration label>``: one registered model per rig and configuration."""
    from pipelines.stages import Configuration

    return f"{prefix}.{Configuration(rig, curve_angle_deg, radius_mm).label}"


def choose_champions(fits: pd.DataFrame, metrics: pd.DataFrame, *, metric: str = "rmse",
                     fit_excitation: str | None = None) -> pd.DataFrame:
    """The fit row with the lowest mean held-out ``metric`` per configuration.

    Configurations without held-out rows fall back to the fit split, and their columns say
    so: ``insample.<m>``, never ``heldout.<m>``. Failed fits never win. Adds the
    ``heldout.<m>`` (or ``insample.<m>``) columns (the mean over the evaluation excitations),
    ``score`` and ``score_split``.
    """
    from pipelines.stages import _num

    ok = fits[fits["error"].isna()] if "error" in fits.columns else fits
    if fit_excitation is not None:
        ok = ok[ok["fit_excitation"] == fit_excitation]
    keys = ["family", "rig", "curve_angle_deg", "radius_mm", "fit_excitation"]
    rows = []
    for fit in ok.to_dict("records"):
        sel = metrics[(metrics["family"] == fit["family"]) & (metrics["rig"] == fit["rig"])
                      & (metrics["fit_excitation"] == fit["fit_excitation"])
                      & _same(metrics["curve_angle_deg"], _num(fit["curve_angle_deg"]))
                      & _same(metrics["radius_mm"], _num(fit["radius_mm"]))]
        held = sel[sel["split"] == "heldout"]
        use = held if not held.empty else sel[sel["split"] == "fit"]
        if use.empty:
            continue
        prefix = "heldout" if not held.empty else "insample"
        means = {f"{prefix}.{m}": float(use[m].astype(float).mean())
                 for m in TAG_METRICS if m in use.columns}
        score = float(use[metric].astype(float).mean())
        if score != score:
            continue
        rows.append({**fit, **means, "score": score,
                     "score_split": "heldout" if not held.empty else "fit"})
    if not rows:
        return pd.DataFrame(columns=[*fits.columns, "score"])
    frame = pd.DataFrame(rows)
    frame["_cfg"] = frame.apply(lambda r: registered_name(
        str(r["rig"]), _num(r["curve_angle_deg"]), _num(r["radius_mm"]), prefix=""), axis=1)
    # a held-out score always outranks an in-sample one (a model never judged on unseen data
    # cannot beat one that was)
    frame["_insample"] = frame["score_split"] != "heldout"
    best = (frame.sort_values(["_cfg", "_insample", "score", "family"])
            .groupby("_cfg", sort=True).head(1))
    return (best.drop(columns=["_cfg", "_insample"]).sort_values(keys[1:4])
            .reset_index(drop=True))


def _same(column: pd.Series, value: float | None) -> pd.Series:
    col = pd.to_numeric(column, errors="coerce")
    return col.isna() if value is None else (col - value).abs() < 1e-9


@dataclass(frozen=True)
class Registered:
    name: str
    version: str
    family: str
    run_id: str
    new: bool


def register_champions(tracker: Any, fits: pd.DataFrame, metrics: pd.DataFrame, *,
                       data_hash: str, prefix: str = DEFAULT_PREFIX, alias: str = ALIAS,
                       fit_excitation: str | None = None, units: tuple[str, str] = ("?", "?"),
                       processed: Path | None = None) -> list[Registered]:
    """Register each configuration's champion and point ``alias`` at it.

    The pyfunc goes into the child run already logged for that model (found by its
    ``model_key`` tag). A configuration whose current champion already wraps the same model
    key on the same data is left as it is (a rerun with nothing changed adds no version).
    Processes registering at once add one version per configuration: on a local SQLite
    store the check and the new version are made under a lock of the registered name
    (:func:`pipelines.tracking.key_lock`); on a server an existing version of the same run,
    model key and data is reused instead of made again.
    """
    from pipelines.stages import _num
    from pipelines.tracking import key_lock

    client = tracker.client
    out: list[Registered] = []
    for champ in choose_champions(fits, metrics, fit_excitation=fit_excitation).to_dict(
            "records"):
        name = registered_name(str(champ["rig"]), _num(champ["curve_angle_deg"]),
                               _num(champ["radius_mm"]), prefix=prefix)
        # The alias check and the version it decides on are one step for every process
        # registering into this store: two pipelines at once add one version, not two.
        with key_lock(tracker.settings, name):
            done = _register_one(tracker, client, champ, name, alias=alias,
                                 data_hash=data_hash, units=units, processed=processed)
        if done is not None:
            out.append(done)
    log.info("registry: %d configurations, %d new versions", len(out),
             sum(r.new for r in out))
    return out


def _register_one(tracker: Any, client: Any, champ: Mapping[str, Any], name: str, *,
                  alias: str, data_hash: str, units: tuple[str, str] = ("?", "?"),
                  processed: Path | None = None) -> Registered | None:
    """Point ``alias`` of ``name`` at a version wrapping ``champ``, creating the version only
    when none wraps that model on that data (see :func:`register_champions`)."""
    from mlflow.exceptions import MlflowException

    from pipelines.tracking import retry

    key = str(champ["key"])
    family = str(champ["family"])
    try:
        current = retry(client.get_model_version_by_alias, name, alias)
    except MlflowException:
        current = None
    if current is not None and _wraps(current, key, data_hash):
        return Registered(name, str(current.version), family, str(current.run_id), False)
    runs = tracker.find_runs(f"tags.model_key = '{key}' and tags.kind = 'model'")
    if not runs:
        log.warning("registry: no run logged for model %s (%s); %s not registered",
                    key, family, name)
        return None
    run_id = str(runs[0].info.run_id)
    # Create if absent: a version of this run, model and data made by another process (a
    # server store has no file lock) is reused, not made again.
    existing = [v for v in _versions_of_run(client, name, run_id) if _wraps(v, key, data_hash)]
    if existing:
        first = min(existing, key=lambda v: int(v.version))
        retry(client.set_registered_model_alias, name, alias, first.version)
        _describe_champion(client, name, family, str(first.version),
                           str((first.tags or {}).get("score", "")))
        return Registered(name, str(first.version), family, run_id, False)
    config = name.split(".", 1)[-1]
    score = _score_text(champ, units[1])
    tags = {"family": family, "configuration": config, "model_key": key,
            "dataset_hash": data_hash, "fit_excitation": str(champ["fit_excitation"]),
            "fit_run_ids": str(champ["fit_run_ids"]),
            "score_split": str(champ["score_split"]), "score": score,
            "unit.input": units[0], "unit.output": units[1],
            **{k: repr(float(v)) for k, v in champ.items()
               if k.startswith(("heldout.", "insample.")) and v == v}}
    model_id = log_pyfunc(
        tracker, run_id, str(champ["model_json"]), name=f"{config}-{family}", units=units,
        example=_identification_input(processed, str(champ["fit_run_ids"])),
        tags={k: tags[k] for k in ("family", "configuration", "model_key", "dataset_hash",
                                   "score")},
        params={k: str(v) for k, v in _family_params(champ).items()},
        metrics={k: float(v) for k, v in champ.items()
                 if k.startswith(("heldout.", "insample.")) and v == v})
    try:
        retry(client.create_registered_model, name, tags={
            "rig": str(champ["rig"]), "curve_angle_deg": _tag(champ["curve_angle_deg"]),
            "radius_mm": _tag(champ["radius_mm"])},
            description=f"The best model family of sheath configuration {config} (lowest "
                        "held-out RMSE); alias 'champion' is the current one.")
    except MlflowException as exc:
        if "RESOURCE_ALREADY_EXISTS" not in str(exc) and "already exists" not in str(exc):
            raise
    # the store resolves a models:/ source through the global tracking URI (MLflow 3.17)
    with _store(tracker.settings.tracking_uri):
        version = retry(client.create_model_version, name, f"models:/{model_id}",
                        run_id=run_id, tags=tags, model_id=model_id, description=(
                            f"{family} on {config}, identified on "
                            f"{champ['fit_excitation']}; {score}."))
    retry(client.set_registered_model_alias, name, alias, version.version)
    _describe_champion(client, name, family, str(version.version), score)
    return Registered(name, str(version.version), family, run_id, True)


def _score_text(champ: Mapping[str, Any], unit: str) -> str:
    """``held-out RMSE 0.0591 mm`` (or in-sample, when nothing held out was scored)."""
    split = "held-out" if champ.get("score_split") == "heldout" else "in-sample"
    return f"{split} RMSE {float(champ['score']):.3g} {unit}".rstrip()


def _describe_champion(client: Any, name: str, family: str, version: str, score: str) -> None:
    """The registered model's tags and description name its champion, so the registry's
    model list shows the winning family without opening a version."""
    from pipelines.tracking import retry

    retry(client.set_registered_model_tag, name, "champion_family", family)
    retry(client.set_registered_model_tag, name, "champion_score", score)
    config = name.split(".", 1)[-1]
    retry(client.update_registered_model, name, description=(
        f"Sheath configuration {config}: champion {family} (version {version}, {score}). "
        "The alias 'champion' always points at the family with the lowest held-out RMSE."))


def _family_params(champ: Mapping[str, Any]) -> dict[str, Any]:
    from pipelines.tracking import flatten

    try:
        return flatten(json.loads(str(champ.get("params_json") or "{}")))
    except json.JSONDecodeError:
        return {}


def _identification_input(processed: Path | None, run_ids: str) -> np.ndarray | None:
    """The input of the model's first identification run (for its input example)."""
    if processed is None:
        return None
    for rid in run_ids.split(","):
        file = Path(processed) / "samples" / f"{rid.strip()}.parquet"
        if rid.strip() and file.is_file():
            try:
                u: np.ndarray = pd.read_parquet(file, columns=["input"])["input"].to_numpy(
                    dtype=np.float64)
                return u
            except (OSError, KeyError, ValueError):
                return None
    return None


def _wraps(version: Any, key: str, data_hash: str) -> bool:
    tags = version.tags or {}
    return tags.get("model_key") == key and tags.get("dataset_hash") == data_hash


def _versions_of_run(client: Any, name: str, run_id: str) -> list[Any]:
    from mlflow.exceptions import MlflowException

    from pipelines.tracking import retry

    try:
        return list(retry(client.search_model_versions,
                          f"name = '{name}' and run_id = '{run_id}'"))
    except MlflowException:  # no such registered model yet
        return []


def _tag(value: Any) -> str:
    from pipelines.stages import _num

    v = _num(value)
    return "NA" if v is None else f"{v:g}"


def load_champion(name: str, *, tracking_uri: str, alias: str = ALIAS) -> HysteresisModel:
    """The family object behind ``models:/<name>@<alias>`` (for ``invert``, ``simulate``)."""
    from pipelines.tracking import retry

    mlflow.set_registry_uri(tracking_uri)
    mlflow.set_tracking_uri(tracking_uri)
    try:
        loaded = retry(mlflow.pyfunc.load_model, f"models:/{name}@{alias}")
    except Exception as exc:
        raise RegistryError(f"no model {name}@{alias} in {tracking_uri}: {exc}") from exc
    model = loaded.unwrap_python_model().model
    if not isinstance(model, HysteresisModel):  # pragma: no cover - our own wrapper
        raise RegistryError(f"{name}@{alias} is not a hysteresis model")
    return model


def champion_table(tracker: Any, names: Sequence[str] | None = None, *,
                   prefix: str = DEFAULT_PREFIX, alias: str = ALIAS) -> pd.DataFrame:
    """One row per registered model with its champion version and tags."""
    from pipelines.tracking import retry

    client = tracker.client
    if names is None:
        models = retry(client.search_registered_models, f"name LIKE '{prefix}.%'",
                       max_results=1000)
        names = sorted(m.name for m in models)
    rows: list[Mapping[str, Any]] = []
    for name in names:
        mv = retry(client.get_model_version_by_alias, name, alias)
        rows.append({"name": name, "version": mv.version, "run_id": mv.run_id, **mv.tags})
    return pd.DataFrame(rows)


def register_pipeline(tracker: Any, registry: Any, *, fit_excitation: str,
                      fits: pd.DataFrame | None, metrics: pd.DataFrame | None,
                      processed: Path) -> list[Registered]:
    """``make pipeline``'s last step: register the champions of ``fit_excitation`` when the
    ``tracking.registry`` settings (:class:`pipelines.tracking.RegistryGroup`) ask for it
    and this invocation fitted and validated."""
    from pipelines.common import dataset_hash, dataset_units

    if not tracker.enabled or not registry.enabled or fits is None \
            or metrics is None or fits.empty or metrics.empty:
        return []
    return register_champions(
        tracker, fits, metrics, data_hash=dataset_hash(processed),
        prefix=registry.prefix, alias=registry.alias, fit_excitation=fit_excitation,
        units=dataset_units(processed), processed=processed)
