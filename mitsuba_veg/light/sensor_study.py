"""Time series of virtual sensors: clear-sky daylight over a date range, hourly or daily.

One light scene holds the scene's shapes, the sensors (:mod:`mitsuba_veg.light.sensors`, one
mesh in sensor mode) and two emitters built once:

- ``sun``: ``veg_sun_steps`` (:class:`mitsuba_veg.integrators.veg_sun.VegSunSteps`), a
  delta-direction emitter holding the sun directions of one time step (every ``sub_minutes``
  while the sun is up: 6 per hour, up to 144 per day) with weights; its spectrum is the
  SPCTRAL2 beam (DNI) of a reference sun (elevation 45°, day 172). Each step sets its
  directions (no rebuild, no recompile) and traces one photon pass of the sun alone;
- ``sky``: ``veg_sky`` with a *uniform* (isotropic) radiance distribution and the SPCTRAL2
  diffuse spectrum (DHI) of the reference sun. Its light does not depend on the time except for
  a factor per band, so it is traced once, with ``sky_photons`` photons.

Per step [t0, t1) and band b the reading is the mean over the step::

    sun:  R_b = c_b × (pass reading),  weights w_k = (Δt/T) DNI_PAR(k) / DNI_PAR,ref,
          c_b = Σ_k (Δt/T) DNI_b(k) sin e_k / Σ_k w_k DNI_b,ref sin e_k   (c_PAR = 1)
    sky:  R_b = (Σ_k (Δt/T) DHI_b(k) / DHI_b,ref) × (sky pass reading)

with DNI_b(k), DHI_b(k) the SPCTRAL2 band irradiances of the sun at sub-step k
(:func:`mitsuba_veg.light.clear_sky.clear_sky_spectra`, tabulated over elevation and scaled by
the Sun-Earth distance of the day). This is exact for PAR and for the open horizontal; other
bands share the PAR weights of the sun positions (their spectra change little with elevation:
docs/deviations.md). The sky is isotropic, as in the moss run (a Perez sky would need a rebuild
per hour). Light is clear-sky: no clouds (twilight, el <= 0, is dark).
"""
from __future__ import annotations

import datetime as _dt
import math
import time as _time
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from mitsuba_veg.defaults import check_light
from mitsuba_veg.errors import ParameterError, check_range

from . import sensors as S
from .clear_sky import band_irradiance, clear_sky_spectra, regular_spectrum
from .photon import BANDS, photon_irradiance
from .solar_position import sun_direction, sun_position

__all__ = ["band_table", "daylight_bands", "reference", "step_starts", "SensorSeries",
           "run_series", "daily_light_integral", "hours_above"]

#: reference sun of the emitters' spectra
REF_ELEVATION, REF_DOY = 45.0, 172


# --------------------------------------------------------------------------------------------
# SPCTRAL2 band irradiances, tabulated
# --------------------------------------------------------------------------------------------
def _bands_of(wl, spec):
    return np.array([band_irradiance(wl, spec, *BANDS[b]) for b in S.PASS_BANDS])


@lru_cache(maxsize=1)
def band_table():
    """SPCTRAL2 band irradiances tabulated over the sun elevation, at day :data:`REF_DOY`.

    Elevations in 0.25° steps below 3°, 1° above; bands :data:`sensors.PASS_BANDS`.

    Returns
    -------
    elevations : numpy.ndarray
        (E,) sun elevations [deg].
    dni : numpy.ndarray
        (E, 4) direct-normal band irradiances [W m-2].
    dhi : numpy.ndarray
        (E, 4) diffuse-horizontal band irradiances [W m-2].
    """
    els = np.concatenate([np.arange(0.05, 3.0, 0.25), np.arange(3.0, 90.01, 1.0)])
    dni, dhi = [], []
    for el in els:
        wl, a, b = clear_sky_spectra(float(el), day_of_year=REF_DOY, step_nm=None)
        dni.append(_bands_of(wl, a))
        dhi.append(_bands_of(wl, b))
    return els, np.array(dni), np.array(dhi)


@lru_cache(maxsize=1)
def _doy_table():
    """Sun-Earth distance factor of SPCTRAL2 relative to day REF_DOY, every 5 days."""
    days = np.arange(1, 372, 5)
    out = []
    for d in days:
        wl, a, _ = clear_sky_spectra(REF_ELEVATION, day_of_year=int(min(d, 366)), step_nm=None)
        v = float(np.trapezoid(a, wl))
        out.append(v)
    wl, a, _ = clear_sky_spectra(REF_ELEVATION, day_of_year=REF_DOY, step_nm=None)
    ref = float(np.trapezoid(a, wl))
    return days, np.array(out) / ref


