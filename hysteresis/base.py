"""The one estimator face every hysteresis model family wears (scikit-learn style).

* ``__init__`` only stores hyper-parameters (keyword arguments, same names as attributes);
* ``fit(u, y)`` identifies the model and sets trailing-underscore attributes; ``u`` and ``y``
  may also be lists of records (several runs), each simulated from its own start
  (:func:`check_records`), never joined into one record with seams;
* ``predict(u, *, state=None)`` simulates from the rest state (or a given state);
* ``invert(y_desired, *, state=None)`` returns an input that makes the model produce ``y``;
* ``score(u, y)`` is the coefficient of determination R^2 (higher is better, as in sklearn);
* ``get_params``/``set_params`` so Hydra can ``instantiate`` and sweep it;
* ``to_json``/``from_json`` are lossless (floats are written with ``repr`` precision).

Families register themselves by name with :func:`register_family` so that
``conf/family/<name>.yaml`` and :func:`make_family` find them.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import inspect
import json
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, TypeVar, runtime_checkable

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

FloatArray = npt.NDArray[np.float64]
M = TypeVar("M", bound="HysteresisModel")
S = TypeVar("S", bound="DataclassInstance")

_REGISTRY: dict[str, type[HysteresisModel]] = {}


class HysteresisError(Exception):
    """The one error class of :mod:`hysteresis` (bad input arrays, unfitted model, ...)."""


class NotFittedError(HysteresisError):
    """``predict``/``invert`` called before ``fit``."""


def register_family(name: str) -> Any:
    """Class decorator: register a family under ``name`` (``gamma``, ``bouc_wen``, ...)."""

    def deco(cls: type[M]) -> type[M]:
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            raise HysteresisError(f"family {name!r} is registered twice")
        cls.family = name
        _REGISTRY[name] = cls
        return cls

    return deco


def family_names() -> list[str]:
    """Registered family names, sorted."""
    _import_all_families()
    return sorted(_REGISTRY)


def family_class(name: str) -> type[HysteresisModel]:
    _import_all_families()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise HysteresisError(
            f"unknown model family {name!r}; known: {', '.join(sorted(_REGISTRY))}"
        ) from None


def make_family(name: str, **params: Any) -> HysteresisModel:
    """Instantiate family ``name`` with hyper-parameters ``params``."""
    return family_class(name)(**params)


#: The modules that register the families (imported by name on the first lookup, so the
#: registry knows every family without base importing the modules that import it).
FAMILY_MODULES = ("linear", "gamma", "preisach", "bouc_wen", "coleman_hodgdon")


def _import_all_families() -> None:
    import importlib

    for module in FAMILY_MODULES:
        importlib.import_module(f"hysteresis.{module}")


def as_1d(x: Any, name: str) -> FloatArray:
    """Validate and convert an input signal to a finite 1-D float64 array, C-contiguous and
    writeable: the compiled kernels then see one array type, and compile once instead of once
    more for each read-only or strided view they are handed."""
    if (type(x) is np.ndarray and x.dtype == np.float64 and x.flags.c_contiguous
            and x.flags.writeable):
        arr = x  # already what np.require would hand back, without its overhead
    else:
        arr = np.require(x, dtype=np.float64,
                         requirements=["C_CONTIGUOUS", "WRITEABLE", "ENSUREARRAY"])
    if arr.ndim != 1:
        raise HysteresisError(f"{name} must be 1-D, got shape {arr.shape}")
    if arr.size == 0:
        raise HysteresisError(f"{name} is empty")
    # a finite sum means every value is finite (one pass, no temporary); only an overflowing
    # sum of finite values needs the element-wise check
    if not math.isfinite(float(arr.sum())) and not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise HysteresisError(f"{name} has a non-finite value at index {bad}")
    return arr


def state_from(state: Any, state_type: type[S], family: str) -> S:
    """``state`` as a ``state_type`` (a dataclass of floats): itself, or built from a mapping
    with the same field names (a state written by hand); anything else is refused."""
    if isinstance(state, state_type):
        return state
    names = [f.name for f in dataclasses.fields(state_type)]
    if isinstance(state, Mapping):
        try:
            return state_type(**{k: float(state[k]) for k in names})
        except (KeyError, TypeError, ValueError):
            pass
    raise HysteresisError(f"{family} state must be a {state_type.__name__} or a mapping with "
                          f"keys {names}, got {state!r}")


def check_pair(u: Any, y: Any) -> tuple[FloatArray, FloatArray]:
    uu, yy = as_1d(u, "u"), as_1d(y, "y")
    if uu.shape != yy.shape:
        raise HysteresisError(f"u and y differ in length: {uu.size} vs {yy.size}")
    return uu, yy


@dataclasses.dataclass(frozen=True)
class Records:
    """One or several identification records, each to be simulated from its own start.

    ``u``/``y`` are the records joined end to end (what a design matrix is built over);
    ``bounds[i]:bounds[i + 1]`` is record ``i``. A family that fits on ``Records`` restarts
    its state at every boundary, so no seam of a joined record is ever read as a jump.
    """

    u: FloatArray
    y: FloatArray
    bounds: tuple[int, ...]

    @property
    def n_records(self) -> int:
        return len(self.bounds) - 1

    def slices(self) -> list[slice]:
        return [slice(a, b) for a, b in zip(self.bounds[:-1], self.bounds[1:], strict=True)]

    def pairs(self) -> list[tuple[FloatArray, FloatArray]]:
        return [(self.u[s], self.y[s]) for s in self.slices()]

    def thin(self, keep: Sequence[npt.NDArray[np.intp]]) -> Records:
        """The records with only the samples ``keep[i]`` (indices into record ``i``)."""
        parts = [(uu[k], yy[k]) for (uu, yy), k in zip(self.pairs(), keep, strict=True)]
        return _join(parts)


def is_record_list(x: Any) -> bool:
    """True when ``x`` is a list/tuple of signals (several records), not one signal."""
    return (isinstance(x, (list, tuple)) and len(x) > 0
            and all(isinstance(v, (np.ndarray, list, tuple)) for v in x))


def check_records(u: Any, y: Any, *, min_samples: int = 1) -> Records:
    """One record (two 1-D signals) or several (two equally long lists of 1-D signals) as
    :class:`Records`; every record must have ``min_samples`` samples or more."""
    if is_record_list(u) or is_record_list(y):
        if not (is_record_list(u) and is_record_list(y)) or len(u) != len(y):
            raise HysteresisError(
                "several records need a list of inputs and a list of outputs of the same "
                f"length, got {type(u).__name__} and {type(y).__name__}")
        parts = [check_pair(uu, yy) for uu, yy in zip(u, y, strict=True)]
    else:
        parts = [check_pair(u, y)]
    for i, (uu, _) in enumerate(parts):
        if uu.size < min_samples:
            which = f"record {i}" if len(parts) > 1 else "the record"
            raise HysteresisError(f"need at least {min_samples} samples to fit, {which} "
                                  f"has {uu.size}")
    return _join(parts)


def _join(parts: Sequence[tuple[FloatArray, FloatArray]]) -> Records:
    bounds = np.cumsum([0, *(p[0].size for p in parts)]).tolist()
    if len(parts) == 1:
        return Records(parts[0][0], parts[0][1], tuple(bounds))
    return Records(np.concatenate([p[0] for p in parts]),
                   np.concatenate([p[1] for p in parts]), tuple(bounds))


#: Share of every identification record a default's form choice is judged on: its last part,
#: predicted after the model has been run through the record's head.
CHOICE_HELDOUT_FRACTION = 0.3
#: Relative drop in that held-out error an alternative form must bring to replace the
#: default's physical one (less is noise, and the physical form extrapolates more safely).
CHOICE_GAIN = 0.1


def choose_form(build: Any, forms: Sequence[Any], records: Records) -> tuple[Any, list[float]]:
    """The form (the first of ``forms`` is the physical default) whose model, fitted on the
    head of every record, predicts the records' tails best; ``build(form)`` returns an
    unfitted model. Returns the chosen form and every form's held-out squared error.

    A later form must lower the error by :data:`CHOICE_GAIN` to be chosen; a form whose fit
    fails scores infinity. Records too short to split are judged in-sample. A model that
    fitted one offset per record (``record_offsets_``) predicts each tail with its own
    record's offset: head and tail are one run, and its zero is known from the head.
    """
    heads, tails = [], []
    for uu, yy in records.pairs():
        cut = int(round(uu.size * (1.0 - CHOICE_HELDOUT_FRACTION)))
        if cut < 20 or uu.size - cut < 10:
            cut = uu.size
        heads.append((uu[:cut], yy[:cut]))
        tails.append(cut)
    scores = []
    for form in forms:
        try:
            model = build(form).fit([h[0] for h in heads], [h[1] for h in heads])
            err = 0.0
            own = getattr(model, "record_offsets_", None)
            for i, ((uu, yy), cut) in enumerate(zip(records.pairs(), tails, strict=True)):
                pred = np.asarray(model.predict(uu), dtype=np.float64)
                if own is not None:
                    pred = pred + (float(own[i]) - float(model.offset_))
                part = slice(cut, None) if cut < uu.size else slice(None)
                err += float(np.sum((pred[part] - yy[part]) ** 2))
            scores.append(err if math.isfinite(err) else math.inf)
        except (HysteresisError, ValueError, FloatingPointError, np.linalg.LinAlgError):
            scores.append(math.inf)
    best = 0
    for i in range(1, len(forms)):
        if scores[i] < (1.0 - CHOICE_GAIN) * scores[best]:
            best = i
    return forms[best], scores


def records_sse(model: Any, records: Records) -> float:
    """Squared error summed over the records, each predicted from rest (its own start)."""
    total = 0.0
    for uu, yy in records.pairs():
        pred = np.asarray(model.predict(uu), dtype=np.float64)
        if not np.all(np.isfinite(pred)):
            return math.inf
        total += float(np.sum((yy - pred) ** 2))
    return total


def check_inverse_reach(model: Any, *, identified_range: tuple[float, float] | None = None,
                        desired: Any = None) -> None:
    """Refuse, before anything is driven, an inverse that cannot reach what it is asked for.

    A family judges its own reach (:meth:`HysteresisModel.check_reach`: Gamma by its weights
    and thresholds, any other by a slow sweep of ``identified_range`` that must reach the
    ``desired`` outputs); raises :class:`HysteresisError` naming the range."""
    if isinstance(model, HysteresisModel):
        model.check_reach(identified_range=identified_range, desired=desired)
    else:
        check_swept_reach(model, identified_range, desired)


def check_swept_reach(model: Any, identified_range: tuple[float, float] | None,
                       desired: Any) -> None:
    """Refuse demanded outputs a model cannot produce inside its identification range: a
    slow sweep low -> high -> low of that range bounds what it reaches (a saturating or
    softening loop flattens at its ends, and its inverse would otherwise run off towards
    inputs it never saw)."""
    if identified_range is None or desired is None or not hasattr(model, "predict"):
        return
    yd = np.asarray(desired, dtype=np.float64)
    lo, hi = (float(v) for v in identified_range)
    if not (yd.size and hi > lo):
        return
    ramp = np.linspace(lo, hi, 400)
    try:
        swept = np.asarray(model.predict(np.concatenate([ramp, ramp[::-1], ramp])),
                           dtype=np.float64)
    except HysteresisError:
        return
    if not np.all(np.isfinite(swept)):
        return
    ylo, yhi = float(swept.min()), float(swept.max())
    margin = 0.02 * max(yhi - ylo, 1e-300)
    dlo, dhi = float(yd.min()), float(yd.max())
    if dlo < ylo - margin or dhi > yhi + margin:
        raise HysteresisError(
            f"{type(model).__name__} cannot reach the demanded outputs {dlo:.4g}..{dhi:.4g} "
            f"inside its identification range (inputs {lo:.4g}..{hi:.4g}): swept over that "
            f"range it reaches {ylo:.4g}..{yhi:.4g} (its loop flattens at the ends); scale "
            f"the target into that band or identify on a wider stroke")


class HysteresisModel:
    """Base class. Subclasses implement ``fit``, ``predict`` and (where they can) ``invert``."""

    family: ClassVar[str] = "base"

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Every family's ``fit`` leaves the model fitted only when it succeeded: a fit that
        raises removes the fitted attributes (a half-set plane or last run's parameters
        would otherwise make the model look fitted to data it never fitted)."""
        super().__init_subclass__(**kwargs)
        fit = cls.__dict__.get("fit")
        if fit is None or getattr(fit, "_clears_on_failure", False):
            return

        @functools.wraps(fit)
        def fit_or_forget(self: HysteresisModel, u: Any, y: Any, **fit_params: Any) -> Any:
            try:
                return fit(self, u, y, **fit_params)
            except BaseException:
                for name in list(self.fitted_attributes()):
                    delattr(self, name)
                raise

        fit_or_forget._clears_on_failure = True  # type: ignore[attr-defined]
        cls.fit = fit_or_forget  # type: ignore[method-assign]

    # -- scikit-learn parameter protocol -------------------------------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [
            p.name
            for p in sig.parameters.values()
            if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
        ]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self: M, **params: Any) -> M:
        valid = set(self._param_names())
        for key, value in params.items():
            if key not in valid:
                raise HysteresisError(
                    f"{type(self).__name__} has no hyper-parameter {key!r}; valid: {sorted(valid)}"
                )
            setattr(self, key, value)
        return self

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    @classmethod
    def structure_candidates(cls, models: Sequence[HysteresisModel]) -> list[dict[str, Any]]:
        """Hyper-parameter sets to refit ``models`` (fitted models of this family, e.g. one
        per sheath shape) with so that their fitted parameters compare element by element;
        ``[]`` when they already do. Only a family whose fit chooses its structure from the
        data (Gamma's play widths) returns any; the caller keeps the candidate that fits the
        records best (:func:`hysteresis.shape_aware.refit_on_common_structure`)."""
        return []

    # -- fitted state -----------------------------------------------------------------
    def fitted_attributes(self) -> dict[str, Any]:
        """Public attributes ending in ``_`` (set by ``fit``)."""
        return {
            k: v
            for k, v in vars(self).items()
            if k.endswith("_") and not k.startswith("_")
        }

    @property
    def is_fitted(self) -> bool:
        return any(k.endswith("_") and not k.startswith("_") for k in vars(self))

    def check_fitted(self) -> None:
        if not self.is_fitted:
            raise NotFittedError(f"{type(self).__name__} is not fitted yet; call fit(u, y) first")

    # -- the estimator face -----------------------------------------------------------
    def fit(self: M, u: Any, y: Any, **fit_params: Any) -> M:  # pragma: no cover - abstract
        raise NotImplementedError

    def predict(self, u: Any, *, state: Any = None) -> FloatArray:  # pragma: no cover
        raise NotImplementedError

    def invert(self, y_desired: Any, *, state: Any = None) -> FloatArray:
        raise HysteresisError(f"family {self.family!r} has no inverse")

    def check_reach(self, *, identified_range: tuple[float, float] | None = None,
                    desired: Any = None) -> None:
        """Raise :class:`HysteresisError` when an inverse of this model cannot reach the
        ``desired`` outputs: by default, when a slow sweep of ``identified_range`` (low ->
        high -> low) does not reach them (a saturating or softening loop). A family that can
        tell from its parameters (Gamma) overrides it."""
        check_swept_reach(self, identified_range, desired)

    def clone(self: M) -> M:
        """An unfitted copy with the same hyper-parameters (scikit-learn's ``clone``)."""
        return type(self)(**copy.deepcopy(self.get_params()))

    def score(self, u: Any, y: Any) -> float:
        """Coefficient of determination R^2 of ``predict(u)`` against ``y``."""
        uu, yy = check_pair(u, y)
        resid = yy - self.predict(uu)
        ss_tot = float(np.sum((yy - yy.mean()) ** 2))
        return 1.0 - float(np.sum(resid**2)) / ss_tot if ss_tot > 0 else float("nan")

    # -- lossless JSON ----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "family": self.family,
            "class": f"{type(self).__module__}.{type(self).__qualname__}",
            "params": _encode(self.get_params()),
            "fitted": _encode(self.fitted_attributes()),
        }

    def to_json(self, *, indent: int | None = 1) -> str:
        return json.dumps(self.to_dict(), indent=indent, allow_nan=True)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> HysteresisModel:
        target = family_class(data["family"]) if cls is HysteresisModel else cls
        model = target(**_decode(data["params"]))
        for key, value in _decode(data["fitted"]).items():
            setattr(model, key, value)
        return model

    @classmethod
    def from_json(cls, text: str) -> HysteresisModel:
        return cls.from_dict(json.loads(text))


