"""A backlash in the drive in front of a smooth loop, from the clean-room generator
``backlash_smooth`` (written from physics by a session that had not read the implementation):
the Bouc-Wen base searches its width itself and recovers it."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.discrepancy.effects import CANDIDATES, _sse, fit_joint
from hysteresis.discrepancy.runs import RunData
from hysteresis.discrepancy.workflow import base_factory_for
from tests.cleanroom import load

DEAD_TRAVEL_MM = 0.3


@pytest.fixture(scope="module")
def ident() -> RunData:
    """The generator's ``bw1`` plant (its Bouc-Wen, n = 1, at the scale it calibrates) behind
    a centred drive backlash, on its identification sine, read at 25 Hz."""
    gen = load("backlash_smooth")
    widths = gen._width_of("bw1", np.geomspace(0.05, 5.0, 40))["out"]
    k = int(np.argmax(np.abs(widths)))
    grid, w = np.geomspace(0.05, 5.0, 40)[k:], np.abs(widths[k:])
    order = np.argsort(w)
    plant = gen._with_scale("bw1", float(np.interp(gen.LOOP_WIDTH_MM, w[order], grid[order])))
    sine = gen.excitations()[0]
    half = DEAD_TRAVEL_MM / 2.0
    sim = gen.simulate(plant, sine.u[None, :], hl=half, hr=half, band=0.0)
    step = 40  # 1 kHz -> 25 Hz
    rng = np.random.default_rng(0)
    y = sim["y"][0, ::step] + rng.normal(0.0, gen.OUTPUT_NOISE_MM, sine.u[::step].size)
    return RunData(run_id="bw1-sine", t=sine.t_s[::step], u=sine.u[::step], y=y,
                   excitation="sine_decay")


def test_the_bouc_wen_base_recovers_a_drive_backlash(
        ident: RunData) -> None:
    dead_zone = CANDIDATES["dead_zone"]
    factory = base_factory_for("bouc_wen")
    own = fit_joint(factory, [], dead_zone, ident)
    assert own.terms[-1].effect.form(own.terms[-1].theta) == "backlash"
    assert own.terms[-1].theta == pytest.approx(DEAD_TRAVEL_MM, rel=0.15)
    assert np.sqrt(_sse(own, ident) / ident.n) < 1.5 * 0.01  # the output noise
