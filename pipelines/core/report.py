"""The core of stage ``report`` (no Hydra, no MLflow; its command
is :mod:`pipelines.report`; the command line is in its docstring).

Reads only the other stages' outputs: ``metrics.parquet``, the model files and the
predictions files. Writes under ``${paths.reports}``: ``gamma_weights.parquet|csv``,
``leaderboard.parquet|csv``, ``family_summary.csv``, ``generalisation.csv`` (held-out /
in-sample RMSE per family and excitation), ``plots/*.png``, ``report.md``,
``report.html``. Nothing is redrawn when its inputs are unchanged (``report_key.json``).
"""

from __future__ import annotations

import html
import json
import logging
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hysteresis.play import play_matrix
from pipelines import artifacts, cache, schemas, stages
from pipelines.artifacts import load_models, prediction_path, read_prediction_meta
from pipelines.common import Paths, dataset_hash, dataset_units, hydra_sweep_dir
from pipelines.skeleton import KeyFile
from pipelines.stages import Configuration, PipelineError
from rig_io.atomic import atomic_path, clean_leftovers, contained, write_text_atomic

log = logging.getLogger("pipelines.report")  # the stage's name, as its command logs
KEY_FILE = "report_key.json"


@dataclass
class ReportResult:
    """What the report stage produced (paths are absolute)."""

    reports_dir: Path
    files: list[Path] = field(default_factory=list)
    #: configuration label -> figure files showing it (attached to that configuration's runs)
    config_plots: dict[str, list[Path]] = field(default_factory=dict)
    cached: bool = False
    key: str = ""
    seconds: float = 0.0


# --------------------------------------------------------------------------------------
# the document (Markdown and HTML from the same blocks)
# --------------------------------------------------------------------------------------


class Doc:
    def __init__(self, root: Path) -> None:
        self.root = root
        self.blocks: list[tuple[str, Any]] = []

    def h(self, level: int, text: str) -> None:
        self.blocks.append(("h", (level, text)))

    def p(self, text: str) -> None:
        self.blocks.append(("p", text))

    def headline(self, text: str) -> None:
        """The sentence a reader takes away, first under the title."""
        self.blocks.append(("headline", text))

    def table(self, frame: pd.DataFrame, *, floatfmt: str = ".3g") -> None:
        self.blocks.append(("table", (frame, floatfmt)))

    def img(self, path: Path, caption: str) -> None:
        self.blocks.append(("img", (path.relative_to(self.root).as_posix(), caption)))

    def thumbs(self, items: Sequence[tuple[str, Path]]) -> None:
        """Small images, each linking to its full-size figure, with a caption."""
        self.blocks.append(("thumbs", [(t, p.relative_to(self.root).as_posix())
                                       for t, p in items]))

    def links(self, items: Sequence[tuple[str, Path]]) -> None:
        self.blocks.append(("links", [(t, p.relative_to(self.root).as_posix())
                                      for t, p in items]))

    @staticmethod
    def _cell(v: Any, floatfmt: str) -> str:
        if isinstance(v, (float, np.floating)):
            return "" if v != v else format(float(v), floatfmt)
        if isinstance(v, list):
            return ", ".join(format(x, "g") if isinstance(x, float) else str(x) for x in v)
        return "" if v is None or v is pd.NA else str(v)

    def markdown(self) -> str:
        return "\n".join(line for kind, data in self.blocks for line in _MARKDOWN[kind](data))

    def html(self, title: str) -> str:
        esc = html.escape
        body = [_HTML[kind](data) for kind, data in self.blocks]
        style = ("body{font-family:sans-serif;max-width:1200px;margin:auto;padding:1em}"
                 "table{border-collapse:collapse;font-size:12px;margin:0.5em 0}"
                 "td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}"
                 "img{max-width:100%}figcaption{font-size:12px;color:#555}"
                 ".thumbs{display:flex;flex-wrap:wrap;gap:8px}"
                 ".thumb{margin:0;width:280px}.thumb img{width:280px;border:1px solid #ddd}"
                 ".headline{font-size:1.25em}")
        return (f"<!doctype html><html><head><meta charset='utf-8'><title>{esc(title)}"
                f"</title><style>{style}</style></head><body>{''.join(body)}</body></html>\n")


def _md_table(data: tuple[pd.DataFrame, str]) -> list[str]:
    frame, fmt = data
    cols = [str(c) for c in frame.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join(Doc._cell(v, fmt) for v in row) + " |"
              for row in frame.itertuples(index=False)]
    return [*lines, ""]


