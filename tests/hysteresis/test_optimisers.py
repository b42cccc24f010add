"""Bouc-Wen optimiser comparison of seed 002 IV-A (reduced size: the bench runs all 18 cases)."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis import HysteresisError
from hysteresis.bouc_wen import paper_mse
from hysteresis.optimisers import (
    INIT_BOX,
    METHODS,
    PAPER_METHODS,
    PAPER_THRESHOLD,
    compare_optimisers,
    format_table,
    paper_cases,
    pso,
)

SMALL = {"maxiter": 200, "ga_popsize": 5, "ga_maxiter": 20, "pso_particles": 10,
         "pso_iters": 20}


def test_cases_follow_the_paper_protocol() -> None:
    cases = paper_cases()
    assert [c.sheath_deg for c in cases] == [15.0 * i for i in range(18)]
    u = cases[0].u
    assert u.size == 600  # 20 s of calibration at the camera's 30 Hz
    assert u.min() == pytest.approx(0.0, abs=0.05) and u.max() == pytest.approx(60.0, abs=0.05)
    for c in cases:
        # the success threshold is reachable (noise floor ~1) and the guess is not the truth
        assert paper_mse(c.u, c.y, c.true_params) < 0.5 * PAPER_THRESHOLD
        assert paper_mse(c.u, c.y, c.x0) > paper_mse(c.u, c.y, c.true_params)
    # loops grow with the bend: larger |beta| (loop height) at 255 deg than at 0 deg
    assert abs(cases[-1].true_params[5]) > 4 * abs(cases[0].true_params[5])
    boxed = paper_cases(init="box")
    lo, hi = INIT_BOX
    assert all(np.all((c.x0 >= lo) & (c.x0 <= hi)) for c in boxed)
    with pytest.raises(HysteresisError, match="n_cases"):
        paper_cases(19)


def test_pso_is_seeded_and_finds_a_box_minimum() -> None:
    def rosen(x: np.ndarray) -> float:
        return float(100 * (x[1] - x[0] ** 2) ** 2 + (1 - x[0]) ** 2)

    box = (np.array([-2.0, -1.0]), np.array([2.0, 3.0]))
    x1, f1, n1 = pso(rosen, box, n_particles=30, iters=200, seed=4)
    x2, f2, _ = pso(rosen, box, n_particles=30, iters=200, seed=4)
    np.testing.assert_array_equal(x1, x2)
    assert f1 == f2 < 1e-4
    assert n1 == 30 * 201
    np.testing.assert_allclose(x1, [1.0, 1.0], atol=0.05)


@pytest.mark.parametrize("init", ["paper", "box"])
def test_reduced_comparison_ours_succeeds_everywhere(init: str) -> None:
    cases = paper_cases(3, init=init)
    methods = METHODS if init == "paper" else ("ours", "bfgs", "nelder-mead", "slsqp")
    res = compare_optimisers(cases, methods=methods, progress=False, **SMALL)
    assert res["n_cases"] == 3 and res["threshold"] == PAPER_THRESHOLD
    assert list(res["methods"]) == list(methods)
    assert len(res["runs"]) == 3 * len(methods)
    ours = res["methods"]["ours"]
    assert ours["success"] == 3 and ours["mse_mean"] < 1.2
    for m in methods:
        s = res["methods"][m]
        assert 0 <= s["success"] <= 3 and s["time_median_s"] > 0
    # ours reaches the best optimum any method found on every case
    for case in range(3):
        runs = [r for r in res["runs"] if r["case"] == case]
        best = min(r["mse"] for r in runs)
        assert next(r["mse"] for r in runs if r["method"] == "ours") <= best + 0.02
    table = format_table(res)
    assert "ours" in table and "3/3" in table


def test_unknown_method_is_rejected() -> None:
    with pytest.raises(HysteresisError, match="unknown method"):
        compare_optimisers(paper_cases(1), methods=("newton",), progress=False)
    assert set(PAPER_METHODS) == {"ga", "pso", "nelder-mead", "powell", "cg", "bfgs", "tnc",
                                  "cobyla", "slsqp"}
