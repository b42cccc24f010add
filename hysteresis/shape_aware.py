"""A model for sheath shapes nobody calibrated: a family's parameters as smooth functions of shape.

A tendon-sheath mechanism's hysteresis comes from friction along the sheath. By the capstan
law the tension decays as ``exp(-mu * wrap)`` along the bend, where the total wrap angle is
the curve angle ``theta`` (in rad), and the contact pressure per unit length grows with the
curvature ``1 / R``. So the shape enters the physics through ``theta`` and ``kappa = 1 / R``,
and a family's identified parameters (Gamma's weights, Bouc-Wen's coefficients, ...) change
smoothly with them. :class:`ShapeAwareModel` learns that dependence from models identified on
a set of configurations and hands out a model of the same family for any other one:

* every floating-point fitted attribute (``weights_``, ``offset_``, ``A_`` ...) is regressed,
  element by element, on the features ``theta^a kappa^b`` (``a <= angle_degree``,
  ``b <= curvature_degree``; ridge-regularised least squares on features scaled to [0, 1]),
  or interpolated by a thin-plate radial basis function (``method="rbf"``);
* everything else (integer and boolean attributes, attributes whose shape differs between
  configurations, and attributes equal on every configuration, such as Gamma's shared
  thresholds) is taken from the nearest training configuration.

A family whose fit chooses its structure from the data (Gamma picks its play widths from each
record) gives parameters that do not compare between shapes: the records are then refitted on
one structure (:func:`refit_on_common_structure`: of the family's
:meth:`~hysteresis.base.HysteresisModel.structure_candidates`, the one that fits all the
records best), and fitted models that disagree are refused.

Because the regression is linear in the training values, a linear constraint every training
model satisfies (Gamma's ``sum(Q) = 1``) holds for the predicted model too.

It wears the estimator face of :mod:`hysteresis.base`: ``__init__`` stores hyper-parameters,
``fit(shapes, models)`` sets trailing-underscore attributes, ``predict``/``invert``/``score``
take the shape as keyword arguments, ``to_json``/``from_json`` are lossless. It is not a
registered family (the fit stage must not identify it on one record).
"""

from __future__ import annotations

import json
import math
import warnings
from collections import Counter
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from hysteresis.base import (
    FloatArray,
    HysteresisError,
    HysteresisModel,
    as_1d,
    check_pair,
    make_family,
)

METHODS = ("poly", "rbf")


def shape_features(curve_angle_deg: Any, radius_mm: Any) -> FloatArray:
    """``(n, 2)`` physical shape features: total wrap angle (rad) and curvature (1/mm)."""
    phi = np.atleast_1d(np.asarray(curve_angle_deg, dtype=np.float64))
    r = np.atleast_1d(np.asarray(radius_mm, dtype=np.float64))
    if phi.shape != r.shape or phi.ndim != 1:
        raise HysteresisError(f"curve angles and radii differ in shape: {phi.shape} vs {r.shape}")
    if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(r))) or np.any(r <= 0):
        raise HysteresisError("curve angles must be finite and radii finite and positive, got "
                              f"{phi.tolist()} deg, {r.tolist()} mm")
    return np.column_stack([np.radians(phi), 1.0 / r])


