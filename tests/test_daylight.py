"""Daylight: SPCTRAL2 spectra, sun/sky emitter dicts and the `veg_sky` environment emitter."""
from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")
dr = pytest.importorskip("drjit")


import mitsuba_veg  # noqa: E402,F401  (selects the variant, registers the plugins)
from mitsuba_veg.errors import ParameterError  # noqa: E402
from mitsuba_veg.integrators.veg_sky import VegSky, attach_scene  # noqa: E402
from mitsuba_veg.light import sky as sky_mod  # noqa: E402
from mitsuba_veg.light.clear_sky import (  # noqa: E402
    Atmosphere, DEFAULT_ATMOSPHERE, band_irradiance, clear_sky_spectra, daylight,
    daylight_from_angles, photon_flux, red_far_red_ratio, regular_spectrum)


def _global(el, **kw):
    wl, dni, dhi = clear_sky_spectra(el, **kw)
    return wl, dni * math.sin(math.radians(el)) + dhi, dni, dhi


def _sampler(n, seed=0):
    s = mi.load_dict({"type": "independent"})
    s.seed(seed, n)
    return s


# ----------------------------------------------------------------------------------- spectra
def test_spectra_grid_and_units():
    wl, dni, dhi = clear_sky_spectra(45.0)
    assert wl[0] == 300.0 and wl[-1] == 4000.0 and np.allclose(np.diff(wl), 1.0)
    assert dni.shape == dhi.shape == wl.shape
    assert np.all(dni >= 0) and np.all(dhi >= 0)
    # visible beam around 1.2-1.6 W m-2 nm-1, diffuse an order of magnitude less
    i = np.searchsorted(wl, 550.0)
    assert 1.1 < dni[i] < 1.7 and 0.1 < dhi[i] < 0.4
    # native grid: SPCTRAL2's 122 wavelengths
    assert clear_sky_spectra(45.0, step_nm=None).wavelengths.size == 122


def test_broadband_dni_high_sun():
    for el in (60.0, 75.0):
        wl, dni, _ = clear_sky_spectra(el)
        e = np.trapezoid(dni, wl)
        assert 800.0 < e < 1000.0, (el, e)


def test_par_at_60_degrees():
    wl, g, _, _ = _global(60.0)
    par = band_irradiance(wl, g, 400.0, 700.0)          # W m-2
    assert 380.0 < par < 500.0, par                     # default atmosphere: 399.9 W m-2
    ppfd = photon_flux(wl, g, 400.0, 700.0)             # umol m-2 s-1
    assert 1700.0 < ppfd < 2300.0, ppfd


@pytest.mark.parametrize("el", [30.0, 45.0, 60.0])
def test_red_far_red_ratio(el):
    wl, g, dni, _ = _global(el)
    rfr = red_far_red_ratio(wl, g)                      # sun + sky on open flat ground
    assert 1.10 <= rfr <= 1.20, (el, rfr)
    assert 1.08 <= red_far_red_ratio(wl, dni) <= 1.20   # direct sun alone (field ~1.14)


def test_photon_flux_exact_for_linear_spectra():
    wl = np.arange(300.0, 801.0)
    e = np.full_like(wl, 2.0)                           # flat 2 W m-2 nm-1
    # integral of E lambda over 655-665 nm: 2 * (665^2 - 655^2)/2
    expect = 2.0 * (665.0 ** 2 - 655.0 ** 2) / 2 * 1e-9 / (6.62607015e-34 * 2.99792458e8) \
        / 6.02214076e23 * 1e6
    assert photon_flux(wl, e, 655.0, 665.0) == pytest.approx(expect, rel=1e-12)
    assert band_irradiance(wl, e, 400.5, 700.25) == pytest.approx(2.0 * 299.75)


