"""Tests of mitsuba_veg.light.solar_position (NREL SPA, scene-frame sun directions)."""
from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from mitsuba_veg.errors import ParameterError
from mitsuba_veg.light import solar_position as sp


def _wrap180(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


# ------------------------------------------------------------------------------------------
# NREL report worked example (Reda & Andreas, NREL/TP-560-34302, Table A5.1)
# ------------------------------------------------------------------------------------------
NREL = dict(latitude=39.742476, longitude=-105.1786, elevation=1830.14, pressure=820.0,
            temperature=11.0, delta_t=67.0)
NREL_WHEN = dt.datetime(2003, 10, 17, 12, 30, 30, tzinfo=dt.timezone(dt.timedelta(hours=-7)))


def _nrel(when=NREL_WHEN, **kw):
    args = dict(NREL)
    lat, lon = args.pop("latitude"), args.pop("longitude")
    args.update(kw)
    return sp.sun_position(lat, lon, when, **args)


def test_nrel_report_example():
    az, el = _nrel()
    assert isinstance(az, float) and isinstance(el, float)
    assert abs((90.0 - el) - 50.11162) < 1e-4       # topocentric zenith angle theta [deg]
    assert abs(az - 194.34024) < 1e-4               # topocentric azimuth Phi [deg]


def test_nrel_report_intermediate_values():
    eph = sp.sun_ephemeris(NREL["latitude"], NREL["longitude"], NREL_WHEN,
                           elevation=NREL["elevation"], pressure=NREL["pressure"],
                           temperature=NREL["temperature"], delta_t=NREL["delta_t"])
    assert abs(sp.julian_day(NREL_WHEN) - 2452930.312847) < 1e-6
    assert abs(eph.earth_sun_distance - 0.9965422974) < 1e-9        # R [AU]
    assert abs(eph.declination - (-9.316179)) < 1e-6                # delta' [deg]
    assert abs(eph.hour_angle - 11.10629) < 5e-5                    # H' [deg]
    assert abs(eph.elevation_geometric - 39.872046) < 1e-6          # e0 [deg]
    assert abs(eph.elevation - 39.888378) < 1e-6                    # e [deg]
    assert abs(eph.zenith - 50.11162) < 1e-5


@pytest.mark.parametrize("when", [
    NREL_WHEN,
    dt.datetime(2003, 10, 17, 19, 30, 30),                           # naive = UTC
    np.datetime64("2003-10-17T19:30:30"),
    "2003-10-17T12:30:30-07:00",
    "2003-10-17T19:30:30Z",
    "2003-10-17 19:30:30",
])
def test_time_input_forms(when):
    az, el = _nrel(when)
    assert abs(az - 194.34024) < 1e-4 and abs(90 - el - 50.11162) < 1e-4


def test_refraction_switch():
    az, el = _nrel()
    az0, el0 = _nrel(refraction=False)
    assert az == az0
    assert abs((el - el0) - 0.016332) < 1e-6        # Delta e of the report (eq. 42)
    # At night (geometric elevation < -0.83337 deg) no correction is applied.
    night = np.datetime64("2003-10-18T07:30:00")
    assert _nrel(night)[1] == _nrel(night, refraction=False)[1] < -10


# ------------------------------------------------------------------------------------------
# Against pvlib's SPA (test reference only; the module itself does not use pvlib)
# ------------------------------------------------------------------------------------------
def _random_cases(n=4000, seed=20240601):
    rng = np.random.default_rng(seed)
    t0 = np.datetime64("1950-01-01T00:00:00", "us").astype(np.int64)
    t1 = np.datetime64("2101-01-01T00:00:00", "us").astype(np.int64)
    us = rng.integers(t0, t1, n)
    return dict(us=us, when=us.astype("datetime64[us]"), lat=rng.uniform(-80, 80, n),
                lon=rng.uniform(-180, 180, n), elev=rng.uniform(0, 4000, n),
                pres=rng.uniform(600, 1050, n), temp=rng.uniform(-30, 40, n))


def test_against_pvlib_spa():
    pspa = pytest.importorskip("pvlib.spa")
    c = _random_cases()
    delta_t = sp.default_delta_t(c["when"])
    az, el = sp.sun_position(c["lat"], c["lon"], c["when"], elevation=c["elev"],
                             pressure=c["pres"], temperature=c["temp"])
    ref = pspa.solar_position_numpy(c["us"] / 1e6, c["lat"], c["lon"], c["elev"], c["pres"],
                                    c["temp"], delta_t, 0.5667, 1)
    _, _, e_ref, e0_ref, phi_ref, _ = ref
    up = e_ref > -1.0
    assert up.sum() > 1000
    err_el = np.abs(el - e_ref)[up].max()
    high = e_ref > 1.0
    err_az = np.abs(_wrap180(az - phi_ref))[high].max()
    assert err_el < 0.05 and err_az < 0.05
    # In fact the two implementations agree to rounding level.
    assert err_el < 1e-5 and err_az < 1e-4, (err_el, err_az)
    az0, el0 = sp.sun_position(c["lat"], c["lon"], c["when"], elevation=c["elev"],
                               refraction=False)
    assert np.abs(el0 - e0_ref).max() < 1e-5


def test_default_delta_t_matches_espenak_meeus():
    pspa = pytest.importorskip("pvlib.spa")
    c = _random_cases(500)
    years = c["when"].astype("datetime64[Y]").astype(int) + 1970
    months = c["when"].astype("datetime64[M]").astype(int) % 12 + 1
    np.testing.assert_allclose(sp.default_delta_t(c["when"]),
                               pspa.calculate_deltat(years, months), atol=1e-9)


def test_default_delta_t_values():
    # Espenak & Meeus value for 1985-02 (as in pvlib's test-suite) and rough observed values.
    assert abs(sp.default_delta_t("1985-02-15") - 54.413442486) < 1e-6
    assert abs(sp.default_delta_t("1950-07-01") - 29.1) < 1.0
    assert abs(sp.default_delta_t("2000-01-01") - 63.8) < 1.0
    assert 60 < sp.default_delta_t("2100-01-01") < 250


# ------------------------------------------------------------------------------------------
# Vectorisation and conventions
# ------------------------------------------------------------------------------------------
def test_broadcasting_and_scalars():
    times = np.arange("2024-06-21T00", "2024-06-22T00", np.timedelta64(3, "h"),
                      dtype="datetime64[h]")                                  # (8,)
    lats = np.array([[-45.0], [0.0], [52.0]])                                  # (3, 1)
    az, el = sp.sun_position(lats, 5.0, times)
    assert az.shape == el.shape == (3, 8)
    for i, lat in enumerate(lats[:, 0]):
        for j, t in enumerate(times):
            a, e = sp.sun_position(float(lat), 5.0, t)
            assert a == pytest.approx(az[i, j], abs=1e-9)
            assert e == pytest.approx(el[i, j], abs=1e-9)
    # Lists of datetimes / strings work like arrays.
    lst = [dt.datetime(2024, 6, 21, 12, tzinfo=dt.timezone.utc), "2024-06-21T14:00:00+02:00"]
    az2, el2 = sp.sun_position(52.0, 5.0, lst)
    assert az2.shape == (2,) and az2[0] == pytest.approx(az2[1], abs=1e-12)


def test_azimuth_convention():
    # Equinox at the equator, Greenwich: sun rises in the east, culminates near the zenith,
    # sets in the west; at 52 N it culminates in the south.
    az_morning, el_morning = sp.sun_position(0.0, 0.0, "2024-03-20T08:00:00Z")
    az_evening, _ = sp.sun_position(0.0, 0.0, "2024-03-20T16:00:00Z")
    assert abs(az_morning - 90.0) < 2.0 and 25 < el_morning < 35
    assert abs(az_evening - 270.0) < 2.0
    az_noon, el_noon = sp.sun_position(52.0, 0.0, "2024-03-20T12:07:00Z")
    assert abs(az_noon - 180.0) < 1.0 and abs(el_noon - 38.0) < 1.0
    az_s, _ = sp.sun_position(-52.0, 0.0, "2024-03-20T12:07:00Z")
    assert abs(_wrap180(az_s)) < 1.0                      # southern hemisphere: north


# ------------------------------------------------------------------------------------------
# sun_direction / direction_to_angles
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("az, el, expected", [
    (180.0, 0.0, (0.0, 0.0, 1.0)),     # south = +z
    (0.0, 0.0, (0.0, 0.0, -1.0)),      # north = -z
    (90.0, 0.0, (1.0, 0.0, 0.0)),      # east = +x
    (270.0, 0.0, (-1.0, 0.0, 0.0)),    # west = -x
    (123.0, 90.0, (0.0, 1.0, 0.0)),    # zenith = +y
    (135.0, 45.0, (0.5, np.sqrt(0.5), 0.5)),
])
def test_sun_direction_known(az, el, expected):
    d = sp.sun_direction(az, el)
    assert d.shape == (3,)
    np.testing.assert_allclose(d, expected, atol=1e-12)


def test_frame_is_right_handed():
    x = sp.sun_direction(90.0, 0.0)
    y = sp.sun_direction(0.0, 90.0)
    z = sp.sun_direction(180.0, 0.0)
    np.testing.assert_allclose(np.cross(x, y), z, atol=1e-12)


def test_direction_round_trip_and_shapes():
    rng = np.random.default_rng(3)
    az = rng.uniform(0, 360, (4, 5))
    el = rng.uniform(-89, 89, (4, 5))
    d = sp.sun_direction(az, el)
    assert d.shape == (4, 5, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12)
    az2, el2 = sp.direction_to_angles(3.0 * d)            # need not be normalised
    assert az2.shape == el2.shape == (4, 5)
    np.testing.assert_allclose(_wrap180(az2 - az), 0.0, atol=1e-9)
    np.testing.assert_allclose(el2, el, atol=1e-9)
    assert sp.sun_direction(np.array([0.0, 90.0]), 10.0).shape == (2, 3)
    a, e = sp.direction_to_angles([0.0, 0.0, 1.0])
    assert (a, e) == (pytest.approx(180.0), pytest.approx(0.0))
    assert sp.direction_to_angles([0.0, 2.0, 0.0]) == (0.0, 90.0)


def test_direction_of_computed_sun():
    az, el = _nrel()
    d = sp.sun_direction(az, el)
    assert d[1] > 0 and d[2] > 0          # above the horizon, to the south (+z) of Golden, CO
    a, e = sp.direction_to_angles(d)
    assert a == pytest.approx(az, abs=1e-9) and e == pytest.approx(el, abs=1e-9)


# ------------------------------------------------------------------------------------------
# Errors
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kw, field", [
    (dict(latitude=95.0), "latitude"),
    (dict(latitude=np.nan), "latitude"),
    (dict(longitude=-200.0), "longitude"),
    (dict(pressure=-1.0), "pressure"),
    (dict(temperature=-300.0), "temperature"),
    (dict(delta_t=1e5), "delta_t"),
])
def test_bad_parameters(kw, field):
    args = dict(latitude=45.0, longitude=5.0, when="2024-06-21T12:00:00Z")
    args.update(kw)
    with pytest.raises(ParameterError) as exc:
        sp.sun_position(args.pop("latitude"), args.pop("longitude"), args.pop("when"), **args)
    assert exc.value.field == field
    assert "allowed" in str(exc.value)


