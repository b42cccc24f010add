"""The shared estimator face on the linear, gamma and preisach families: registry, parameters,
lossless JSON round trip (predictions and inverses identical after reload)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hysteresis import (
    HysteresisError,
    HysteresisModel,
    NotFittedError,
    family_class,
    family_names,
    make_family,
)
from hysteresis.gamma import GammaModel, seed001_table41, sine_decay, triangle_decay
from hysteresis.linear import LinearModel
from hysteresis.play import gamma_simulate
from hysteresis.preisach import PreisachModel

U = sine_decay()
TRI = triangle_decay()
Q = np.array(seed001_table41()[20]["weights"])
Y, _ = gamma_simulate(U, np.linspace(0, 2, 11), Q, 0.0, np.zeros(11))

FAMILIES = {
    "linear": {"max_delay": 3},
    "gamma": {"n_operators": 11, "constraint": "sum_to_one"},
    "preisach": {"density": "gauss_gauss", "n_levels": 16},
    "preisach_np": {"density": "nonparametric", "n_levels": 16},
}


def test_registry_knows_the_three_families() -> None:
    names = family_names()
    for name in ("linear", "gamma", "preisach"):
        assert name in names
    assert family_class("gamma") is GammaModel
    assert family_class("linear") is LinearModel
    assert family_class("preisach") is PreisachModel
    with pytest.raises(HysteresisError, match="unknown model family"):
        make_family("tanh")


@pytest.mark.parametrize("key", sorted(FAMILIES))
def test_params_protocol(key: str) -> None:
    name = key.split("_")[0]
    model = make_family(name, **FAMILIES[key])
    params = model.get_params()
    for k, v in FAMILIES[key].items():
        assert params[k] == v
    clone = type(model)(**params)
    assert clone.get_params() == params
    assert model.set_params(**params) is model
    with pytest.raises(HysteresisError, match="no hyper-parameter"):
        model.set_params(colour="red")
    assert not model.is_fitted
    with pytest.raises(NotFittedError):
        model.predict(U)
    # __init__ sets no fitted attribute
    assert model.fitted_attributes() == {}


@pytest.mark.parametrize("key", sorted(FAMILIES))
def test_json_round_trip_is_lossless(key: str) -> None:
    name = key.split("_")[0]
    model = make_family(name, **FAMILIES[key]).fit(U, Y)
    text = model.to_json()
    json.loads(text)  # plain JSON
    back = HysteresisModel.from_json(text)
    assert type(back) is type(model)
    assert back.get_params() == model.get_params()
    fa, fb = model.fitted_attributes(), back.fitted_attributes()
    assert fa.keys() == fb.keys()
    for k, v in fa.items():
        if isinstance(v, np.ndarray):
            assert isinstance(fb[k], np.ndarray) and fb[k].dtype == v.dtype
            np.testing.assert_array_equal(fb[k], v)
        else:
            assert fb[k] == v or (v != v and fb[k] != fb[k]), k  # NaN multiplier of "free"
    np.testing.assert_array_equal(back.predict(TRI), model.predict(TRI))
    yd = 0.9 * model.predict(TRI)
    np.testing.assert_array_equal(back.invert(yd), model.invert(yd))
    assert back.to_json() == text
    # the class-specific loader works too
    assert type(type(model).from_json(text)) is type(model)


def test_score_is_r2() -> None:
    m = GammaModel(constraint="free").fit(U, Y)
    assert m.score(TRI, m.predict(TRI)) == 1.0
    lin = LinearModel().fit(U, Y)
    assert 0.9 < lin.score(U, Y) < 1.0


def test_families_fit_virtual_rig_sine_and_predict_its_triangle(
        virtual_pair_90_30: tuple[np.ndarray, ...]) -> None:
    """Seed 001 4.5: identify on the sine run, validate on the triangle run (90 deg, 30 mm)."""
    u, y, ut, yt = virtual_pair_90_30
    assert u.size == 8001
    rmse = {}
    for name in ("linear", "gamma", "preisach"):
        model = make_family(name).fit(u, y)
        err = model.predict(ut) - yt
        rmse[name] = float(np.sqrt(np.mean(err**2)))
        assert model.score(ut, yt) > (0.9 if name == "linear" else 0.99), name
        back = HysteresisModel.from_json(model.to_json())
        np.testing.assert_array_equal(back.predict(ut), model.predict(ut))
    # hysteresis models beat the no-hysteresis baseline on held-out data by a clear margin
    assert rmse["gamma"] < 0.6 * rmse["linear"]
    assert rmse["preisach"] < 0.6 * rmse["linear"]
    # and the Gamma inverse compensates the model's own hysteresis on the triangle target
    gm = make_family("gamma").fit(u, y)
    np.testing.assert_allclose(gm.predict(gm.invert(yt)), yt, atol=1e-9)


@pytest.mark.parametrize("name", ["linear", "gamma", "preisach"])
def test_hydra_family_config_instantiates_the_default_model(name: str) -> None:
    """conf/family/<name>.yaml names every hyper-parameter with the class default."""
    from pathlib import Path

    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    path = Path(__file__).resolve().parents[2] / "conf" / "family" / f"{name}.yaml"
    cfg = OmegaConf.load(path)
    model = instantiate(cfg, _convert_="all")
    assert type(model) is family_class(name)
    assert model.get_params() == family_class(name)().get_params()
    assert set(cfg.keys()) - {"_target_"} == set(model.get_params())


def test_as_1d_gives_the_kernels_one_array_type() -> None:
    from hysteresis.base import as_1d

    frozen = np.linspace(0.0, 1.0, 8)
    frozen.setflags(write=False)
    for x in (frozen, np.linspace(0.0, 1.0, 16)[::2], [0, 1, 2], np.ma.masked_array([1.0, 2.0])):
        a = as_1d(x, "u")
        assert type(a) is np.ndarray and a.dtype == np.float64
        assert a.flags.c_contiguous and a.flags.writeable
        assert np.array_equal(a, np.asarray(x, dtype=np.float64))
    assert not frozen.flags.writeable  # the caller's array is left as it was
    plain = np.linspace(0.0, 1.0, 8)
    assert as_1d(plain, "u") is plain  # no copy when none is needed


def test_as_1d_finds_every_non_finite_value_and_only_those() -> None:
    from hysteresis.base import as_1d

    for bad, at in (([1.0, np.nan, 2.0], 1), ([np.inf, -np.inf], 0), ([0.0, 0.0, -np.inf], 2)):
        with pytest.raises(HysteresisError, match=f"non-finite value at index {at}"):
            as_1d(np.array(bad), "u")
    # finite values whose sum overflows are still finite
    big = np.array([1e308, 1e308, -1e308])
    assert as_1d(big, "u") is big
    # a big-endian float64 is converted, not passed through as it is
    swapped = np.arange(4.0).astype(">f8")
    a = as_1d(swapped, "u")
    assert a.dtype == np.dtype("=f8") and np.array_equal(a, swapped)
