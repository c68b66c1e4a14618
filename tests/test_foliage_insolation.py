"""Sun path and per-leaf insolation with ray-traced shadows (paper 003 §3.2)."""
import numpy as np
import pytest

import mitsuba_veg.foliage  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.foliage.insolation import (SunPath, clear_sky_broadband, instantaneous_insolation,
                                            leaf_insolation, sky_view_factor, sun_path)
from mitsuba_veg.light.validation import box_mesh
from mitsuba_veg.trees.structure import Leaves


def _leaves(pos, nrm, size=0.1):
    pos = np.atleast_2d(np.asarray(pos, float))
    nrm = np.atleast_2d(np.asarray(nrm, float))
    return Leaves(pos, nrm, np.full(len(pos), size), np.full(len(pos), -1))


def test_sun_path_noon_elevation_and_daylight_steps():
    # equinox at the equator-ish longitude 0: noon elevation = 90 - |latitude|
    p = sun_path(35.0, 0.0, "2026-03-20", days=1, step_hours=0.25, utc_offset_hours=0)
    assert p.elevation.max() == pytest.approx(55.0, abs=0.6)
    assert len(p) == pytest.approx(12 * 4, abs=2)            # ~12 h of day
    assert np.allclose(np.linalg.norm(p.direction, axis=1), 1.0)
    assert (p.dni >= 0).all() and (p.dni > 0).mean() > 0.9 and p.dni.max() < 1100
    with pytest.raises(ParameterError):
        sun_path(35.0, 0.0, "2026-03-20", days=1, step_hours=5)


def test_clear_sky_broadband_matches_the_spectral_model():
    """The broadband DNI/DHI are the SPCTRAL2 spectra integrated (the same model as the
    emitters' spectra), one sun or many at once, and close to pvlib's broadband Bird clear-sky
    model (Bird & Hulstrom 1981: the same authors' broadband model, independent code) with the
    same atmosphere: DNI within 5 %, DHI within 12 %."""
    import pvlib
    from mitsuba_veg.light.clear_sky import Atmosphere, clear_sky_spectra
    dni, dhi = clear_sky_broadband([45.0], 172)
    wl, d, h = clear_sky_spectra(45.0, step_nm=None)
    assert dni[0] == pytest.approx(np.trapezoid(d, wl), rel=1e-6)
    assert dhi[0] == pytest.approx(np.trapezoid(h, wl), rel=1e-6)
    el, doy = np.array([10.0, 30.0, 60.0, 85.0]), np.array([172, 172, 355, 80])
    dni, dhi = clear_sky_broadband(el, doy)
    for k in range(len(el)):                     # each sun alone: the same up to rounding
        d1, h1 = clear_sky_broadband([el[k]], doy[k])
        assert d1[0] == pytest.approx(dni[k], rel=1e-12) and h1[0] == pytest.approx(dhi[k],
                                                                                    rel=1e-12)
    atm = Atmosphere()
    zen = 90.0 - el
    bird = pvlib.clearsky.bird(
        zen, pvlib.atmosphere.get_relative_airmass(zen, model="kastenyoung1989"),
        atm.aerosol_turbidity * (380.0 / 500.0) ** -atm.angstrom_alpha, atm.aerosol_turbidity,
        atm.precipitable_water, atm.ozone, atm.pressure,
        pvlib.irradiance.get_extra_radiation(doy), atm.aerosol_asymmetry, atm.ground_albedo)
    np.testing.assert_allclose(dni, np.asarray(bird["dni"]), rtol=0.05)
    np.testing.assert_allclose(dhi, np.asarray(bird["dhi"]), rtol=0.12)
    assert 900 < dni[2] < 1000 and dni[0] < 0.6 * dni[2]   # high sun, low sun


def test_unshaded_leaves_get_I_cos_summed():
    path = sun_path(35.0, 139.0, "2026-10-01", days=3)
    lv = _leaves([[0, 0, 0], [5, 0, 0], [10, 0, 0]], [[0, 1, 0], [0, -1, 0], [0, 0, 1]])
    r = leaf_insolation(lv, path)
    dt = path.step_hours * 3600 / 1e6
    up = np.bincount(path.day, path.dni * path.direction[:, 1] * dt)
    south = np.bincount(path.day, path.dni * np.abs(path.direction[:, 2]) * dt)
    assert np.allclose(r.daily[0], up, rtol=1e-5)           # horizontal leaf, lit from above
    assert np.allclose(r.daily[1], up, rtol=1e-5)           # upside-down: both faces count
    assert np.allclose(r.daily[2], south, rtol=1e-5)        # vertical leaf facing south
    assert np.allclose(r.open_daily, up, rtol=1e-5)
    one = leaf_insolation(lv, path, two_sided=False)
    assert one.cumulative[1] == 0.0 and one.cumulative[0] == pytest.approx(r.cumulative[0])
    assert np.all(r.sunlit_fraction == 1.0)


