"""Sun position from the NREL Solar Position Algorithm (SPA), in pure numpy.

Implements the full SPA of Reda & Andreas, *Solar Position Algorithm for Solar Radiation
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

This module imports numpy only (not Mitsuba), so it is cheap to import and to test.
"""
from __future__ import annotations

import datetime as _dt
from typing import NamedTuple

import numpy as np

from ..errors import ParameterError

__all__ = ["sun_position", "sun_ephemeris", "SunEphemeris", "sun_direction",
           "direction_to_angles", "julian_day", "default_delta_t"]

# --------------------------------------------------------------------------------------------
# Periodic terms (A [1e-8 rad or 1e-8 AU], B [rad], C [rad per Julian millennium]) of the Earth
# heliocentric longitude L0..L5, latitude B0..B1 and radius vector R0..R4: report Table A4.2.
# Each term contributes A cos(B + C JME) (eq. 9).
# --------------------------------------------------------------------------------------------
_L0 = np.array([
    (175347046.0, 0.0, 0.0), (3341656.0, 4.6692568, 6283.07585), (34894.0, 4.6261, 12566.1517),
    (3497.0, 2.7441, 5753.3849), (3418.0, 2.8289, 3.5231), (3136.0, 3.6277, 77713.7715),
    (2676.0, 4.4181, 7860.4194), (2343.0, 6.1352, 3930.2097), (1324.0, 0.7425, 11506.7698),
    (1273.0, 2.0371, 529.691), (1199.0, 1.1096, 1577.3435), (990.0, 5.233, 5884.927),
    (902.0, 2.045, 26.298), (857.0, 3.508, 398.149), (780.0, 1.179, 5223.694),
    (753.0, 2.533, 5507.553), (505.0, 4.583, 18849.228), (492.0, 4.205, 775.523),
    (357.0, 2.92, 0.067), (317.0, 5.849, 11790.629), (284.0, 1.899, 796.298),
    (271.0, 0.315, 10977.079), (243.0, 0.345, 5486.778), (206.0, 4.806, 2544.314),
    (205.0, 1.869, 5573.143), (202.0, 2.458, 6069.777), (156.0, 0.833, 213.299),
    (132.0, 3.411, 2942.463), (126.0, 1.083, 20.775), (115.0, 0.645, 0.98),
    (103.0, 0.636, 4694.003), (102.0, 0.976, 15720.839), (102.0, 4.267, 7.114),
    (99.0, 6.21, 2146.17), (98.0, 0.68, 155.42), (86.0, 5.98, 161000.69), (85.0, 1.3, 6275.96),
    (85.0, 3.67, 71430.7), (80.0, 1.81, 17260.15), (79.0, 3.04, 12036.46), (75.0, 1.76, 5088.63),
    (74.0, 3.5, 3154.69), (74.0, 4.68, 801.82), (70.0, 0.83, 9437.76), (62.0, 3.98, 8827.39),
    (61.0, 1.82, 7084.9), (57.0, 2.78, 6286.6), (56.0, 4.39, 14143.5), (56.0, 3.47, 6279.55),
    (52.0, 0.19, 12139.55), (52.0, 1.33, 1748.02), (51.0, 0.28, 5856.48), (49.0, 0.49, 1194.45),
    (41.0, 5.37, 8429.24), (41.0, 2.4, 19651.05), (39.0, 6.17, 10447.39), (37.0, 6.04, 10213.29),
    (37.0, 2.57, 1059.38), (36.0, 1.71, 2352.87), (36.0, 1.78, 6812.77), (33.0, 0.59, 17789.85),
    (30.0, 0.44, 83996.85), (30.0, 2.74, 1349.87), (25.0, 3.16, 4690.48),
])
_L1 = np.array([
    (628331966747.0, 0.0, 0.0), (206059.0, 2.678235, 6283.07585), (4303.0, 2.6351, 12566.1517),
    (425.0, 1.59, 3.523), (119.0, 5.796, 26.298), (109.0, 2.966, 1577.344), (93.0, 2.59, 18849.23),
    (72.0, 1.14, 529.69), (68.0, 1.87, 398.15), (67.0, 4.41, 5507.55), (59.0, 2.89, 5223.69),
    (56.0, 2.17, 155.42), (45.0, 0.4, 796.3), (36.0, 0.47, 775.52), (29.0, 2.65, 7.11),
    (21.0, 5.34, 0.98), (19.0, 1.85, 5486.78), (19.0, 4.97, 213.3), (17.0, 2.99, 6275.96),
    (16.0, 0.03, 2544.31), (16.0, 1.43, 2146.17), (15.0, 1.21, 10977.08), (12.0, 2.83, 1748.02),
    (12.0, 3.26, 5088.63), (12.0, 5.27, 1194.45), (12.0, 2.08, 4694.0), (11.0, 0.77, 553.57),
    (10.0, 1.3, 6286.6), (10.0, 4.24, 1349.87), (9.0, 2.7, 242.73), (9.0, 5.64, 951.72),
    (8.0, 5.3, 2352.87), (6.0, 2.65, 9437.76), (6.0, 4.67, 4690.48),
])
_L2 = np.array([
    (52919.0, 0.0, 0.0), (8720.0, 1.0721, 6283.0758), (309.0, 0.867, 12566.152),
    (27.0, 0.05, 3.52), (16.0, 5.19, 26.3), (16.0, 3.68, 155.42), (10.0, 0.76, 18849.23),
    (9.0, 2.06, 77713.77), (7.0, 0.83, 775.52), (5.0, 4.66, 1577.34), (4.0, 1.03, 7.11),
    (4.0, 3.44, 5573.14), (3.0, 5.14, 796.3), (3.0, 6.05, 5507.55), (3.0, 1.19, 242.73),
    (3.0, 6.12, 529.69), (3.0, 0.31, 398.15), (3.0, 2.28, 553.57), (2.0, 4.38, 5223.69),
    (2.0, 3.75, 0.98),
])
_L3 = np.array([
    (289.0, 5.844, 6283.076), (35.0, 0.0, 0.0), (17.0, 5.49, 12566.15), (3.0, 5.2, 155.42),
    (1.0, 4.72, 3.52), (1.0, 5.3, 18849.23), (1.0, 5.97, 242.73),
])
_L4 = np.array([
    (114.0, 3.142, 0.0), (8.0, 4.13, 6283.08), (1.0, 3.84, 12566.15),
])
_L5 = np.array([
    (1.0, 3.14, 0.0),
])
_B0 = np.array([
    (280.0, 3.199, 84334.662), (102.0, 5.422, 5507.553), (80.0, 3.88, 5223.69),
    (44.0, 3.7, 2352.87), (32.0, 4.0, 1577.34),
])
_B1 = np.array([
    (9.0, 3.9, 5507.55), (6.0, 1.73, 5223.69),
])
_R0 = np.array([
    (100013989.0, 0.0, 0.0), (1670700.0, 3.0984635, 6283.07585), (13956.0, 3.05525, 12566.1517),
    (3084.0, 5.1985, 77713.7715), (1628.0, 1.1739, 5753.3849), (1576.0, 2.8469, 7860.4194),
    (925.0, 5.453, 11506.77), (542.0, 4.564, 3930.21), (472.0, 3.661, 5884.927),
    (346.0, 0.964, 5507.553), (329.0, 5.9, 5223.694), (307.0, 0.299, 5573.143),
    (243.0, 4.273, 11790.629), (212.0, 5.847, 1577.344), (186.0, 5.022, 10977.079),
    (175.0, 3.012, 18849.228), (110.0, 5.055, 5486.778), (98.0, 0.89, 6069.78),
    (86.0, 5.69, 15720.84), (86.0, 1.27, 161000.69), (65.0, 0.27, 17260.15), (63.0, 0.92, 529.69),
    (57.0, 2.01, 83996.85), (56.0, 5.24, 71430.7), (49.0, 3.25, 2544.31), (47.0, 2.58, 775.52),
    (45.0, 5.54, 9437.76), (43.0, 6.01, 6275.96), (39.0, 5.36, 4694.0), (38.0, 2.39, 8827.39),
    (37.0, 0.83, 19651.05), (37.0, 4.9, 12139.55), (36.0, 1.67, 12036.46), (35.0, 1.84, 2942.46),
    (33.0, 0.24, 7084.9), (32.0, 0.18, 5088.63), (32.0, 1.78, 398.15), (28.0, 1.21, 6286.6),
    (28.0, 1.9, 6279.55), (26.0, 4.59, 10447.39),
])
_R1 = np.array([
    (103019.0, 1.10749, 6283.07585), (1721.0, 1.0644, 12566.1517), (702.0, 3.142, 0.0),
    (32.0, 1.02, 18849.23), (31.0, 2.84, 5507.55), (25.0, 1.32, 5223.69), (18.0, 1.42, 1577.34),
    (10.0, 5.91, 10977.08), (9.0, 1.42, 6275.96), (9.0, 0.27, 5486.78),
])
_R2 = np.array([
    (4359.0, 5.7846, 6283.0758), (124.0, 5.579, 12566.152), (12.0, 3.14, 0.0),
    (9.0, 3.63, 77713.77), (6.0, 1.87, 5573.14), (3.0, 5.47, 18849.23),
])
_R3 = np.array([
    (145.0, 4.273, 6283.076), (7.0, 3.92, 12566.15),
])
_R4 = np.array([
    (4.0, 2.56, 6283.08),
])
_NUTATION = np.array([
    ( 0,  0,  0,  0,  1, -171996.0, -174.2, 92025.0, 8.9),
    (-2,  0,  0,  2,  2, -13187.0, -1.6, 5736.0, -3.1),
    ( 0,  0,  0,  2,  2, -2274.0, -0.2, 977.0, -0.5),
    ( 0,  0,  0,  0,  2, 2062.0, 0.2, -895.0, 0.5),
    ( 0,  1,  0,  0,  0, 1426.0, -3.4, 54.0, -0.1),
    ( 0,  0,  1,  0,  0, 712.0, 0.1, -7.0, 0.0),
    (-2,  1,  0,  2,  2, -517.0, 1.2, 224.0, -0.6),
    ( 0,  0,  0,  2,  1, -386.0, -0.4, 200.0, 0.0),
    ( 0,  0,  1,  2,  2, -301.0, 0.0, 129.0, -0.1),
    (-2, -1,  0,  2,  2, 217.0, -0.5, -95.0, 0.3),
    (-2,  0,  1,  0,  0, -158.0, 0.0, 0.0, 0.0),
    (-2,  0,  0,  2,  1, 129.0, 0.1, -70.0, 0.0),
    ( 0,  0, -1,  2,  2, 123.0, 0.0, -53.0, 0.0),
    ( 2,  0,  0,  0,  0, 63.0, 0.0, 0.0, 0.0),
    ( 0,  0,  1,  0,  1, 63.0, 0.1, -33.0, 0.0),
    ( 2,  0, -1,  2,  2, -59.0, 0.0, 26.0, 0.0),
    ( 0,  0, -1,  0,  1, -58.0, -0.1, 32.0, 0.0),
    ( 0,  0,  1,  2,  1, -51.0, 0.0, 27.0, 0.0),
    (-2,  0,  2,  0,  0, 48.0, 0.0, 0.0, 0.0),
    ( 0,  0, -2,  2,  1, 46.0, 0.0, -24.0, 0.0),
    ( 2,  0,  0,  2,  2, -38.0, 0.0, 16.0, 0.0),
    ( 0,  0,  2,  2,  2, -31.0, 0.0, 13.0, 0.0),
    ( 0,  0,  2,  0,  0, 29.0, 0.0, 0.0, 0.0),
    (-2,  0,  1,  2,  2, 29.0, 0.0, -12.0, 0.0),
    ( 0,  0,  0,  2,  0, 26.0, 0.0, 0.0, 0.0),
    (-2,  0,  0,  2,  0, -22.0, 0.0, 0.0, 0.0),
    ( 0,  0, -1,  2,  1, 21.0, 0.0, -10.0, 0.0),
    ( 0,  2,  0,  0,  0, 17.0, -0.1, 0.0, 0.0),
    ( 2,  0, -1,  0,  1, 16.0, 0.0, -8.0, 0.0),
    (-2,  2,  0,  2,  2, -16.0, 0.1, 7.0, 0.0),
    ( 0,  1,  0,  0,  1, -15.0, 0.0, 9.0, 0.0),
    (-2,  0,  1,  0,  1, -13.0, 0.0, 7.0, 0.0),
    ( 0, -1,  0,  0,  1, -12.0, 0.0, 6.0, 0.0),
    ( 0,  0,  2, -2,  0, 11.0, 0.0, 0.0, 0.0),
    ( 2,  0, -1,  2,  1, -10.0, 0.0, 5.0, 0.0),
    ( 2,  0,  1,  2,  2, -8.0, 0.0, 3.0, 0.0),
    ( 0,  1,  0,  2,  2, 7.0, 0.0, -3.0, 0.0),
    (-2,  1,  1,  0,  0, -7.0, 0.0, 0.0, 0.0),
    ( 0, -1,  0,  2,  2, -7.0, 0.0, 3.0, 0.0),
    ( 2,  0,  0,  2,  1, -7.0, 0.0, 3.0, 0.0),
    ( 2,  0,  1,  0,  0, 6.0, 0.0, 0.0, 0.0),
    (-2,  0,  2,  2,  2, 6.0, 0.0, -3.0, 0.0),
    (-2,  0,  1,  2,  1, 6.0, 0.0, -3.0, 0.0),
    ( 2,  0, -2,  0,  1, -6.0, 0.0, 3.0, 0.0),
    ( 2,  0,  0,  0,  1, -6.0, 0.0, 3.0, 0.0),
    ( 0, -1,  1,  0,  0, 5.0, 0.0, 0.0, 0.0),
    (-2, -1,  0,  2,  1, -5.0, 0.0, 3.0, 0.0),
    (-2,  0,  0,  0,  1, -5.0, 0.0, 3.0, 0.0),
    ( 0,  0,  2,  2,  1, -5.0, 0.0, 3.0, 0.0),
    (-2,  0,  2,  0,  1, 4.0, 0.0, 0.0, 0.0),
    (-2,  1,  0,  2,  1, 4.0, 0.0, 0.0, 0.0),
    ( 0,  0,  1, -2,  0, 4.0, 0.0, 0.0, 0.0),
    (-1,  0,  1,  0,  0, -4.0, 0.0, 0.0, 0.0),
    (-2,  1,  0,  0,  0, -4.0, 0.0, 0.0, 0.0),
    ( 1,  0,  0,  0,  0, -4.0, 0.0, 0.0, 0.0),
    ( 0,  0,  1,  2,  0, 3.0, 0.0, 0.0, 0.0),
    ( 0,  0, -2,  2,  2, -3.0, 0.0, 0.0, 0.0),
    (-1, -1,  1,  0,  0, -3.0, 0.0, 0.0, 0.0),
    ( 0,  1,  1,  0,  0, -3.0, 0.0, 0.0, 0.0),
    ( 0, -1,  1,  2,  2, -3.0, 0.0, 0.0, 0.0),
    ( 2, -1, -1,  2,  2, -3.0, 0.0, 0.0, 0.0),
    ( 0,  0,  3,  2,  2, -3.0, 0.0, 0.0, 0.0),
    ( 2, -1,  0,  2,  2, -3.0, 0.0, 0.0, 0.0),
])