def _md_thumbs(data: list[tuple[str, str]]) -> list[str]:
    return [" ".join(f'<a href="{p}"><img src="{p}" width="240" alt="{t}" title="{t}"></a>'
                     for t, p in data) + "\n",
            "\n".join(f"- [{t}]({p})" for t, p in data) + "\n"]


#: Each block kind as Markdown lines.
_MARKDOWN: dict[str, Callable[[Any], list[str]]] = {
    "h": lambda d: [f"{'#' * d[0]} {d[1]}\n"],
    "p": lambda d: [f"{d}\n"],
    "headline": lambda d: [f"**{d}**\n"],
    "table": _md_table,
    "img": lambda d: [f"![{d[1]}]({d[0]})\n\n*{d[1]}*\n"],
    "links": lambda d: ["\n".join(f"- [{t}]({p})" for t, p in d) + "\n"],
    "thumbs": _md_thumbs,
}


def _html_table(data: tuple[pd.DataFrame, str]) -> str:
    esc = html.escape
    frame, fmt = data
    head = "".join(f"<th>{esc(str(c))}</th>" for c in frame.columns)
    rows = "".join("<tr>" + "".join(f"<td>{esc(Doc._cell(v, fmt))}</td>" for v in row)
                   + "</tr>" for row in frame.itertuples(index=False))
    return f"<table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>"


def _html_thumbs(data: list[tuple[str, str]]) -> str:
    esc = html.escape
    items = "".join(f'<figure class="thumb"><a href="{esc(p)}"><img src="{esc(p)}" '
                    f'alt="{esc(t)}" loading="lazy"></a><figcaption>{esc(t)}</figcaption>'
                    "</figure>" for t, p in data)
    return f'<div class="thumbs">{items}</div>'


#: Each block kind as HTML.
_HTML: dict[str, Callable[[Any], str]] = {
    "h": lambda d: f"<h{d[0]}>{_inline_html(html.escape(d[1]))}</h{d[0]}>",
    "p": lambda d: f"<p>{_inline_html(html.escape(d))}</p>",
    "headline": lambda d: (f'<p class="headline" id="headline"><strong>{html.escape(d)}'
                           "</strong></p>"),
    "table": _html_table,
    "img": lambda d: (f'<figure><img src="{html.escape(d[0])}" alt="{html.escape(d[1])}">'
                      f"<figcaption>{html.escape(d[1])}</figcaption></figure>"),
    "links": lambda d: "<ul>" + "".join(f'<li><a href="{html.escape(p)}">{html.escape(t)}'
                                        "</a></li>" for t, p in d) + "</ul>",
    "thumbs": _html_thumbs,
}


def _inline_html(text: str) -> str:
    """The Markdown a paragraph uses (``**bold**``, `` `code` ``) as HTML (text escaped)."""
    text = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", text)
    return re.sub(r"`([^`]+)`", r"<code>\1</code>", text)


# --------------------------------------------------------------------------------------
# the stage
# --------------------------------------------------------------------------------------


def _config_of(row: Mapping[str, Any]) -> Configuration:
    return Configuration(str(row["rig"]), stages._num(row["curve_angle_deg"]),
                         stages._num(row["radius_mm"]))


def pick_exemplary(configs: Sequence[Configuration], wanted: Any) -> Configuration:
    """The configured exemplary shape (:class:`schemas.ExemplaryShape`, or a mapping of its
    fields), else the largest angle with the smallest radius."""
    shape = schemas.settings(schemas.ExemplaryShape, wanted)
    for c in configs:
        if (c.rig == shape.rig and stages._matches(c.curve_angle_deg, [shape.curve_angle_deg])
                and stages._matches(c.radius_mm, [shape.radius_mm])):
            return c
    return sorted(configs, key=lambda c: (-(c.curve_angle_deg or 0), c.radius_mm or 0))[0]


def _write_table(frame: pd.DataFrame, base: Path, *, csv: bool = True) -> list[Path]:
    out = []
    with atomic_path(base.with_suffix(".parquet")) as tmp:
        frame.to_parquet(tmp, index=False)
    out.append(base.with_suffix(".parquet"))
    if csv:
        flat = frame.copy()
        for col in flat.columns:
            if any(isinstance(v, list) for v in flat[col]):
                flat[col] = flat[col].map(json.dumps)
        with atomic_path(base.with_suffix(".csv")) as tmp:
            flat.to_csv(tmp, index=False)
        out.append(base.with_suffix(".csv"))
    return out