def test_bad_array_element_is_named():
    with pytest.raises(ParameterError) as exc:
        sp.sun_position(np.array([10.0, 20.0, 95.0]), 0.0, "2024-06-21T12:00:00Z")
    assert exc.value.field == "latitude[2]" and exc.value.value == 95.0


@pytest.mark.parametrize("when", [
    "not a date", 2452930.3, dt.date(2024, 6, 21), np.datetime64("NaT"),
    [np.datetime64("2024-01-01"), np.datetime64("NaT")], np.array([1.0, 2.0]),
    "9999-01-01T00:00:00",
])
def test_bad_times(when):
    with pytest.raises(ParameterError) as exc:
        sp.sun_position(45.0, 5.0, when)
    assert exc.value.field == "when"


def test_bad_shapes_and_directions():
    with pytest.raises(ParameterError):
        sp.sun_position(np.zeros(3), np.zeros(4), "2024-06-21T12:00:00Z")
    with pytest.raises(ParameterError):
        sp.sun_direction(0.0, 95.0)
    with pytest.raises(ParameterError):
        sp.direction_to_angles([0.0, 0.0, 0.0])
    with pytest.raises(ParameterError):
        sp.direction_to_angles([1.0, 0.0])


# ------------------------------------------------------------------------------------------
# The daily sun path of the moss and world loops (light/sunpath.py)
# ------------------------------------------------------------------------------------------
def test_day_sun_path_is_the_clear_sky_sun_path_normalised():
    """day_sun_path: the directions of sun_path over the UTC day, weighted by the SPCTRAL2
    broadband DNI of the same path (one clear-sky model) and normalised to a unit horizontal
    daily-mean beam."""
    from mitsuba_veg.light.sunpath import clear_sky_broadband, day_sun_path, sun_path
    day = dt.date(2026, 9, 14)
    dirs, w, el = day_sun_path(35.0, 139.0, day, step_minutes=10.0)
    p = sun_path(35.0, 139.0, start=day, days=1, step_hours=10 / 60, utc_offset_hours=0.0)
    np.testing.assert_allclose(dirs, p.direction)
    np.testing.assert_allclose(el, p.elevation)
    assert np.sum(w * np.sin(np.radians(el))) == pytest.approx(1.0, rel=1e-12)
    dni, _ = clear_sky_broadband(el, day.timetuple().tm_yday)
    up = dni > 0
    np.testing.assert_allclose(w[up] / dni[up], w[up][0] / dni[up][0], rtol=1e-12)
    assert np.all(w[~up] == 0) and np.all(el[~up] <= 0.5)
    # the weight per W m-2 of DNI is Δt / 86400 over the horizontal daily-mean beam [W m-2]
    beam = np.sum(dni * 600.0 / 86400.0 * np.sin(np.radians(el)))
    assert w[up][0] / dni[up][0] == pytest.approx(600.0 / 86400.0 / beam, rel=1e-12)
    # low sun keeps SPCTRAL2's share: at 10° elevation 0.54 of the DNI at 45° (day 257)
    d10, d45 = clear_sky_broadband([10.0, 45.0], 257)[0]
    assert 0.5 < d10 / d45 < 0.6          # 0.540 (the former Meinel weights: 0.499)


