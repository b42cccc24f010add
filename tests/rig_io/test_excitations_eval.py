"""The campaign's evaluation-only excitations: seed 001 eq. 4.11 at other amplitudes, and
band-limited random motion with drifting amplitude and rate (seed 002's non-periodic test)."""

from __future__ import annotations

import numpy as np
import pytest

from rig_io.virtual.excitations import (
    EVALUATION_EXCITATIONS,
    check_excitation,
    make_excitation,
    manifest_excitation,
)

BAND = {"amplitude_mm": 5.0, "band_hz": [0.03, 0.35], "duration_s": 40.0, "seed": 11}


def _spec(kind: str) -> dict[str, object]:
    spec = next(e for e in EVALUATION_EXCITATIONS if e["kind"] == kind)
    return {k: v for k, v in spec.items() if k != "kind"}


def _reversals(y: np.ndarray) -> np.ndarray:
    d = np.sign(np.diff(y))
    d = d[d != 0]
    return np.flatnonzero(np.diff(d) != 0) + 1


def test_mixed_sine_is_eq_4_11_at_other_amplitudes() -> None:
    terms = _spec("mixed_sine")["terms"]
    assert isinstance(terms, list)
    freqs = [t["frequency_hz"] for t in terms]
    amps = np.array([t["amplitude"] for t in terms])
    # eq. 4.11: 7 sin(pi t / 4) + 2 sin(1.1 pi t / 4) - 4 sin(0.2 pi t / 4) + sin(0.45 pi t / 4)
    assert freqs == pytest.approx([1 / 8, 1.1 / 8, 0.2 / 8, 0.45 / 8])
    assert amps / amps[0] == pytest.approx(np.array([7.0, 2.0, -4.0, 1.0]) / 7.0)
    t, y = make_excitation("mixed_sine", **_spec("mixed_sine"))
    ref = sum(a * np.sin(2 * np.pi * f * t) for a, f in zip(amps, freqs, strict=True))
    assert np.max(np.abs(y - ref)) < 1e-12
    # not the identification amplitudes (6, 4.5, 3, 1.5 mm), but inside their +-6 mm range
    assert 4.0 < np.max(np.abs(y)) < 6.0 and t[-1] == pytest.approx(30.0)


def test_band_random_is_reproducible_from_rest_and_peaks_at_its_amplitude() -> None:
    t, y = make_excitation("band_random", **BAND)
    assert t.size == 4001 and np.all(np.diff(t) > 0)
    assert y[0] == 0.0 and abs(y[-1]) < 1e-12
    assert np.max(np.abs(y)) == pytest.approx(5.0)
    _, again = make_excitation("band_random", **BAND)
    np.testing.assert_array_equal(y, again)
    _, other = make_excitation("band_random", **{**BAND, "seed": 12})
    assert np.max(np.abs(other - y)) > 1.0
    # the spectrum stays low: almost no power above twice the band's upper edge
    spec = np.abs(np.fft.rfft(y)) ** 2
    freqs = np.fft.rfftfreq(y.size, 0.01)
    assert spec[freqs > 0.7].sum() < 1e-3 * spec.sum()


def test_band_random_has_minor_loops_and_varying_rate() -> None:
    t, y = make_excitation("band_random", **BAND)
    rev = _reversals(y)
    assert rev.size >= 12
    swings = np.abs(np.diff(y[rev]))
    # minor loops (small reversals) beside major ones
    assert swings.min() < 0.2 * swings.max()
    # the rate varies: the mean speed between reversals differs by > 3x
    times = np.diff(t[rev])
    speeds = swings / times
    assert speeds.max() > 3.0 * speeds.min()
    # not periodic: the record does not repeat at any lag of 2-20 s
    yc = y - y.mean()
    for lag in range(200, 2000, 50):
        corr = np.dot(yc[:-lag], yc[lag:]) / np.sqrt(np.dot(yc[:-lag], yc[:-lag])
                                                    * np.dot(yc[lag:], yc[lag:]))
        assert corr < 0.9


def test_band_random_short_record_and_manifest() -> None:
    t, y = make_excitation("band_random", **{**BAND, "duration_s": 10.0})
    assert t[-1] == pytest.approx(10.0) and np.max(np.abs(y)) == pytest.approx(5.0)
    block = manifest_excitation("band_random", {**BAND, "rate_range": (0.5, 1.5)})
    assert block == {"kind": "free", "name": "band_random", **BAND, "rate_range": [0.5, 1.5]}


@pytest.mark.parametrize(("params", "match"), [
    ({**BAND, "band_hz": [0.4, 0.1]}, "band_hz"),
    ({**BAND, "band_hz": [0.1, 0.2], "duration_s": 1.0}, "holds no frequency"),
    ({**BAND, "rate_range": [0.0, 1.0]}, "rate_range"),
    ({**BAND, "amplitude_mm": -1.0}, "amplitude_mm"),
    ({k: v for k, v in BAND.items() if k != "seed"}, "missing"),
    ({**BAND, "speed": 2.0}, "does not take"),
])
def test_band_random_bad_parameters(params: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        check_excitation("band_random", params)
        make_excitation("band_random", **params)