class ShapeAwareModel(HysteresisModel):
    """One model family over every sheath shape (curve angle x radius).

    Parameters
    ----------
    base_family, family_params:
        The family (a registered name) and its hyper-parameters, used when ``fit`` is given
        ``(u, y)`` records to identify; fitted models passed to ``fit`` must be of this family.
    method:
        ``"poly"``: ridge regression on the monomials ``theta^a kappa^b``; ``"rbf"``:
        thin-plate spline interpolation (``rbf_smoothing`` > 0 smooths) in the scaled
        features, linear beyond the training shapes.
    angle_degree, curvature_degree:
        Highest powers of ``theta`` and ``kappa`` in the ``poly`` basis.
    ridge:
        Ridge penalty on the non-constant ``poly`` coefficients (features scaled to [0, 1]).
    rbf_smoothing:
        Smoothing of the ``rbf`` interpolant (0 = exact interpolation).
    """

    family: ClassVar[str] = "shape_aware"

    def __init__(
        self,
        *,
        base_family: str = "gamma",
        family_params: dict[str, Any] | None = None,
        method: str = "poly",
        angle_degree: int = 3,
        curvature_degree: int = 1,
        ridge: float = 1e-3,
        rbf_smoothing: float = 0.0,
    ) -> None:
        self.base_family = base_family
        self.family_params = family_params
        self.method = method
        self.angle_degree = angle_degree
        self.curvature_degree = curvature_degree
        self.ridge = ridge
        self.rbf_smoothing = rbf_smoothing

    # -- identification ---------------------------------------------------------------
    def fit(self, u: Any, y: Any, **fit_params: Any) -> ShapeAwareModel:
        """Learn the shape dependence from ``u``: shapes, ``y``: one model or record each.

        ``u`` is a sequence of ``(curve_angle_deg, radius_mm)``; ``y`` holds, per shape,
        a fitted model of ``base_family`` or a ``(u, y)`` record to identify one on.
        """
        if fit_params:
            raise HysteresisError(f"ShapeAwareModel.fit takes no extra arguments: "
                                  f"{sorted(fit_params)}")
        if self.method not in METHODS:
            raise HysteresisError(f"method must be one of {METHODS}, got {self.method!r}")
        if int(self.angle_degree) < 0 or int(self.curvature_degree) < 0 or self.ridge < 0:
            raise HysteresisError("angle_degree, curvature_degree and ridge must be >= 0")
        shapes = np.asarray(u, dtype=np.float64)
        if shapes.ndim != 2 or shapes.shape[1] != 2:
            raise HysteresisError(f"shapes must be (curve_angle_deg, radius_mm) pairs, got "
                                  f"shape {shapes.shape}")
        items = list(y)
        if len(items) != shapes.shape[0]:
            raise HysteresisError(f"{shapes.shape[0]} shapes but {len(items)} models/records")
        if len(items) < 2:
            raise HysteresisError("need at least two configurations to learn a shape dependence")
        models = [self._model_of(item) for item in items]
        if type(models[0]).structure_candidates(models):
            if any(isinstance(item, HysteresisModel) for item in items):
                raise HysteresisError(
                    f"the {self.base_family} models were fitted with different structures "
                    f"(e.g. Gamma's play widths), so their parameters cannot be regressed on "
                    f"the shape; pass (u, y) records, or refit them with "
                    f"refit_on_common_structure")
            models, _ = refit_on_common_structure(models, [check_pair(*it) for it in items])
        feats = shape_features(shapes[:, 0], shapes[:, 1])
        if np.unique(feats, axis=0).shape[0] != feats.shape[0]:
            raise HysteresisError("a configuration is given twice")
        self.shapes_ = shapes.copy()
        self.models_ = [m.to_dict() for m in models]
        self.feature_min_ = feats.min(axis=0)
        self.feature_span_ = np.where(np.ptp(feats, axis=0) > 0, np.ptp(feats, axis=0), 1.0)
        return self

    def _model_of(self, item: Any) -> HysteresisModel:
        if isinstance(item, HysteresisModel):
            if item.family != self.base_family:
                raise HysteresisError(f"a {item.family!r} model given to a shape-aware "
                                      f"{self.base_family!r} model")
            item.check_fitted()
            return item
        try:
            uu, yy = item
        except (TypeError, ValueError):
            raise HysteresisError("each record must be a fitted model or a (u, y) pair, got "
                                  f"{type(item).__name__}") from None
        uu, yy = check_pair(uu, yy)
        return make_family(self.base_family, **dict(self.family_params or {})).fit(uu, yy)

    # -- the model for a shape ----------------------------------------------------------
    def _scaled(self, feats: FloatArray) -> FloatArray:
        return np.asarray((feats - self.feature_min_) / self.feature_span_, dtype=np.float64)

    def degrees(self) -> tuple[int, int]:
        """The ``poly`` degrees used: as asked, but never more than the training shapes
        resolve (one angle, or one radius, fixes nothing about its dependence)."""
        self.check_fitted()
        n_phi = np.unique(self.shapes_[:, 0]).size
        n_r = np.unique(self.shapes_[:, 1]).size
        return (min(int(self.angle_degree), n_phi - 1), min(int(self.curvature_degree), n_r - 1))

    def _basis(self, x: FloatArray) -> FloatArray:
        deg_phi, deg_kappa = self.degrees()
        cols = [x[:, 0] ** a * x[:, 1] ** b for a in range(deg_phi + 1)
                for b in range(deg_kappa + 1)]
        return np.column_stack(cols)

    def _regress(self, values: FloatArray, x_train: FloatArray, x_new: FloatArray
                 ) -> FloatArray:
        """Values (n_train, k) at the training features -> (k,) at one new feature row."""
        if self.method == "rbf":
            from scipy.interpolate import RBFInterpolator

            rbf = RBFInterpolator(x_train, values, kernel="thin_plate_spline",
                                  smoothing=float(self.rbf_smoothing), degree=1)
            out: FloatArray = np.asarray(rbf(x_new)[0], dtype=np.float64)
            return out
        a = self._basis(x_train)
        if a.shape[1] > a.shape[0] and float(self.ridge) == 0.0:
            raise HysteresisError(f"{a.shape[1]} basis terms but only {a.shape[0]} "
                                  "configurations and no ridge; lower the degrees or set ridge > 0")
        pen = np.full(a.shape[1], math.sqrt(float(self.ridge)))
        pen[0] = 0.0  # the constant is not shrunk
        lhs = np.vstack([a, np.diag(pen)])
        rhs = np.vstack([values, np.zeros((a.shape[1], values.shape[1]))])
        coef, *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
        fitted: FloatArray = np.asarray(self._basis(x_new) @ coef, dtype=np.float64)[0]
        return fitted

    def nearest_index(self, curve_angle_deg: float, radius_mm: float) -> int:
        """Index of the training configuration nearest in the scaled (theta, kappa) plane."""
        self.check_fitted()
        x_new = self._scaled(shape_features(curve_angle_deg, radius_mm))
        x_train = self._scaled(shape_features(self.shapes_[:, 0], self.shapes_[:, 1]))
        return int(np.argmin(np.sum((x_train - x_new) ** 2, axis=1)))

    def model_for(self, curve_angle_deg: float, radius_mm: float) -> HysteresisModel:
        """A fitted model of ``base_family`` for this shape (a fitted shape is reproduced closely,
        not exactly: the regression smooths)."""
        self.check_fitted()
        x_train = self._scaled(shape_features(self.shapes_[:, 0], self.shapes_[:, 1]))
        x_new = self._scaled(shape_features(curve_angle_deg, radius_mm))
        nearest = HysteresisModel.from_dict(self.models_[self.nearest_index(curve_angle_deg,
                                                                            radius_mm)])
        trained = [HysteresisModel.from_dict(d) for d in self.models_]
        for name, value in nearest.fitted_attributes().items():
            column = [getattr(m, name, None) for m in trained]
            stacked = _float_stack(column)
            if stacked is None or np.all(stacked == stacked[0]):
                continue
            new = self._regress(stacked.reshape(len(trained), -1), x_train, x_new)
            if isinstance(value, np.ndarray):
                setattr(nearest, name, np.ascontiguousarray(new.reshape(value.shape)))
            else:
                setattr(nearest, name, float(new[0]))
        return nearest

    # -- the estimator face, with the shape as keywords -----------------------------------
    def _shape_model(self, curve_angle_deg: float | None, radius_mm: float | None
                     ) -> HysteresisModel:
        if curve_angle_deg is None or radius_mm is None:
            raise HysteresisError("a shape-aware model needs curve_angle_deg= and radius_mm=")
        return self.model_for(float(curve_angle_deg), float(radius_mm))

    def predict(self, u: Any, *, state: Any = None, curve_angle_deg: float | None = None,
                radius_mm: float | None = None) -> FloatArray:
        model = self._shape_model(curve_angle_deg, radius_mm)
        out: FloatArray = model.predict(as_1d(u, "u"), state=state)
        return out

    def invert(self, y_desired: Any, *, state: Any = None, curve_angle_deg: float | None = None,
               radius_mm: float | None = None) -> FloatArray:
        model = self._shape_model(curve_angle_deg, radius_mm)
        out: FloatArray = model.invert(as_1d(y_desired, "y_desired"), state=state)
        return out

    def score(self, u: Any, y: Any, *, curve_angle_deg: float | None = None,
              radius_mm: float | None = None) -> float:
        return self._shape_model(curve_angle_deg, radius_mm).score(u, y)


