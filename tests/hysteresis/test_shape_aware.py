"""The shape-aware model: a family's parameters as smooth functions of curve angle and radius."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.base import HysteresisError, HysteresisModel
from hysteresis.gamma import GammaModel
from hysteresis.linear import LinearModel
from hysteresis.shape_aware import (
    ShapeAwareModel,
    leave_one_out_models,
    refit_on_common_structure,
    shape_features,
)

ANGLES = (15.0, 30.0, 45.0, 60.0, 75.0, 90.0)
RADII = (30.0, 45.0, 60.0, 75.0)
P = np.linspace(0.0, 2.0, 6)


def _true_weights(phi: float, r: float) -> np.ndarray:
    """Weights cubic in the wrap angle and linear in the curvature, summing to 1."""
    th, k = np.radians(phi), 1.0 / r
    raw = np.array([1.0, 0.5 + th, 0.2 * th**2, 0.3 * th**3 + 5 * k, 8 * k * th, 0.1])
    return raw / raw.sum() * (1.0 + 0.0 * th)


def _gamma(phi: float, r: float) -> GammaModel:
    m = GammaModel(thresholds=list(P))
    m.thresholds_ = P.copy()
    q = _true_weights(phi, r)
    m.weights_ = q / q.sum()
    m.offset_ = 0.01 * phi - 2.0 / r
    m.sse_ = 0.0
    return m


def _u() -> np.ndarray:
    t = np.arange(0, 20, 0.05)
    return 5.0 * np.sin(0.5 * t) * np.exp(-0.05 * t)


def test_features_are_wrap_angle_and_curvature() -> None:
    f = shape_features([90.0, 45.0], [30.0, 60.0])
    np.testing.assert_allclose(f, [[np.pi / 2, 1 / 30], [np.pi / 4, 1 / 60]])
    with pytest.raises(HysteresisError, match="positive"):
        shape_features([90.0], [0.0])


def test_recovers_a_smooth_dependence_on_an_unseen_shape() -> None:
    grid = [(p, r) for p in ANGLES for r in RADII]
    held = (60.0, 45.0)
    train = [s for s in grid if s != held]
    # ridge 0: the basis theta^0..3 x kappa^0..1 spans the true offset exactly
    sa = ShapeAwareModel(base_family="gamma", ridge=0.0).fit(train, [_gamma(*s) for s in train])
    model = sa.model_for(*held)
    assert isinstance(model, GammaModel)
    truth = _gamma(*held)
    np.testing.assert_allclose(model.offset_, truth.offset_, atol=1e-9)
    np.testing.assert_array_equal(model.thresholds_, P)  # equal everywhere: copied
    # the weights are not in the basis (a ratio), but the smooth fit is close and sums to 1
    np.testing.assert_allclose(model.weights_, truth.weights_, atol=2e-3)
    assert model.weights_.sum() == pytest.approx(1.0, abs=1e-12)
    u = _u()
    y = sa.predict(u, curve_angle_deg=held[0], radius_mm=held[1])
    assert np.sqrt(np.mean((y - truth.predict(u)) ** 2)) < 5e-3
    # the nearest configuration's model is clearly worse than the shape-aware one
    near = _gamma(*train[sa.nearest_index(*held)])
    assert np.sqrt(np.mean((near.predict(u) - truth.predict(u)) ** 2)) > 5 * np.sqrt(
        np.mean((y - truth.predict(u)) ** 2))


def test_fits_from_records_and_round_trips_through_json() -> None:
    u = _u()
    shapes = [(30.0, 30.0), (60.0, 30.0), (90.0, 30.0), (30.0, 60.0), (90.0, 60.0)]
    records = [(u, _gamma(*s).predict(u)) for s in shapes]
    sa = ShapeAwareModel(base_family="gamma", family_params={"thresholds": list(P),
                                                            "fit_offset": True},
                         angle_degree=1, curvature_degree=1)
    sa.fit(shapes, records)
    assert sa.degrees() == (1, 1)
    # a training shape is reproduced closely (the fit smooths, it does not interpolate)
    assert sa.score(u, records[1][1], curve_angle_deg=60.0, radius_mm=30.0) > 0.999
    back = ShapeAwareModel.from_json(sa.to_json())
    assert isinstance(back, ShapeAwareModel) and back.get_params() == sa.get_params()
    np.testing.assert_array_equal(back.predict(u, curve_angle_deg=45.0, radius_mm=45.0),
                                  sa.predict(u, curve_angle_deg=45.0, radius_mm=45.0))
    # the inverse of the shape's model: driving it with the inverse reproduces the target
    target = 2.0 * np.sin(np.linspace(0, 6, 200))
    drive = sa.invert(target, curve_angle_deg=45.0, radius_mm=45.0)
    np.testing.assert_allclose(sa.predict(drive, curve_angle_deg=45.0, radius_mm=45.0), target,
                               atol=1e-9)


def _widening_plant(phi: float) -> GammaModel:
    """Plays widening with the wrap angle: default fits choose different widest plays."""
    top = 0.5 + 5.0 * np.radians(phi)
    p = np.linspace(0.0, top, 6)
    q = np.full(6, 1.0 / 6.0)
    return GammaModel.from_params(p, q)


def test_models_fitted_on_different_play_grids_are_refitted_on_one() -> None:
    u = _u()
    shapes = [(15.0, 45.0), (45.0, 45.0), (90.0, 45.0), (45.0, 75.0)]
    records = [(u, _widening_plant(phi).predict(u)) for phi, _ in shapes]
    own = [GammaModel().fit(uu, yy) for uu, yy in records]
    assert len({float(m.thresholds_.max()) for m in own}) > 1  # the premise: grids differ
    # fitted models on different grids: their weights do not compare, so they are refused
    with pytest.raises(HysteresisError, match="different structures"):
        ShapeAwareModel(base_family="gamma", angle_degree=1).fit(shapes, own)
    refits, chosen = refit_on_common_structure(own, records)
    grids = {tuple(m.thresholds_) for m in refits}
    assert grids == {tuple(chosen["thresholds"])}
    # the chosen grid is the candidate with the least summed squared error over the records
    def total(grid: list[float]) -> float:
        return sum(float(np.sum((yy - GammaModel(thresholds=grid).fit(uu, yy).predict(uu)) ** 2))
                   for uu, yy in records)
    candidates = {tuple(m.thresholds_) for m in own}
    assert total(chosen["thresholds"]) <= min(total(list(g)) for g in candidates) + 1e-12
    # from records the shape-aware model does this itself
    sa = ShapeAwareModel(base_family="gamma", angle_degree=1).fit(shapes, records)
    assert len({tuple(HysteresisModel.from_dict(d).thresholds_)  # type: ignore[attr-defined]
                for d in sa.models_}) == 1
    assert sa.score(u, records[1][1], curve_angle_deg=45.0, radius_mm=45.0) > 0.95


def test_degrees_follow_what_the_shapes_resolve_and_rbf_interpolates() -> None:
    u = _u()
    shapes = [(30.0, 45.0), (90.0, 45.0)]
    models = [_gamma(*s) for s in shapes]
    sa = ShapeAwareModel().fit(shapes, models)
    assert sa.degrees() == (1, 0)  # two angles, one radius: a line in theta
    mid = sa.model_for(60.0, 45.0)
    np.testing.assert_allclose(mid.weights_, 0.5 * (models[0].weights_ + models[1].weights_),
                               atol=1e-9)
    grid = [(p, r) for p in ANGLES[::2] for r in RADII[::2]]
    rbf = ShapeAwareModel(method="rbf").fit(grid, [_gamma(*s) for s in grid])
    exact = rbf.model_for(*grid[3])  # interpolates the training shapes exactly
    np.testing.assert_allclose(exact.predict(u), _gamma(*grid[3]).predict(u), atol=1e-9)


def test_other_attributes_come_from_the_nearest_configuration() -> None:
    shapes = [(15.0, 30.0), (90.0, 30.0), (15.0, 75.0)]
    models = []
    for i, s in enumerate(shapes):
        m = LinearModel()
        m.gain_, m.offset_, m.delay_, m.sse_ = 0.5 + 0.005 * s[0], 0.0, i, 0.0
        models.append(m)
    sa = ShapeAwareModel(base_family="linear", curvature_degree=0, ridge=0.0).fit(shapes, models)
    got = sa.model_for(85.0, 35.0)
    assert isinstance(got, LinearModel) and got.delay_ == 1  # an integer: the nearest one's
    assert got.gain_ == pytest.approx(0.5 + 0.005 * 85.0)


@pytest.mark.parametrize(("call", "match"), [
    (lambda: ShapeAwareModel().fit([(15.0, 30.0)], [_gamma(15.0, 30.0)]), "at least two"),
    (lambda: ShapeAwareModel().fit([(15.0, 30.0), (30.0, 30.0)], [_gamma(15.0, 30.0)]),
     "2 shapes but 1"),
    (lambda: ShapeAwareModel(base_family="linear").fit(
        [(15.0, 30.0), (30.0, 30.0)], [_gamma(15.0, 30.0), _gamma(30.0, 30.0)]), "shape-aware"),
    (lambda: ShapeAwareModel(method="spline").fit(
        [(15.0, 30.0), (30.0, 30.0)], [_gamma(15.0, 30.0), _gamma(30.0, 30.0)]), "method"),
    (lambda: ShapeAwareModel().fit([(15.0, 30.0), (15.0, 30.0)],
                                   [_gamma(15.0, 30.0), _gamma(15.0, 30.0)]), "twice"),
    (lambda: ShapeAwareModel().fit([(15.0, 30.0), (30.0, 30.0)],
                                   [_gamma(15.0, 30.0), _gamma(30.0, 30.0)]).predict(_u()),
     "curve_angle_deg= and radius_mm="),
    (lambda: ShapeAwareModel().model_for(15.0, 30.0), "not fitted"),
])
def test_clear_errors(call: object, match: str) -> None:
    with pytest.raises(HysteresisError, match=match):
        call()  # type: ignore[operator]


def test_not_a_registered_family() -> None:
    from hysteresis import family_names

    assert "shape_aware" not in family_names()
    assert ShapeAwareModel.family == "shape_aware"
    assert HysteresisModel.family == "base"


def _explicit_fold(shapes: list[tuple[float, float]], models: list[GammaModel], i: int,
                   **params: object) -> tuple[HysteresisModel, int]:
    others = [j for j in range(len(shapes)) if j != i]
    sa = ShapeAwareModel(base_family="gamma", **params).fit(  # type: ignore[arg-type]
        [shapes[j] for j in others], [models[j] for j in others])
    return sa.model_for(*shapes[i]), others[sa.nearest_index(*shapes[i])]


@pytest.mark.parametrize("params", [{}, {"ridge": 0.0}, {"angle_degree": 2, "ridge": 0.1}])
@pytest.mark.parametrize("extra", [
    # an extreme angle alone (without it the feature scaling moves: left to the caller),
    # and an angle and a radius alone inside the range (the same regression: solved)
    ((100.0, 50.0), (52.5, 40.0)),
    # an angle alone among two others (without it the angle degree drops: left to the caller)
    ((52.5, 40.0),)])
def test_closed_form_leave_one_out_equals_refitting_every_fold(
        params: dict, extra: tuple[tuple[float, float], ...]) -> None:
    angles = ANGLES if len(extra) == 2 else (15.0, 90.0)
    shapes = [(p, r) for p in angles for r in RADII] + list(extra)
    models = [_gamma(*s) for s in shapes]
    for k, m in enumerate(models):  # an attribute equal everywhere but on one shape
        m.sse_ = 0.5 if k == 3 else 0.0
    solved = leave_one_out_models(shapes, models, base_family="gamma", **params)
    left = {len(shapes) - 2} if len(extra) == 2 else {len(shapes) - 1}
    if params.get("ridge") == 0.0 and len(extra) == 1:
        # one shape at the middle angle cannot separate its angle terms: without a ridge the
        # regression is rank-deficient (least squares picks the smallest coefficients), so
        # every fold is left to the caller
        left = set(range(len(shapes)))
    assert {i for i, s in enumerate(solved) if s is None} == left
    for i, got in enumerate(solved):
        if got is None:
            continue
        want, near = _explicit_fold(shapes, models, i, **params)
        assert got[1] == near
        for name, value in want.fitted_attributes().items():
            np.testing.assert_allclose(getattr(got[0], name), value, rtol=1e-9, atol=1e-12,
                                       err_msg=f"fold {i} {name}")


def test_closed_form_leave_one_out_with_one_odd_value() -> None:
    # one shape's offset is not finite: only the fold leaving it out regresses the offset
    shapes = [(p, r) for p in ANGLES for r in RADII]
    models = [_gamma(*s) for s in shapes]
    models[5].offset_ = float("nan")
    solved = leave_one_out_models(shapes, models, base_family="gamma")
    assert [i for i, s in enumerate(solved) if s is None] == [5]
    for i, got in enumerate(solved):
        if got is not None:
            want, _ = _explicit_fold(shapes, models, i)
            np.testing.assert_allclose(got[0].offset_, want.offset_, rtol=1e-9)
            np.testing.assert_allclose(got[0].weights_, want.weights_, rtol=1e-9, atol=1e-12)


def test_closed_form_leave_one_out_leaves_rbf_to_the_caller() -> None:
    shapes = [(p, r) for p in ANGLES for r in RADII]
    assert leave_one_out_models(shapes, [_gamma(*s) for s in shapes], base_family="gamma",
                                method="rbf") == [None] * len(shapes)
