"""Sun position from the NREL Solar Position Algorithm (SPA), in numpy.

This is the full SPA of Reda & Andreas, *Solar Position Algorithm for Solar Radiation
Applications*, NREL/TP-560-34302 (revised January 2008; also Solar Energy 76 (2004) 577-589 and
its corrigendum, Solar Energy 81 (2007) 838). "Eq. N", "§N" and "Table AN" below refer to that
report. The report states an uncertainty of +-0.0003 deg for years -2000..6000 (given the exact
TT-UT1 difference ``delta_t``).

Steps (all vectorised over numpy arrays):

1. Julian day JD from UT, Julian ephemeris day JDE = JD + delta_t/86400 and the Julian
   (ephemeris) century / millennium (§3.1, eqs. 4-8).
2. Earth heliocentric longitude L, latitude B and radius vector R [AU] from the periodic terms
   of Table A4.2 (§3.2, eqs. 9-12).
3. Geocentric longitude and latitude (§3.3, eqs. 13-14).
4. Nutation in longitude and obliquity from the terms of Table A4.3 (§3.4, eqs. 15-23).
5. True obliquity of the ecliptic (§3.5, eqs. 24-25), aberration (§3.6, eq. 26), apparent sun
   longitude (§3.7, eq. 27), apparent sidereal time at Greenwich (§3.8, eqs. 28-29).
6. Geocentric right ascension and declination (§3.9-3.10, eqs. 30-31), local hour angle
   (§3.11, eq. 32).
7. Parallax -> topocentric right ascension, declination and hour angle (§3.12-3.13,
   eqs. 33-40).
8. Topocentric elevation with the atmospheric refraction correction and zenith angle (§3.14,
   eqs. 41-44); topocentric azimuth (§3.15, eqs. 45-46).

Conventions (see ``docs/conventions.md``): angles are in degrees at this module's boundary;
azimuth is measured clockwise from north (east = 90 deg), as SPA's Phi (eq. 46); times are UTC
unless they carry a timezone. :func:`sun_direction` maps (azimuth, elevation) to the scene frame
+x east, +y up, +z south.

Steps 1-6 (the time-only part: the report's periodic-term tables and series) are pvlib's
implementation of the same report (``pvlib.spa``, a dependency: one implementation, checked
against the report's example in ``tests/test_sun_position.py``); this module adds the input
checks (times in many forms, ranges, shapes), the default delta_t, the observer part broadcast
over times x locations (steps 7-8) and the scene-frame directions. It imports neither Mitsuba nor (until a sun position is asked for) pvlib.
"""
from __future__ import annotations

import datetime as _dt
from typing import NamedTuple

import numpy as np

from ..errors import ParameterError

__all__ = ["sun_position", "sun_ephemeris", "SunEphemeris", "sun_direction",
           "direction_to_angles", "julian_day", "default_delta_t"]

# Constants of the report.
_SUN_RADIUS = 0.26667           # [deg], used by the refraction switch (as in NREL's spa.c)
_ATMOS_REFRACT = 0.5667         # [deg], refraction at sunrise/sunset (spa.c default)
_EARTH_RADIUS_EQ = 6378140.0    # [m], equatorial radius (eqs. 35-36)
_FLATTENING_FACTOR = 0.99664719  # 1 - f (eqs. 34, 36)

_JD_UNIX_EPOCH = 2440587.5      # Julian day of 1970-01-01T00:00 UTC
_US_PER_DAY = 86_400_000_000

_WHEN_ALLOWED = ("a datetime.datetime (naive = UTC), a numpy.datetime64 (UTC), an ISO 8601 "
                 "string, or an array/list of these")
_YEAR_RANGE = (-2000, 6000)     # validity range of SPA (report §2 and spa.c)


