"""Fits of the *discrete* moss model (mitsuba_veg.tune.discrete): the discrete run as a function
of its parameters on fixed seeds, patch losses, and parameter recovery by defect correction from
targets made by discrete runs on other seeds (docs/tuning.md). The acceptance here is small
(15 days, 100 k photons, 4 + 4 seeds); experiments/tune_discrete_fit.py runs the 30-day set."""
from pathlib import Path

import numpy as np
import pytest

from mitsuba_veg import tune
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.tune.discrete import (DiscreteExperiment, DiscreteMossModel, fit_discrete,
                                       fit_discrete_experiments, patch_cover, patch_labels,
                                       patch_loss_value)

ROOT = Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
SP = ["bryum_argenteum"]
DAYS, PHOTONS = 15, 100_000


@pytest.fixture(scope="module")
def dm():
    """The discrete model of the test set (15 days, 100 k photons, seeds 0-3).

    Returns
    -------
    DiscreteMossModel
        The model.
    """
    return DiscreteMossModel(SCEN, DAYS, species=SP, seeds=range(4), photons=PHOTONS)


@pytest.fixture(scope="module")
def base(dm):
    """Runs of seeds 0 and 1 at the table values, reported on days 10 and 15.

    Parameters
    ----------
    dm : DiscreteMossModel
        The discrete model.

    Returns
    -------
    DiscreteResult
        The runs.
    """
    return dm.run({}, report=[10, 15], seeds=[0, 1])


def test_common_random_numbers_and_parameters(dm, base):
    """The same seeds give identical runs, and the parameters reach the runs.

    Parameters
    ----------
    dm : DiscreteMossModel
        The discrete model.
    base : DiscreteResult
        Its runs at the table values.
    """
    again = dm.run({}, report=[10, 15], seeds=[0, 1])
    assert np.array_equal(again.cover, base.cover)           # same seeds: identical runs
    assert base.cover.shape == (2, 2, dm.n)
    assert np.allclose(base.total[:, -1], (base.cover[:, -1] * dm.areas).sum(1))
    # parameters reach the run: more growth -> more cover, less light -> other cover
    more = dm.run({"alpha_g": 0.4}, seeds=[0, 1])
    assert more.total[:, -1].mean() > 1.1 * base.total[:, -1].mean()
    dark = dm.run({"strength.sky": 0.5, "strength.sun": 0.5}, seeds=[0, 1])
    assert not np.array_equal(dark.cover[:, -1], base.cover[:, -1])
    assert dm.default_value("S1") == 60.0 and dm.default_value("strength.sky") == 1.0
    assert 0 < dm.default_value("albedo.ground") < 1


def test_bad_parameters(dm):
    """Unknown names, invalid values and days past the run are refused.

    Parameters
    ----------
    dm : DiscreteMossModel
        The discrete model.
    """
    with pytest.raises(ParameterError, match="S2"):
        dm.run({"S2": 1.0})
    with pytest.raises(ParameterError, match="albedo.moon"):
        dm.run({"albedo.moon": 0.2})
    with pytest.raises(ParameterError, match="alpha_g"):
        dm.run({"alpha_g": 1.5})                              # species validation (0, 1)
    with pytest.raises(ParameterError, match="report"):
        dm.run({}, report=[DAYS + 1])
    with pytest.raises(ParameterError, match="trees"):
        DiscreteMossModel(SCEN, 2, species=SP, seeds=[0], photons=10_000, world=True)


def test_patches(dm, base):
    """Patch labels, the area-weighted patch cover, and a zero loss against itself.

    Parameters
    ----------
    dm : DiscreteMossModel
        The discrete model.
    base : DiscreteResult
        Its runs at the table values.
    """
    data_c = np.asarray(base.cover[0, -1])
    cen = np.zeros((dm.n, 3))
    lab = patch_labels(cen, dm.shape_slices, np.ones(dm.n, bool), 0.2)
    assert lab.max() + 1 == len(dm.shape_slices)                  # one patch per shape
    pc = patch_cover(data_c, dm.areas, lab)
    for k, sl in enumerate(dm.shape_slices.values()):
        assert pc[k] == pytest.approx((data_c[sl] * dm.areas[sl]).sum() / dm.areas[sl].sum())
    assert patch_loss_value(data_c, dm.areas, lab, pc) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ParameterError):
        patch_labels(cen, dm.shape_slices, np.ones(dm.n, bool), 0.0)


