"""Sun paths: the sun at regular steps over days (NREL SPA, SPCTRAL2 clear-sky irradiance).

:func:`sun_path` samples the sun every ``step_hours`` (the hourly sun paths of paper 003);
:func:`day_sun_path` (one day) and :func:`day_sun_paths` (consecutive days in one call) give the
sun directions and weights of the ``veg_sun_path`` emitter
(:class:`mitsuba_veg.integrators.veg_sun.VegSunPath`): a whole day of sun as one emitter, for
daily-mean light in one photon pass. The weights w_k = E_n,k Δt / 86400 are normalised so that
an unobstructed horizontal plane receives a daily-mean beam of exactly 1 W m-2 nm-1: a
triangle's result divided by the band width is its *sun fraction* f_sun.
"""
from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field

import numpy as np

from ..errors import ParameterError, check_range
from ..parallel import map_on_cores
from .clear_sky import clear_sky_broadband
from .solar_position import sun_direction, sun_position


__all__ = ["SunPath", "sun_path", "day_sun_path", "DaySunPaths", "SUN_PATH_BLOCK_DAYS",
           "day_sun_paths"]

@dataclass
class SunPath:
    """The sun at regular steps (daytime only): times, angles, direction, irradiances."""

    times: np.ndarray        # datetime64[s] UTC, mid-step
    day: np.ndarray          # (h,) int: day index from the start (local dates)
    azimuth: np.ndarray      # [deg] clockwise from north
    elevation: np.ndarray    # [deg]
    direction: np.ndarray    # (h, 3) unit vector towards the sun (+x east, +y up, +z south)
    dni: np.ndarray          # (h,) direct normal irradiance [W m-2]
    dhi: np.ndarray          # (h,) diffuse horizontal irradiance [W m-2]
    step_hours: float
    days: int
    settings: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.dni)


def _start_date(start) -> _dt.date:
    if isinstance(start, _dt.datetime):
        return start.date()
    if isinstance(start, _dt.date):
        return start
    try:
        return _dt.date.fromisoformat(str(start)[:10])
    except ValueError:
        raise ParameterError("start", start, "a date 'YYYY-MM-DD'", "e.g. start='2026-10-01'") \
            from None


def sun_path(latitude: float, longitude: float, start="2026-10-01", days: int = 60,
             step_hours: float = 1.0, utc_offset_hours: float | None = None,
             intensity="clear_sky", min_elevation: float = 0.0) -> SunPath:
    """The sun every ``step_hours`` from local midnight of ``start`` for ``days`` days.

    Sun positions by the NREL SPA (:func:`~mitsuba_veg.light.solar_position.sun_position`) at
    the middle of each step; the sampler of the hourly sun paths of paper 003 and of the daily
    ``veg_sun_path`` (:func:`day_sun_path`).

    Parameters
    ----------
    latitude : float
        Latitude [deg], north positive.
    longitude : float
        Longitude [deg], east positive.
    start : str or datetime.date
        First local day, 'YYYY-MM-DD'.
    days : int
        Number of days (1-3660).
    step_hours : float
        Time step [h], a divisor of 24 h.
    utc_offset_hours : float, optional
        Local standard time offset [h] (default: round(longitude / 15)).
    intensity : str or float
        ``"clear_sky"`` (SPCTRAL2 broadband DNI/DHI, :func:`clear_sky_broadband`) or a number:
        constant beam I [W m-2] (the paper's I), with DHI 0.
    min_elevation : float
        Steps with the sun at or below this elevation [deg] are dropped.

    Returns
    -------
    SunPath
        The daytime steps: times (UTC), day index, azimuth [deg], elevation [deg], direction
        towards the sun, DNI [W m-2] and DHI [W m-2].
    """
    check_range("latitude", latitude, -90.0, 90.0)
    check_range("longitude", longitude, -180.0, 180.0)
    check_range("days", days, 1, 3660)
    check_range("step_hours", step_hours, 1 / 60, 24.0)
    if abs(24.0 / step_hours - round(24.0 / step_hours)) > 1e-9:
        raise ParameterError("step_hours", step_hours, "a divisor of 24 h", "e.g. 1, 0.5, 2")
    d0 = _start_date(start)
    off = round(longitude / 15.0) if utc_offset_hours is None else float(utc_offset_hours)
    per_day = int(round(24.0 / step_hours))
    n = int(days) * per_day
    mid_s = ((np.arange(n) + 0.5) * step_hours * 3600.0 - off * 3600.0).round().astype(np.int64)
    t0 = np.datetime64(d0.isoformat(), "s")
    times = t0 + mid_s.astype("timedelta64[s]")
    day = np.arange(n) // per_day
    az, el = sun_position(latitude, longitude, times)
    az, el = np.asarray(az, float), np.asarray(el, float)
    keep = el > min_elevation
    doy = np.array([(d0 + _dt.timedelta(days=int(k))).timetuple().tm_yday for k in range(days)])
    if isinstance(intensity, str):
        if intensity != "clear_sky":
            raise ParameterError("intensity", intensity, "'clear_sky' or a number [W m-2]")
        dni, dhi = clear_sky_broadband(el[keep], doy[day[keep]])
    else:
        check_range("intensity", intensity, 0.0, 2000.0)
        dni = np.full(int(keep.sum()), float(intensity))
        dhi = np.zeros(int(keep.sum()))
    return SunPath(times[keep], day[keep], az[keep], el[keep],
                   np.asarray(sun_direction(az[keep], el[keep]), float).reshape(-1, 3),
                   dni, dhi, float(step_hours), int(days),
                   dict(latitude=latitude, longitude=longitude, start=d0.isoformat(),
                        utc_offset_hours=off, intensity=intensity))