def daylight_bands(elevation, day_of_year):
    """SPCTRAL2 DNI and DHI band irradiances for sun elevations and days.

    Interpolated in :func:`band_table` and scaled by the Sun-Earth distance of the day.

    Parameters
    ----------
    elevation : array_like
        Sun elevations [deg].
    day_of_year : array_like
        Days of the year (1-366), broadcast against the elevations.

    Returns
    -------
    dni, dhi : numpy.ndarray
        (..., 4) direct-normal and diffuse-horizontal band irradiances [W m-2]
        (:data:`sensors.PASS_BANDS`); 0 where the sun is at or below the horizon.
    """
    els, dni, dhi = band_table()
    days, fac = _doy_table()
    e = np.asarray(elevation, float)
    f = np.interp(np.asarray(day_of_year, float), days, fac)
    up = e > 0
    ec = np.clip(e, els[0], els[-1])
    a = np.stack([np.interp(ec, els, dni[:, b]) for b in range(dni.shape[1])], -1)
    c = np.stack([np.interp(ec, els, dhi[:, b]) for b in range(dhi.shape[1])], -1)
    m = (up * f)[..., None]
    return a * m, c * m


@lru_cache(maxsize=1)
def reference():
    """The emitters of the reference sun (elevation :data:`REF_ELEVATION`, day :data:`REF_DOY`).

    Returns
    -------
    sun : dict
        ``veg_sun_steps`` emitter dict, its spectrum the SPCTRAL2 DNI [W m-2 nm-1].
    sky : dict
        Uniform ``veg_sky`` emitter dict, radiance DHI/π [W m-2 sr-1 nm-1].
    dni_ref, dhi_ref : numpy.ndarray
        (4,) their band irradiances [W m-2] (:data:`sensors.PASS_BANDS`).
    """
    wl, dni, dhi = clear_sky_spectra(REF_ELEVATION, day_of_year=REF_DOY)
    sun = {"type": "veg_sun_steps", "id": "sun", "irradiance": regular_spectrum(wl, dni)}
    sky = {"type": "veg_sky", "id": "sky", "distribution": "uniform",
           "radiance": regular_spectrum(wl, dhi / math.pi)}
    return sun, sky, _bands_of(wl, dni), _bands_of(wl, dhi)


# --------------------------------------------------------------------------------------------
# Time steps
# --------------------------------------------------------------------------------------------
def _tz(latitude, longitude, timezone):
    if timezone is None:
        return float(round(float(longitude) / 15.0))
    check_range("timezone", timezone, -14.0, 14.0, fix="hours east of UTC, e.g. 9 for Japan")
    return float(timezone)


def step_starts(start: _dt.date, end: _dt.date, step: str) -> np.ndarray:
    """Local start times of the steps covering the days start..end (inclusive).

    Parameters
    ----------
    start, end : datetime.date
        First and last local day (at most 5 years apart).
    step : str
        ``"daily"`` or ``"hourly"``.

    Returns
    -------
    numpy.ndarray
        Step starts, naive local ``datetime64[m]``.
    """
    if step not in ("daily", "hourly"):
        raise ParameterError("step", step, "daily or hourly")
    if end < start:
        raise ParameterError("--to", end.isoformat(), f">= --from ({start.isoformat()})",
                             "swap the dates")
    days = (end - start).days + 1
    if days > 366 * 5:
        raise ParameterError("--to", end.isoformat(), "at most 5 years after --from",
                             "split the study")
    t0 = np.datetime64(start.isoformat(), "m")
    if step == "daily":
        return t0 + np.arange(days).astype("timedelta64[D]").astype("timedelta64[m]")
    return t0 + (np.arange(days * 24) * 60).astype("timedelta64[m]")


@dataclass
class SensorSeries:
    """Readings of sensors over time steps.

    ``values[t, s, q, c]``: mean over step ``t`` (local start :attr:`times`, length
    :attr:`step_hours`) of quantity ``q`` (:data:`sensors.QUANTITIES`, units
    :data:`sensors.UNITS`), component ``c`` (direct, diffuse, total) for sensor ``s``.
    ``open_values[t, q, c]``: the same for an unobstructed horizontal cosine sensor (SPCTRAL2,
    no scene).
    """

    sensors: S.SensorSet
    times: np.ndarray              # naive local datetime64[m], step starts
    step_hours: float
    timezone: float
    values: np.ndarray
    open_values: np.ndarray
    sun_passes: int = 0
    photons: int = 0
    seconds: float = 0.0
    settings: dict = field(default_factory=dict)

    def iso_times(self) -> list[str]:
        """Step starts as ISO 8601 strings with the UTC offset.

        Returns
        -------
        list of str
            One per step.
        """
        tz = _dt.timezone(_dt.timedelta(hours=self.timezone))
        return [_dt.datetime.fromisoformat(str(t)).replace(tzinfo=tz).isoformat()
                for t in self.times.astype("datetime64[s]")]

    def table(self, sensors=None):
        """The series as a tidy table.

        Parameters
        ----------
        sensors : array_like, optional
            A boolean mask or rows of the sensors to keep (default all).

        Returns
        -------
        pandas.DataFrame
            Columns time (tz-aware), sensor, band, component, value, unit.
        """
        import pandas as pd
        tz = _dt.timezone(_dt.timedelta(hours=self.timezone))
        times = pd.DatetimeIndex(self.times.astype("datetime64[ns]")).tz_localize(tz)
        keep = np.arange(len(self.sensors)) if sensors is None else \
            np.arange(len(self.sensors))[sensors]
        return S.tidy_table(self.values[:, keep], self.sensors.names[keep], times)


