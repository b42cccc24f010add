"""A stretch named on a tension that carries a speed-dependent force is answered with its class."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.discrepancy._ops import play
from hysteresis.discrepancy.evidence import SPEED_SHARE, tension_speed_share
from hysteresis.discrepancy.identifiability import force_statement
from hysteresis.discrepancy.runs import RunData


def _run(force_per_speed: float) -> RunData:
    t = np.arange(0.0, 80.0, 0.04)
    amp = np.repeat([6.0, 4.5, 3.0, 1.5], t.size // 4 + 1)[:t.size]
    u = amp * np.sin(2 * np.pi * 0.25 * t)
    v = np.gradient(u, t)
    rng = np.random.default_rng(0)
    # capstan tension set by the friction state (a play of the input: pulling or releasing)
    state = (u - play(u, 0.8)) / 0.8
    tension = 6.0 * np.exp(0.3 * state) + force_per_speed * v + rng.normal(0, 0.01, t.size)
    return RunData(run_id="r", t=t, u=u, y=u, tension=tension)


def test_a_capstan_tension_leaves_little_to_the_speed() -> None:
    share = tension_speed_share([_run(0.0)])
    assert share is not None and share < 0.2


def test_a_tension_that_carries_a_viscous_force_follows_the_speed() -> None:
    share = tension_speed_share([_run(0.3)])
    assert share is not None and share > SPEED_SHARE


def test_no_share_without_an_input_tension() -> None:
    run = _run(0.0)
    run.tension = None
    assert tension_speed_share([run]) is None


def _stretch(rival_gain: float) -> dict:
    return {"name": "tendon_elongation", "form": "square_output", "evidence": {
        "runner_up": {"name": "rate_dependence", "relative_gain": rival_gain,
                      "delta_bic": -500.0}}}


@pytest.mark.parametrize(("share", "rival_gain", "classed"), [
    (0.97, 0.7, True),    # the tension follows the speed and a rate term alone clears the bar
    (0.97, 0.05, False),  # no rate term explains the output: the stretch stands
    (0.3, 0.7, False),    # the tension is the friction state's: the stretch stands
    (None, 0.7, False),   # no input tension
])
def test_the_class_needs_both_the_tension_and_a_rival(share: float | None, rival_gain: float,
                                                     classed: bool) -> None:
    out = force_statement(_stretch(rival_gain), share, min_gain=0.2, max_delta_bic=-10.0)
    assert (out is not None) is classed
    if out is not None:
        assert out["class"] == ["rate_dependence", "tendon_elongation"]
        assert out["statement"].startswith("rate_dependence or tendon_elongation: ")