def day_sun_path(latitude, longitude, date, step_minutes: float = 10.0):
    """Sun directions and weights of one day, for the ``veg_sun_path`` emitter.

    The sun every ``step_minutes`` over the whole UTC day from :func:`sun_path` with its
    SPCTRAL2 clear-sky direct-normal irradiance (:func:`clear_sky_broadband`, the model of every
    sun path in the package), weighted by DNI_k × Δt / 86400 and normalised so that
    Σ_k w_k sin(el_k) = 1 (a unit daily-mean beam on the horizontal). The whole 24 h are
    covered, so the time zone does not matter for daily means. Directions with the sun at or
    below 0.5° elevation keep a zero weight (SPCTRAL2 gives no beam there).

    Parameters
    ----------
    latitude, longitude : float
        The site [deg].
    date : datetime.date
        The day (UTC).
    step_minutes : float
        Time step [min] (a divisor of 24 h).

    Returns
    -------
    dirs : numpy.ndarray
        (K, 3) unit vectors towards the sun (scene frame).
    weights : numpy.ndarray
        (K,) weights w_k [-].
    elevations : numpy.ndarray
        (K,) sun elevations [deg]. All three are empty when the sun stays below the horizon.
    """
    if isinstance(date, _dt.datetime):
        date = date.date()
    p = sun_path(latitude, longitude, start=date, days=1, step_hours=step_minutes / 60.0,
                 utc_offset_hours=0.0, intensity="clear_sky")
    w = p.dni * (step_minutes * 60.0 / 86400.0)
    horizontal = float(np.sum(w * np.sin(np.radians(p.elevation))))
    if len(p) == 0 or horizontal <= 0.0:  # polar night, or the sun never above 0.5°
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0)
    w = w / horizontal
    return p.direction, w, p.elevation


