"""Gradients of the relaxed moss model on the moss garden against central finite differences:
species parameters (S1, T1, alpha_g), climate (T, rh), reflectance (roof and ground, through
the differentiable photon pass) and the sky's strength, in both reverse-mode schemes (day-by-day
adjoint, one graph), with the mean-field and the near-field closure. Tolerance: 1 % relative
(the README states it)."""
from pathlib import Path

import drjit as dr
import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
from mitsuba_veg import tune
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.tune.fitting import coverage_loss

ROOT = Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
DAYS = 24
PARAMS = {"S1": 60.0, "T1": 299.15, "alpha_g": 0.3, "T": 288.15, "rh": 0.73, "albedo.roof": 0.35,
          "albedo.ground": 0.25, "strength.sky": 1.0}
REL = 0.01
#: central-difference steps (small against the scale of each parameter, large against rounding)
STEPS = {"S1": 0.5, "T1": 0.1, "alpha_g": 0.003, "T": 0.05, "rh": 0.002, "albedo.roof": 0.01,
         "albedo.ground": 0.01, "strength.sky": 0.01}


@pytest.fixture(scope="module")
def model():
    data = tune.prepare(SCEN, days=DAYS, species=["bryum_argenteum"], photons=100_000,
                        light_every=12, differentiable_light=True)
    return tune.SmoothMossModel(data, temperature=0.05, precision="float64")


@pytest.fixture(scope="module")
def loss_fn(model):
    # target: a run with other parameters, so that every parameter has a generic gradient
    with dr.suspend_grad():
        target = np.asarray(model.run({"S1": 50.0, "T1": 296.0, "alpha_g": 0.27, "T": 289.0,
                                       "rh": 0.75, "albedo.roof": 0.3, "albedo.ground": 0.2,
                                       "strength.sky": 1.1}).cover)
    T = model.T
    w = T(model.data.areas / model.data.areas.sum())
    tg = T(target)
    lf = coverage_loss("sqrt")
    return lambda res, m: lf(res.cover, tg, w, m)


@pytest.fixture(scope="module")
def adjoint(model, loss_fn):
    return tune.value_and_grad(model, PARAMS, loss_fn, checkpoint_every=5)


@pytest.mark.parametrize("name", list(PARAMS))
def test_gradient_matches_central_difference(model, loss_fn, adjoint, name):
    fd = tune.finite_difference(model, PARAMS, loss_fn, name, STEPS[name])
    ad = adjoint.grad[name]
    assert abs(fd) > 0
    # measured (24 days, float64): S1 5.8e-4, T1 1.3e-4, alpha_g 8.5e-4, T 2.2e-5, rh 9.4e-5,
    # albedo.roof 1.6e-4, albedo.ground 3.2e-3, strength.sky 6.6e-5
    assert ad == pytest.approx(fd, rel=REL), (name, ad, fd)


@pytest.fixture(scope="module")
def model_nf(model):
    return tune.SmoothMossModel(model.data, temperature=0.05, precision="float64",
                                closure="near-field")


@pytest.mark.parametrize("name", ["S1", "T1", "alpha_g"])
def test_near_field_gradient_matches_central_difference(model_nf, loss_fn, name):
    p = {k: PARAMS[k] for k in ("S1", "T1", "alpha_g")}
    ad = tune.value_and_grad(model_nf, p, loss_fn, checkpoint_every=5).grad[name]
    fd = tune.finite_difference(model_nf, p, loss_fn, name, STEPS[name])
    assert abs(fd) > 0
    # measured: S1 5.9e-4, T1 1.7e-4, alpha_g 3.2e-4
    assert ad == pytest.approx(fd, rel=REL), (name, ad, fd)


def test_adjoint_equals_one_graph(model, loss_fn):
    p = {"S1": 55.0, "T": 288.5, "albedo.roof": 0.4}
    a = tune.value_and_grad(model, p, loss_fn, days=8, checkpoint_every=3)
    g = tune.value_and_grad(model, p, loss_fn, days=8, mode="graph")
    assert a.loss == pytest.approx(g.loss, rel=1e-12)
    for k in p:
        assert a.grad[k] == pytest.approx(g.grad[k], rel=1e-9, abs=1e-15), k
    assert a.stats["mode"] == "adjoint" and a.stats["checkpoints"] == 3


def test_adjoint_stats_and_loss(adjoint):
    assert adjoint.loss > 0 and np.isfinite(adjoint.loss)
    s = adjoint.stats
    assert s["checkpoints"] == 5 and s["state_bytes"] > 0
    assert s["stored_state_bytes"] <= s["state_bytes"] * 11


def test_bad_parameter_names(model, loss_fn):
    with pytest.raises(ParameterError, match="S2"):
        tune.value_and_grad(model, {"S2": 1.0}, loss_fn, days=2)
    with pytest.raises(ParameterError, match="albedo.moon"):
        tune.value_and_grad(model, {"albedo.moon": 0.2}, loss_fn, days=2)
