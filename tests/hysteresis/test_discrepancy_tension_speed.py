"""A stretch named on a tension that carries a speed-dependent force, or on an output tension that
follows the output, is answered with its class."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.discrepancy._ops import play
from hysteresis.discrepancy.evidence import (
    FOLLOWS_OUTPUT_R2,
    SPEED_SHARE,
    output_tension_follows,
    tension_speed_share,
)
from hysteresis.discrepancy.identifiability import force_statement, statement
from hysteresis.discrepancy.runs import RunData
from tests.cleanroom import load


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


def _follower(spring: bool) -> RunData:
    """A run whose output tension is a return spring's (``F0 + k y``) or a constant force's."""
    run = _run(0.0)
    rng = np.random.default_rng(1)
    y = 0.85 * run.u
    load = 5.0 + 0.3 * y if spring else np.full(run.n, 5.0)
    return RunData(run_id="r", t=run.t, u=run.u, y=y,
                   tension_out=load + rng.normal(0, 0.01, run.n))


def test_a_spring_followers_tension_follows_the_output() -> None:
    spring = output_tension_follows([_follower(True)])
    constant = output_tension_follows([_follower(False)])
    assert spring is not None and spring > FOLLOWS_OUTPUT_R2
    assert constant is not None and constant < 0.1
    assert output_tension_follows([_run(0.0)]) is None  # no output tension


@pytest.mark.parametrize(("follows", "classed"), [(0.9999, True), (0.5, False), (None, False)])
def test_a_stretch_on_an_output_tension_that_follows_the_output_keeps_its_class(
        follows: float | None, classed: bool) -> None:
    """A stretch with the square of a spring follower's tension is a quadratic of the output:
    the output tension does not split it from a static curvature (or the plant's own
    asymmetric loop). A tension that carries more than the output does."""
    entry = {"name": "tendon_elongation", "form": "square_output", "evidence": {}}
    out = statement(entry, {"tension", "tension_out"}, follows_output=follows)
    assert (out is not None) is classed
    if out is not None:
        assert out["label"] == "saturation or tendon_elongation"
        assert "the output tension follows the output" in out["statement"]
    # without the channel the class stands whatever the reading
    assert statement(entry, {"tension"}, follows_output=follows) is not None


@pytest.mark.parametrize("plant", ["GPIPlant", "LuGrePlant"])
def test_the_cleanroom_spring_follower_leaves_the_output_tension_nothing_new(plant: str) -> None:
    """On the tenth clean-room generator's plants (``tests/cleanroom/absorbed_effects.py``,
    written without our code: a generalised Prandtl-Ishlinskii sum with different up and down
    envelopes, a LuGre tendon-sheath), a return-spring follower's tension is read as following
    the output, so a stretch on its square stays a class there."""
    generator = load("absorbed_effects")
    model = generator.calibrate(getattr(generator, plant)())
    t = np.arange(0.0, 20.0, 0.04)
    u = 6.0 * np.sin(2 * np.pi * 0.2 * t) * np.exp(-t / 20.0)
    out = model.simulate(u, start="loaded", h=0.04)
    rng = np.random.default_rng(2)
    run = RunData(run_id="r", t=t, u=u, y=out["y"] + rng.normal(0, 0.01, t.size),
                  tension=out["t_in"], tension_out=out["t_out"] + rng.normal(0, 0.01, t.size))
    follows = output_tension_follows([run])
    assert follows is not None and follows >= FOLLOWS_OUTPUT_R2