def test_atmosphere_effects_and_scaling():
    _, dni0, dhi0 = clear_sky_spectra(40.0)
    _, dni1, dhi1 = clear_sky_spectra(40.0, aerosol_turbidity=0.4)
    assert dni1.sum() < dni0.sum() and dhi1.sum() > dhi0.sum()      # haze: less beam, more sky
    wl, dni, dhi = clear_sky_spectra(40.0, dni_target=300.0, dhi_target=250.0)
    nat = clear_sky_spectra(40.0, dni_target=300.0, dhi_target=250.0, step_nm=None)
    assert np.trapezoid(nat.dni, nat.wavelengths) == pytest.approx(300.0, rel=1e-9)
    assert np.trapezoid(nat.dhi, nat.wavelengths) == pytest.approx(250.0, rel=1e-9)
    _, dni2, dhi2 = clear_sky_spectra(40.0, beam_scale=0.5, diffuse_scale=2.0)
    assert np.allclose(dni2, 0.5 * dni0) and np.allclose(dhi2, 2.0 * dhi0)
    assert DEFAULT_ATMOSPHERE.precipitable_water == 2.9
    a = Atmosphere(ozone=0.3)
    _, dni3, _ = clear_sky_spectra(40.0, atmosphere=a)
    assert not np.allclose(dni3, dni0)


@pytest.mark.parametrize("kw, field", [
    (dict(aerosol_turbidity=-0.1), "aerosol_turbidity"),
    (dict(precipitable_water=-1.0), "precipitable_water"),
    (dict(pressure=1013.25), "pressure"),
    (dict(ground_albedo=1.5), "ground_albedo"),
    (dict(beam_scale=0.5, dni_target=100.0), "beam_scale"),
    (dict(wavelength_range=(250.0, 800.0)), "wavelength_range"),
    (dict(day_of_year=0), "day_of_year"),
])
def test_bad_inputs(kw, field):
    with pytest.raises(ParameterError) as e:
        clear_sky_spectra(45.0, **kw)
    assert e.value.field == field
    assert "allowed" in str(e.value)


@pytest.mark.parametrize("el", [0.0, -10.0, 95.0])
def test_elevation_out_of_model_range(el):
    with pytest.raises(ParameterError, match="elevation"):
        clear_sky_spectra(el)


# ----------------------------------------------------------------------------- emitter dicts
def test_daylight_dicts():
    d = daylight_from_angles(135.0, 45.0)
    assert set(d) == {"sun", "sky"}
    s = np.array([0.5, math.sqrt(0.5), 0.5])            # SE, 45 deg: +x east, +z south
    assert np.allclose(d["sun"]["direction"], -s)
    assert np.allclose(d["sky"]["sun_direction"], s)
    irr = d["sun"]["irradiance"]
    assert irr["type"] == "regular" and irr["wavelength_min"] == 300.0
    assert irr["wavelength_max"] == 4000.0 and len(irr["values"].split(",")) == 3701
    assert d["sky"]["type"] == "veg_sky" and d["sky"]["distribution"] == "perez"
    assert d["sky"]["perez_epsilon"] > 4.5                # a clear sky
    assert set(daylight_from_angles(135.0, 45.0, sun=False)) == {"sky"}
    assert set(daylight_from_angles(135.0, 45.0, sky=False)) == {"sun"}
    assert daylight_from_angles(135.0, -3.0) == {}       # night: no emitters
    assert daylight_from_angles(135.0, 0.0) == {}
    with pytest.raises(ParameterError):
        daylight_from_angles(135.0, 45.0, sky_model="hosek")
    with pytest.raises(ParameterError):
        regular_spectrum([400.0, 410.0, 430.0], [1.0, 1.0, 1.0])


def test_daylight_from_place_and_time():
    from mitsuba_veg.light.solar_position import sun_position

    when = dt.datetime(2024, 6, 21, 11, 0, tzinfo=dt.timezone.utc)
    az, el = sun_position(48.14, 11.58, when)
    d = daylight(48.14, 11.58, when, sky_resolution=32)
    ref = daylight_from_angles(float(az), float(el), day_of_year=173, sky_resolution=32)
    assert np.allclose(d["sun"]["direction"], ref["sun"]["direction"])
    assert d["sun"]["irradiance"] == ref["sun"]["irradiance"]
    # the sun where pvlib's NREL SPA puts it (azimuth 171.479 deg, apparent elevation 65.110
    # deg): the emitter's direction is the light's, away from the sun (+x east, +y up, +z south)
    a_, e_ = np.radians(171.479339), np.radians(65.110335)
    towards = np.array([np.sin(a_) * np.cos(e_), np.sin(e_), -np.cos(a_) * np.cos(e_)])
    np.testing.assert_allclose(d["sun"]["direction"], -towards, atol=1e-3)   # ~0.06 deg
    night = dt.datetime(2024, 6, 21, 23, 0, tzinfo=dt.timezone.utc)
    assert daylight(48.14, 11.58, night) == {}
    with pytest.raises(ParameterError):
        daylight(95.0, 11.58, when)