# --------------------------------------------------------------------------------------------
# Input handling
# --------------------------------------------------------------------------------------------
def _scalar_to_us(v) -> int:
    """One time value -> microseconds since 1970-01-01T00:00 UTC."""
    if isinstance(v, np.datetime64):
        if np.isnat(v):
            raise ParameterError("when", v, _WHEN_ALLOWED, "give a valid time, not NaT")
        return int(v.astype("datetime64[us]").astype(np.int64))
    if isinstance(v, (str, np.str_)):
        s = str(v).strip()
        try:
            v = _dt.datetime.fromisoformat(s[:-1] + "+00:00" if s.endswith(("Z", "z")) else s)
        except ValueError:
            try:
                return _scalar_to_us(np.datetime64(s, "us"))
            except ValueError:
                raise ParameterError(
                    "when", s, _WHEN_ALLOWED,
                    "write the time as ISO 8601, e.g. '2003-10-17T12:30:30-07:00' or "
                    "'2003-10-17 19:30:30' (UTC)") from None
    if isinstance(v, _dt.datetime):
        if v.tzinfo is not None and v.utcoffset() is not None:
            v = v.astimezone(_dt.timezone.utc).replace(tzinfo=None)
        return (v - _dt.datetime(1970, 1, 1)) // _dt.timedelta(microseconds=1)
    if isinstance(v, _dt.date):
        raise ParameterError("when", v, _WHEN_ALLOWED,
                             "give a datetime with a time of day, e.g. "
                             f"datetime.datetime({v.year}, {v.month}, {v.day}, 12, 0, "
                             "tzinfo=datetime.timezone.utc)")
    raise ParameterError("when", v, _WHEN_ALLOWED,
                         "Julian days and plain numbers are not accepted; convert them to "
                         "numpy.datetime64 (UTC)")


def _times_us(when) -> np.ndarray:
    """``when`` -> int64 array of microseconds since the Unix epoch (UTC), same shape."""
    if isinstance(when, (str, np.str_, _dt.date, np.datetime64)):
        return np.asarray(_scalar_to_us(when), dtype=np.int64)
    try:
        arr = np.asarray(when)
    except (ValueError, TypeError):
        raise ParameterError("when", when, _WHEN_ALLOWED,
                             "pass a rectangular list/array of times") from None
    if arr.dtype.kind == "M":
        if np.isnat(arr).any():
            bad = arr[np.isnat(arr)].flat[0]
            raise ParameterError("when", bad, _WHEN_ALLOWED, "remove NaT values")
        return arr.astype("datetime64[us]").astype(np.int64)
    if arr.dtype.kind in "OUS":
        out = np.empty(arr.shape, dtype=np.int64)
        for idx, v in np.ndenumerate(arr):
            out[idx] = _scalar_to_us(v.decode() if isinstance(v, bytes) else v)
        return out
    raise ParameterError("when", when, _WHEN_ALLOWED,
                         "Julian days and plain numbers are not accepted; convert them to "
                         "numpy.datetime64 (UTC)")