def test_instantaneous_insolation():
    lv = _leaves([[0, 0, 0]], [[0, 1, 0]])
    assert instantaneous_insolation(lv, [0, 0.5, np.sqrt(0.75)], 1000.0)[0] == pytest.approx(
        500.0, rel=1e-5)


def test_shadows_from_leaves_branches_and_obstacles():
    path = sun_path(35.0, 139.0, "2026-10-01", days=2)
    # leaf 0 in the open; leaf 1 under a big roof (obstacle); leaf 2 under another leaf
    lv = _leaves([[0, 0, 0], [20, 0, 0], [40, 0, 0], [40, 0.02, 0]],
                 [[0, 1, 0]] * 4, size=0.1)
    lv.size[3] = 5.0                                     # a huge leaf just above leaf 2
    roof = box_mesh((15, 1.0, -20), (25, 1.1, 20))
    r = leaf_insolation(lv, path, obstacles=[roof])
    assert r.cumulative[0] > 0
    # roof spans +-20 m in z, 5 m in x at 1 m height: only low-sun hours from east/west reach
    assert r.cumulative[1] < 0.3 * r.cumulative[0]
    assert r.cumulative[2] == 0.0
    # translucent leaves: the shaded leaf gets T of the beam (the other occluders are opaque)
    rt = leaf_insolation(lv, path, obstacles=[roof], leaf_transmittance=0.1)
    assert rt.cumulative[2] == pytest.approx(0.1 * rt.cumulative[0], rel=1e-3)
    assert rt.cumulative[1] == pytest.approx(r.cumulative[1], rel=1e-6)


def test_sky_view_factor():
    lv = _leaves([[-50, 0, 0], [5, 0, 0], [5, 0.01, 0]], [[0, 1, 0], [1, 0, 0], [0, 1, 0]])
    lv.size[2] = 20.0
    v = sky_view_factor(lv, rays=256)
    assert v[0] == pytest.approx(1.0, abs=0.02)
    assert v[2] == pytest.approx(1.0, abs=0.02)
    assert v[1] < 0.05          # under a 20 m leaf 1 cm above
    path = sun_path(35.0, 139.0, "2026-10-01", days=1)
    r = leaf_insolation(_leaves([[0, 0, 0]], [[0, 1, 0]]), path, sky=True)
    dhi = (path.dhi * path.step_hours * 3600 / 1e6).sum()
    assert r.cumulative[0] == pytest.approx(r.beam_daily.sum() + dhi, rel=0.02)


def test_many_leaves_many_hours_in_few_kernels():
    rng = np.random.default_rng(0)
    n = 3000
    nrm = rng.standard_normal((n, 3))
    lv = Leaves(rng.random((n, 3)) * [2, 1, 2], nrm / np.linalg.norm(nrm, axis=1, keepdims=True),
                np.full(n, 0.08), np.full(n, -1))
    path = sun_path(35.0, 139.0, "2026-10-01", days=10)
    r = leaf_insolation(lv, path)
    assert r.rays == n * len(path)
    assert r.daily.shape == (n, 10)
    top = lv.position[:, 1] > 0.8
    bottom = lv.position[:, 1] < 0.2
    assert r.cumulative[top].mean() > 1.5 * r.cumulative[bottom].mean()
    assert isinstance(path, SunPath)


def test_sky_factor_from_the_photon_pass():
    lv = _leaves([[0, 0, 0], [3, 0, 0], [3, 0.05, 0]], [[0, 1, 0], [0, 1, 0], [0, 1, 0]],
                 size=0.3)
    lv.size[2] = 2.0                                   # a big leaf just above leaf 1
    from mitsuba_veg.foliage.insolation import sky_view_factor_photons
    v = sky_view_factor_photons(lv, photons=1_000_000)
    r = sky_view_factor(lv, rays=256)
    assert v[0] == pytest.approx(1.0, rel=0.05) and r[0] == pytest.approx(1.0, abs=0.02)
    # under a leaf: the ray-cast factor sees little sky; the photon pass adds the light the big
    # leaf transmits and scatters (green leaf: PAR T ~ 0.06)
    assert r[1] < 0.2 and r[1] < v[1] < 0.4
    path = sun_path(35.0, 139.0, "2026-10-01", days=1)
    res = leaf_insolation(lv, path, sky=True, sky_method="photons", sky_photons=200_000)
    assert res.sky_view.shape == (3,)
    with pytest.raises(ParameterError):
        leaf_insolation(lv, path, sky=True, sky_method="nope")
    # the photon sky pass sees the tree only: obstacles and bark=False are refused, not ignored
    box = (np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1]], float), np.array([[0, 1, 2]]))
    for kw in ({"obstacles": [box]}, {"bark": False}):
        with pytest.raises(ParameterError, match="sky_method"):
            leaf_insolation(lv, path, sky=True, sky_method="photons", **kw)