def test_day_sun_path_in_polar_night_is_empty():
    from mitsuba_veg.light.sunpath import day_sun_path
    dirs, w, el = day_sun_path(80.0, 0.0, dt.date(2026, 12, 21))
    assert dirs.shape == (0, 3) and w.shape == (0,) and el.shape == (0,)
    dirs, w, el = day_sun_path(80.0, 0.0, dt.date(2026, 6, 21), step_minutes=30.0)
    assert len(w) == 48 and np.all(w > 0)     # midnight sun: every step of the day


def test_day_sun_paths_of_a_long_run_come_in_blocks_with_the_values_of_one_call(monkeypatch):
    """Runs longer than sun_path's 3,660 days (simulation.days allows 100,000): day_sun_paths
    computes them in blocks; with blocks of 7 days, 20 days (at 78 N the polar night begins
    on 25 October: days without rows) equal one call's arrays, day by day."""
    from mitsuba_veg.light import sunpath
    one = sunpath.day_sun_paths(78.0, 0.0, dt.date(2026, 10, 20), 20)
    monkeypatch.setattr(sunpath, "SUN_PATH_BLOCK_DAYS", 7)
    blocks = sunpath.day_sun_paths(78.0, 0.0, dt.date(2026, 10, 20), 20)
    assert np.array_equal(one.offsets, blocks.offsets) and len(one.offsets) == 21
    assert np.diff(one.offsets)[-1] == 0 < np.diff(one.offsets)[0]   # the sun sets for good
    for f in ("directions", "weights", "elevations"):
        assert np.array_equal(getattr(one, f), getattr(blocks, f)), f
    for k in (0, 6, 7, 13, 14):            # each block's first and last day as day_sun_path
        d, w, _ = blocks.day(k)
        d1, w1, _ = sunpath.day_sun_path(78.0, 0.0, dt.date(2026, 10, 20) + dt.timedelta(k))
        np.testing.assert_allclose(w, w1, rtol=1e-12)
        np.testing.assert_allclose(d, d1, rtol=1e-12, atol=1e-15)
    with pytest.raises(ParameterError, match="days"):
        sunpath.day_sun_paths(78.0, 0.0, dt.date(2026, 10, 20), 100_001)