def generalisation_table(metrics: pd.DataFrame, *, fit_excitation: str,
                         metric: str = "rmse") -> pd.DataFrame:
    """Held-out / in-sample ``metric`` per family and evaluation excitation.

    For every (family, configuration) model identified on ``fit_excitation``, the ratio of its
    ``metric`` on each held-out excitation to the one on its identification record; then the
    median, min and max over the configurations. A ratio near 1 on an excitation unlike the
    identification record (other amplitudes, random rate) is what generalising means.
    Columns: family, eval_excitation, configurations, median_ratio, min_ratio, max_ratio,
    median_heldout_<metric>, median_fit_<metric>.
    """
    keys = ["family", "rig", "curve_angle_deg", "radius_mm"]
    cols = ["family", "eval_excitation", "configurations", "median_ratio", "min_ratio",
            "max_ratio", f"median_heldout_{metric}", f"median_fit_{metric}"]
    m = metrics[metrics["fit_excitation"] == fit_excitation].copy()
    for col in ("curve_angle_deg", "radius_mm"):
        m[col] = m[col].fillna(-1.0)  # groupby drops NaN keys otherwise
    fit = m[m["split"] == "fit"].groupby(keys, observed=True)[metric].mean().rename("fit")
    held = m[m["split"] == "heldout"][[*keys, "eval_excitation", metric]]
    if fit.empty or held.empty:
        return pd.DataFrame(columns=cols)
    both = held.join(fit, on=keys, how="inner")
    both["ratio"] = both[metric] / both["fit"]
    g = both.groupby(["family", "eval_excitation"], observed=True)
    out = pd.DataFrame({
        "configurations": g.size(), "median_ratio": g["ratio"].median(),
        "min_ratio": g["ratio"].min(), "max_ratio": g["ratio"].max(),
        f"median_heldout_{metric}": g[metric].median(), f"median_fit_{metric}": g["fit"].median(),
    }).reset_index()
    out["family"] = out["family"].astype(str)
    out["eval_excitation"] = out["eval_excitation"].astype(str)
    return out[cols].sort_values(["family", "eval_excitation"]).reset_index(drop=True)


def _plot_configuration(pred_path: Path, out: Path, title: str, fit_excitation: str,
                        dpi: int, max_points: int,
                        units: tuple[str, str] = ("mm", "mm")) -> Path | None:
    from pipelines import plots

    preds = artifacts.read_predictions(pred_path)
    if preds is None or preds.empty:
        return None
    return plots.configuration_figure(preds, out, title=title, fit_excitation=fit_excitation,
                                      dpi=dpi, max_points=max_points, units=units)


@dataclass
class _Inputs:
    """What the report is drawn from (the other stages' outputs)."""

    paths: Paths
    metrics: pd.DataFrame
    fits: pd.DataFrame
    configs: list[Configuration]
    #: configuration label -> the key of its (intact) predictions file, None when missing
    pred_keys: dict[str, Any]
    units: tuple[str, str]
    by_run: pd.DataFrame


def run(settings: Any, *, metrics: pd.DataFrame | None = None,
        fits: pd.DataFrame | None = None) -> ReportResult:
    """Hydra-free core: settings (:class:`schemas.ReportConfig`, or a mapping of its fields)
    in, :class:`ReportResult` out; writes under reports/."""
    start = time.perf_counter()
    s = schemas.settings(schemas.ReportConfig, settings)
    paths = Paths.from_config(s.paths)
    clean_leftovers(paths.reports)  # temporaries of a killed report
    reports = paths.reports
    inputs = _inputs(s, paths, metrics, fits)
    key = _content_key(s, inputs)
    keyfile = KeyFile(reports / KEY_FILE, enabled=s.cache, needs=(reports / "report.md",),
                      with_files=True)
    record = keyfile.hit(key)
    if record is not None:
        log.info("report: up to date (%s)", key)
        return ReportResult(reports, [Path(f) for f in record["files"]],
                            {k: [Path(p) for p in v]
                             for k, v in record.get("config_plots", {}).items()},
                            cached=True, key=key, seconds=time.perf_counter() - start)
    tables = _write_tables(s, inputs)
    figures = _draw_figures(s, inputs)
    config_plots = figures.config_plots
    files = [*tables.written, *figures.files, *(p for _, p in figures.shape_figs)]
    doc = _document(reports, metrics=inputs.metrics, fits=inputs.fits, tables=tables,
                    metric=s.metric, fit_exc=s.fit_excitation, figures=figures,
                    paths=paths, units=inputs.units, by_run=inputs.by_run)
    if "md" in s.formats:
        files.append(write_text_atomic(reports / "report.md", doc.markdown()))
    if "html" in s.formats:
        files.append(write_text_atomic(reports / "report.html",
                                       doc.html("TSM hysteresis pipeline report")))
    keyfile.store(key, files=files,
                  config_plots={k: [str(p) for p in v] for k, v in config_plots.items()})
    seconds = time.perf_counter() - start
    log.info("report: %d files in %.1f s -> %s", len(files), seconds, reports / "report.md")
    return ReportResult(reports, files, config_plots, cached=False, key=key, seconds=seconds)


