"""PROSPECT-D in Dr.Jit, differentiable leaf colour, and fits of pigments to a leaf colour.

References: ``prosail`` (through tests/test_leaf_spectra.py; ``foliage.prospect`` is the NumPy
face of the one Dr.Jit model), SciPy's exponential integral, colour-science's XYZ, sRGB and
CIELAB, the NumPy colour pipeline (``spectra.spectrum_to_srgb``) against the Dr.Jit one, central
finite differences, and synthetic inverse problems with known pigments (Ishikura stages of
``foliage.pigments``). Numbers: docs/tuning.md, "Leaf colour (PROSPECT-D)".
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401  (selects the variant)
import drjit as dr

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.foliage import colour_dr as cdr
from mitsuba_veg.foliage import prospect, prospect_dr, spectra
from mitsuba_veg.foliage.pigments import LeafTraits, pigments_at_stage
from mitsuba_veg.tune import colour_sensitivity, fit_leaf_colour

F = prospect_dr.Float64
TR = LeafTraits()
TRAITS = {"N": TR.N, "Cw": TR.Cw, "Cm": TR.Cm, "Cbrown": TR.Cbrown}
WLC = np.arange(400.0, 831.0)


def stage_leaf(stage):
    pig = {k: float(v) for k, v in pigments_at_stage(stage).items()}
    wl, R, T = prospect.prospect_d(**TRAITS, **pig)
    return pig, wl, R, T


def random_parameters(rng, n):
    """Random PROSPECT-D inputs over (most of) the allowed ranges, some contents zero."""
    p = {"N": rng.uniform(1.0, 3.5, n), "Cab": rng.uniform(0, 120, n),
         "Car": rng.uniform(0, 30, n), "Anth": rng.uniform(0, 60, n),
         "Cbrown": rng.uniform(0, 2, n), "Cw": rng.uniform(0, 0.08, n),
         "Cm": rng.uniform(0, 0.04, n)}
    for k in ("Cab", "Car", "Anth", "Cbrown"):
        p[k][rng.random(n) < 0.15] = 0.0
    return p


# ------------------------------------------------------------------------------------------
# the exponential integral and the plate transmissivity
# ------------------------------------------------------------------------------------------
def test_exp1_matches_scipy_with_its_derivative():
    from scipy.special import exp1
    x = np.concatenate([np.geomspace(1e-12, 200.0, 3000), np.linspace(2.45, 2.55, 41)])
    e = np.asarray(prospect_dr.exp1(x))
    assert np.max(np.abs(e / exp1(x) - 1)) < 1e-12
    assert math.isinf(float(prospect_dr.exp1(0.0)[0]))
    # derivative -e^{-x}/x through AD, reverse and forward mode
    xs = np.array([1e-6, 0.01, 0.7, 2.4999, 2.5001, 9.0, 60.0])
    xa = F(xs)
    dr.enable_grad(xa)
    dr.backward(dr.sum(prospect_dr.exp1(xa)))
    ref = -np.exp(-xs) / xs
    assert np.max(np.abs(np.asarray(dr.grad(xa)) / ref - 1)) < 1e-12
    xf = F(xs)
    dr.enable_grad(xf)
    y = prospect_dr.exp1(xf)
    dr.forward(xf)
    assert np.max(np.abs(np.asarray(dr.grad(y)) / ref - 1)) < 1e-12


def test_plate_transmissivity_and_its_derivative():
    from scipy.special import exp1

    def tau_np(k):
        return (1 - k) * np.exp(-k) + k * k * exp1(k)

    k = np.array([0.0, 1e-9, 1e-4, 0.05, 0.8, 2.5, 4.0, 30.0])
    kd = F(k)
    dr.enable_grad(kd)
    tau = prospect_dr.plate_transmissivity(kd)
    ref = np.where(k > 0, tau_np(np.maximum(k, 1e-300)), 1.0)
    assert np.max(np.abs(np.asarray(dr.detach(tau)) - ref)) < 1e-14
    dr.backward(dr.sum(tau))
    g = np.asarray(dr.grad(kd))
    assert g[0] == pytest.approx(-2.0, abs=1e-15)          # τ'(0) = -2, finite
    kk = k[3:]
    h = 1e-6 * kk
    fd = (tau_np(kk + h) - tau_np(kk - h)) / (2 * h)
    assert np.max(np.abs(g[3:] / fd - 1)) < 1e-6


# ------------------------------------------------------------------------------------------
# PROSPECT-D: Dr.Jit against NumPy
# ------------------------------------------------------------------------------------------
def test_numpy_face_broadcasts_leaves_and_wavelengths_as_the_model():
    """``foliage.prospect.prospect_d`` is the NumPy face of the one Dr.Jit model: its
    broadcasting over leaves, the extremes of every range and a wavelength subset give the
    model's spectra. (The model itself is checked against prosail's implementation in
    tests/test_leaf_spectra.py.)"""
    rng = np.random.default_rng(8)
    p = random_parameters(rng, 64)
    wl, R, T = prospect.prospect_d(**p)
    s = prospect_dr.prospect_d(**p)
    Rd, Td = s.numpy()
    assert s.n_leaves == 64 and Rd.shape == R.shape == (64, 2101)
    assert np.max(np.abs(Rd - R)) < 1e-9 and np.max(np.abs(Td - T)) < 1e-9
    # extremes: lossless plates (all contents 0) and the upper ends of every range
    for kw in ({"N": 2.5, "Cab": 0, "Car": 0, "Anth": 0, "Cbrown": 0, "Cw": 0, "Cm": 0},
               {"N": 4.0, "Cab": 200, "Car": 60, "Anth": 100, "Cbrown": 5, "Cw": 0.2,
                "Cm": 0.1}):
        _, R1, T1 = prospect.prospect_d(**kw)
        Rd1, Td1 = prospect_dr.prospect_d(**kw).numpy()
        assert np.max(np.abs(Rd1 - R1)) < 1e-9 and np.max(np.abs(Td1 - T1)) < 1e-9
    # one leaf on a wavelength subset
    s = prospect_dr.prospect_d(**{k: v[3] for k, v in p.items()}, wavelengths=(500, 700))
    assert np.array_equal(s.wavelength, np.arange(500, 701))
    assert np.max(np.abs(s.numpy()[0] - R[3, 100:301])) < 1e-9


def test_prospect_dr_gradients_match_finite_differences():
    base = {"N": 1.6, "Cab": 35.0, "Car": 6.0, "Anth": 8.0, "Cbrown": 0.3, "Cw": 0.015,
            "Cm": 0.006}
    rng = np.random.default_rng(3)
    wR, wT = rng.uniform(0, 1, 2101), rng.uniform(0, 1, 2101)

    def f_np(p):
        _, R, T = prospect.prospect_d(**p)
        return float(R @ wR + T @ wT)

    x = {k: F(v) for k, v in base.items()}
    for v in x.values():
        dr.enable_grad(v)
    s = prospect_dr.prospect_d(**x)
    dr.backward(dr.sum(s.reflectance * F(wR) + s.transmittance * F(wT)))
    for k, v in base.items():
        h = 1e-4 * v
        fd = (f_np({**base, k: v + h}) - f_np({**base, k: v - h})) / (2 * h)
        assert float(dr.grad(x[k])[0]) == pytest.approx(fd, rel=1e-5), k
    # forward mode: dR(λ)/dAnth at every wavelength
    a = F(base["Anth"])
    dr.enable_grad(a)
    s = prospect_dr.prospect_d(**{**base, "Anth": a})
    dr.forward(a)
    h = 1e-3
    fd = (prospect.prospect_d(**{**base, "Anth": base["Anth"] + h})[1]
          - prospect.prospect_d(**{**base, "Anth": base["Anth"] - h})[1]) / (2 * h)
    g = np.asarray(dr.grad(s.reflectance))
    assert np.max(np.abs(g - fd)) < 1e-6 * np.max(np.abs(fd))


# ------------------------------------------------------------------------------------------
# colour
# ------------------------------------------------------------------------------------------
def test_colour_matches_spectrum_to_srgb_and_colour_science():
    import colour
    # XYZ and sRGB of leaf spectra against colour-science's own integration (CIE 1931 2 deg,
    # D65, 360-830 nm with the 400 nm value held below 400 nm as in the scenes) and its sRGB
    wl_v = np.arange(360, 831)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    W_v = cdr.colour_weights(wl_v)
    d65 = colour.SDS_ILLUMINANTS["D65"].copy().align(cmfs.shape)   # (no alignment warning)
    for st in (1, 4, 7):
        _, wl, R, T = stage_leaf(st)
        r = np.concatenate([np.full(40, R[0]), R[:431]])
        sd = colour.SpectralDistribution(dict(zip(wl_v, r)))
        xyz_ref = colour.sd_to_XYZ(sd, cmfs, d65, method="Integration") / 100
        np.testing.assert_allclose(r @ W_v, xyz_ref, rtol=1e-4)
        for exposure in (1.0, 4.0):
            srgb_ref = np.clip(colour.XYZ_to_sRGB(xyz_ref * exposure), 0.0, 1.0)
            np.testing.assert_allclose(spectra.spectrum_to_srgb(wl_v, r, exposure), srgb_ref,
                                       atol=5e-4)
    spec = []
    for st in range(1, 8):
        _, wl, R, T = stage_leaf(st)
        spec += [R, T]
    spec = np.array(spec)                       # 14 spectra, 400-2500 nm
    for exposure in (1.0, 4.0):                 # 4x: some channels clip
        ref = spectra.spectrum_to_srgb(wl, spec, exposure)
        got = cdr.spectrum_to_srgb(wl, F(spec.ravel()), exposure, n_leaves=len(spec))
        got = np.stack([np.asarray(c) for c in got], 1)
        assert np.max(np.abs(got - ref)) < 1e-12
    # CIELAB against colour-science with the same white
    W = cdr.colour_weights(wl)
    white = cdr.white_point(W)
    xyz = cdr.spectrum_to_xyz(F(spec.ravel()), W, n_leaves=len(spec))
    lab = np.stack([np.asarray(c) for c in cdr.xyz_to_lab(xyz, white)], 1)
    xyz_np = spec @ W
    ref = colour.XYZ_to_Lab(xyz_np, illuminant=colour.XYZ_to_xy(white))
    assert np.max(np.abs(lab - ref)) < 1e-9
    assert np.max(np.abs(cdr.xyz_to_lab_np(xyz_np, white) - ref)) < 1e-9
    # NumPy twins round-trip (target conversions)
    assert np.max(np.abs(cdr.lab_to_xyz_np(ref, white) - xyz_np)) < 1e-12
    srgb = cdr.xyz_to_srgb_np(xyz_np, clip=False)   # some leaf colours lie outside sRGB
    assert np.max(np.abs(cdr.srgb_to_xyz_np(srgb) - xyz_np)) < 1e-12


def test_colour_gradient_matches_finite_differences():
    import colour
    base = {**TRAITS, "Cab": 25.0, "Car": 4.0, "Anth": 12.0}
    W = cdr.colour_weights(WLC)
    white = cdr.white_point(W)
    xy = colour.XYZ_to_xy(white)

    def lab_np(p):
        _, R, _ = prospect.prospect_d(**p)
        return colour.XYZ_to_Lab(R[:431] @ W, illuminant=xy)

    names = ("N", "Cab", "Car", "Anth")
    for i in range(3):
        x = {k: F(v) for k, v in base.items()}
        for k in names:
            dr.enable_grad(x[k])
        s = prospect_dr.prospect_d(**x, wavelengths=(400, 830))
        lab = cdr.xyz_to_lab(cdr.spectrum_to_xyz(s.reflectance, W), white)
        dr.backward(lab[i])
        for k in names:
            h = 1e-4 * base[k]
            fd = (lab_np({**base, k: base[k] + h})[i] - lab_np({**base, k: base[k] - h})[i]) \
                / (2 * h)
            assert float(dr.grad(x[k])[0]) == pytest.approx(fd, rel=1e-5, abs=1e-9), (i, k)


# ------------------------------------------------------------------------------------------
# identifiability and fits
# ------------------------------------------------------------------------------------------
def test_what_a_colour_identifies():
    # red leaves (little chlorophyll): every pigment moves the colour; green leaves: the blue
    # is saturated by chlorophyll and carotenoids barely change the colour
    red = colour_sensitivity(stage_leaf(7)[0])["per_delta_e"]
    green = colour_sensitivity(stage_leaf(1)[0])["per_delta_e"]
    assert max(red.values()) < 2.5                  # µg cm-2 per ΔE*ab = 1
    assert green["Car"] > 5.0 > green["Anth"] and green["Car"] > 5 * red["Car"]
    # with N, the 3 x 4 Jacobian has a null space: scaling N and all contents together (the
    # absorption per plate k = Σ C_i K_i / N stays the same)
    pig = stage_leaf(5)[0]
    s4 = colour_sensitivity(pig, ("N", "Cab", "Car", "Anth"))
    v = np.array([TR.N, pig["Cab"], pig["Car"], pig["Anth"]])
    assert abs(float(s4["null_space"][0] @ v / np.linalg.norm(v))) > 0.99


@pytest.mark.parametrize("signs", [(-1, -1, -1), (1, 1, 1), (-1, 1, -1), (1, -1, 1)])
def test_adam_recovers_pigments_from_colour(signs):
    # stage 5 (dark green-red: Cab 25, Car 4, Anth 12), target = its sRGB colour; starts at
    # corners of the ±30 % box
    pig, wl, R, _ = stage_leaf(5)
    target = spectra.spectrum_to_srgb(wl, R)
    init = {k: v * (1 + 0.3 * s) for (k, v), s in zip(pig.items(), signs)}
    res = fit_leaf_colour(target, init=init, progress=False)
    assert res.delta_e < 1e-3
    for k, v in pig.items():
        assert res.values[k] == pytest.approx(v, rel=1e-3), k


def test_least_squares_and_other_losses():
    pig, wl, R, _ = stage_leaf(7)
    target = spectra.spectrum_to_srgb(wl, R)
    lab = colour_sensitivity(pig)["lab"]
    # a Lab target, least squares from the look-up-table start
    res = fit_leaf_colour({"lab": lab}, method="least_squares", steps=60, progress=False)
    assert res.stats["evaluations"] < 40 and res.delta_e < 1e-8
    for k, v in pig.items():
        assert res.values[k] == pytest.approx(v, rel=1e-6), k
    # the sRGB loss with Adam from a ±30 % start
    res = fit_leaf_colour(target, init={"Cab": 3.9, "Car": 1.4, "Anth": 26.0}, loss="rgb",
                          progress=False)
    for k, v in pig.items():
        assert res.values[k] == pytest.approx(v, rel=1e-3), k


def test_colour_pins_contents_per_plate_not_structure():
    # a wrong N still matches the colour exactly, with every content scaled by about N'/N:
    # the colour fixes the contents per plate (C/N), not N and C separately
    pig, wl, R, _ = stage_leaf(5)
    target = spectra.spectrum_to_srgb(wl, R)
    res = fit_leaf_colour(target, init={**pig, "N": 1.6}, method="least_squares", steps=60,
                          progress=False)
    assert res.delta_e < 1e-6
    assert abs(res.values["Cab"] / pig["Cab"] - 1) > 0.1
    assert res.values["Cab"] / 1.6 == pytest.approx(pig["Cab"] / TR.N, rel=0.02)
    assert res.values["Anth"] / 1.6 == pytest.approx(pig["Anth"] / TR.N, rel=0.02)
    with pytest.raises(ParameterError, match="at most 3"):
        fit_leaf_colour(target, params=("N", "Cab", "Car", "Anth"), progress=False)


def test_spectrum_target_recovers_six_parameters():
    truth = {"N": 1.4, "Cab": 25.0, "Car": 4.0, "Anth": 12.0, "Cw": 0.012, "Cm": 0.0045}
    _, R, _ = prospect.prospect_d(**truth)
    res = fit_leaf_colour({"reflectance": R}, params=list(truth), progress=False)
    assert res.stats["loss"] == "spectrum" and math.sqrt(res.loss) < 1e-6
    for k, v in truth.items():
        assert res.values[k] == pytest.approx(v, rel=1e-4), k


# ------------------------------------------------------------------------------------------
# errors and outputs
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, field", [
    ({"target": (1.2, 0.3, 0.2)}, "target srgb"),
    ({"target": {"lab": (120.0, 0.0, 0.0)}}, "target lab"),
    ({"target": {"rgb": (0.2, 0.3, 0.2)}}, "target"),
    ({"target": np.full(100, 0.1)}, "target reflectance"),
    ({"target": (0.3, 0.3, 0.2), "params": ("Cab", "Chl")}, "params"),
    ({"target": (0.3, 0.3, 0.2), "init": {"Cab": 250.0}}, "init['Cab']"),
    ({"target": (0.3, 0.3, 0.2), "loss": "spectrum"}, "loss"),
    ({"target": (0.3, 0.3, 0.2), "method": "newton"}, "method"),
    ({"target": (0.3, 0.3, 0.2), "side": "top"}, "side"),
])
def test_bad_input_names_field_value_and_range(kwargs, field):
    target = kwargs.pop("target")
    with pytest.raises(ParameterError) as e:
        fit_leaf_colour(target, progress=False, steps=2, **kwargs)
    assert e.value.field == field and e.value.allowed and e.value.fix
    assert "invalid (allowed:" in str(e.value)
    with pytest.raises(ParameterError, match=r"Cab = -1\.0 .*\[0\.0, 200\.0\]\)\. Fix"):
        prospect_dr.prospect_d(Cab=-1.0)


def test_outputs(tmp_path):
    pig, wl, R, _ = stage_leaf(6)
    res = fit_leaf_colour({"reflectance": R[:431], "wavelength": wl[:431]}, loss="lab",
                          init={"Cab": 20.0, "Car": 4.0, "Anth": 12.0}, steps=40,
                          out=tmp_path, progress=False)
    assert set(res.files) == {"fitted", "loss_curve", "leaf_colour"}
    d = json.loads((tmp_path / "fitted.json").read_text())
    assert set(d["fitted"]) == {"Cab", "Car", "Anth"} and len(d["history"]) == 41
    assert d["target"]["kind"] == "spectrum" and d["settings"]["loss"] == "lab"
    assert d["history"][-1]["loss"] < d["history"][0]["loss"]
    for k in ("loss_curve", "leaf_colour"):
        assert (tmp_path / f"{k}.png").stat().st_size > 10_000