def _float_stack(column: Sequence[Any]) -> FloatArray | None:
    """The values as one float array (n, ...) if all are finite floats of one shape."""
    if any(v is None or isinstance(v, (bool, np.bool_, int, np.integer, str)) for v in column):
        return None
    arrays = [np.asarray(v) for v in column]
    if any(a.dtype.kind != "f" or a.shape != arrays[0].shape for a in arrays):
        return None
    stacked = np.stack(arrays).astype(np.float64)
    return stacked if np.all(np.isfinite(stacked)) else None



def refit_on_common_structure(
    models: Sequence[HysteresisModel], records: Sequence[tuple[FloatArray, FloatArray]], *,
    keys: Sequence[Any] | None = None, memo: dict[tuple[Any, str], HysteresisModel] | None = None,
    sse_memo: dict[tuple[Any, str], float] | None = None,
) -> tuple[list[HysteresisModel], dict[str, Any]]:
    """``models`` (one family, each fitted on its record) refitted with one common structure,
    so their parameters compare: of the family's
    :meth:`~hysteresis.base.HysteresisModel.structure_candidates`, the one with the least
    summed squared error over all the records. Returns the models unchanged and ``{}`` when
    they already share a structure.

    ``memo`` (keyed by ``keys[i]``, default the index, and the candidate) keeps refits between
    calls on overlapping sets (leave-one-out folds), ``sse_memo`` their squared errors (a
    fold then sums them instead of simulating every other record again).
    """
    if len(records) != len(models):
        raise HysteresisError(f"{len(models)} models but {len(records)} records")
    candidates = type(models[0]).structure_candidates(models) if models else []
    if not candidates:
        return list(models), {}
    ids = list(keys) if keys is not None else list(range(len(models)))
    store = memo if memo is not None else {}
    best: tuple[float, list[HysteresisModel], dict[str, Any]] | None = None
    for cand in candidates:
        tag = json.dumps(cand, sort_keys=True)
        refits, sse = [], 0.0
        for key, model, (u, y) in zip(ids, models, records, strict=True):
            if (key, tag) not in store:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    store[(key, tag)] = type(model)(**{**model.get_params(), **cand}).fit(u, y)
            refit = store[(key, tag)]
            err = sse_memo.get((key, tag)) if sse_memo is not None else None
            if err is None:
                err = float(np.sum((np.asarray(y) - refit.predict(u)) ** 2))
                if sse_memo is not None:
                    sse_memo[(key, tag)] = err
            sse += err
            refits.append(refit)
        if best is None or sse < best[0]:
            best = (sse, refits, cand)
    assert best is not None
    return best[1], best[2]