class StatefulModel(HysteresisModel):
    """A family whose ``predict`` can also return its final state (``return_state=True``).

    It gets the state-carrying API that compensation loops use for free: ``simulate`` (a
    record, continuing from ``state``) and ``step`` (one sample). Families with a cheaper
    one-sample update override ``step``.
    """

    def predict(self, u: Any, *, state: Any = None,
                return_state: bool = False) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def simulate(self, u: Any, state: Any = None) -> tuple[FloatArray, Any]:
        """``(y, final_state)``: :meth:`predict` with the state returned."""
        y, st = self.predict(u, state=state, return_state=True)
        return y, st

    def step(self, u_k: float, state: Any = None) -> tuple[float, Any]:
        """One forward step: ``(y_k, state_k)`` from ``u_k`` and ``state_{k-1}`` (not modified)."""
        y, st = self.predict(np.array([float(u_k)]), state=state, return_state=True)
        return float(y[0]), st

    def initial_state(self, u0: float = 0.0) -> Any:  # pragma: no cover - every family has one
        """The state at rest at the input ``u0``, as the identification assumed it."""
        raise NotImplementedError

    def invert_step(self, y_k: float, state: Any = None
                    ) -> tuple[float, Any]:  # pragma: no cover - every family has one
        """One inverse step: the input ``u_k`` whose forward step from ``state`` gives (or
        comes nearest to) ``y_k``, and the state after it."""
        raise NotImplementedError


