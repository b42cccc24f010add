"""What the independent injector's runs can and cannot show.

A one-way backlash (the injector's ``asymmetry``) of size ``a`` is the symmetric backlash of
total width ``a`` (its ``dead_zone``) shifted by ``a / 2``: after the first motion the two
outputs differ by a constant, which every base's offset takes. On the output the two effects
are one effect, so no workflow can name both right from it; only the input tension tells them
apart (the dead zone sits before the load cell, the one-way backlash after it).
"""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.discrepancy.inject import NOISE_MM, REFERENCE_PLANTS, SIZES, inject


@pytest.mark.parametrize("plant", REFERENCE_PLANTS)
@pytest.mark.parametrize("strength", [1.0, 2.0])
def test_injected_asymmetry_is_a_dead_zone_plus_an_offset(plant: str, strength: float) -> None:
    a = SIZES["asymmetry"] * strength
    one_way = inject(plant, {"asymmetry": strength}, "triangle_decay")
    symmetric = inject(plant, {"dead_zone": a / SIZES["dead_zone"]}, "triangle_decay")
    clean = inject(plant, {}, "triangle_decay")
    after = one_way.t > 5.0  # past the first motion (the input ramps up over 2 s)
    gap = one_way.y[after] - symmetric.y[after]
    # a constant: a / 2 (times the plant's gain) ...
    assert np.mean(gap) == pytest.approx(-a / 2, rel=0.02)
    # ... to well under the noise (exactly on the shift-invariant Gamma and Bouc-Wen plants;
    # the Preisach plane's relays sit at fixed inputs, so a shifted input moves a few)
    assert np.max(np.abs(gap - np.mean(gap))) < 0.15 * NOISE_MM
    # while the effect itself is 22-45 times the noise
    assert np.sqrt(np.mean((one_way.y - clean.y)[after] ** 2)) > 15 * NOISE_MM
    # the input load cell: the dead zone's dead travel shows, the one-way backlash's does not
    assert one_way.tension is not None and clean.tension is not None
    assert symmetric.tension is not None
    np.testing.assert_array_equal(one_way.tension, clean.tension)
    assert np.sqrt(np.mean((symmetric.tension - clean.tension) ** 2)) > 0.05


def test_ragged_load_cell_streams_end_early_or_drop_out() -> None:
    from hysteresis.discrepancy.inject import ragged_tension

    run = inject("gamma", {}, "sine_decay")
    assert run.tension is not None
    end = ragged_tension(run.tension, "end", 1)
    assert np.isnan(end[-3:]).all() and np.isfinite(end[:-3]).all()
    gap = ragged_tension(run.tension, "gap", 2)
    assert 3 <= int(np.isnan(gap).sum()) <= 8 and np.isfinite(gap[[0, -1]]).all()
    assert not np.isnan(ragged_tension(run.tension, "mixed", 0)).any()
    with pytest.raises(Exception, match="ragged"):
        ragged_tension(run.tension, "frayed", 0)