_L_TERMS = (_L0, _L1, _L2, _L3, _L4, _L5)
_B_TERMS = (_B0, _B1)
_R_TERMS = (_R0, _R1, _R2, _R3, _R4)
_NUT_Y = _NUTATION[:, :5]                                    # multipliers of X0..X4
_NUT_A, _NUT_B, _NUT_C, _NUT_D = (_NUTATION[:, 5 + i] for i in range(4))  # [0.0001 arcsec]

# Constants of the report.
_SUN_RADIUS = 0.26667           # [deg], used by the refraction switch (as in NREL's spa.c)
_ATMOS_REFRACT = 0.5667         # [deg], refraction at sunrise/sunset (spa.c default)
_EARTH_RADIUS_EQ = 6378140.0    # [m], equatorial radius (eqs. 35-36)
_FLATTENING_FACTOR = 0.99664719  # 1 - f (eqs. 34, 36)

_JD_UNIX_EPOCH = 2440587.5      # Julian day of 1970-01-01T00:00 UTC
_J2000 = 2451545.0              # Julian day of 2000-01-01T12:00 TT
_US_PER_DAY = 86_400_000_000
_CHUNK = 4096                   # times per block in the periodic sums (bounds temporary memory)

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
# SPA
# --------------------------------------------------------------------------------------------
def _periodic_sum(table: np.ndarray, jme: np.ndarray) -> np.ndarray:
    """Sum_i A_i cos(B_i + C_i JME) over the rows of ``table`` (eqs. 9-10), for flat ``jme``."""
    out = np.empty_like(jme)
    a, b, c = table[:, 0], table[:, 1:2], table[:, 2:3]
    for s in range(0, jme.size, _CHUNK):
        x = jme[s:s + _CHUNK]
        out[s:s + _CHUNK] = a @ np.cos(b + c * x[None, :])
    return out