def _inputs(s: schemas.ReportConfig, paths: Paths, metrics: pd.DataFrame | None,
            fits: pd.DataFrame | None) -> _Inputs:
    """The metrics (given, or validate's file), the fits of the report's excitation, the
    keys of the intact predictions, the units and the per-run scores."""
    if metrics is None:
        metrics = artifacts.read_metrics(paths.reports)
        if metrics is None:
            raise PipelineError(f"{paths.metrics_parquet} does not exist; run `make validate`")
    if metrics.empty:
        raise PipelineError("the metrics table is empty: nothing to report")
    configs = sorted({_config_of(r) for r in metrics.to_dict("records")},
                     key=lambda c: (c.rig, c.curve_angle_deg or -1, c.radius_mm or -1))
    if fits is None:
        fits = load_models(paths.models)
    labels = {c.label for c in configs}
    fits = fits[fits.apply(lambda r: _config_of(r).label in labels, axis=1)
                if not fits.empty else []]
    fits = fits[fits["fit_excitation"] == s.fit_excitation].reset_index(drop=True)
    # Only predictions whose bytes match their recorded hash are drawn (and keyed): a damaged
    # file is left out of the figures instead of passing for the one validate wrote.
    pred_keys = {c.label: (read_prediction_meta(prediction_path(paths.predictions, c)) or {})
                 .get("key") for c in configs}
    by_run = artifacts.read_metrics(paths.reports, artifacts.METRICS_BY_RUN)
    if by_run is None:
        by_run = pd.DataFrame()
    return _Inputs(paths, metrics, fits, configs, pred_keys, dataset_units(paths.processed),
                   by_run)


def _content_key(s: schemas.ReportConfig, inputs: _Inputs) -> str:
    """What the report is made from: its inputs, its settings and its code."""
    from pipelines import plots

    # The unseen-shape stage's summary, shown when it was written (it runs before the report).
    unseen_csv = inputs.paths.reports / artifacts.UNSEEN_SHAPE_SUMMARY
    keyed = {k: v for k, v in asdict(s).items()
             if k not in ("paths", "tracking", "n_jobs", "cache")}
    return cache.combine({
        "stage": "report", "metrics": cache.hash_frame(inputs.metrics),
        "units": list(inputs.units),
        "by_run": cache.hash_frame(inputs.by_run) if not inputs.by_run.empty else "",
        "unseen_shape": cache.hash_files([unseen_csv]) if unseen_csv.exists() else "",
        "models": sorted(inputs.fits["key"].astype(str)), "predictions": inputs.pred_keys,
        "settings": keyed,
        "code": cache.hash_files([Path(__file__), Path(plots.__file__)]),
    })


@dataclass
class _Tables:
    gamma: pd.DataFrame
    board: pd.DataFrame
    summary: pd.DataFrame
    general: pd.DataFrame
    written: list[Path] = field(default_factory=list)


def _write_tables(s: schemas.ReportConfig, inputs: _Inputs) -> _Tables:
    """Gamma weights, leaderboard, family summary and the generalisation table."""
    reports, metrics = inputs.paths.reports, inputs.metrics
    files: list[Path] = []
    gamma = stages.gamma_weights_table(inputs.fits, metrics)
    files += _write_table(gamma, reports / "gamma_weights")
    board = stages.leaderboard(metrics[metrics["fit_excitation"] == s.fit_excitation],
                               metric=s.metric)
    files += _write_table(board, reports / "leaderboard")
    summary = stages.family_summary(board, metric=s.metric) if not board.empty else board
    with atomic_path(reports / "family_summary.csv") as tmp:
        summary.to_csv(tmp, index=False)
    files.append(reports / "family_summary.csv")
    general = generalisation_table(metrics, fit_excitation=s.fit_excitation, metric=s.metric)
    with atomic_path(reports / "generalisation.csv") as tmp:
        general.to_csv(tmp, index=False)
    files.append(reports / "generalisation.csv")
    return _Tables(gamma, board, summary, general, files)


@dataclass
class _Figures:
    exemplary: Configuration
    elementary: Path | None
    #: the per-configuration figures and the elementary one, in the order drawn
    files: list[Path] = field(default_factory=list)
    config_plots: dict[str, list[Path]] = field(default_factory=dict)
    shape_figs: list[tuple[str, Path]] = field(default_factory=list)


