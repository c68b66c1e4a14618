"""PROSPECT-D leaf spectra, the Ishikura stage pigment table and leaf colours (paper 003)."""
import numpy as np
import pytest

import mitsuba_veg.foliage as fo
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.foliage.pigments import stage_table, state_pigments
from mitsuba_veg.foliage.prospect import coefficients


def test_prospect_d_matches_the_prosail_reference_implementation():
    prosail = pytest.importorskip("prosail")
    cases = [(1.5, 40, 5, 0, 0, 0.012, 0.005), (2.1, 60, 10, 5, 0.1, 0.013, 0.016),
             (1.3, 3, 2.2, 22, 0, 0.012, 0.005), (1.0, 0, 0, 0, 0, 0.0, 0.001)]
    # and 16 random leaves over the parameters' ranges, and the upper end of every range
    rng = np.random.default_rng(21)
    lo, hi = np.array([1.0, 0, 0, 0, 0, 0.0005, 0.0005]), np.array([3.5, 150, 40, 60, 1, 0.05,
                                                                    0.03])
    cases += [tuple(x) for x in rng.uniform(lo, hi, (16, 7))]
    cases.append((4.0, 200, 60, 100, 5, 0.2, 0.1))
    for N, cab, car, ant, cb, cw, cm in cases:
        wl, R, T = fo.prospect_d(N, cab, car, ant, cb, cw, cm)
        _, R2, T2 = prosail.run_prospect(N, cab, car, cb, cw, cm, ant=ant)
        assert np.max(np.abs(R - R2)) < 1e-10 and np.max(np.abs(T - T2)) < 1e-10
    # all the leaves at once (one spectrum per leaf) give each leaf's spectra
    P = np.array(cases[4:]).T
    _, Rb, Tb = fo.prospect_d(*P)
    _, R1, T1 = fo.prospect_d(*cases[-1])
    assert Rb.shape == (17, 2101) and np.max(np.abs(Rb[-1] - R1)) < 1e-12


def test_spectra_cover_400_2500_nm_and_conserve_energy():
    s = fo.leaf_spectra(tau=np.linspace(0, 1, 5))
    assert s.wavelength[0] == 400 and s.wavelength[-1] == 2500 and len(s.wavelength) == 2101
    assert s.reflectance.shape == (5, 2101)
    assert (s.reflectance > 0).all() and (s.transmittance >= 0).all()
    assert (s.reflectance + s.transmittance <= 1.0).all()
    assert len(coefficients().kant) == 2101


def test_green_leaf_optics_are_those_of_a_leaf():
    s = fo.leaf_spectra(tau=0.0)
    (R550, R660, R730, R850), (T550, T660, T730, T850) = s.at([550, 660, 730, 850])
    assert R550 > 1.5 * R660            # green peak, chlorophyll absorbs red
    assert R660 + T660 < 0.1            # red is absorbed (> 90 %)
    assert R850 + T850 > 0.85           # near-infrared plateau: little absorbed
    assert T730 > 5 * T660              # far-red passes leaves, red does not
    assert 0.3 < R850 < 0.6


def test_red_autumn_leaf_reflects_red_and_absorbs_green():
    g, r = fo.leaf_spectra(tau=0.0), fo.leaf_spectra(tau=1.0)
    (gR550, gR660), _ = g.at([550, 660])
    (rR550, rR660), (rT550, rT660) = r.at([550, 660])
    assert rR660 > 3 * gR660            # chlorophyll gone: red reflected
    assert rR660 > 1.5 * rR550          # anthocyanin absorbs green


def test_stage_table_keeps_the_paper_facts():
    tb = stage_table()
    assert tb.cab[0] / tb.car[0] == pytest.approx(8.0)         # green leaf 8:1 (paper §2.1)
    assert tb.anth[0] == 0.0
    assert np.all(np.diff(tb.anth[1:]) > 0) and tb.anth[1] > 0  # rising through stages 2-7
    assert np.all(np.diff(tb.cab) <= 0)                         # chlorophyll breaks down
    # chlorophyll breaks down faster than carotenoids
    assert tb.cab[-1] / tb.cab[0] < tb.car[-1] / tb.car[0]
    assert "Ishikura" in tb.source and "8 : 1" in tb.source
    # intermediate stages are the area mixtures of the three tissue states
    sp = state_pigments()
    for i in range(7):
        c, r = tb.coloured[i], tb.red[i]
        mix = ((1 - c) * sp["green"]["Cab"] + (c - r) * sp["dark_green_red"]["Cab"]
               + r * sp["red"]["Cab"])
        assert tb.cab[i] == pytest.approx(mix)


def test_tau_stage_mapping_and_interpolation():
    assert fo.stage_from_tau([0, 0.5, 1, 1.7, -1]).tolist() == [1, 4, 7, 7, 1]
    assert fo.tau_from_stage(4.0) == pytest.approx(0.5)
    p = fo.pigments_at_stage(2.5)
    tb = stage_table()
    assert p["Anth"] == pytest.approx(0.5 * (tb.anth[1] + tb.anth[2]))
    with pytest.raises(ParameterError):
        fo.pigments_at_stage(8.0)
    with pytest.raises(ParameterError):
        fo.prospect_d(Cab=-1.0)


def test_per_leaf_variation_is_lognormal_around_the_table():
    p = fo.pigments_at_tau(np.full(20000, 0.5))
    v = fo.vary_pigments(p, 1, sigma=0.1)
    ratio = v["Cab"] / p["Cab"]
    assert np.median(ratio) == pytest.approx(1.0, abs=0.01)
    assert np.std(np.log(ratio)) == pytest.approx(0.1, rel=0.05)


def test_mitsuba_spectrum_extends_to_360_nm():
    s = fo.leaf_spectra(tau=0.0)
    d = fo.mitsuba_spectrum(s.wavelength, s.reflectance)
    vals = [float(x) for x in d["values"].split(",")]
    assert d["wavelength_min"] == 360.0 and d["wavelength_max"] == 2500.0
    assert len(vals) == 2141 and vals[0] == pytest.approx(s.reflectance[0], rel=1e-5)


def test_colours_green_then_red():
    s = fo.leaf_spectra(tau=np.array([0.0, 1.0]))
    rgb = fo.spectrum_to_srgb(s.wavelength, s.reflectance, exposure=2.2)
    assert rgb[0, 1] > rgb[0, 0] and rgb[0, 1] > rgb[0, 2]   # green leaf
    assert rgb[1, 0] > rgb[1, 1] and rgb[1, 0] > rgb[1, 2]   # red leaf