def test_sun_emitter_weight_is_dni():
    d = daylight_from_angles(200.0, 35.0, sky=False)
    sun = mi.load_dict(d["sun"])
    wl, dni, _ = clear_sky_spectra(35.0)
    lam = [[400.0, 500.0, 660.0], [730.0, 1000.0, 2400.0], [310.0, 1500.0, 3000.0],
           [450.0, 550.0, 650.0]]
    it = dr.zeros(mi.Interaction3f, 3)
    it.wavelengths = mi.Spectrum(*lam)
    ds, w = sun.sample_direction(it, mi.Point2f(0.5, 0.5))
    for k in range(4):
        assert np.allclose(np.array(w[k]), np.interp(lam[k], wl, dni), rtol=1e-4)
    towards_sun = np.array(ds.d)[:, 0]
    az, el = math.radians(200.0), math.radians(35.0)
    expect = [math.sin(az) * math.cos(el), math.sin(el), -math.cos(az) * math.cos(el)]
    assert np.allclose(towards_sun, expect, atol=1e-6)


# --------------------------------------------------------------------------------- veg_sky
def _sky(el=45.0, az=135.0, **kw):
    return mi.load_dict(daylight_from_angles(az, el, sun=False, **kw)["sky"])


@pytest.mark.parametrize("el, model", [(45.0, "perez"), (20.0, "perez"), (70.0, "cie_clear"),
                                       (30.0, "uniform")])
