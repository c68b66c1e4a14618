"""The inputs of every simulated day, computed once at a run's set-up.

A day of the pipeline needs the day's weather (climate.py), the sun's path over the day
(``veg_sun_path``: directions and weights) and the clear-sky spectral shapes of beam and
diffuse light (SPCTRAL2 at the noon sun, to turn the unit-spectrum photon pass into band
irradiances). All of them depend only on the site and the date, so they are computed for the
whole run in one vectorised call each (:func:`mitsuba_veg.light.sunpath.day_sun_paths`, one
pvlib ``spectrl2`` call for all days); a day hands its values to its kernels as evaluated
width-1 arrays (kernel inputs), never as new Python literals that would compile new kernels.
"""
from __future__ import annotations

import datetime as _dt
import functools
from dataclasses import dataclass
from types import MappingProxyType

import mitsuba as mi
import numpy as np

from ..arrays import Pack
from ..climate import DailyWeather, solar_declination
from ..light.clear_sky import DEFAULT_ATMOSPHERE, SPCTRL2_RANGE_NM, _spectrl2
from ..light.photon import band_range
from ..light.sunpath import DaySunPaths, day_sun_paths
from .config import BANDS

__all__ = ["WEATHER_FIELDS", "noon_elevation", "band_shapes_days", "band_shapes", "DayInputs",
           "DayValues"]

#: the weather fields a day's kernels read [units of climate.DailyWeather]
WEATHER_FIELDS = ("T", "rh", "U", "A", "P", "beam", "diffuse")


def noon_elevation(latitude: float, day_of_year) -> np.ndarray:
    """Noon sun elevation from the FAO-56 declination: 90° − ``|latitude − δ|``, at least 1° [deg].

    Parameters
    ----------
    latitude : float
        Site latitude [deg].
    day_of_year : int or array_like
        Day of the year (1-366).

    Returns
    -------
    numpy.ndarray
        Noon elevation [deg], one per day.
    """
    dec = np.degrees(np.asarray(solar_declination(np.asarray(day_of_year)), float))
    return np.clip(90.0 - np.abs(latitude - dec), 1.0, 90.0)


def band_shapes_days(latitude: float, days_of_year, bands=BANDS) -> np.ndarray:
    """Band-mean spectral irradiance per W m-2 of broadband irradiance [nm-1], beam and
    diffuse, for many days in one SPCTRAL2 call.

    Clear-sky beam and diffuse light (broadband: SPCTRAL2's 300-4000 nm) at the day's noon sun
    (:func:`noon_elevation`), resampled to 1 nm as :func:`~mitsuba_veg.light.clear_sky.\
clear_sky_spectra` does; the band mean over the 1 nm grid divided by the broadband integral.
    Multiplied by a broadband daily mean [W m-2] it gives the band-mean spectral irradiance
    [W m-2 nm-1].

    Parameters
    ----------
    latitude : float
        Site latitude [deg].
    days_of_year : array_like of int
        Days of the year (1-366).
    bands : sequence of str
        Band names (:data:`mitsuba_veg.integrators.photon_irradiance.BANDS`).

    Returns
    -------
    numpy.ndarray
        (days, 2, bands): [:, 0] beam, [:, 1] diffuse shapes [nm-1] (0 where the component
        is 0).
    """
    doy = np.asarray(days_of_year, int).reshape(-1)
    el = noon_elevation(latitude, doy)
    wl, dni, dhi, _etr, _am = _spectrl2(el, doy, DEFAULT_ATMOSPHERE)
    lo, hi = SPCTRL2_RANGE_NM
    grid = lo + np.arange(int(round(hi - lo)) + 1, dtype=float)
    masks = []
    for b in bands:
        blo, bhi = band_range(b)
        masks.append((grid >= blo) & (grid <= bhi))
    out = np.zeros((len(doy), 2, len(bands)))
    for i in range(len(doy)):
        for c, arr in enumerate((dni[:, i], dhi[:, i])):
            f = np.interp(grid, wl, arr)
            total = float(np.trapezoid(f, grid))
            if total > 0:
                out[i, c] = [float(f[m].mean()) / total for m in masks]
    return out