@pytest.fixture(scope="module")
def surrogate():
    """The relaxed model of the test set (near field, t = 0.02).

    Returns
    -------
    SmoothMossModel
        The model.
    """
    data = tune.prepare(SCEN, days=DAYS, species=SP, photons=PHOTONS, light_every=15)
    return tune.SmoothMossModel(data, temperature=0.02, closure="near-field")


@pytest.mark.slow
def test_fit_discrete_recovers_alpha_g(dm, surrogate, tmp_path):
    """alpha_g from -30 %: target = mean of 4 discrete runs on seeds 100-103 (~3 min on 2
    shared cores: each iteration runs the 4 discrete runs and a 25-step relaxed fit).

    Parameters
    ----------
    dm : DiscreteMossModel
        The discrete model (seeds 0-3).
    surrogate : SmoothMossModel
        The relaxed model.
    tmp_path : pathlib.Path
        Output folder.
    """
    tm = DiscreteMossModel(SCEN, DAYS, species=SP, seeds=range(100, 104), photons=PHOTONS)
    target = tm.run({}).mean()
    res = fit_discrete(dm, surrogate, target, ["alpha_g"], init={"alpha_g": 0.21},
                       iterations=4, steps=25, out=tmp_path)
    assert abs(res.values["alpha_g"] / 0.3 - 1) < 0.05, res.iterations
    # the discrete cover at the fit matches the target's (at the start it is far below)
    tot = float(np.sum(target * dm.areas))
    assert abs(res.iterations[-1]["covered_m2_discrete"] / tot - 1) < 0.1, res.iterations
    assert res.iterations[0]["covered_m2_discrete"] < 0.9 * tot, res.iterations
    assert (tmp_path / "fitted_discrete.json").exists()


def test_fit_discrete_arguments(dm, surrogate):
    """No parameters, no iterations, an unknown loss and a target of the wrong size are refused.

    Parameters
    ----------
    dm : DiscreteMossModel
        The discrete model.
    surrogate : SmoothMossModel
        The relaxed model.
    """
    t = np.zeros(dm.n)
    with pytest.raises(ParameterError):
        fit_discrete(dm, surrogate, t, [], iterations=1)
    with pytest.raises(ParameterError):
        fit_discrete(dm, surrogate, t, ["S1"], iterations=0)
    with pytest.raises(ParameterError):
        fit_discrete(dm, surrogate, t, ["S1"], loss="l1")
    with pytest.raises(ParameterError):
        fit_discrete(dm, surrogate, np.zeros(3), ["S1"])


@pytest.mark.slow
def test_fit_discrete_experiments_plumbing(surrogate):
    """Several experiments: the summed discrete loss is the weighted sum of the experiments'
    losses, each the single experiment's; the record names every experiment.

    Parameters
    ----------
    surrogate : SmoothMossModel
        The relaxed model.
    """
    dm1 = DiscreteMossModel(SCEN, DAYS, species=SP, seeds=[0], photons=PHOTONS)
    # the target: the mean of the run's own seed and another (the run then lies closer to
    # it than bare ground does, whatever the other seed's moss)
    tm = DiscreteMossModel(SCEN, DAYS, species=SP, seeds=[0, 100], photons=PHOTONS)
    target = tm.to_layout(tm.run({}).mean(), surrogate.data.shape_slices)
    bare = np.zeros_like(target)
    kw = dict(init={"alpha_g": 0.21}, iterations=1, steps=1)
    one = fit_discrete(dm1, surrogate, target, ["alpha_g"], **kw)
    l0 = one.iterations[0]["discrete_loss"]
    two = fit_discrete_experiments([DiscreteExperiment(dm1, surrogate, target, "a", 0.5),
                                    DiscreteExperiment(dm1, surrogate, bare, "bare", 3.0)],
                                   ["alpha_g"], **kw)
    it = two.iterations[0]
    e = it["experiments"]
    assert set(e) == {"a", "bare"}
    assert e["a"]["discrete_loss"] == pytest.approx(l0, rel=1e-9)   # same start, same runs
    assert e["bare"]["discrete_loss"] > l0                           # moss vs bare ground
    assert it["discrete_loss"] == pytest.approx(0.5 * l0 + 3.0 * e["bare"]["discrete_loss"],
                                                rel=1e-9)
    assert it["covered_m2_discrete"] == pytest.approx(2 * e["a"]["covered_m2_discrete"])


