"""Unit tests of the moss species table and fitness functions (paper 000 §3.6, eqs 3.17-3.24).

Reference values are computed here with plain ``math``:
    s(x, x0, x1) = exp(-4 ln2 (x - (x0 + x1)/2)^2 / (x1 - x0)^2)             eq 3.18
    g = 1/2 + (s - 1/2)^n if s > 1/2 else 1/2 - (1/2 - s)^n                   eq 3.19
e.g. Bryum argenteum (T 274.15-299.15, nT 1; rh 0.8-1.2, nrh 0.5; S 0-60, nS 1) at Ts = 287.48633 K,
rhs = 0.9999629, S = 10 W m-2:
    s_T  = exp(-2.7725887 * (287.48633 - 286.65)^2 / 25^2)   = 0.9969020 -> g_T = 0.9969020
    s_rh = exp(-2.7725887 * (0.9999629 - 1.0)^2 / 0.4^2)     = 0.99999998 -> g_rh = 0.5 + sqrt(0.49999998)
                                                               = 1.2071068
    s_S  = exp(-2.7725887 * (10 - 30)^2 / 60^2)              = 0.7348672 -> g_S = 0.7348672
    G    = 0.9969020 * 1.2071068 * 0.7348672                 = 0.8843151
    D    = 0.3 * (0.8843151 - 0.1)                           = 0.2352945
"""
from __future__ import annotations

import importlib
import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (selects the variant)
from mitsuba_veg import moss
from mitsuba_veg.moss import Species, SPECIES, load_species
from mitsuba_veg.errors import ParameterError

import drjit as dr
from drjit.llvm.ad import Float, Float64

# `mitsuba_veg.moss.fitness` is the function g (eq 3.19, as in the API sketch); its module is
# mitsuba_veg.moss.fitness_model.
fit = importlib.import_module("mitsuba_veg.moss.fitness_model")

LN2x4 = 4 * math.log(2)


def s_hand(x, x0, x1):
    return math.exp(-LN2x4 * (x - (x0 + x1) / 2) ** 2 / (x1 - x0) ** 2)


def g_hand(x, x0, x1, n):
    s = s_hand(x, x0, x1)
    return 0.5 + (s - 0.5) ** n if s > 0.5 else 0.5 - (0.5 - s) ** n


# Table 4.2 of paper 000, written out
TABLE_4_2 = {
    "bryum_argenteum": dict(T0=274.15, T1=299.15, nT=1, rh0=0.8, rh1=1.2, nrh=0.5, S0=0.0, S1=60.0,
                            nS=1, alpha_g=0.3, tau_g=0.1, tau_b=0.4, tau_d=0.1),
    "hypnum_plumaeforme": dict(T0=276.15, T1=295.15, nT=1, rh0=0.9, rh1=1.1, nrh=0.5, S0=0.0,
                               S1=40.0, nS=1, alpha_g=0.25, tau_g=0.1, tau_b=0.35, tau_d=0.15),
    "polytrichum": dict(T0=278.15, T1=297.15, nT=1, rh0=0.85, rh1=1.15, nrh=1, S0=0.0, S1=50.0,
                        nS=1, alpha_g=0.3, tau_g=0.075, tau_b=0.37, tau_d=0.12),
}


# ---------------------------------------------------------------------------- eq 3.18
def test_s_values():
    assert fit.s(274.15, 274.15, 299.15) == pytest.approx(0.5, rel=1e-14)
    assert fit.s(299.15, 274.15, 299.15) == pytest.approx(0.5, rel=1e-14)
    assert fit.s(286.65, 274.15, 299.15) == 1.0
    assert fit.s(10.0, 0.0, 60.0) == pytest.approx(s_hand(10.0, 0.0, 60.0), rel=1e-14)
    assert fit.s(10.0, 0.0, 60.0) == pytest.approx(0.7348672, rel=1e-6)
    # half-width of the range further out: s = 2^-4 = 1/16
    assert fit.s(60.0 + 30.0, 0.0, 60.0) == pytest.approx(1 / 16, rel=1e-13)