@dataclass
class DaySunPaths:
    """The sun paths of consecutive days, packed (:func:`day_sun_paths`).

    Day ``k``'s directions and weights are rows ``offsets[k]:offsets[k + 1]`` of ``directions``
    and ``weights``; a day without sun above 0.5 degrees has no rows.
    """

    directions: np.ndarray   # (N, 3) unit vectors towards the sun (scene frame)
    weights: np.ndarray      # (N,) w_k [-], each day's normalised to a unit horizontal beam
    elevations: np.ndarray   # (N,) [deg]
    offsets: np.ndarray      # (days + 1,) int64

    def day(self, k: int):
        """Directions, weights and elevations of day ``k`` (as :func:`day_sun_path`).

        Parameters
        ----------
        k : int
            Day index from the first day.

        Returns
        -------
        tuple of numpy.ndarray
            (K, 3) directions, (K,) weights [-], (K,) elevations [deg].
        """
        a, b = int(self.offsets[k]), int(self.offsets[k + 1])
        return self.directions[a:b], self.weights[a:b], self.elevations[a:b]


#: days of one vectorised block of :func:`day_sun_paths` (the blocks run on the machine's
#: cores; at most :func:`sun_path`'s 3,660)
SUN_PATH_BLOCK_DAYS = 122


def day_sun_paths(latitude, longitude, start, days: int, step_minutes: float = 10.0) -> DaySunPaths:
    """The sun paths of ``days`` consecutive days in vectorised calls: day ``k`` is exactly
    :func:`day_sun_path` of ``start + k`` (the same steps of the same UTC days, the same
    SPCTRAL2 DNI and normalisation), computed for all days at a run's set-up instead of once a
    day, in blocks of up to :data:`SUN_PATH_BLOCK_DAYS` days on the machine's cores. Each day
    is normalised on its own and every step is computed element by element, so the blocks give
    the values of one call (bit for bit for 20 days in blocks of 7 in
    tests/test_sun_position.py, and for 730 and 3,653 days in blocks of 122; NumPy's
    vectorised functions may round the last bit of a value otherwise for arrays of only a few
    elements: SPCTRAL2 of one sun alone differs from the same sun among four by ~1e-15).

    Parameters
    ----------
    latitude, longitude : float
        The site [deg].
    start : datetime.date or str
        The first day (UTC).
    days : int
        Number of days (1-100,000, the longest run).
    step_minutes : float
        Time step [min] (a divisor of 24 h).

    Returns
    -------
    DaySunPaths
        Packed directions, weights and elevations with per-day offsets.
    """
    check_range("days", days, 1, 100_000)
    d0 = _start_date(start)
    block = int(SUN_PATH_BLOCK_DAYS)

    def one(first):
        return _day_sun_paths_block(latitude, longitude, d0 + _dt.timedelta(days=first),
                                    min(block, int(days) - first), step_minutes)
    # (NumPy and pvlib's SPCTRAL2 let go of the GIL in their array work: a ten-year run's
    # 3,653 days took 25 s in one call on 2 cores)
    parts = map_on_cores(one, range(0, int(days), block))
    if len(parts) == 1:
        return parts[0]
    counts = np.concatenate([np.diff(p.offsets) for p in parts])
    return DaySunPaths(np.concatenate([p.directions for p in parts]),
                       np.concatenate([p.weights for p in parts]),
                       np.concatenate([p.elevations for p in parts]),
                       np.concatenate([[0], np.cumsum(counts)]).astype(np.int64))


def _day_sun_paths_block(latitude, longitude, d0, days: int, step_minutes: float) -> DaySunPaths:
    """:func:`day_sun_paths` of at most :data:`SUN_PATH_BLOCK_DAYS` days, in one call."""
    p = sun_path(latitude, longitude, start=d0, days=int(days), step_hours=step_minutes / 60.0,
                 utc_offset_hours=0.0, intensity="clear_sky")
    w = p.dni * (step_minutes * 60.0 / 86400.0)
    day = np.asarray(p.day, np.int64)
    horizontal = np.bincount(day, weights=w * np.sin(np.radians(p.elevation)),
                             minlength=int(days))
    good = horizontal[day] > 0.0
    # per day as day_sun_path: w / (sum of w sin(el)) over that day's steps
    w = np.where(good, w / np.where(horizontal[day] > 0, horizontal[day], 1.0), 0.0)
    keep = good
    counts = np.bincount(day[keep], minlength=int(days))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return DaySunPaths(np.asarray(p.direction[keep], float), w[keep], p.elevation[keep],
                       offsets)