@pytest.mark.slow
def test_safeguarded_outer_step(surrogate, monkeypatch):
    """accept="decrease": a step that raises the discrete loss is halved ``backtrack`` times,
    then the fit stops where it was; a step that lowers it is taken whole. "always" takes
    every step. The inner fit is replaced by a fixed proposal (bare-ground target: the loss
    rises with alpha_g).

    Parameters
    ----------
    surrogate : SmoothMossModel
        The relaxed model.
    monkeypatch : pytest.MonkeyPatch
        Replaces the inner fit.
    """
    from mitsuba_veg.tune import discrete as disc
    dm1 = DiscreteMossModel(SCEN, DAYS, species=SP, seeds=[0], photons=PHOTONS)
    bare = np.zeros(surrogate.data.areas.shape)
    proposal = {}
    monkeypatch.setattr(disc, "_inner_adam",
                        lambda terms, params, theta, *a: (dict(proposal), 0.0))
    kw = dict(init={"alpha_g": 0.3}, iterations=3, steps=1)

    proposal["alpha_g"] = 0.6                           # more growth: worse on bare ground
    up = fit_discrete(dm1, surrogate, bare, ["alpha_g"], accept="decrease", backtrack=2, **kw)
    first = up.iterations[0]
    assert [t["step"] for t in first["trials"]] == [1.0, 0.5, 0.25]
    assert [t["params"]["alpha_g"] for t in first["trials"]] == pytest.approx([0.6, 0.45,
                                                                               0.375])
    assert all(t["discrete_loss"] > first["discrete_loss"] for t in first["trials"])
    assert first["step"] == 0.0 and len(up.iterations) == 2        # stopped, then the final row
    assert up.values["alpha_g"] == 0.3 and up.discrete_loss == first["discrete_loss"]

    always = fit_discrete(dm1, surrogate, bare, ["alpha_g"], accept="always", **kw)
    assert always.values["alpha_g"] == 0.6 and always.discrete_loss > first["discrete_loss"]
    assert "trials" not in always.iterations[0]

    proposal["alpha_g"] = 0.15                          # less growth: better, taken whole
    down = fit_discrete(dm1, surrogate, bare, ["alpha_g"], accept="decrease", iterations=1,
                        init={"alpha_g": 0.3}, steps=1)
    assert down.iterations[0]["step"] == 1.0 and len(down.iterations[0]["trials"]) == 1
    assert down.values["alpha_g"] == 0.15
    assert down.discrete_loss == down.iterations[0]["trials"][0]["discrete_loss"] \
        < first["discrete_loss"]
    with pytest.raises(ParameterError, match="accept"):
        fit_discrete(dm1, surrogate, bare, ["alpha_g"], accept="sometimes")
    with pytest.raises(ParameterError, match="backtrack"):
        fit_discrete(dm1, surrogate, bare, ["alpha_g"], backtrack=-1)


def test_inner_fit_sums_weighted_terms(monkeypatch):
    """The inner Adam fit minimises the weighted sum of its terms: with two quadratic terms
    (a fake gradient for value_and_grad) it ends at their weighted mean.

    Parameters
    ----------
    monkeypatch : pytest.MonkeyPatch
        Replaces value_and_grad.
    """
    from mitsuba_veg.tune import discrete as disc
    from mitsuba_veg.tune.grad import GradResult
    import mitsuba as mi

    class Model:
        T = mi.Float64

    def fake(model, vals, loss_fn, days=None):
        c = loss_fn                                  # the term's centre
        x = vals["x"]
        return GradResult((x - c) ** 2, {"x": 2 * (x - c)})
    monkeypatch.setattr(disc, "value_and_grad", fake)
    terms = [(Model(), 1, 1.0, 1.0), (Model(), 1, 3.0, 3.0)]   # centres 1 and 3, weights 1, 3
    vals, L = disc._inner_adam(terms, ["x"], {"x": 0.0}, {"x": 1.0}, {"x": (-10.0, 10.0)},
                               steps=400, lr=0.05, lr_final=0.02)
    assert vals["x"] == pytest.approx(2.5, abs=0.02)              # (1 * 1 + 3 * 3) / 4
    assert L == pytest.approx(1 * 1.5 ** 2 + 3 * 0.5 ** 2, abs=0.05)


