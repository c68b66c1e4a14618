"""Unit tests of the soil surface model (paper 000 §3.5, eqs 3.2-3.16) in mitsuba_veg/soil.py.

Reference values are computed here independently with plain ``math`` and the constants written
out, not with the module's helpers.

Worked case (S = 100 W m-2, T = 288.15 K, rh = 0.73, U = 0.2 m/s, A = 0.75, humus theta = 0.3,
C_H = 0.0015), step by step in the order of §3.7:

    eq 3.2   C   = 0.826*0.75^3 - 1.234*0.75^2 + 1.135*0.75 + 0.298      = 0.80359375
             sigma T^4 = 5.67e-8 * 288.15^4                            = 390.8926951 W m-2
    eq 3.3   L   = 390.8926951 * (1 - 0.26*0.80359375)                 = 309.2217742 W m-2
    eq 3.4   R   = 0.8*100 + 309.2217742                               = 389.2217742 W m-2
    eq 3.5   C_H = 0.0015 (bare soil, m = 0)
    eq 3.9   F   = 216 * (0.490 - 0.3)^10                              = 1.3243103e-5 m
    eq 3.10  beta = 1 / (1 + 0.0015*0.2*1.3243103e-5/2.54e-5)          = 0.99984361
    eq 3.12  e_SAT = 6.1078 * 10^(7.5*15/252.3)                        = 17.0522837 hPa
    eq 3.13  q_SAT = 0.622*e/1013 / (1 - 0.378*e/1013)                 = 0.0105374555
    eq 3.15  Delta = e ln10 7.5*237.3/252.3^2 * 0.622*1013/(1013-0.378e)^2 = 6.8272877e-4 K-1
             k = iota rho beta C_H U = 2.543e6*1.19*0.99984361*0.0015*0.2 = 907.709021 W m-2
    eq 3.11  num = 389.2217742 - 390.8926951 - 907.709021*0.0105374555*0.27 = -4.25345566 W m-2
             den = 4 sigma T^3 (5.42623904) + 1210*0.0003 (0.363) + k Delta (0.61971906)
                                                                      = 6.40895811 W m-2 K-1
             deltaT = -4.25345566 / 6.40895811                         = -0.66367350 K
             Ts  = 288.15 - 0.66367350                                 = 287.48632650 K
    eq 3.14  iotaE = 907.709021 * (0.0105374555*0.27 - 6.8272877e-4*0.66367350) = 2.17124359 W m-2
             E = iotaE / iota = 8.5381e-7 mm/s                         = 0.07376935 mm/day
    eq 3.16  rhs = 0.99984361 + 0.73*0.0105374555*0.00015639/(0.0105374555 - 4.5311e-4)
                                                                      = 0.99996290
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (selects the variant)
from mitsuba_veg import soil
from mitsuba_veg.errors import ParameterError

import drjit as dr
from drjit.llvm.ad import Float, Float64, UInt32

# Constants written out (paper 000, tables 3.5, 3.6)
SIG, P, REF, DATM, IOTA, RHO, CPR = 5.67e-8, 1013.0, 0.2, 2.54e-5, 2.543e6, 1.19, 1.21e3
HUMUS, SAND, ASPHALT = (2.16e2, 10.0, 0.490), (8.32e5, 16.6, 0.392), (7.25e7, 19.4, 0.012)

CASE = dict(S=100.0, T=288.15, rh=0.73, U=0.2, A=0.75, theta=0.3, geology=0, C_H=0.0015)
TABLE = dict(C=0.80359375, sT4=390.8926951, L=309.2217742, R=389.2217742, F=1.3243103e-5,
             beta=0.99984361, e=17.0522837, q=0.0105374555, Delta=6.8272877e-4, k=907.709021,
             num=-4.25345566, den=6.40895811, dT=-0.66367350, Ts=287.48632650, lE=2.17124359,
             E_day=0.07376935, rhs=0.99996290)


def hand(S, T, rh, U, A, theta, geo, C_H):
    """The whole model in plain math (scalars), the derivative of eq 3.15 written by hand."""
    F1, F2, ts = geo
    C = 0.826 * A**3 - 1.234 * A**2 + 1.135 * A + 0.298
    sT4 = SIG * T**4
    L = sT4 * (1 - 0.26 * C)
    R = (1 - REF) * S + L
    F = F1 * max(ts - theta, 0.0) ** F2
    beta = 1 / (1 + C_H * U * F / DATM)
    t = T - 273.15
    e = 6.1078 * 10 ** (7.5 * t / (t + 237.3))
    q = (0.622 * e / P) / (1 - 0.378 * e / P)
    Delta = e * math.log(10) * 7.5 * 237.3 / (t + 237.3) ** 2 * 0.622 * P / (P - 0.378 * e) ** 2
    k = IOTA * RHO * beta * C_H * U
    num = R - sT4 - k * q * (1 - rh)
    den = 4 * SIG * T**3 + CPR * C_H * U + k * Delta
    dT = num / den
    lE = k * (q * (1 - rh) + Delta * dT)
    rhs = beta + rh * q * (1 - beta) / (q + Delta * dT)
    return dict(C=C, sT4=sT4, L=L, R=R, F=F, beta=beta, e=e, q=q, Delta=Delta, k=k, num=num,
                den=den, dT=dT, Ts=T + dT, lE=lE, E_day=lE / IOTA * 86400, rhs=rhs)


H = hand(CASE["S"], CASE["T"], CASE["rh"], CASE["U"], CASE["A"], CASE["theta"], HUMUS, CASE["C_H"])


def close(a, b, rel=1e-12, abs_=0.0):
    return np.allclose(np.asarray(a, dtype=float), b, rtol=rel, atol=abs_)


# ---------------------------------------------------------------------------- constants
def test_constants_as_printed():
    assert (soil.SIGMA, soil.P_ATM, soil.ALBEDO, soil.D_ATM) == (SIG, P, REF, DATM)
    assert (soil.LATENT_HEAT, soil.RHO_AIR, soil.CP_RHO) == (IOTA, RHO, CPR)
    assert (soil.C_H_MIN, soil.C_H_MAX, soil.SECONDS_PER_DAY) == (0.0015, 0.0030, 86400.0)
    for code, ref in ((0, HUMUS), (1, SAND), (2, ASPHALT)):
        g = soil.GEOLOGY[code]
        assert (g.F1, g.F2, g.theta_sat) == ref
    assert soil.geology_code("Sand") == 1
    with pytest.raises(ParameterError, match="geology"):
        soil.geology_code("granite")


def test_hand_table_in_docstring():
    """The numbers in this file's docstring are what the plain-math model gives."""
    for key, val in TABLE.items():
        assert H[key] == pytest.approx(val, rel=2e-7), key


