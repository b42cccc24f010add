"""The headline of an ``unexplained`` answer says which candidate the output alone would have
named and why the load cells refused it (:func:`hysteresis.discrepancy.headline.headline`)."""

from __future__ import annotations

from typing import Any

from hysteresis.discrepancy.headline import REFUSED_SHOWN_GAIN, headline


def _unexplained(gain: float, corroborated: bool | None) -> dict[str, Any]:
    rate = {"name": "rate_dependence", "relative_gain": gain,
            "load_cell_evidence": {"claim": "speed_ratio", "corroborated": corroborated,
                                   "per_configuration": {"c": 1.003}},
            "parameters": {"c": {"name": "rate_dependence", "form": "viscous"}}}
    drift = {"name": "drift", "relative_gain": 0.01, "load_cell_evidence": {}, "parameters": {}}
    return {"base_family": "gamma_tension", "verdict": "unexplained", "effects": [],
            "rankings": [[rate, drift]], "residual": {"rmse_over_noise": 7.8},
            "summary": {"heldout_rmse_before": 0.037}}


def test_a_candidate_the_load_cells_refused_is_told_with_their_reading() -> None:
    text = headline(_unexplained(0.37, False))
    assert text.startswith("unexplained: the base gamma_tension leaves a residual")
    assert ("rate_dependence (viscous) would cut it 37 % but the load cells do not show it "
            "(friction at speed over friction at low speed: 1.00)") in text


def test_only_a_refused_candidate_that_would_have_cleared_the_bar_is_told() -> None:
    assert "would cut" not in headline(_unexplained(0.9 * REFUSED_SHOWN_GAIN, False))
    # not refused: the load cells had nothing to say (None), or agreed
    assert "would cut" not in headline(_unexplained(0.37, None))
    assert "would cut" not in headline(_unexplained(0.37, True))