# ---------------------------------------------------------------------------- eq 3.19
@pytest.mark.parametrize("n", [0.25, 0.5, 0.75, 1.0])
def test_g_half_at_edges_and_symmetric(n):
    x0, x1 = 0.8, 1.2
    assert fit.fitness(x0, x0, x1, n) == pytest.approx(0.5, abs=1e-6)
    assert fit.fitness(x1, x0, x1, n) == pytest.approx(0.5, abs=1e-6)
    d = np.linspace(0.0, 1.0, 101)
    c = 1.0
    assert np.allclose(fit.fitness(c + d, x0, x1, n), fit.fitness(c - d, x0, x1, n), rtol=0, atol=1e-12)
    for x in (0.7, 0.85, 1.0, 1.1, 1.5):
        assert fit.fitness(x, x0, x1, n) == pytest.approx(g_hand(x, x0, x1, n), rel=1e-13)


@pytest.mark.parametrize("n", [0.25, 0.5, 1.0])
def test_g_monotone_between_centre_and_edge(n):
    x = np.linspace(286.65, 330.0, 2001)  # centre -> far outside
    g = fit.fitness(x, 274.15, 299.15, n)
    assert np.all(np.diff(g) <= 0)
    x = np.linspace(240.0, 286.65, 2001)
    assert np.all(np.diff(fit.fitness(x, 274.15, 299.15, n)) >= 0)


def test_g_centre_and_n1_equals_s():
    assert fit.fitness(286.65, 274.15, 299.15, 1.0) == 1.0
    x = np.linspace(250, 320, 141)
    assert np.allclose(fit.fitness(x, 274.15, 299.15, 1.0), fit.s(x, 274.15, 299.15), rtol=1e-15)
    # as printed, n < 1 gives g(centre) = 1/2 + (1/2)^n and g -> 1/2 - (1/2)^n far away
    assert fit.fitness(1.0, 0.8, 1.2, 0.5) == pytest.approx(0.5 + math.sqrt(0.5), rel=1e-14)
    assert fit.fitness(5.0, 0.8, 1.2, 0.5) == pytest.approx(0.5 - math.sqrt(0.5), rel=1e-12)


def test_smaller_n_is_sharper():
    inside, outside = 1.1, 1.3
    assert fit.fitness(inside, 0.8, 1.2, 0.5) > fit.fitness(inside, 0.8, 1.2, 1.0)
    assert fit.fitness(outside, 0.8, 1.2, 0.5) < fit.fitness(outside, 0.8, 1.2, 1.0)


def test_fitness_rejects_bad_scalar_window():
    with pytest.raises(ParameterError, match="x0"):
        fit.fitness(1.0, 1.2, 0.8, 1.0)
    with pytest.raises(ParameterError, match="n"):
        fit.fitness(1.0, 0.8, 1.2, 0.0)


# ---------------------------------------------------------------------------- eqs 3.17, 3.20
def test_daily_fitness_and_growth_hand_values():
    Ts, rhs, S = 287.48633, 0.9999629, 10.0
    b = TABLE_4_2["bryum_argenteum"]
    G_ref = (g_hand(Ts, b["T0"], b["T1"], b["nT"]) * g_hand(rhs, b["rh0"], b["rh1"], b["nrh"])
             * g_hand(S, b["S0"], b["S1"], b["nS"]))
    G = moss.daily_fitness("bryum_argenteum", Ts, rhs, S)
    assert G == pytest.approx(G_ref, rel=1e-13)
    assert G == pytest.approx(0.8843151, rel=1e-6)
    D = moss.daily_growth(SPECIES["bryum_argenteum"], G)
    assert D == pytest.approx(0.3 * (G_ref - 0.1), rel=1e-13)
    assert D == pytest.approx(0.2352945, rel=1e-6)
    # vectorised over moss, all species
    for key, p in TABLE_4_2.items():
        Tsv = np.array([270.0, 285.0, 300.0])
        rv = np.array([0.7, 1.0, 1.3])
        Sv = np.array([0.0, 20.0, 80.0])
        Gv = moss.daily_fitness(key, Tsv, rv, Sv)
        for i in range(3):
            ref = (g_hand(Tsv[i], p["T0"], p["T1"], p["nT"]) * g_hand(rv[i], p["rh0"], p["rh1"], p["nrh"])
                   * g_hand(Sv[i], p["S0"], p["S1"], p["nS"]))
            assert Gv[i] == pytest.approx(ref, rel=1e-12)