# ---------------------------------------------------------------------------- eqs 3.2-3.5
def test_cloud_factor():
    assert soil.cloud_factor(0.0) == pytest.approx(0.298, abs=1e-15)
    assert soil.cloud_factor(1.0) == pytest.approx(0.826 - 1.234 + 1.135 + 0.298, rel=1e-15)
    assert soil.cloud_factor(1.0) == pytest.approx(1.025, rel=1e-12)
    assert close(soil.cloud_factor(np.array([0.0, 0.75, 1.0])), [0.298, TABLE["C"], 1.025])


def test_sky_longwave_and_net_radiation():
    T = CASE["T"]
    assert soil.sky_longwave(T, H["C"]) == pytest.approx(SIG * T**4 * (1 - 0.26 * H["C"]), rel=1e-14)
    assert soil.sky_longwave(T, H["C"]) == pytest.approx(TABLE["L"], rel=1e-9)
    # clear sky (A = 1) -> less longwave than overcast (A = 0)
    assert soil.sky_longwave(T, soil.cloud_factor(1.0)) < soil.sky_longwave(T, soil.cloud_factor(0.0))
    assert soil.net_radiation(100.0, H["L"]) == pytest.approx(80.0 + H["L"], rel=1e-15)
    assert soil.net_radiation(100.0, 0.0, ref=0.5) == pytest.approx(50.0)


def test_transfer_coefficient():
    assert close(soil.transfer_coefficient(np.array([0, 5, 10, 20, -1]), 10),
                 [0.0015, 0.00225, 0.0030, 0.0030, 0.0015])
    assert soil.transfer_coefficient(0.25) == pytest.approx(0.0015 + 0.0015 * 0.25)


# ---------------------------------------------------------------------------- eqs 3.6-3.10
def test_soil_depth():
    assert close(soil.soil_depth(np.array([0.0, -3.0, 0.5, 50.0, 1000.0, 5000.0])),
                 [1.0, 1.0, 0.5, 50.0, 1000.0, 1000.0])


def test_bucket_capacity_and_theta():
    assert close(soil.bucket_capacity(np.array([100.0, 100.0, 100.0]), np.array([0, 1, 2])),
                 [49.0, 39.2, 1.2])
    assert soil.water_content(30.0, 100.0) == pytest.approx(0.3)