def _draw_figures(s: schemas.ReportConfig, inputs: _Inputs) -> _Figures:
    """Each configuration's figure, the exemplary one's elementary operators, and the error
    over the shapes."""
    paths, fit_exc = inputs.paths, s.fit_excitation
    plots_dir = paths.reports / "plots"
    dpi, max_points, units = s.plots.dpi, s.plots.max_points, inputs.units
    jobs = _configuration_jobs(s, inputs) if s.plots.per_configuration else []
    n_jobs = 1 if hydra_sweep_dir() is not None else s.n_jobs
    if n_jobs > 1 and len(jobs) > 1:
        from joblib import Parallel, delayed

        made = Parallel(n_jobs=n_jobs)(delayed(_plot_configuration)(
            p, o, t, fit_exc, dpi, max_points, units) for _, p, o, t in jobs)
    else:
        made = [_plot_configuration(p, o, t, fit_exc, dpi, max_points, units)
                for _, p, o, t in jobs]
    config_plots: dict[str, list[Path]] = {}
    files: list[Path] = []
    for (label, *_), path in zip(jobs, made, strict=True):
        if path is not None:
            config_plots.setdefault(label, []).append(path)
            files.append(path)
    exemplary = pick_exemplary(inputs.configs, s.exemplary)
    figures = _Figures(exemplary, _elementary_plot(inputs.fits, exemplary, paths, fit_exc,
                                                   plots_dir, dpi, max_points, units),
                       files, config_plots)
    if figures.elementary is not None:
        figures.files.append(figures.elementary)
        figures.config_plots.setdefault(exemplary.label, []).append(figures.elementary)
    figures.shape_figs = _shape_figures(s, inputs.metrics, plots_dir)
    return figures


def _configuration_jobs(s: schemas.ReportConfig, inputs: _Inputs
                        ) -> list[tuple[str, Path, Path, str]]:
    """(label, predictions file, figure file, title) of every configuration with intact
    predictions."""
    jobs = []
    for c in inputs.configs:
        if inputs.pred_keys[c.label] is None:
            continue
        out = contained(inputs.paths.reports / "plots", f"config_{c.label}.png")
        title = (f"{c.rig}  phi={c.curve_angle_deg:g} deg  r={c.radius_mm:g} mm"
                 if c.curve_angle_deg is not None and c.radius_mm is not None else c.label)
        jobs.append((c.label, prediction_path(inputs.paths.predictions, c), out, title))
    return jobs


def _shape_figures(s: schemas.ReportConfig, metrics: pd.DataFrame, plots_dir: Path
                   ) -> list[tuple[str, Path]]:
    """Error against curve angle and radius: heatmaps (held-out metric, in-sample SSE) and
    lines of the held-out metric."""
    from pipelines import plots

    metric, dpi = s.metric, s.plots.dpi
    sub = metrics[metrics["fit_excitation"] == s.fit_excitation]
    shape_figs = []
    for split, m in (("heldout", metric), ("fit", "sse")):
        fig = plots.shape_heatmaps(sub, plots_dir / f"heatmap_{split}_{m}.png", metric=m,
                                   split=split, title=f"{split} {m} vs curve angle and radius",
                                   dpi=dpi)
        if fig is not None:
            shape_figs.append((f"{split} {m} over curve angle x radius", fig))
    line = plots.error_vs_shape_lines(sub, plots_dir / f"lines_heldout_{metric}.png",
                                      metric=metric, split="heldout",
                                      title=f"held-out {metric} vs curve angle", dpi=dpi)
    if line is not None:
        shape_figs.append((f"held-out {metric} vs curve angle, one line per radius", line))
    return shape_figs