def _check_array(field: str, value, lo=None, hi=None, *, lo_open=False, hi_open=False,
                 fix: str | None = None) -> np.ndarray:
    """float64 array of ``value``; raise ParameterError naming the first bad element."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(field, value, "a number or an array of numbers", fix) from None
    bad = ~np.isfinite(a)
    if lo is not None:
        bad |= (a <= lo) if lo_open else (a < lo)
    if hi is not None:
        bad |= (a >= hi) if hi_open else (a > hi)
    if bad.any():
        lo_s = "-inf" if lo is None else repr(lo)
        hi_s = "inf" if hi is None else repr(hi)
        allowed = f"{'(' if lo_open else '['}{lo_s}, {hi_s}{')' if hi_open else ']'}"
        if a.ndim == 0:
            raise ParameterError(field, value, allowed, fix)
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ParameterError(f"{field}[{', '.join(map(str, idx))}]", float(a[idx]), allowed, fix)
    return a


def _year_month(us: np.ndarray):
    """Calendar year and month (proleptic Gregorian) of microsecond timestamps."""
    t = us.astype("datetime64[us]")
    year = t.astype("datetime64[Y]").astype(np.int64) + 1970
    month = t.astype("datetime64[M]").astype(np.int64) % 12 + 1
    return year, month


def _check_years(us: np.ndarray):
    year, _ = _year_month(us)
    bad = (year < _YEAR_RANGE[0]) | (year > _YEAR_RANGE[1])
    if bad.any():
        v = us.astype("datetime64[us]")[bad].flat[0]
        raise ParameterError("when", str(v), f"years {_YEAR_RANGE[0]}..{_YEAR_RANGE[1]}",
                             "SPA is only valid for years -2000..6000")


# --------------------------------------------------------------------------------------------
# Time scales
# --------------------------------------------------------------------------------------------
def julian_day(when) -> np.ndarray | float:
    """Julian day JD of ``when`` (report eq. 4; UT, proleptic Gregorian calendar).

    Computed as 2440587.5 + days since the Unix epoch, which equals eq. 4 for Gregorian dates
    (eq. 4 switches to the Julian calendar before 1582-10-15; numpy and Python dates are
    proleptic Gregorian).

    Parameters
    ----------
    when : datetime.datetime or numpy.datetime64 or str or array_like
        Time(s), anything :func:`sun_position` accepts.

    Returns
    -------
    float or numpy.ndarray
        Julian day(s) JD [d]; a float for one time.
    """
    jd = _JD_UNIX_EPOCH + _times_us(when) / _US_PER_DAY
    return float(jd) if np.ndim(jd) == 0 else jd


def _delta_t_from_us(us: np.ndarray) -> np.ndarray:
    year, month = _year_month(us)
    y = year + (month - 0.5) / 12.0
    dt = np.full(y.shape, np.nan)

    def seg(lo, hi, f):
        m = (year >= lo) & (year < hi)
        if m.any():
            dt[m] = f(y[m])

    seg(-10**9, -500, lambda y: -20 + 32 * ((y - 1820) / 100) ** 2)
    seg(-500, 500, lambda y: np.polyval(
        [0.0090316521, 0.022174192, -0.1798452, -5.952053, 33.78311, -1014.41, 10583.6],
        y / 100))
    seg(500, 1600, lambda y: np.polyval(
        [0.0083572073, -0.005050998, -0.8503463, 0.319781, 71.23472, -556.01, 1574.2],
        (y - 1000) / 100))
    seg(1600, 1700, lambda y: np.polyval([1 / 7129, -0.01532, -0.9808, 120.0], y - 1600))
    seg(1700, 1800, lambda y: np.polyval(
        [-1 / 1174000, 0.00013336, -0.0059285, 0.1603, 8.83], y - 1700))
    seg(1800, 1860, lambda y: np.polyval(
        [0.000000000875, -0.0000001699, 0.0000121272, -0.00037436, 0.0041116, 0.0068612,
         -0.332447, 13.72], y - 1800))
    seg(1860, 1900, lambda y: np.polyval(
        [1 / 233174, -0.0004473624, 0.01680668, -0.251754, 0.5737, 7.62], y - 1860))
    seg(1900, 1920, lambda y: np.polyval(
        [-0.000197, 0.0061966, -0.0598939, 1.494119, -2.79], y - 1900))
    seg(1920, 1941, lambda y: np.polyval([0.0020936, -0.076100, 0.84493, 21.20], y - 1920))
    seg(1941, 1961, lambda y: np.polyval([1 / 2547, -1 / 233, 0.407, 29.07], y - 1950))
    seg(1961, 1986, lambda y: np.polyval([-1 / 718, -1 / 260, 1.067, 45.45], y - 1975))
    seg(1986, 2005, lambda y: np.polyval(
        [0.00002373599, 0.000651814, 0.0017275, -0.060374, 0.3345, 63.86], y - 2000))
    seg(2005, 2050, lambda y: np.polyval([0.005589, 0.32217, 62.92], y - 2000))
    seg(2050, 2150, lambda y: -20 + 32 * ((y - 1820) / 100) ** 2 - 0.5628 * (2150 - y))
    seg(2150, 10**9, lambda y: -20 + 32 * ((y - 1820) / 100) ** 2)
    return dt


def default_delta_t(when) -> np.ndarray | float:
    """Model of delta_t = TT - UT1 used when :func:`sun_position` gets ``delta_t=None``.

    The polynomial expressions of Espenak & Meeus (NASA *Five Millennium Canon of Solar
    Eclipses*, 2006; https://eclipse.gsfc.nasa.gov/SEhelp/deltatpoly2004.html), evaluated at
    y = year + (month - 0.5)/12 with the branch chosen by the calendar year. They fit the
    observed delta_t to about 1 s over 1950-2005; after 2005 they are a prediction (the
    2005-2050 branch gives 74 s for 2024 where the observed value is 69 s). A delta_t error
    of dT [s] only shifts the ephemeris time, i.e. the Sun by about 4e-5 deg per 1 s of dT
    along the ecliptic, so the model is far more accurate than needed for 1950-2100; pass
    ``delta_t`` explicitly (e.g. from IERS Bulletin A) to reproduce SPA to 1e-4 deg.

    Parameters
    ----------
    when : datetime.datetime or numpy.datetime64 or str or array_like
        Time(s), anything :func:`sun_position` accepts.

    Returns
    -------
    float or numpy.ndarray
        delta_t = TT - UT1 [s] (eq. 5); a float for one time.
    """
    dt = _delta_t_from_us(_times_us(when))
    return float(dt) if dt.ndim == 0 else dt


# --------------------------------------------------------------------------------------------
# SPA: the time-only part (eqs. 5-31) from pvlib's implementation of the same report
# --------------------------------------------------------------------------------------------
def _geocentric(jd: np.ndarray, delta_t: np.ndarray):
    """Time-only part of SPA (eqs. 5-31) for flat arrays, by ``pvlib.spa`` (the NREL SPA's
    periodic-term tables and series, a dependency of the package: one implementation).

    Returns the apparent sidereal time at Greenwich nu [deg], the geocentric right ascension
    alpha [deg] and declination delta [deg] of the Sun, and the Earth-Sun distance R [AU].
    """
    # imported here, as clear_sky does: pvlib's package import loads pandas, which
    # ``import mitsuba_veg`` does not (tests/test_sweep.py)
    from pvlib import spa as _spa
    jde = _spa.julian_ephemeris_day(jd, delta_t)                         # eq. 5
    jc = _spa.julian_century(jd)                                         # eq. 6
    jce = _spa.julian_ephemeris_century(jde)                             # eq. 7
    jme = _spa.julian_ephemeris_millennium(jce)                          # eq. 8
    r_au = _spa.heliocentric_radius_vector(jme)                          # eqs. 9-12
    theta = _spa.geocentric_longitude(_spa.heliocentric_longitude(jme))  # eq. 13
    beta = _spa.geocentric_latitude(_spa.heliocentric_latitude(jme))     # eq. 14
    x = [f(jce) for f in (_spa.mean_elongation, _spa.mean_anomaly_sun,   # eqs. 15-19
                          _spa.mean_anomaly_moon, _spa.moon_argument_latitude,
                          _spa.moon_ascending_longitude)]
    nut = np.empty((2, len(jce)))
    _spa.longitude_obliquity_nutation(jce, *x, nut)                      # eqs. 20-23
    dpsi, deps = nut
    eps = _spa.true_ecliptic_obliquity(_spa.mean_ecliptic_obliquity(jme), deps)  # eqs. 24-25
    lam = _spa.apparent_sun_longitude(theta, dpsi, _spa.aberration_correction(r_au))  # 26-27
    nu = _spa.apparent_sidereal_time(_spa.mean_sidereal_time(jd, jc), dpsi, eps)  # 28-29
    alpha = _spa.geocentric_sun_right_ascension(lam, eps, beta)          # eq. 30
    delta = _spa.geocentric_sun_declination(lam, eps, beta)              # eq. 31
    return nu, alpha, delta, r_au


class SunEphemeris(NamedTuple):
    """Output of :func:`sun_ephemeris` (floats for scalar inputs, else broadcast arrays)."""

    azimuth: np.ndarray            #: topocentric azimuth Phi, clockwise from north [deg] (eq. 46)
    elevation: np.ndarray          #: topocentric elevation e, refracted if asked [deg] (eq. 43)
    zenith: np.ndarray             #: topocentric zenith angle theta = 90 - e [deg] (eq. 44)
    elevation_geometric: np.ndarray  #: elevation e0 without refraction [deg] (eq. 41)
    declination: np.ndarray        #: topocentric declination delta' [deg] (eq. 39)
    hour_angle: np.ndarray         #: topocentric local hour angle H', (-180, 180] [deg] (eq. 40)
    earth_sun_distance: np.ndarray  #: Earth-Sun distance R [AU] (§3.2.8)


def sun_ephemeris(latitude, longitude, when, *, elevation=0.0, pressure=1013.25,
                  temperature=12.0, delta_t=None, refraction=True) -> SunEphemeris:
    """Full SPA output for an observer (NREL SPA, Reda & Andreas 2004, eqs. 4-46).

    Parameters
    ----------
    latitude, longitude : float or array_like
        Observer position [deg], north / east positive, as :func:`sun_position`.
    when : datetime.datetime or numpy.datetime64 or str or array_like
        Time(s), as :func:`sun_position`.
    elevation : float or array_like, keyword-only
        Observer height above sea level [m] (parallax, eqs. 35-36).
    pressure : float or array_like, keyword-only
        Local air pressure [hPa] (refraction, eq. 42).
    temperature : float or array_like, keyword-only
        Local air temperature [degC] (refraction, eq. 42).
    delta_t : float or array_like or None, keyword-only
        TT - UT1 [s] (eq. 5); ``None`` uses :func:`default_delta_t`.
    refraction : bool, keyword-only
        Add the refraction correction (eq. 42) to the elevation, as :func:`sun_position`.

    Returns
    -------
    SunEphemeris
        Topocentric azimuth [deg], elevation [deg], zenith [deg], geometric elevation (no
        refraction) [deg], declination [deg], hour angle [deg] and the Earth-Sun distance [AU]
        (e.g. to scale the extraterrestrial irradiance by 1/R^2); floats for scalar inputs,
        else arrays of the broadcast shape.
    """
    lat = _check_array("latitude", latitude, -90.0, 90.0,
                       fix="latitude is in degrees, north positive, within [-90, 90]")
    lon = _check_array("longitude", longitude, -180.0, 180.0,
                       fix="longitude is in degrees, east positive, within [-180, 180]")
    elev = _check_array("elevation", elevation, -6_500_000.0, None,
                        fix="elevation is the observer's height above sea level [m]")
    pres = _check_array("pressure", pressure, 0.0, 5000.0,
                        fix="pressure is the local air pressure in hPa (mbar), e.g. 1013.25")
    temp = _check_array("temperature", temperature, -273.0, 6000.0, lo_open=True,
                        fix="temperature is the local air temperature in degC, e.g. 12")

    us = _times_us(when)
    _check_years(us)
    if delta_t is None:
        dt = _delta_t_from_us(us)
    else:
        dt = _check_array("delta_t", delta_t, -8000.0, 8000.0,
                          fix="delta_t is TT - UT1 in seconds (about 69 s in 2024), or None "
                              "for the built-in model")
    try:
        t_shape = np.broadcast_shapes(us.shape, dt.shape)
        shape = np.broadcast_shapes(t_shape, lat.shape, lon.shape, elev.shape, pres.shape,
                                    temp.shape)
    except ValueError:
        raise ParameterError(
            "shapes", {"when": us.shape, "delta_t": dt.shape, "latitude": lat.shape,
                       "longitude": lon.shape, "elevation": elev.shape,
                       "pressure": pres.shape, "temperature": temp.shape},
            "shapes that broadcast together (numpy rules)",
            "give scalars, or arrays of one common (broadcastable) shape") from None

    # Time-only part, once per distinct time sample (eqs. 4-31).
    jd = _JD_UNIX_EPOCH + np.broadcast_to(us, t_shape).ravel() / _US_PER_DAY      # eq. 4
    nu, alpha, delta, r_au = _geocentric(jd, np.broadcast_to(dt, t_shape).ravel())
    nu, alpha, delta, r_au = (a.reshape(t_shape) for a in (nu, alpha, delta, r_au))

    # Observer part (eqs. 32-46), broadcast over locations.
    h = (nu + lon - alpha) % 360.0                                   # eq. 32
    xi = np.deg2rad(8.794 / (3600.0 * r_au))                         # eq. 33
    lat_r = np.deg2rad(lat)
    u = np.arctan(_FLATTENING_FACTOR * np.tan(lat_r))                # eq. 34
    x = np.cos(u) + elev / _EARTH_RADIUS_EQ * np.cos(lat_r)          # eq. 35
    y = _FLATTENING_FACTOR * np.sin(u) + elev / _EARTH_RADIUS_EQ * np.sin(lat_r)  # eq. 36
    h_r, delta_r = np.deg2rad(h), np.deg2rad(delta)
    den = np.cos(delta_r) - x * np.sin(xi) * np.cos(h_r)
    dalpha = np.arctan2(-x * np.sin(xi) * np.sin(h_r), den)          # eq. 37 [rad]
    # (eq. 38, alpha' = alpha + dalpha, is not needed for the horizontal coordinates)
    delta_p = np.arctan2((np.sin(delta_r) - y * np.sin(xi)) * np.cos(dalpha), den)  # eq. 39
    h_p = h_r - dalpha                                               # eq. 40 [rad]

    e0 = np.rad2deg(np.arcsin(np.sin(lat_r) * np.sin(delta_p)
                              + np.cos(lat_r) * np.cos(delta_p) * np.cos(h_p)))  # eq. 41
    if refraction:
        with np.errstate(divide="ignore", invalid="ignore"):
            de = ((pres / 1010.0) * (283.0 / (273.0 + temp)) * 1.02
                  / (60.0 * np.tan(np.deg2rad(e0 + 10.3 / (e0 + 5.11)))))    # eq. 42
        # Only where the Sun's upper limb can be above the horizon (as NREL's spa.c).
        de = np.where(e0 >= -(_SUN_RADIUS + _ATMOS_REFRACT), de, 0.0)
    else:
        de = np.zeros_like(e0)
    e = e0 + de                                                      # eq. 43
    zenith = 90.0 - e                                                # eq. 44
    gamma = np.arctan2(np.sin(h_p), np.cos(h_p) * np.sin(lat_r)
                       - np.tan(delta_p) * np.cos(lat_r))            # eq. 45 [rad]
    phi = (np.rad2deg(gamma) + 180.0) % 360.0                        # eq. 46

    h_p_deg = (np.rad2deg(h_p) + 180.0) % 360.0 - 180.0
    out = [np.broadcast_to(a, shape).astype(np.float64, copy=True)
           for a in (phi, e, zenith, e0, np.rad2deg(delta_p), h_p_deg, r_au)]
    if shape == ():
        out = [float(a) for a in out]
    return SunEphemeris(*out)


def sun_position(latitude, longitude, when, *, elevation=0.0, pressure=1013.25,
                 temperature=12.0, delta_t=None, refraction=True):
    """Solar azimuth and elevation [deg] seen by an observer, by the NREL SPA.

    Parameters
    ----------
    latitude, longitude : float or array
        Observer position [deg], north / east positive; latitude in [-90, 90], longitude in
        [-180, 180] (geodetic, WGS84-like ellipsoid as in the report's eqs. 34-36).
    when : datetime, numpy.datetime64, str, or array/list of these
        Time(s). A timezone-aware ``datetime.datetime`` is converted to UTC; a naive one, a
        ``numpy.datetime64`` and an ISO 8601 string without offset are taken as UTC
        (strictly UT1; UTC - UT1 < 0.9 s, i.e. < 0.004 deg). Years -2000..6000.
    elevation : float or array, keyword-only
        Observer height above sea level [m] (parallax, eqs. 35-36).
    pressure : float or array, keyword-only
        Local air pressure [hPa] (= [mbar]), for the refraction correction (eq. 42).
    temperature : float or array, keyword-only
        Local air temperature [degC], for the refraction correction (eq. 42).
    delta_t : float, array or None, keyword-only
        TT - UT1 [s] (eq. 5). ``None`` uses :func:`default_delta_t` (Espenak & Meeus
        polynomials).
    refraction : bool, keyword-only
        Add SPA's atmospheric refraction correction (eq. 42) to the elevation; as in NREL's
        spa.c it is applied only when the geometric elevation is >= -0.83337 deg (Sun radius
        0.26667 deg + 0.5667 deg refraction at the horizon).

    Returns
    -------
    azimuth_deg, elevation_deg
        Topocentric azimuth [deg] in [0, 360), clockwise from north (east = 90, south = 180;
        eq. 46), and topocentric elevation [deg] = 90 - zenith (eqs. 43-44). Floats when all
        inputs are scalars, else arrays of the broadcast shape of ``when``, ``latitude``,
        ``longitude`` (and the other array arguments).

    Raises
    ------
    mitsuba_veg.errors.ParameterError
        For a value out of range (e.g. latitude 95), an unparseable time, or shapes that do
        not broadcast.

    Examples
    --------
    >>> az, el = sun_position(39.742476, -105.1786, "2003-10-17T12:30:30-07:00",
    ...                       elevation=1830.14, pressure=820, temperature=11, delta_t=67)
    >>> round(az, 4), round(90 - el, 4)
    (194.3402, 50.1116)
    """
    eph = sun_ephemeris(latitude, longitude, when, elevation=elevation, pressure=pressure,
                        temperature=temperature, delta_t=delta_t, refraction=refraction)
    return eph.azimuth, eph.elevation


# --------------------------------------------------------------------------------------------
# Scene-frame directions
# --------------------------------------------------------------------------------------------
def sun_direction(azimuth_deg, elevation_deg) -> np.ndarray:
    """Unit vector(s) pointing from the scene TOWARDS the Sun.

    Scene frame of the project (``docs/conventions.md``): +x east, +y up, +z south
    (right-handed, x cross y = z). With azimuth ``az`` [deg] clockwise from north and
    elevation ``el`` [deg]::

        d = (sin(az) cos(el), sin(el), -cos(az) cos(el))

    so az = 0 (north) -> -z, az = 90 (east) -> +x, az = 180 (south) -> +z, el = 90 -> +y.
    A Mitsuba ``directional`` emitter takes the direction the light travels, i.e.
    ``-sun_direction(az, el)``.

    Parameters
    ----------
    azimuth_deg : float or array_like
        Azimuth [deg], clockwise from north.
    elevation_deg : float or array_like
        Elevation [deg] in [-90, 90]; broadcasts with ``azimuth_deg`` (numpy rules).

    Returns
    -------
    numpy.ndarray
        Unit vectors [-], shape ``(..., 3)`` (the broadcast shape plus 3).
    """
    az = _check_array("azimuth_deg", azimuth_deg,
                      fix="azimuth is in degrees, clockwise from north")
    el = _check_array("elevation_deg", elevation_deg, -90.0, 90.0,
                      fix="elevation is in degrees above the horizon, within [-90, 90]")
    try:
        az, el = np.broadcast_arrays(np.deg2rad(az), np.deg2rad(el))
    except ValueError:
        raise ParameterError("shapes", {"azimuth_deg": az.shape, "elevation_deg": el.shape},
                             "shapes that broadcast together (numpy rules)") from None
    cos_el = np.cos(el)
    return np.stack([np.sin(az) * cos_el, np.sin(el), -np.cos(az) * cos_el], axis=-1)


def direction_to_angles(d):
    """Inverse of :func:`sun_direction`: direction(s) -> (azimuth, elevation).

    Parameters
    ----------
    d : array_like
        Direction(s), shape ``(..., 3)`` (x east, y up, z south); need not be normalised but
        must be non-zero and finite.

    Returns
    -------
    azimuth, elevation : float or numpy.ndarray
        Azimuth [deg] in [0, 360) clockwise from north (0 for (anti-)vertical directions,
        where it is undefined) and elevation [deg]; floats for a single vector, else arrays
        of shape ``d.shape[:-1]``.
    """
    v = _check_array("d", d, fix="give direction vectors (x east, y up, z south)")
    if v.ndim == 0 or v.shape[-1] != 3:
        raise ParameterError("d", d, "an array of shape (..., 3)",
                             "give direction vectors (x east, y up, z south)")
    norm = np.linalg.norm(v, axis=-1)
    if (norm == 0).any():
        raise ParameterError("d", d, "non-zero vectors", "a direction cannot be (0, 0, 0)")
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    horiz = np.hypot(x, z)
    el = np.rad2deg(np.arctan2(y, horiz))
    az = np.where(horiz > 1e-12 * norm, np.rad2deg(np.arctan2(x, -z)) % 360.0, 0.0)
    az = np.where(az >= 360.0, 0.0, az)     # -tiny % 360 can round to 360.0
    if az.ndim == 0:
        return float(az), float(el)
    return az, el