def test_bucket_overflow_runs_off():
    r = soil.bucket_step(O=40.0, E=0.0, P=20.0, h=100.0, geology=0)  # O_SAT = 49 mm
    assert r.O == pytest.approx(49.0) and r.runoff == pytest.approx(11.0)
    assert r.theta == pytest.approx(0.49) and r.deficit == 0.0
    # rain that fits stays
    r = soil.bucket_step(O=40.0, E=0.0, P=5.0, h=100.0, geology=0)
    assert r.O == pytest.approx(45.0) and r.runoff == 0.0


def test_bucket_drying_and_mass_balance():
    # wall element of humus (h = 1 mm, O_SAT = 0.49 mm) evaporating 0.1 mm/day without rain
    E = 0.1 / 86400.0
    O, series = 0.49, []
    for _ in range(6):
        r = soil.bucket_step(O, E, 0.0, 1.0, 0)
        series.append(float(r.O))
        O = r.O
    assert series[:4] == pytest.approx([0.39, 0.29, 0.19, 0.09], abs=1e-12)
    assert series[4] == 0.0 and series[5] == 0.0  # cannot go below 0 mm
    r = soil.bucket_step(0.09, E, 0.0, 1.0, 0)
    assert r.deficit == pytest.approx(0.01, abs=1e-12)
    # mass balance: O_new + runoff - deficit = O_old - 86400 E + P (vectorised, all geologies)
    rng = np.random.default_rng(1)
    Oo = rng.uniform(0, 40, 50)
    Ee = rng.uniform(-1e-6, 3e-5, 50)
    Pp = rng.choice([0.0, 10.34, 60.0], 50)
    g = rng.integers(0, 3, 50)
    r = soil.bucket_step(Oo, Ee, Pp, 100.0, g)
    assert close(r.O + r.runoff - r.deficit, Oo - 86400 * Ee + Pp, rel=1e-12, abs_=1e-12)
    assert np.all(r.O >= 0) and np.all(r.O <= soil.bucket_capacity(100.0, g) + 1e-12)


def test_soil_state_dataclass():
    st = soil.SoilState.saturated(np.array([0.0, 100.0, 5000.0]), np.array([0, 1, 2]))
    assert close(st.h, [1.0, 100.0, 1000.0])
    assert close(st.theta, [0.49, 0.392, 0.012])
    st2, r = st.step(E=0.0, P=5.0)
    assert close(st2.O, st.O) and close(r.runoff, [5.0, 5.0, 5.0])


def test_evaporation_F_and_beta():
    assert soil.evaporation_F(0.3, 0) == pytest.approx(216 * 0.19**10, rel=1e-13)
    assert soil.evaporation_F(0.3, 0) == pytest.approx(TABLE["F"], rel=1e-7)
    assert soil.evaporation_F(0.0, 1) == pytest.approx(8.32e5 * 0.392**16.6, rel=1e-12)
    beta = soil.evaporation_efficiency(0.3, 0.0015, 0.2, 0)
    assert beta == pytest.approx(1 / (1 + 0.0015 * 0.2 * 216 * 0.19**10 / 2.54e-5), rel=1e-14)
    # theta >= theta_SAT: F = 0, beta = 1 (no NaN from a negative base, no rise for humus F2 = 10)
    th = np.array([0.49, 0.6, 0.392, 0.5, 0.012, 0.3])
    geo = np.array([0, 0, 1, 1, 2, 2])
    assert np.all(soil.evaporation_F(th, geo) == 0.0)
    assert np.all(soil.evaporation_efficiency(th, 0.0015, 0.2, geo) == 1.0)
    # drier soil -> smaller beta (humus, sand); asphalt beta ~ 1 for any theta (table 3.4)
    b = soil.evaporation_efficiency(np.array([0.4, 0.2, 0.0]), 0.0015, 0.2, 0)
    assert b[0] > b[1] > b[2] and b[2] == pytest.approx(0.3294192594588119, rel=1e-9)
    assert soil.evaporation_efficiency(0.0, 0.0015, 0.2, 2) == pytest.approx(1.0, abs=1e-20)


# ---------------------------------------------------------------------------- eqs 3.11-3.16
def test_e_sat_and_q_sat():
    assert soil.e_sat(273.15) == pytest.approx(6.1078, rel=1e-15)
    assert soil.e_sat(288.15) == pytest.approx(6.1078 * 10 ** (7.5 * 15 / 252.3), rel=1e-14)
    assert soil.e_sat(288.15) == pytest.approx(TABLE["e"], rel=1e-8)
    e = 6.1078 * 10 ** (7.5 * 15 / 252.3)
    assert soil.q_sat(288.15) == pytest.approx(0.622 * e / 1013 / (1 - 0.378 * e / 1013), rel=1e-14)
    assert soil.q_sat(288.15) == pytest.approx(TABLE["q"], rel=1e-8)