def _elementary_plot(fits: pd.DataFrame, config: Configuration, paths: Paths, fit_exc: str,
                     plots_dir: Path, dpi: int, max_points: int,
                     units: tuple[str, str] = ("mm", "mm")) -> Path | None:
    """Seed 001 Fig. 4.12 for the exemplary configuration's Gamma model."""
    from pipelines import plots

    rows = fits[(fits["family"] == "gamma") & fits["model_json"].notna()
                & (fits.apply(lambda r: _config_of(r).label == config.label, axis=1))]
    pred_path = prediction_path(paths.predictions, config)
    if rows.empty or not cache.digest_matches(pred_path):
        return None
    model = stages.load_model(str(rows.iloc[0]["model_json"]))
    preds = artifacts.read_predictions(pred_path)
    if preds is None:
        return None
    sub = preds[(preds["family"].astype(str) == "gamma")
                & (preds["eval_excitation"].astype(str) == fit_exc)
                & (preds["fit_excitation"].astype(str) == fit_exc)]
    if sub.empty:
        return None
    sub = sub[sub["run_id"] == sub["run_id"].iloc[0]]
    u = sub["input"].to_numpy(dtype=np.float64)
    q = np.asarray(getattr(model, "weights_", []), dtype=np.float64).ravel()
    p = np.asarray(getattr(model, "thresholds_", []), dtype=np.float64).ravel()
    if q.size == 0 or q.size != p.size:
        return None
    design = getattr(model, "design_matrix", None)
    ops = np.asarray(design(u)) if callable(design) else play_matrix(u, p, np.zeros(p.size))[0]
    return plots.elementary_figure(
        sub["t_s"].to_numpy(), u, sub["output"].to_numpy(), ops[:, :q.size], q, p,
        contained(plots_dir, f"elementary_{config.label}.png"),
        title=f"Weighted elementary operators q_i gamma_i of Gamma, {config.label} "
              f"({fit_exc}; seed 001 Fig. 4.12)", dpi=dpi, max_points=max_points, units=units)


def _document(root: Path, *, metrics: pd.DataFrame, fits: pd.DataFrame, tables: _Tables,
              metric: str, fit_exc: str, figures: _Figures, paths: Paths,
              units: tuple[str, str] = ("mm", "mm"),
              by_run: pd.DataFrame | None = None) -> Doc:
    doc = Doc(root)
    unit = units[1]
    n_cfg = metrics.groupby(["rig", "curve_angle_deg", "radius_mm"], dropna=False).ngroups
    doc.h(1, "TSM hysteresis pipeline report")
    doc.headline(stages.headline(tables.summary, metric=metric, unit=unit))
    doc.p(f"{metrics['family'].nunique()} families x {n_cfg} configurations; identification "
          f"excitation `{fit_exc}`; {len(metrics)} metric rows "
          f"(`metrics.parquet`, `metrics.csv`). Dataset hash `{dataset_hash(paths.processed)}`."
          f" Ranking metric: mean held-out {metric}. Input in {units[0]}, output in {unit}.")
    doc.h(2, "Families over all configurations")
    doc.table(with_units(tables.summary, unit))
    if by_run is not None and not by_run.empty:
        _per_run_section(doc, by_run, metric=metric, unit=unit)
    _generalisation_section(doc, tables.general, metric=metric, fit_exc=fit_exc, unit=unit)
    _unseen_shape_section(doc, paths, unit=unit)
    _leaderboard_section(doc, tables.board, metric=metric, unit=unit)
    doc.h(2, "Table 4.1 equivalent: Gamma weights Q and SSE per configuration")
    doc.p(f"{_gamma_constraint_text(fits)} SSE on the identification record(s) at the rig's "
          f"sample rate, in {unit}^2 (`gamma_weights.parquet`).")
    if not tables.gamma.empty:
        doc.p(f"Weights are printed to 3 decimals (in {unit} of output per {units[0]} of "
              "input): a weight below 0.0005 is a solver's zero, not a finding.")
        doc.table(gamma_table(tables.gamma, units))
    _cross_section(doc, metrics, metric=metric, unit=unit)
    _figures_sections(doc, figures, tables.board, metric=metric, unit=unit)
    _failures_section(doc, fits, paths, unit=unit)
    return doc


def _generalisation_section(doc: Doc, general: pd.DataFrame, *, metric: str, fit_exc: str,
                            unit: str) -> None:
    if general.empty:
        return
    doc.h(2, f"Held-out / in-sample {metric} per family and excitation")
    doc.p(f"Each model's {metric} on an excitation it was not identified on, divided by its "
          f"{metric} on its own `{fit_exc}` record (median, min, max over the "
          "configurations; `generalisation.csv`). `mixed_sine` (seed 001 eq. 4.11 at "
          "other amplitudes) and `band_random` (non-periodic, drifting amplitude and rate) "
          "are evaluation-only: a ratio near 1 there means the model generalises.")
    doc.table(with_units(general, unit))


def _unseen_shape_section(doc: Doc, paths: Paths, *, unit: str) -> None:
    unseen = artifacts.read_unseen_shape_summary(paths.reports)
    if unseen.empty:
        return
    doc.h(2, "Shapes no model was fitted on (leave-one-configuration-out)")
    doc.p("Median RMSE (mm) over the configurations of each one's evaluation runs, predicted "
          "by its own model, by the nearest other configuration's model, and by the "
          "shape-aware model fitted without it (`unseen_shape.parquet`, "
          "`docs/unseen-shape.md`). Targets: shape-aware / own <= 1.15 and shape-aware "
          "below nearest in >= 20 of 24 configurations.")
    doc.table(with_units(unseen, unit, also=("median_own", "median_nearest",
                                             "median_shape_aware")))
    fig = paths.reports / "plots" / "unseen_shape.png"
    if fig.exists():
        doc.img(fig, "Leave-one-configuration-out RMSE per configuration")