def leave_one_out_models(
    shapes: Any, models: Sequence[HysteresisModel], **params: Any,
) -> list[tuple[HysteresisModel, int] | None]:
    """Leave-one-configuration-out without refitting the regression once per configuration.

    For each ``i``: what ``ShapeAwareModel(**params).fit(shapes without i, models without
    i)`` would hand out for shape ``i`` (``model_for``) and the index (into ``models``) of
    the training configuration nearest to it, as ``(model, nearest)``. The ``poly`` model is
    a ridge regression, linear in its coefficients, with the same design for every fold, so
    one solve on all the configurations gives every fold's prediction through the PRESS
    residual: ``y_i - e_i / (1 - h_ii)`` (``e``: the residuals of the fit on all, ``h``: the
    diagonal of its hat matrix ``A (A'A + P'P)^-1 A'``), for all the parameters at once.

    A fold that is not the same regression with one row fewer is ``None`` (the caller fits
    it): ``method="rbf"``; leaving the shape out moves the feature scaling (the only shape
    at an extreme angle or radius) or lowers the degrees (the only shape at an angle or
    radius); a parameter that is not one float array of one shape on every other
    configuration (or only on the others); a hat value near 1 (a fold the basis cannot
    determine).
    """
    shapes = np.asarray(shapes, dtype=np.float64)
    n = shapes.shape[0]
    est = ShapeAwareModel(**params)
    if est.method != "poly" or n < 3 or len(models) != n:
        return [None] * n
    feats = shape_features(shapes[:, 0], shapes[:, 1])
    ok = _folds_keeping_the_design(est, shapes, feats)
    x = est._scaled(feats)
    a = est._basis(x)
    gram_inv = _ridge_inverse(a, float(est.ridge), n)
    if gram_inv is None:
        return [None] * n
    leverage = np.einsum("ij,jk,ik->i", a, gram_inv, a)
    ok &= (1.0 - leverage) > 1e-8
    # nearest other configuration in the scaled plane (the fold's scaling is the full one)
    dist = np.sum((x[:, None, :] - x[None, :, :]) ** 2, axis=2)
    np.fill_diagonal(dist, np.inf)
    nearest = np.argmin(dist, axis=1)
    loo = _press_values(models, a, gram_inv, leverage, ok)
    dicts = [m.to_dict() for m in models]
    return [(_fold_model(dicts[int(nearest[i])], loo, i), int(nearest[i])) if ok[i] else None
            for i in range(n)]


