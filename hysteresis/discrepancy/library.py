"""Sparse screen of the forms that are linear in their coefficients.

Many forms of the candidate effects add feature columns to the output (a creep, a viscous
damper, a stretch read off a load cell, a direction- or side-dependent gain, a soft stop): with
their nonlinear parameter on its grid, each is a column, and together they make a library in
which the identification residual is regressed sparsely (orthogonal matching pursuit,
scikit-learn's ``orthogonal_mp``). The screen says which forms explain the residual *together*
(two effects at once show as two columns, where one candidate at a time sees each alone); the
workflow reports it beside every round's ranking. It decides nothing: every candidate is still
refitted jointly with the base and judged on the held-out runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from hysteresis.base import HysteresisError
from hysteresis.discrepancy._ops import FloatArray
from hysteresis.discrepancy.effects import CANDIDATES
from hysteresis.discrepancy.runs import RunData


def library(run: RunData, y_base: FloatArray, names: Sequence[str]
            ) -> list[tuple[str, str, Any, FloatArray]]:
    """Every linear output form's columns on ``run``: ``(effect, form, theta, column)``."""
    cols: list[tuple[str, str, Any, FloatArray]] = []
    for name in names:
        eff = CANDIDATES[name]
        if not eff.available(run):
            continue
        ctx = eff.context(run)
        for theta in eff.grid(run):
            if eff.side_of(theta) != "output" or eff.n_linear_of(theta) == 0:
                continue
            try:
                phi = eff.features(run, theta, y_base, ctx)
            except HysteresisError:
                continue
            f = eff.form(theta)
            for j in range(phi.shape[1]):
                cols.append((name, eff.label(f), theta, phi[:, j]))
    return cols


def screen(run: RunData, residual: FloatArray, y_base: FloatArray, names: Sequence[str], *,
           max_terms: int = 3) -> list[dict[str, Any]]:
    """The library columns that orthogonal matching pursuit picks for ``residual``, in the
    order they enter, each with the share of the residual's variance explained once it is
    in (cumulative). Columns are centred and scaled to unit norm first; a column that does
    not vary is left out."""
    from sklearn.linear_model import orthogonal_mp

    cols = library(run, y_base, names)
    if not cols:
        return []
    x = np.column_stack([c[3] for c in cols])
    x = x - x.mean(axis=0)
    norm = np.linalg.norm(x, axis=0)
    keep = np.flatnonzero(norm > 1e-12 * max(float(norm.max()), 1e-300))
    if keep.size == 0:
        return []
    xs = x[:, keep] / norm[keep]
    r = residual - residual.mean()
    total = float(r @ r)
    if total <= 0:
        return []
    k = int(min(max_terms, keep.size))
    path = np.atleast_2d(orthogonal_mp(xs, r, n_nonzero_coefs=k, return_path=True).T).T
    out: list[dict[str, Any]] = []
    seen: list[int] = []
    for step in range(path.shape[1]):
        new = [int(i) for i in np.flatnonzero(path[:, step]) if int(i) not in seen]
        if not new:
            continue
        seen += new
        fit = xs[:, seen] @ path[seen, step]
        explained = 1.0 - float((r - fit) @ (r - fit)) / total
        for i in new:
            name, form, theta, _ = cols[int(keep[i])]
            out.append({"name": name, "form": form,
                        "theta": [v if isinstance(v, str) else float(v) for v in theta]
                        if isinstance(theta, tuple) else
                        (None if not np.isfinite(theta) else float(theta)),
                        "explained": explained})
    return out
