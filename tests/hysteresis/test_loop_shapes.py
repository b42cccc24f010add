"""Defaults that fit any loop's shape: the textbook softening loop (Bouc-Wen, the clean-room
plant of ``tests/cleanroom/plants.py``) that defeated three families' physical defaults, and a
backlash-like tendon-sheath loop on which they must keep their physical form."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis import make_family
from hysteresis.base import HysteresisError, check_inverse_reach
from tests.cleanroom import plants

GRIDS = {
    "gamma": [{"constraint": c} for c in ("nonneg", "free")],
    "preisach": [{"density_sign": s} for s in ("positive", "negative")],
    "coleman_hodgdon": [{"b_sign": b} for b in ("negative", "free")],
    "linear": [{"delay": 0}, {}],
}


def _records(plant: str) -> tuple[dict, dict]:
    return (plants.record(plant, "sine_decay", seed=1),
            plants.record(plant, "triangle_decay", seed=2))


def _heldout(family: str, params: dict, ident: dict, held: dict) -> float:
    model = make_family(family, **params).fit(ident["u"], ident["y"])
    return float(np.sqrt(np.mean((model.predict(held["u"]) - held["y"]) ** 2)))


@pytest.mark.parametrize("family", sorted(GRIDS))
def test_each_default_fits_a_softening_loop_within_1p5x_of_its_best_setting(family: str
                                                                            ) -> None:
    ident, held = _records("bouc_wen")
    default = _heldout(family, {}, ident, held)
    best = min(_heldout(family, kw, ident, held) for kw in GRIDS[family])
    assert default <= 1.5 * best, (family, default, best)


def test_the_chosen_form_is_recorded_and_the_physical_one_kept_where_it_fits() -> None:
    soft, _ = _records("bouc_wen")
    tsm, _ = _records("tendon_sheath")
    chosen = {"gamma": "constraint_", "preisach": "density_sign_",
              "coleman_hodgdon": "b_sign_"}
    other = {"gamma": "free", "preisach": "negative", "coleman_hodgdon": "free"}
    physical = {"gamma": "nonneg", "preisach": "positive", "coleman_hodgdon": "negative"}
    for family, attr in chosen.items():
        assert getattr(make_family(family).fit(soft["u"], soft["y"]), attr) == other[family]
        if family != "coleman_hodgdon":  # its free form is also a true backlash's flat reversal
            assert getattr(make_family(family).fit(tsm["u"], tsm["y"]), attr) == \
                physical[family]
    # the physical bound stays an explicit setting
    m = make_family("gamma", constraint="nonneg").fit(soft["u"], soft["y"])
    assert m.constraint_ == "nonneg" and (m.weights_ >= 0).all()


def test_an_uninvertible_chosen_form_is_refused_by_the_reach_guard() -> None:
    soft, held = _records("bouc_wen")
    span = (float(soft["u"].min()), float(soft["u"].max()))
    gamma = make_family("gamma").fit(soft["u"], soft["y"])
    if gamma.weights_.sum() <= 0:  # a free fit of a softening loop may turn the outer slope
        with pytest.raises(HysteresisError, match="constraint='auto' chose free"):
            check_inverse_reach(gamma, identified_range=span, desired=held["y"])
    bw = make_family("bouc_wen").fit(soft["u"], soft["y"])
    check_inverse_reach(bw, identified_range=span, desired=held["y"])  # what it reached
    with pytest.raises(HysteresisError, match="flattens at the ends"):
        check_inverse_reach(bw, identified_range=span, desired=2.0 * held["y"])