def _folds_keeping_the_design(est: ShapeAwareModel, shapes: FloatArray,
                              feats: FloatArray) -> np.ndarray:
    """Which folds are the full regression with one row fewer: the feature scaling and the
    degrees stay (no lone shape at an extreme, none alone at its angle or radius). Sets the
    full fit's scaling on ``est``."""
    n = shapes.shape[0]
    lo, hi = feats.min(axis=0), feats.max(axis=0)
    ok = np.ones(n, dtype=bool)
    for col in range(feats.shape[1]):  # the fold's scaling must equal the full one
        f = feats[:, col]
        ok &= ~(((f == lo[col]) & (np.sum(f == lo[col]) == 1))
                | ((f == hi[col]) & (np.sum(f == hi[col]) == 1)))
    est.shapes_ = shapes
    est.feature_min_ = lo
    est.feature_span_ = np.where(np.ptp(feats, axis=0) > 0, np.ptp(feats, axis=0), 1.0)
    for col, asked in ((0, int(est.angle_degree)), (1, int(est.curvature_degree))):
        values, counts = np.unique(shapes[:, col], return_inverse=False, return_counts=True)
        if min(asked, values.size - 2) != min(asked, values.size - 1):  # a fold lowers it
            lonely = values[counts == 1]
            ok &= ~np.isin(shapes[:, col], lonely)
    return ok


def _ridge_inverse(a: FloatArray, ridge: float, n: int) -> FloatArray | None:
    """``(A'A + P'P)^-1`` of the ridge regression (intercept not penalised), or None where
    every fold is underdetermined or the Gram matrix is rank-deficient."""
    p = a.shape[1]
    if p > n - 1 and ridge == 0.0:  # every fold is underdetermined: it raises
        return None
    pen = np.full(p, ridge)
    pen[0] = 0.0
    gram = a.T @ a + np.diag(pen)
    if np.linalg.cond(gram) > 1e12:  # rank-deficient: least squares picks the least norm
        return None
    return np.asarray(np.linalg.inv(gram))


def _press_values(models: Sequence[HysteresisModel], a: FloatArray, gram_inv: FloatArray,
                  leverage: FloatArray, ok: np.ndarray
                  ) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Fitted attribute -> (each fold's PRESS prediction, where a fold keeps the nearest
    model's value). A fold whose own value is the odd one out is marked not ``ok``."""
    n = len(models)
    names = list(dict.fromkeys(k for m in models for k in m.fitted_attributes()))
    loo: dict[str, tuple[FloatArray, FloatArray]] = {}
    for name in names:
        column = [getattr(m, name, None) for m in models]
        stacked = _float_stack(column)
        if stacked is None:
            _mark_odd_fold(column, ok)
            continue
        flat = stacked.reshape(n, -1)
        same0 = np.all(flat == flat[0], axis=1)
        same1 = np.all(flat == flat[1], axis=1)
        # fold i keeps the nearest model's value when the others all agree
        keeps = np.array([bool(np.all(same1[1:])) if i == 0
                          else int(np.sum(~same0)) - int(not same0[i]) == 0 for i in range(n)])
        coef = gram_inv @ (a.T @ flat)
        resid = flat - a @ coef
        with np.errstate(divide="ignore", invalid="ignore"):
            values = flat - resid / (1.0 - leverage)[:, None]
        loo[name] = (values, keeps)
    return loo


def _mark_odd_fold(column: Sequence[Any], ok: np.ndarray) -> None:
    """A fold regresses a parameter only when the one odd value (not a finite float array,
    or of another shape) is its own: leave that fold to the caller."""
    bad = [j for j, v in enumerate(column) if _float_stack([v]) is None]
    if not bad:
        dims = [np.shape(np.asarray(v)) for v in column]
        seen = Counter(dims)
        bad = [j for j, d in enumerate(dims) if seen[d] == 1] if len(seen) == 2 else []
    if len(bad) == 1:
        ok[bad[0]] = False


def _fold_model(nearest: dict[str, Any], loo: dict[str, tuple[FloatArray, FloatArray]],
                i: int) -> HysteresisModel:
    """Fold ``i``'s model: the nearest configuration's, its parameters set to their PRESS
    predictions (those the fold regresses)."""
    model = HysteresisModel.from_dict(nearest)
    for name, value in model.fitted_attributes().items():
        if name not in loo or loo[name][1][i]:
            continue
        new = loo[name][0][i]
        if isinstance(value, np.ndarray):
            setattr(model, name, np.ascontiguousarray(new.reshape(value.shape)))
        else:
            setattr(model, name, float(new[0]))
    return model