@functools.lru_cache(maxsize=1024)
def band_shapes(latitude: float, day_of_year: int) -> MappingProxyType:
    """:func:`band_shapes_days` of one day, as a read-only mapping (cached).

    Parameters
    ----------
    latitude : float
        Site latitude [deg].
    day_of_year : int
        Day of the year (1-366).

    Returns
    -------
    mapping
        ``{"beam": {band: s}, "diffuse": {band: s}}`` for :data:`BANDS`, s [nm-1].
    """
    s = band_shapes_days(latitude, [day_of_year])[0]
    return MappingProxyType({comp: MappingProxyType(dict(zip(BANDS, map(float, s[c]))))
                             for c, comp in enumerate(("beam", "diffuse"))})


@dataclass
class DayInputs:
    """What every day of a run reads: weather, sun paths and band shapes (module docstring).

    Attributes
    ----------
    start : datetime.date
        Date of day 0.
    days : int
        Number of days.
    weather : DailyWeather
        Host copy of the daily weather.
    sun : DaySunPaths
        The sun path of every day (packed).
    shapes : numpy.ndarray
        (days, 2, bands) beam / diffuse band shapes [nm-1] (:func:`band_shapes_days`).
    """

    start: _dt.date
    days: int
    weather: DailyWeather
    sun: DaySunPaths
    shapes: np.ndarray

    @staticmethod
    def build(latitude: float, longitude: float, start: _dt.date, days: int,
              weather: DailyWeather) -> "DayInputs":
        """Compute the inputs of ``days`` days from ``start`` (one call per model).

        Parameters
        ----------
        latitude, longitude : float
            The site [deg].
        start : datetime.date
            Date of day 0.
        days : int
            Number of days.
        weather : DailyWeather
            The run's weather (at least ``days`` rows).

        Returns
        -------
        DayInputs
            Host and device arrays of every day.
        """
        sun = day_sun_paths(latitude, longitude, start, days)
        doy = np.array([(start + _dt.timedelta(days=k)).timetuple().tm_yday
                        for k in range(days)])
        shapes = band_shapes_days(latitude, doy)
        return DayInputs(start, int(days), weather, sun, shapes)

    def date(self, day: int) -> _dt.date:
        """The date of day ``day``.

        Parameters
        ----------
        day : int
            Day index (0-based).

        Returns
        -------
        datetime.date
            ``start + day``.
        """
        return self.start + _dt.timedelta(days=int(day))

    def on_device(self, day: int) -> "DayValues":
        """The day's weather and band shapes as device values: one array copied from the host,
        read inside the kernels (kernel inputs, not literals: one compiled kernel serves every
        day).

        Parameters
        ----------
        day : int
            Day index (0-based).

        Returns
        -------
        DayValues
            Width-1 Dr.Jit expressions.
        """
        d = int(day)
        vals = [float(np.asarray(getattr(self.weather, f))[d]) for f in WEATHER_FIELDS]
        vals += list(self.shapes[d].ravel())
        pk = Pack(mi.Float64, vals)       # one host copy for the day
        w = {f: pk[i] for i, f in enumerate(WEATHER_FIELDS)}
        nf, nb = len(WEATHER_FIELDS), self.shapes.shape[2]
        shp = {}
        for c, comp in enumerate(("beam", "diffuse")):
            for j, b in enumerate(BANDS):
                shp[comp, b] = pk[nf + c * nb + j]
        return DayValues(day=d, weather=w, shapes=shp)


@dataclass
class DayValues:
    """One day's inputs on the device: ``weather[field]`` (climate.DailyWeather's units) and
    ``shapes[("beam" | "diffuse", band)]`` [nm-1]."""

    day: int
    weather: dict
    shapes: dict