def _earth_series(terms, jme: np.ndarray) -> np.ndarray:
    """(X0 + X1 JME + X2 JME^2 + ...) / 1e8 (eq. 11) in [rad] or [AU]."""
    acc = np.zeros_like(jme)
    for table in reversed(terms):   # Horner
        acc = acc * jme + _periodic_sum(table, jme)
    return acc / 1e8


def _nutation(jce: np.ndarray):
    """Nutation in longitude and obliquity, dpsi, deps [deg] (eqs. 15-23), for flat ``jce``."""
    x = np.stack([
        297.85036 + jce * (445267.111480 + jce * (-0.0019142 + jce / 189474.0)),    # eq. 15
        357.52772 + jce * (35999.050340 + jce * (-0.0001603 - jce / 300000.0)),     # eq. 16
        134.96298 + jce * (477198.867398 + jce * (0.0086972 + jce / 56250.0)),      # eq. 17
        93.27191 + jce * (483202.017538 + jce * (-0.0036825 + jce / 327270.0)),     # eq. 18
        125.04452 + jce * (-1934.136261 + jce * (0.0020708 + jce / 450000.0)),      # eq. 19
    ])                                                                              # [deg]
    dpsi = np.empty_like(jce)
    deps = np.empty_like(jce)
    for s in range(0, jce.size, _CHUNK):
        arg = np.deg2rad(_NUT_Y @ x[:, s:s + _CHUNK])            # sum_j X_j Y_ij
        sin_a, cos_a = np.sin(arg), np.cos(arg)
        t = jce[s:s + _CHUNK]
        dpsi[s:s + _CHUNK] = _NUT_A @ sin_a + t * (_NUT_B @ sin_a)   # eqs. 20, 22
        deps[s:s + _CHUNK] = _NUT_C @ cos_a + t * (_NUT_D @ cos_a)   # eqs. 21, 23
    return dpsi / 36_000_000.0, deps / 36_000_000.0