# ---------------------------------------------------------------------------- eq 3.24
def test_germination_windows():
    assert (fit.SPORE_L0, fit.SPORE_L1, fit.GEMMA_L0, fit.GEMMA_L1) == (60, 365, -60, 60)
    G = 0.9
    assert fit.germination_value(G, 212.5, "spore") == pytest.approx(G)
    assert fit.germination_value(G, 60.0, "spore") == pytest.approx(G / 2)
    assert fit.germination_value(G, 0.0, "spore") == pytest.approx(G * s_hand(0.0, 60, 365), rel=1e-13)
    assert fit.germination_value(G, 0.0, "gemma") == pytest.approx(G)
    assert fit.germination_value(G, np.array([-60.0, 60.0]), "gemma") == pytest.approx([G / 2, G / 2])
    # spores need time, gemmae germinate at once (Bryum tau_b = 0.4)
    L = np.array([0.0, 30.0, 212.5])
    assert list(fit.germinates("bryum_argenteum", G, L, "spore")) == [False, False, True]
    assert list(fit.germinates("bryum_argenteum", G, L, "gemma")) == [True, True, False]
    with pytest.raises(ParameterError, match="kind"):
        fit.germination_value(G, 1.0, "seed")


# ---------------------------------------------------------------------------- backends, NaN
@pytest.mark.parametrize("FT,tol", [(Float64, 1e-12), (Float, 1e-5)])
def test_numpy_and_drjit_agree(FT, tol):
    rng = np.random.default_rng(3)
    Ts, rhs, S = rng.uniform(265, 305, 200), rng.uniform(0.6, 1.4, 200), rng.uniform(0, 100, 200)
    for key in SPECIES:
        ref = moss.daily_fitness(key, Ts, rhs, S)
        out = moss.daily_fitness(key, FT(Ts), FT(rhs), FT(S))
        assert isinstance(out, FT)
        # n = 0.5 has an infinite slope where s = 1/2: compare with an absolute tolerance there
        assert np.allclose(out.numpy(), ref, rtol=tol, atol=tol if FT is Float64 else 2e-3)
        Gd = moss.daily_growth(key, out)
        assert isinstance(Gd, FT)
    v = fit.germination_value(FT([0.5, 0.9]), FT([100.0, 212.5]), "spore")
    assert np.allclose(v.numpy(), fit.germination_value(np.array([0.5, 0.9]), np.array([100.0, 212.5]), "spore"),
                       rtol=tol)
    # mixed NumPy / Dr.Jit inputs give Dr.Jit
    assert isinstance(moss.daily_fitness("polytrichum", Ts, FT(rhs), 10.0), FT)


def test_drjit_gradient_finite():
    x = Float64([286.65, 280.0, 320.0])
    dr.enable_grad(x)
    g = fit.fitness(x, 274.15, 299.15, 0.5)
    dr.backward(dr.sum(g))
    grad = dr.grad(x).numpy()
    assert np.all(np.isfinite(grad)) and grad[0] == 0.0 and grad[1] > 0 and grad[2] < 0