@runtime_checkable
class Steppable(Protocol):
    """What an online compensation loop drives, one sample at a time: every
    :class:`StatefulModel` family, or any object with these three methods."""

    def initial_state(self, u0: float = 0.0) -> Any: ...

    def step(self, u_k: float, state: Any = None) -> tuple[float, Any]: ...

    def invert_step(self, y_k: float, state: Any = None) -> tuple[float, Any]: ...


@runtime_checkable
class LinearInParameters(Protocol):
    """A family whose output is linear in its weights once its structure is fixed:
    ``y = design_matrix(u) @ weights_ + offset_`` (Gamma's plays). Its fits are exact least
    squares, and a shape-aware regression or an effect screen can work on the columns."""

    weights_: Any
    offset_: float

    def design_matrix(self, u: Any, y: Any = None) -> FloatArray: ...


def _encode(obj: Any) -> Any:
    """JSON-able form that round-trips numpy arrays (dtype and shape) exactly."""
    if isinstance(obj, np.ndarray):
        return {"__ndarray__": obj.tolist(), "dtype": str(obj.dtype), "shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, dict):
        return {str(k): _encode(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_encode(v) for v in obj]
    return obj


def _decode(obj: Any) -> Any:
    if isinstance(obj, dict):
        if "__ndarray__" in obj:
            return np.asarray(obj["__ndarray__"], dtype=obj["dtype"]).reshape(obj["shape"])
        return {k: _decode(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_decode(v) for v in obj]
    return obj