def _geocentric(jd: np.ndarray, delta_t: np.ndarray):
    """Time-only part of SPA (eqs. 5-31) for flat arrays.

    Returns the apparent sidereal time at Greenwich nu [deg], the geocentric right ascension
    alpha [deg] and declination delta [deg] of the Sun, and the Earth-Sun distance R [AU].
    """
    jde = jd + delta_t / 86400.0                                     # eq. 5
    jc = (jd - _J2000) / 36525.0                                     # eq. 6
    jce = (jde - _J2000) / 36525.0                                   # eq. 7
    jme = jce / 10.0                                                 # eq. 8

    l_deg = np.rad2deg(_earth_series(_L_TERMS, jme)) % 360.0        # eqs. 9-12
    b_deg = np.rad2deg(_earth_series(_B_TERMS, jme))
    r_au = _earth_series(_R_TERMS, jme)

    theta = (l_deg + 180.0) % 360.0                                  # eq. 13
    beta = -b_deg                                                    # eq. 14
    dpsi, deps = _nutation(jce)                                      # eqs. 15-23

    u = jme / 10.0
    eps0 = np.polyval([2.45, 5.79, 27.87, 7.12, -39.05, -249.67, -51.38, 1999.25, -1.55,
                       -4680.93, 84381.448], u)                      # eq. 24 [arcsec]
    eps = eps0 / 3600.0 + deps                                       # eq. 25 [deg]
    dtau = -20.4898 / (3600.0 * r_au)                                # eq. 26
    lam = theta + dpsi + dtau                                        # eq. 27

    nu0 = (280.46061837 + 360.98564736629 * (jd - _J2000)
           + jc * jc * (0.000387933 - jc / 38710000.0)) % 360.0      # eq. 28
    eps_r = np.deg2rad(eps)
    nu = nu0 + dpsi * np.cos(eps_r)                                  # eq. 29

    lam_r, beta_r = np.deg2rad(lam), np.deg2rad(beta)
    alpha = np.rad2deg(np.arctan2(np.sin(lam_r) * np.cos(eps_r)
                                  - np.tan(beta_r) * np.sin(eps_r),
                                  np.cos(lam_r))) % 360.0            # eq. 30
    delta = np.rad2deg(np.arcsin(np.sin(beta_r) * np.cos(eps_r)
                                 + np.cos(beta_r) * np.sin(eps_r) * np.sin(lam_r)))  # eq. 31
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