def run_series(scene, sensors: S.SensorSet, *, latitude: float, longitude: float,
               start: _dt.date, end: _dt.date, step: str = "daily", timezone=None,
               photons: int = 200_000, sky_photons: int | None = None, seed: int = 0,
               max_depth: int = 8, indirect: bool = True, sub_minutes: float = 10.0,
               progress: bool = False, sky_readings=None, light_scene=None) -> SensorSeries:
    """Sensor readings over the days ``start``..``end`` (inclusive) in ``step`` steps.

    Parameters
    ----------
    scene : mi.Scene
        Shapes (its emitters are not used: the sun and sky come from the site and time).
    sensors : SensorSet
        The sensors.
    latitude, longitude : float
        Site [deg], north / east positive.
    start, end : datetime.date
        First and last local day.
    step : str
        ``"daily"`` (one sun pass per day with the day's sun path) or ``"hourly"`` (one pass
        per hour with the sun up).
    timezone : float, optional
        Local time offset from UTC [h] (default: longitude / 15 rounded).
    photons : int
        Photons per sun pass.
    sky_photons : int, optional
        Photons of the one sky pass (default 10 x photons: its noise is not averaged over the
        steps).
    seed : int
        Random seed, as :func:`mitsuba_veg.light.photon_irradiance`.
    max_depth : int
        Bounces per photon.
    indirect : bool
        Trace scattered light (False: direct light only).
    sub_minutes : float
        Sun positions every this many minutes inside a step [min] (divides 60).
    progress : bool
        Progress bar over the steps.
    sky_readings : numpy.ndarray, optional
        Reuse the sky readings (n, 2, 4) [W m-2 per unit reference] of an earlier call with
        the same scene and sensors (the ``settings`` of its result).
    light_scene : tuple, optional
        Reuse the (light scene, face owner) of such a call (its ``settings``).

    Returns
    -------
    SensorSeries
        Step means per sensor, quantity and component, and those of the open horizontal.
    """

    check_range("latitude", latitude, -90.0, 90.0)
    check_range("longitude", longitude, -180.0, 180.0)
    check_light("photons", photons)
    check_range("sub_minutes", sub_minutes, 1.0, 60.0)
    if 60.0 % sub_minutes:
        raise ParameterError("sub_minutes", sub_minutes, "a divisor of 60", "e.g. 10")
    sky_photons = 10 * int(photons) if sky_photons is None else int(sky_photons)
    tz = _tz(latitude, longitude, timezone)
    t_begin = _time.perf_counter()
    starts = step_starts(start, end, step)
    hours = 24.0 if step == "daily" else 1.0
    per = int(round(hours * 60 / sub_minutes))
    # every sub-step of every step, mid-points, local -> UTC, one vectorised sun position call
    sub = starts.astype("datetime64[s]")[:, None] + (
        np.arange(per) * int(sub_minutes * 60) + int(sub_minutes * 30)).astype(
        "timedelta64[s]")[None, :]
    utc = sub - np.timedelta64(int(round(tz * 3600)), "s")
    az, el = sun_position(latitude, longitude, utc.ravel())
    az, el = np.asarray(az, float).reshape(sub.shape), np.asarray(el, float).reshape(sub.shape)
    doy = ((sub.astype("datetime64[D]") - sub.astype("datetime64[Y]")).astype(int) + 1)
    dni, dhi = daylight_bands(el, doy)                          # (T, per, 4)
    frac = 1.0 / per                                             # Δt / T
    sin_e = np.maximum(np.sin(np.radians(el)), 0.0)

    sun_d, sky_d, dni_ref, dhi_ref = reference()
    if light_scene is None:
        light_scene, owner = S.scene_with_sensors(scene, sensors,
                                                  emitters={"sun": sun_d, "sky": sky_d})
    else:
        light_scene, owner = light_scene
    sun_em = [e for e in light_scene.emitters() if e.id() == "sun"][0]
    modes = {S.SENSOR_SHAPE: "sensor"}
    kw = dict(max_depth=int(max_depth), bands=S.PASS_BANDS, indirect=bool(indirect),
              modes=modes)
    if sky_readings is None:
        r = photon_irradiance(light_scene, photons=sky_photons, seed=int(seed),
                              emitters=["sky"], **kw)
        sky_readings = S.sensor_watts(r, sensors, owner, beam=())   # per unit DHI_ref
    n = len(sensors)
    watts = np.zeros((len(starts), n, 2, len(S.PASS_BANDS)))
    open_w = np.zeros((len(starts), 2, len(S.PASS_BANDS)))
    sky_fac = (dhi.sum(axis=1) * frac) / dhi_ref                # (T, 4)
    watts += sky_readings[None] * sky_fac[:, None, None, :]
    open_w[:, 1] = dhi.sum(axis=1) * frac
    open_w[:, 0] = (dni * sin_e[..., None]).sum(axis=1) * frac
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=len(starts), unit="h" if step == "hourly" else "day",
                   desc="sensor steps")
    passes = 0
    dirs_all = sun_direction(az, el)
    for t in range(len(starts)):
        up = el[t] > 0
        if up.any():
            w = frac * dni[t, up, 0] / dni_ref[0]
            step_seed = (int(seed) * 100_003 + 1 + t) & 0x7FFFFFFF
            sun_em.set_directions(dirs_all[t, up], w, seed=step_seed)
            target = frac * (dni[t, up] * sin_e[t, up, None]).sum(axis=0)       # (4,)
            got = (w[:, None] * dni_ref[None] * sin_e[t, up, None]).sum(axis=0)
            c = np.divide(target, got, out=np.zeros(4), where=got > 0)
            r = photon_irradiance(light_scene, photons=int(photons),
                                  seed=step_seed, emitters=["sun"], **kw)
            watts[t] += S.sensor_watts(r, sensors, owner, beam=("sun",)) * c[None, None, :]
            passes += 1
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    vals = S.SensorReadings.from_watts(sensors, watts.reshape(-1, 2, 4)).values.reshape(
        len(starts), n, len(S.QUANTITIES), len(S.COMPONENTS))
    ov = np.moveaxis(S.quantities_from_watts(
        np.concatenate([open_w, open_w.sum(axis=1, keepdims=True)], axis=1)), 1, 2)
    return SensorSeries(sensors, starts, hours, tz, vals, ov, passes, int(photons),
                        _time.perf_counter() - t_begin,
                        dict(latitude=latitude, longitude=longitude, step=step,
                             photons=int(photons), sky_photons=sky_photons, seed=int(seed),
                             max_depth=int(max_depth), indirect=bool(indirect),
                             sub_minutes=sub_minutes, sky_readings=sky_readings,
                             light_scene=(light_scene, owner)))