def test_fit_discrete_experiments_arguments(dm, surrogate):
    """Empty lists, repeated names, zero weights and malformed experiments are refused.

    Parameters
    ----------
    dm : DiscreteMossModel
        The discrete model.
    surrogate : SmoothMossModel
        The relaxed model.
    """
    t = np.zeros(dm.n)
    with pytest.raises(ParameterError, match="at least one"):
        fit_discrete_experiments([], ["S1"])
    with pytest.raises(ParameterError, match="distinct"):
        fit_discrete_experiments([DiscreteExperiment(dm, surrogate, t, "a"),
                                  DiscreteExperiment(dm, surrogate, t, "a")], ["S1"])
    with pytest.raises(ParameterError, match="weight"):
        fit_discrete_experiments([DiscreteExperiment(dm, surrogate, t, "a", 0.0)], ["S1"])
    with pytest.raises(ParameterError, match="experiments"):
        fit_discrete_experiments([(dm, surrogate)], ["S1"])


def test_patch_loss_gradient_smooth_at_empty_patches():
    """The inner fit's loss at the iterate: the relaxed cover shifted by the defect D - R
    puts patches without discrete moss at c = 0 +- float32 rounding. Its gradient must not
    depend on that rounding (four evaluations whose shifts differ by ~1e-7 relative agree to
    1e-3) and must agree with central differences of patch_loss_value (float64) within 2 %.
    With the former hard clip max(c, 0) and sqrt(c + 1e-6), empty patches with a target
    switched their slope (~500) on or off with the rounding's sign, while the central
    difference saw half of it."""
    import drjit as dr
    from mitsuba_veg.tune.discrete import _patch_loss
    from mitsuba_veg.tune.lifecycle import real_type
    T = real_type("float32")
    rng = np.random.default_rng(3)
    n_p, per = 40, 10
    n = n_p * per
    labels = np.repeat(np.arange(n_p), per)
    areas = rng.uniform(1e-3, 4e-3, n)
    R0 = rng.uniform(0.01, 0.3, n).astype(np.float32).astype(float)
    k = rng.uniform(-1.0, 1.0, n).astype(np.float32).astype(float)
    p0 = 0.3

    def relaxed(p):                                   # the "relaxed model" in float64
        return R0 * np.exp(p * k)
    empty = labels < n_p // 2                          # no discrete moss on half the patches
    D = np.where(empty, 0.0, rng.uniform(0.0, 0.2, n))
    target = patch_cover(rng.uniform(0.0, 0.05, n), areas, labels)
    target[: n_p // 4] = 0.0                           # empty in the target too
    assert np.sum(np.abs(target[empty[::per]])) > 0

    def grad(noise):
        # the forward run's R differs from the adjoint's cover by float32 rounding
        R = relaxed(p0) * (1 + noise)
        lf = _patch_loss(T(D - R), areas, labels, target, "sqrt", T)
        p = T(p0)
        dr.enable_grad(p)
        loss = lf(T(R0) * dr.exp(p * T(k)), None, None, None)
        dr.backward(loss)
        return float(np.asarray(dr.grad(p))[0])
    gs = [grad(rng.normal(0, 1e-7, n)) for _ in range(4)]
    shift = D - relaxed(p0)
    h = 1e-5
    fd = (patch_loss_value(relaxed(p0 + h) + shift, areas, labels, target)
          - patch_loss_value(relaxed(p0 - h) + shift, areas, labels, target)) / (2 * h)
    assert abs(fd) > 1e-3                              # a gradient to compare
    assert np.allclose(gs, gs[0], rtol=1e-3, atol=0), gs
    assert gs[0] == pytest.approx(fd, rel=0.02), (gs, fd)