def _leaderboard_section(doc: Doc, board: pd.DataFrame, *, metric: str, unit: str) -> None:
    doc.h(2, f"Leaderboard per configuration (held-out {metric}, winner in the last column)")
    if board.empty:
        return
    wide = board.pivot_table(index=["rig", "curve_angle_deg", "radius_mm"],
                             columns="family", values=f"heldout_{metric}",
                             dropna=False, observed=True)
    winners = (board[board["rank"] == 1].groupby(["rig", "curve_angle_deg", "radius_mm"],
                                                 dropna=False)["family"]
               .agg(lambda s: "/".join(sorted(s))))
    wide["best"] = winners
    wide.columns = [f"{c} [{unit}]" if c != "best" else c for c in wide.columns]
    doc.table(with_units(wide.reset_index(), unit))


def _cross_section(doc: Doc, metrics: pd.DataFrame, *, metric: str, unit: str) -> None:
    if metrics["fit_excitation"].nunique() <= 1:
        return
    doc.h(2, f"Cross-excitation matrix (mean {metric} over the configurations)")
    doc.p("Rows: the model's identification excitation; columns: the evaluated one.")
    cross = metrics.pivot_table(index=["family", "fit_excitation"],
                                columns="eval_excitation", values=metric, aggfunc="mean",
                                observed=True)
    cross.columns = [f"{c} [{unit}]" for c in cross.columns]
    doc.table(cross.reset_index())


def _figures_sections(doc: Doc, figures: _Figures, board: pd.DataFrame, *, metric: str,
                      unit: str) -> None:
    doc.h(2, "Error against curve angle and radius")
    for caption, fig in figures.shape_figs:
        doc.img(fig, caption)
    exemplary, elementary = figures.exemplary, figures.elementary
    doc.h(2, f"Exemplary configuration {exemplary.label}")
    for fig in figures.config_plots.get(exemplary.label, []):
        if fig != elementary:
            doc.img(fig, f"Measured vs the best family, every family's residual, and the loop "
                         f"({exemplary.label})")
    if elementary is not None:
        doc.img(elementary, "Weighted elementary operators of Gamma (seed 001 Fig. 4.12)")
    doc.h(2, "Every configuration")
    doc.p("Each configuration's figure: measured output and the best family, every family's "
          "residual with its RMSE, and the best family's loop (click for full size).")
    doc.thumbs([(_thumb_caption(label, board, metric, unit), figs[0])
                for label, figs in sorted(figures.config_plots.items()) if figs])


def _failures_section(doc: Doc, fits: pd.DataFrame, paths: Paths, *, unit: str) -> None:
    failed = fits[fits["error"].notna()] if "error" in fits else fits.iloc[0:0]
    errors_file = paths.reports / "validate_errors.json"
    val_errors = json.loads(errors_file.read_text()) if errors_file.exists() else []
    if not len(failed) and not val_errors:
        return
    doc.h(2, "Failures")
    if len(failed):
        doc.table(with_units(failed[["family", "rig", "curve_angle_deg", "radius_mm",
                                     "error"]], unit))
    for e in val_errors:
        doc.p(f"validate: {e}")


#: Metric columns in the output's unit (the others are counts, ranks or ratios).
_UNIT_METRICS = ("rmse", "mean_abs_error", "std_error", "error_range", "mean_error",
                 "max_abs_error")


#: Shape columns and their readable headers (the unit is the geometry's, not the signal's).
_SHAPE_HEADERS = {"curve_angle_deg": "curve angle [deg]", "radius_mm": "radius [mm]"}


def with_units(frame: pd.DataFrame, unit: str, *, also: Sequence[str] = ()) -> pd.DataFrame:
    """``frame`` with the unit in the header of every column that carries one (``also``:
    more columns in the output's unit); the shape columns read ``curve angle [deg]``."""
    def name(col: str) -> str:
        if col in _SHAPE_HEADERS:
            return _SHAPE_HEADERS[col]
        if col in also:
            return f"{col} [{unit}]"
        if col.endswith("sse") or col.endswith("_mse") or col == "mse":
            return f"{col} [{unit}^2]"
        if any(col == m or col.endswith("_" + m) for m in _UNIT_METRICS):
            return f"{col} [{unit}]"
        return col

    return frame.rename(columns={c: name(str(c)) for c in frame.columns})