def test_sky_mc_irradiance_equals_dhi(el, model):
    sky = _sky(el, sky_model=model)
    wl, _, dhi = clear_sky_spectra(el)
    n = 1 << 18
    lam = [[450.0, 660.0, 730.0, 1500.0], [400.0, 550.0, 700.0, 2400.0],
           [830.0, 1000.0, 1250.0, 2000.0], [500.0, 600.0, 655.0, 735.0]]
    it = dr.zeros(mi.Interaction3f, n)
    it.p = mi.Point3f(0.3, 1.0, -2.0)
    it.wavelengths = mi.Spectrum(*[mi.Float(np.repeat(np.array(r)[None, :], n // 4, 0).T
                                            .ravel()) for r in lam])
    ds, w = sky.sample_direction(it, _sampler(n).next_2d())
    cos = dr.maximum(ds.d.y, 0.0)
    for k in range(4):
        est = np.array(w[k] * cos).reshape(4, n // 4).mean(axis=1)
        assert np.allclose(est, np.interp(lam[k], wl, dhi), rtol=0.01), (k, est)
    assert dr.all(ds.d.y > 0.0) and dr.all(ds.dist > 0.0)


def test_sky_pdf_consistent():
    sky = _sky(30.0)
    n = 1 << 18
    it = dr.zeros(mi.Interaction3f, n)
    ds, _ = sky.sample_direction(it, _sampler(n, 3).next_2d())
    pdf = sky.pdf_direction(it, ds)
    assert np.allclose(np.array(pdf), np.array(ds.pdf), rtol=1e-6)
    # ds.pdf is the density of the samples: E[g/pdf] = integral of g for simple g
    assert dr.mean(1.0 / ds.pdf)[0] == pytest.approx(2 * math.pi, rel=0.01)      # solid angle
    assert dr.mean(ds.d.y / ds.pdf)[0] == pytest.approx(math.pi, rel=0.01)        # cos
    # and it integrates to 1 over the sphere (uniform sphere samples), 0 below the horizon
    u = mi.warp.square_to_uniform_sphere(_sampler(n, 4).next_2d())
    q = dr.zeros(mi.DirectionSample3f, n)
    q.d = u
    p = sky.pdf_direction(it, q)
    assert dr.mean(p)[0] * 4 * math.pi == pytest.approx(1.0, rel=0.02)
    assert dr.all(dr.select(u.y < 0.0, p == 0.0, True))


def test_sky_eval_matches_sample_weight_and_shape():
    sky = _sky(40.0, az=180.0)
    n = 4096
    it = dr.zeros(mi.Interaction3f, n)
    it.wavelengths = mi.Spectrum(550.0)
    ds, w = sky.sample_direction(it, _sampler(n, 5).next_2d())
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = -ds.d
    si.wavelengths = it.wavelengths
    L = sky.eval(si)
    assert np.allclose(np.array(L[0]), np.array(w[0] * ds.pdf), rtol=1e-4)
    assert np.allclose(np.array(sky.eval_direction(it, ds)[0]), np.array(L[0]), rtol=1e-6)
    # circumsolar sky (sun south at 40 deg) brighter than the antisolar sky; nothing below
    si2 = dr.zeros(mi.SurfaceInteraction3f, 3)
    si2.wavelengths = mi.Spectrum(550.0)
    near = (0.0, math.sin(math.radians(45)), math.cos(math.radians(45)))
    anti = (0.0, math.sin(math.radians(45)), -math.cos(math.radians(45)))
    si2.wi = -mi.Vector3f(*[mi.Float(v) for v in zip(near, anti, (0.0, -0.5, 0.8))])
    l2 = np.array(sky.eval(si2)[0])
    assert l2[0] > 2 * l2[1] > 0 and l2[2] == 0.0


def test_cie_clear_sky_coefficients():
    """CIE type 12, phi(Z) f(chi), rewritten in the Perez form: the same shape up to a scale."""
    coeffs = sky_mod.cie_coefficients(12)
    rng = np.random.default_rng(0)
    th, chi = rng.uniform(0.05, 1.5, 20), rng.uniform(0.0, math.pi, 20)
    gradation = 1.0 - np.exp(-0.32 / np.cos(th))
    indicatrix = 1.0 + 10.0 * (np.exp(-3.0 * chi) - math.exp(-1.5 * math.pi)) \
        + 0.45 * np.cos(chi) ** 2
    ratio = sky_mod.relative_radiance(np.cos(th), np.cos(chi), coeffs) / (gradation * indicatrix)
    assert np.allclose(ratio, ratio[0], rtol=1e-9)


def test_sky_through_mitsuba_path_integrator():
    """Mitsuba's C++ `path` integrator calls the Python emitter (eval/sample/pdf)."""
    def meter_scene(sky):
        return mi.load_dict({
            "type": "scene", "integrator": {"type": "path", "max_depth": 2}, "sky": sky,
            "meter": {"type": "rectangle",
                      "to_world": mi.ScalarTransform4f().look_at(
                          origin=[0, 0, 0], target=[0, 1, 0], up=[0, 0, 1]).scale(0.5),
                      "sensor": {"type": "irradiancemeter",
                                 "sampler": {"type": "independent", "sample_count": 4096},
                                 "film": {"type": "hdrfilm", "width": 1, "height": 1,
                                          "pixel_format": "luminance",
                                          "rfilter": {"type": "box"}}}}})

    def render(scene, seeds=4):
        return np.mean([float(np.array(mi.render(scene, seed=s)).ravel()[0])
                        for s in range(seeds)])

    # geometry with a flat spectrum: horizontal irradiance = pi * S per nm
    for model in ("uniform", "perez"):
        sky = {"type": "veg_sky", "radiance": {"type": "uniform", "value": 1.0},
               "sun_direction": [0.5, math.sqrt(0.5), 0.5], "distribution": model}
        if model == "perez":
            sky.update(perez_epsilon=6.8, perez_delta=0.1)
        assert render(meter_scene(sky)) == pytest.approx(math.pi, rel=0.015), model
    # the real spectrum: 'luminance' = y-bar weighted mean of the spectral irradiance
    d = daylight_from_angles(135.0, 45.0, sun=False)
    wl, _, dhi = clear_sky_spectra(45.0)
    from colour import MSDS_CMFS
    cmf = MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    ybar = np.interp(wl, cmf.wavelengths, cmf.values[:, 1], left=0.0, right=0.0)
    expect = np.trapezoid(dhi * ybar, wl) / np.trapezoid(ybar, wl)
    assert render(meter_scene(d["sky"])) == pytest.approx(expect, rel=0.02)


def test_sample_ray_power_and_symbolic_calls():
    d = daylight_from_angles(135.0, 45.0)
    scene = mi.load_dict({"type": "scene", "sky": d["sky"], "sun": d["sun"],
                          "ground": {"type": "rectangle", "to_world":
                                     mi.ScalarTransform4f().rotate([1, 0, 0], -90).scale(2.0)}})
    assert attach_scene(scene) == 1
    sky = [e for e in scene.emitters() if isinstance(e, VegSky)][0]
    n = 1 << 18
    s = _sampler(n, 7)
    ray, w = sky.sample_ray(0.0, s.next_1d(), s.next_2d(), s.next_2d())
    si = scene.ray_intersect(ray)
    hit = si.is_valid() & (ray.d.y < 0.0)
    power = dr.sum(dr.select(hit, (w[0] + w[1] + w[2] + w[3]) * 0.25, 0.0))[0] / n
    wl, _, dhi = clear_sky_spectra(45.0)
    assert power == pytest.approx(np.trapezoid(dhi, wl) * 16.0, rel=0.02)   # W on 4 m x 4 m
    # through the scene's (symbolic) virtual call, as Mitsuba's own integrators do
    ray2, w2, _ = scene.sample_emitter_ray(0.0, s.next_1d(), s.next_2d(), s.next_2d(), True)
    dr.eval(ray2, w2)
    assert dr.all(dr.isfinite(w2[0]))
    assert str(sky).startswith("VegSky[")
    assert any(k.startswith("radiance") for k in mi.traverse(sky).keys())


def test_sky_property_errors():
    with pytest.raises(RuntimeError, match="radiance/irradiance"):
        mi.load_dict({"type": "veg_sky"})
    with pytest.raises(RuntimeError, match="perez_epsilon"):
        mi.load_dict({"type": "veg_sky", "radiance": 1.0, "distribution": "perez"})
    with pytest.raises(RuntimeError, match="above the horizon"):
        mi.load_dict({"type": "veg_sky", "radiance": 1.0, "sun_direction": [0, -1, 1],
                      "perez_epsilon": 5.0, "perez_delta": 0.2})
    # 'irradiance' = DHI: same emitter as radiance = DHI/pi
    a = mi.load_dict({"type": "veg_sky", "irradiance": {"type": "uniform", "value": math.pi}})
    b = mi.load_dict({"type": "veg_sky", "radiance": {"type": "uniform", "value": 1.0}})
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(0.0, -1.0, 0.0)
    si.wavelengths = mi.Spectrum(500.0)
    assert np.allclose(np.array(a.eval(si)), np.array(b.eval(si)), rtol=1e-6)


def test_a_live_sun_path_does_not_break_other_scenes_symbolic_emitter_calls():
    """Dr.Jit traces every live emitter in a symbolic emitter call, also ones of other scenes:
    a moss run's veg_sun_path must not make another scene's sample_emitter_ray fail."""
    keep = mi.load_dict({"type": "veg_sun_path"})  # noqa: F841 (alive during the call)
    d = daylight_from_angles(135.0, 45.0)
    scene = mi.load_dict({"type": "scene", "sun": d["sun"], "ground": {"type": "rectangle"}})
    s = _sampler(64, 1)
    ray, w, _ = scene.sample_emitter_ray(0.0, s.next_1d(), s.next_2d(), s.next_2d(), True)
    dr.eval(ray, w)
    assert dr.all(dr.isfinite(w[0]))