def test_nan_propagates():
    assert np.isnan(fit.s(np.nan, 0.0, 1.0))
    for n in (0.5, 1.0):
        assert np.isnan(fit.fitness(np.nan, 0.0, 1.0, n))
        assert np.isnan(fit.fitness(Float([float("nan")]), 0.0, 1.0, n).numpy()[0])
        r = fit.fitness(Float([float("nan"), 0.5]), 0.0, 1.0, n).numpy()
        assert np.isnan(r[0]) and np.isfinite(r[1])
    G = moss.daily_fitness("bryum_argenteum", np.array([np.nan, 287.0]), 1.0, 20.0)
    assert np.isnan(G[0]) and np.isfinite(G[1])
    assert np.isnan(moss.daily_growth("polytrichum", np.nan))


# ---------------------------------------------------------------------------- species table
def test_species_table_matches_paper():
    assert set(SPECIES) == set(TABLE_4_2)
    for key, ref in TABLE_4_2.items():
        sp = SPECIES[key]
        for f, v in ref.items():
            assert getattr(sp, f) == v, (key, f)
    assert SPECIES["bryum_argenteum"].name == "Bryum argenteum"
    assert SPECIES["polytrichum"].name_ja == "スギゴケ"
    assert moss.SPECIES_FILE.is_file()
    assert "table 4.2" in moss.SPECIES_FILE.read_text(encoding="utf-8")


def test_user_species_and_file(tmp_path):
    sp = Species(T0=280.0, T1=300.0, nT=1.0, rh0=0.7, rh1=1.1, nrh=1.0, S0=5.0, S1=80.0, nS=1.0,
                 alpha_g=0.2, tau_g=0.1, tau_b=0.3, tau_d=0.1, name="my moss")
    assert moss.daily_fitness(sp, 290.0, 0.9, 42.5) == pytest.approx(1.0)
    f = tmp_path / "mine.toml"
    f.write_text("[species.my_moss]\n" + "\n".join(f"{k} = {v!r}" for k, v in sp.to_dict().items()
                                                   if k != "name") + '\nname = "my moss"\n')
    loaded = load_species(f)
    assert loaded["my_moss"] == sp
    assert sp.replace(tau_b=0.5).tau_b == 0.5


def test_invalid_species_names_the_field(tmp_path):
    good = dict(TABLE_4_2["polytrichum"])
    with pytest.raises(ParameterError) as e:
        Species(**{**good, "T0": 300.0})  # T0 > T1
    assert e.value.field == "T0" and "T0" in str(e.value) and "T1" in str(e.value)
    cases = {"rh0": 1.5, "S0": 60.0, "nrh": 0.0, "nT": 1.5, "alpha_g": 1.0, "tau_d": -0.1,
             "tau_b": float("nan")}
    for field, value in cases.items():
        with pytest.raises(ParameterError) as e:
            Species(**{**good, field: value})
        assert field in str(e.value), field
    with pytest.raises(ParameterError, match="kelvin"):
        Species(**{**good, "T0": 5.0, "T1": 25.0})
    # file errors name the file, the species and the field
    f = tmp_path / "bad.toml"
    f.write_text("[species.x]\n" + "\n".join(f"{k} = {v!r}" for k, v in {**good, "T1": 270.0}.items()))
    with pytest.raises(ParameterError, match=r"bad\.toml.*species\.x.*T0"):
        load_species(f)
    f.write_text("[species.x]\n" + "\n".join(f"{k} = {v!r}" for k, v in good.items()) + "\nTmax = 3.0\n")
    with pytest.raises(ParameterError, match="Tmax"):
        load_species(f)
    f.write_text("[species.x]\nT0 = 280.0\n")
    with pytest.raises(ParameterError, match="T1"):
        load_species(f)
    f.write_text("[species.x\n")
    with pytest.raises(ParameterError, match="TOML"):
        load_species(f)
    with pytest.raises(ParameterError, match="path"):
        load_species(tmp_path / "missing.toml")
    with pytest.raises(ParameterError, match="species"):
        moss.get_species("sphagnum")