def gamma_table(gamma: pd.DataFrame, units: tuple[str, str]) -> pd.DataFrame:
    """The Table 4.1 equivalent as printed: weights rounded to 3 decimals (a solver's
    1e-17 is a zero), units in every header."""
    out = gamma.drop(columns=[c for c in ("thresholds", "fit_excitation") if c in gamma])
    ratio = f"{units[1]}/{units[0]}"
    weights = [c for c in out.columns if re.fullmatch(r"q\d+", str(c))] + ["weights_sum"]
    for col in weights:
        if col in out:
            out[col] = out[col].astype(float).round(3) + 0.0  # + 0.0: no "-0"
    out = out.rename(columns={c: f"{c} [{ratio}]" for c in weights if c in out})
    return with_units(out, units[1])


def _thumb_caption(label: str, board: pd.DataFrame, metric: str, unit: str) -> str:
    """``90°/30 mm: gamma 0.093 mm`` (the configuration's winner and its held-out score)."""
    col = f"heldout_{metric}"
    rows = board[(board["rank"] == 1)] if "rank" in board else board.iloc[0:0]
    for r in rows.to_dict("records"):
        c = _config_of(r)
        if c.label == label and col in r and r[col] == r[col]:
            from pipelines.tracking import shape_text

            shown = "" if unit in ("?", "") else f" {unit}"
            return f"{shape_text(c)}: {r['family']} {float(r[col]):.2g}{shown}"
    return label


def _per_run_section(doc: Doc, by_run: pd.DataFrame, *, metric: str, unit: str) -> None:
    """Each held-out run scored on its own (a paper's per-file table), when there are few
    enough runs to read them one by one."""
    held = by_run[by_run["split"] == "heldout"]
    if held.empty or held["run_id"].nunique() > 30:
        return
    doc.h(2, f"Held-out runs one by one ({metric.upper()} [{unit}])")
    doc.p(f"Every held-out run predicted from rest by each family (`metrics_by_run.csv`); the "
          f"last rows are the mean over the runs and the largest absolute error in {unit}.")
    wide = held.pivot_table(index="run_id", columns="family", values=metric, aggfunc="mean",
                            observed=True)
    worst = held.pivot_table(index="run_id", columns="family", values="max_abs_error",
                             aggfunc="max", observed=True)
    wide.loc["mean over runs"] = wide.mean()
    wide.loc["largest abs error"] = worst.max()
    wide.columns = [f"{c} [{unit}]" for c in wide.columns]
    doc.table(wide.reset_index())


def _gamma_constraint_text(fits: pd.DataFrame) -> str:
    """What the Gamma weights of this report were constrained to, from the fits' settings."""
    rows = fits[fits["family"] == "gamma"] if "family" in fits else fits.iloc[0:0]
    seen = set()
    for text in rows.get("params_json", pd.Series(dtype=object)).dropna():
        try:
            seen.add(str(json.loads(str(text)).get("constraint", "nonneg")))
        except (json.JSONDecodeError, AttributeError):
            continue
    said = {"nonneg": "non-negative (Q >= 0) with a free output offset; sum(Q) is the "
                      "loop's outer slope (output per input), not 1",
            "sum_to_one": "under sum(Q) = 1 (seed 001 eq. 4.10 as its text means it)",
            "free": "by ordinary least squares (any sign)",
            "auto": "as each record decides (constraint=auto: Q >= 0 with a free offset, or "
                    "free weights where they predict the record's last 30 % clearly better)"}
    if not seen:
        return "Weights Q of the Gamma operators."
    return "Weights identified " + "; ".join(said.get(c, c) for c in sorted(seen)) + "."


def log_report(tracker: Any, run_id: str, result: ReportResult) -> None:
    """Report files and tables onto a run (the pipeline's parent run or a report run)."""
    reports = result.reports_dir
    for name in ("gamma_weights", "leaderboard"):
        path = reports / f"{name}.parquet"
        if path.exists():
            tracker.log_table(run_id, pd.read_parquet(path).assign(
                **({"thresholds": lambda d: d["thresholds"].map(
                    lambda v: json.dumps(list(v)))} if name == "gamma_weights" else {})),
                f"tables/{name}.json")
    for f in result.files:
        if f.suffix in (".md", ".html", ".csv"):
            tracker.log_artifact(run_id, f, "report")
        elif f.suffix == ".png":
            tracker.log_artifact(run_id, f, "report/plots")