def daily_light_integral(series: SensorSeries):
    """Daily light integrals of PAR per local day, from the step means.

    Parameters
    ----------
    series : SensorSeries
        A daily or hourly series.

    Returns
    -------
    days : numpy.ndarray
        The local days (``datetime64[D]``).
    dli : numpy.ndarray
        ``dli[day, sensor, component]`` [mol m-2 d-1].
    open : numpy.ndarray
        ``open[day, component]`` of the open horizontal [mol m-2 d-1].
    """
    day = series.times.astype("datetime64[D]")
    days, inv = np.unique(day, return_inverse=True)
    par = series.values[:, :, S.QUANTITIES.index("par"), :] * series.step_hours * 3600e-6
    dli = np.zeros((len(days),) + par.shape[1:])
    np.add.at(dli, inv, par)
    op = series.open_values[:, S.QUANTITIES.index("par"), :] * series.step_hours * 3600e-6
    odli = np.zeros((len(days), op.shape[-1]))
    np.add.at(odli, inv, op)
    return days, dli, odli


def hours_above(series: SensorSeries, threshold: float):
    """Hours per local day with total PPFD above a threshold.

    Parameters
    ----------
    series : SensorSeries
        An hourly series.
    threshold : float
        PPFD threshold [µmol m-2 s-1].

    Returns
    -------
    days : numpy.ndarray
        The local days (``datetime64[D]``).
    hours : numpy.ndarray
        ``hours[day, sensor]`` [h].
    """
    if series.step_hours != 1.0:
        raise ParameterError("step", "daily", "an hourly series", "hours above a threshold "
                             "need hourly steps")
    day = series.times.astype("datetime64[D]")
    days, inv = np.unique(day, return_inverse=True)
    above = series.values[:, :, S.QUANTITIES.index("par"), 2] > threshold
    h = np.zeros((len(days), above.shape[1]))
    np.add.at(h, inv, above.astype(float))
    return days, h