@pytest.mark.parametrize("T", [250.0, 263.15, 273.15, 288.15, 293.15, 303.15, 315.0])
def test_delta_is_derivative_of_q_sat(T):
    h = 1e-3
    fd = (soil.q_sat(T + h) - soil.q_sat(T - h)) / (2 * h)
    assert abs(soil.dq_sat_dT(T) / fd - 1) < 1e-4


def test_delta_hand_value_and_printed_formula():
    assert soil.dq_sat_dT(288.15) == pytest.approx(TABLE["Delta"], rel=1e-7)
    # the printed eq 3.15 (constant 6.1078) is smaller by the factor e_SAT(T)/6.1078
    e, t, T = H["e"], 15.0, 288.15
    printed = 6.1078 * (2500 - 2.4 * t) / (0.4615 * T**2) * 0.622 * P / (P - 0.378 * e) ** 2
    assert soil.dq_sat_dT(T) / printed == pytest.approx(e / 6.1078, rel=2e-3)


def test_delta_matches_drjit_autodiff():
    T = Float64([263.15, 288.15, 303.15])
    dr.enable_grad(T)
    q = soil.q_sat(T)
    dr.backward(dr.sum(q))
    assert close(dr.grad(T).numpy(), soil.dq_sat_dT(np.array([263.15, 288.15, 303.15])), rel=1e-10)


def test_equations_3_11_3_14_3_16_individually():
    dT = soil.surface_temperature_offset(H["R"], 288.15, 0.73, 0.2, H["beta"], 0.0015)
    assert dT == pytest.approx(H["dT"], rel=1e-12)
    lE = soil.latent_heat_flux(288.15, 0.73, 0.2, H["beta"], 0.0015, H["dT"])
    assert lE == pytest.approx(H["lE"], rel=1e-12)
    rhs = soil.surface_humidity(288.15, 0.73, H["beta"], H["dT"])
    assert rhs == pytest.approx(H["rhs"], rel=1e-14)
    assert soil.evaporation_rate(lE) * 86400 == pytest.approx(TABLE["E_day"], rel=1e-6)
    # beta = 1 (wet): rhs = 1 exactly; beta = 0, dT = 0: rhs = rh
    assert soil.surface_humidity(288.15, 0.73, 1.0, -3.0) == 1.0
    assert soil.surface_humidity(288.15, 0.73, 0.0, 0.0) == pytest.approx(0.73, rel=1e-15)


def test_surface_state_worked_case():
    r = soil.surface_state(**CASE)
    assert isinstance(r.Ts, np.floating)
    for key in ("Ts", "rhs", "lE", "beta"):
        assert getattr(r, key) == pytest.approx(H[key], rel=1e-12), key
        assert getattr(r, key) == pytest.approx(TABLE[key], rel=1e-8), key
    # energy balance of the linearised model closes: R - sigma T^4 - 4 sigma T^3 dT - H - lE = 0
    dT = r.Ts - 288.15
    resid = H["R"] - H["sT4"] - 4 * SIG * 288.15**3 * dT - CPR * 0.0015 * 0.2 * dT - r.lE
    assert abs(resid) < 1e-10


def _grid():
    rng = np.random.default_rng(0)
    n = 64
    return dict(S=rng.uniform(0, 300, n), T=rng.uniform(268, 308, n), rh=rng.uniform(0.3, 1.0, n),
                U=rng.uniform(0.1, 5, n), A=rng.uniform(0, 1, n), theta=rng.uniform(0, 0.5, n),
                geology=rng.integers(0, 3, n), C_H=rng.uniform(0.0015, 0.003, n))


def test_surface_state_vectorised_matches_hand():
    g = _grid()
    r = soil.surface_state(**g)
    geos = (HUMUS, SAND, ASPHALT)
    for i in range(0, 64, 7):
        h = hand(g["S"][i], g["T"][i], g["rh"][i], g["U"][i], g["A"][i], g["theta"][i],
                 geos[g["geology"][i]], g["C_H"][i])
        for key in ("Ts", "rhs", "lE", "beta"):
            assert getattr(r, key)[i] == pytest.approx(h[key], rel=1e-10, abs=1e-12), key


@pytest.mark.parametrize("FT,rel", [(Float64, 1e-12), (Float, 2e-4)])
def test_surface_state_numpy_and_drjit_agree(FT, rel):
    g = _grid()
    ref = soil.surface_state(**g)
    dj = {k: (UInt32(v.astype(np.uint32)) if k == "geology" else FT(v)) for k, v in g.items()}
    out = soil.surface_state(**dj)
    for key in ("Ts", "rhs", "lE", "beta"):
        val = getattr(out, key)
        assert isinstance(val, FT), key
        assert close(val.numpy(), getattr(ref, key), rel=rel, abs_=rel * 1e-1), key
    # mixed: a Dr.Jit S with NumPy/Python rest gives Dr.Jit
    mixed = soil.surface_state(FT(g["S"]), g["T"], 0.73, 0.2, 0.75, g["theta"], g["geology"], 0.0015)
    assert isinstance(mixed.Ts, FT)
    ref2 = soil.surface_state(g["S"], g["T"], 0.73, 0.2, 0.75, g["theta"], g["geology"], 0.0015)
    assert close(mixed.Ts.numpy(), ref2.Ts, rel=1e-6 if FT is Float else 1e-12)


def test_drjit_gradients():
    """dTs/dS = (1 - ref)/den (beta does not depend on S), and finite gradients at saturation."""
    S = Float64([100.0, 50.0])
    theta = Float64([0.3, 0.49])  # second one exactly saturated
    dr.enable_grad(S, theta)
    r = soil.surface_state(S, 288.15, 0.73, 0.2, 0.75, theta, 0, 0.0015)
    dr.backward(dr.sum(r.Ts))
    assert dr.grad(S).numpy()[0] == pytest.approx(0.8 / H["den"], rel=1e-10)
    assert np.all(np.isfinite(dr.grad(theta).numpy()))
    assert dr.grad(theta).numpy()[1] == 0.0


def test_nan_propagates():
    """Policy: NaN in any float input gives NaN outputs (NumPy and Dr.Jit); never silently clamped."""
    names = ("S", "T", "rh", "U", "A", "theta", "C_H")
    for name in names:
        args = dict(CASE)
        args[name] = np.array([np.nan, CASE[name]])
        r = soil.surface_state(**args)
        assert np.isnan(r.Ts[0]) and np.isfinite(r.Ts[1]), name
        # beta depends only on theta, C_H, U; rhs/lE on all
        assert np.isnan(r.lE[0]) and np.isnan(r.rhs[0]), name
        args[name] = Float([float("nan"), CASE[name]])
        r = soil.surface_state(**args)
        assert np.isnan(r.Ts.numpy()[0]) and np.isfinite(r.Ts.numpy()[1]), name
    for name in ("theta", "C_H", "U"):
        args = dict(CASE)
        args[name] = float("nan")
        assert np.isnan(soil.surface_state(**args).beta)
    assert np.isnan(soil.evaporation_F(Float([float("nan")]), 0).numpy()[0])
    b = soil.bucket_step(np.array([np.nan, 1.0]), 0.0, 0.0, 10.0, 0)
    assert np.isnan(b.O[0]) and b.O[1] == 1.0
    assert np.isnan(soil.transfer_coefficient(np.nan))
    assert np.isnan(soil.soil_depth(np.nan))


def test_invalid_geology_rejected():
    with pytest.raises(ParameterError, match="geology"):
        soil.surface_state(**{**CASE, "geology": 3})
    with pytest.raises(ParameterError, match="geology"):
        soil.evaporation_F(0.2, np.array([0, 1, -1]))
    with pytest.raises(ParameterError, match="geology"):
        soil.evaporation_F(0.2, np.nan)
    with pytest.raises(ParameterError, match="geology"):
        soil.bucket_step(1.0, 0.0, 0.0, 10.0, UInt32([0, 7]))


def test_eq_3_16_linearisation_range_and_outside():
    """docs/deviations.md (000 eq 3.16): the linearised q_SAT(Ts) is within 10 % for
    dT in [-6.3, +9.0] K at 288 K, reaches 0 at -q_SAT/Delta = -15.4 K, and a cold dry bare
    surface at night-like S = 0, 278 K gives Ts = 264.8 K and the printed rhs = 7.61."""
    import numpy as np
    from mitsuba_veg import soil as s
    T = 288.15
    dT = np.linspace(-12, 12, 2401)
    err = np.abs(s.linearisation_error(T, T + dT))
    ok = dT[err < 0.1]
    assert abs(ok.min() + 6.27) < 0.02 and abs(ok.max() - 9.02) < 0.02
    assert abs(-s.q_sat(T) / s.dq_sat_dT(T) + 15.43) < 0.01
    st = s.surface_state(0.0, 278.15, 0.73, 0.2, 0.75, 0.0, 0, s.transfer_coefficient(0.0))
    assert abs(float(st.Ts) - 264.83) < 0.01 and abs(float(st.rhs) - 7.613) < 0.001
    assert abs(float(s.linearisation_error(278.15, float(st.Ts)))) > 0.1
