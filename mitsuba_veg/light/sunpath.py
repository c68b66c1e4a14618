"""A whole day of sun as one emitter: ``veg_sun_path``, for daily-mean light in one photon pass.

The moss model needs the *daily mean* insolation of each triangle (paper 000 uses daily means
throughout §3.5). The sun moves: the daily-mean beam on a triangle is the time average of
E_n(t) max(0, n·s(t)) V(t) (normal irradiance, incidence, visibility). ``veg_sun_path`` holds the
sun directions s_k of one day (every few minutes while the sun is up) with weights
w_k = E_n,k Δt / 86400, and samples one of them per photon with probability ∝ w_k: a photon pass
with it gives the daily-mean beam irradiance of every triangle at once. The sun positions come
from :func:`sun_path`, the sampler of the hourly sun paths of paper 003 as well. The weights are
normalised so that an unobstructed horizontal plane receives a daily-mean beam of exactly
1 W m-2 nm-1: a triangle's result divided by the band width is its *sun fraction* f_sun.

The directions can be changed every day with :meth:`VegSunPath.set_day` without rebuilding the
scene (the photon pass reads them on each call).
"""
from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, check_range
from .clear_sky import DEFAULT_ATMOSPHERE
from .solar_position import sun_direction, sun_position


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


def clear_sky_broadband(elevation_deg, day_of_year, atmosphere=None):
    """Broadband (300-4000 nm) clear-sky DNI and DHI for arrays of sun elevations: SPCTRAL2
    (Bird & Riordan 1986) with the package's default atmosphere, a vectorised call of pvlib's
    spectrl2 (the clear-sky model of every sun path in the package).

    Parameters
    ----------
    elevation_deg : array_like
        Sun elevations [deg]; at or below 0.5° both irradiances are 0.
    day_of_year : int or array_like
        Day of the year (Earth-Sun distance), broadcast against the elevations.
    atmosphere : daylight.Atmosphere, optional
        Default :data:`mitsuba_veg.light.clear_sky.DEFAULT_ATMOSPHERE`.

    Returns
    -------
    dni, dhi : numpy.ndarray
        Direct normal and diffuse horizontal irradiance [W m-2].
    """
    from pvlib.atmosphere import get_relative_airmass
    from pvlib.spectrum import spectrl2

    atm = atmosphere or DEFAULT_ATMOSPHERE
    el = np.atleast_1d(np.asarray(elevation_deg, float))
    doy = np.broadcast_to(np.asarray(day_of_year, int), el.shape)
    dni = np.zeros(el.shape)
    dhi = np.zeros(el.shape)
    up = el > 0.5
    if up.any():
        z = 90.0 - el[up]
        am = get_relative_airmass(z, model="kastenyoung1989")
        res = spectrl2(apparent_zenith=z, aoi=z, surface_tilt=np.zeros_like(z),
                       ground_albedo=atm.ground_albedo, surface_pressure=atm.pressure,
                       relative_airmass=am, precipitable_water=atm.precipitable_water,
                       ozone=atm.ozone, aerosol_turbidity_500nm=atm.aerosol_turbidity,
                       dayofyear=np.asarray(doy[up], float),
                       scattering_albedo_400nm=atm.aerosol_single_scattering_albedo,
                       alpha=atm.angstrom_alpha, aerosol_asymmetry_factor=atm.aerosol_asymmetry)
        wl = np.asarray(res["wavelength"], float)
        dni[up] = np.trapezoid(np.clip(np.nan_to_num(np.asarray(res["dni"])), 0, None), wl, axis=0)
        dhi[up] = np.trapezoid(np.clip(np.nan_to_num(np.asarray(res["dhi"])), 0, None), wl, axis=0)
    return dni, dhi


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

    utc_offset_hours: local standard time offset (default: round(longitude / 15)).
    intensity: "clear_sky" (SPCTRAL2 broadband DNI/DHI) or a number: constant beam I [W m-2]
    (the paper's I), with DHI 0. Steps with the sun at or below ``min_elevation`` are dropped.
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


class DeltaSun(mi.Emitter):
    """Base of the package's sun emitters: delta directions towards a discrete set of suns.

    Subclasses pick a direction and its weight in :meth:`sample_direction` (through
    :meth:`_direction_sample`). Light tracers that call ``sample_ray`` get zero-weight rays:
    emission from a scene-sized disk needs the scene's bounds, which Mitsuba does not give
    Python emitters; these emitters serve the photon pass (which aims photons itself) and
    integrators that use ``sample_direction`` (path tracing). A zero-weight ray keeps symbolic
    virtual calls over all emitters valid: Dr.Jit traces every live emitter, also ones of other
    scenes, so raising there broke unrelated renders in the process.
    """

    def __init__(self, props: mi.Properties):
        mi.Emitter.__init__(self, props)
        self.m_flags = mi.EmitterFlags.Infinite | mi.EmitterFlags.DeltaDirection

    @staticmethod
    def _direction_sample(it, d):
        """A delta direction sample towards ``d`` (unit vectors) from ``it``."""
        ds = dr.zeros(mi.DirectionSample3f)
        ds.d = d
        ds.p = it.p + d * 1e7
        ds.dist = dr.inf
        ds.pdf = 1.0
        ds.delta = True
        return ds

    def pdf_direction(self, it, ds, active=True):
        return mi.Float(0.0)

    def eval(self, si, active=True):
        return mi.Spectrum(0.0)

    def sample_ray(self, time, wavelength_sample, sample2, sample3, active=True):
        ds, _ = self.sample_direction(dr.zeros(mi.Interaction3f), sample3, active)
        ray = mi.Ray3f(ds.p, -ds.d, time, mi.Spectrum(wavelength_sample * 470.0 + 360.0))
        return ray, mi.Spectrum(0.0)

    def sample_wavelengths(self, si, sample, active=True):
        return mi.Spectrum(mi.sample_shifted(sample) * 470.0 + 360.0), mi.Spectrum(470.0)

    def traverse(self, callback):
        pass

    def parameters_changed(self, keys):
        pass


class VegSunPath(DeltaSun):
    """Delta-direction emitter with a discrete set of sun directions (see module docstring).

    Properties: ``scale`` (float, 1: spectral irradiance per unit weight [W m-2 nm-1], flat).
    Directions are set with :meth:`set_day` (default: one sun at the zenith). Supports the
    photon pass and ``sample_direction`` (next-event estimation of path tracers); light tracers
    (``sample_ray``, e.g. Mitsuba's ``ptracer``) get no light from it.
    """

    def __init__(self, props: mi.Properties):
        DeltaSun.__init__(self, props)
        self.scale = float(props.get("scale", 1.0))
        self.set_day(np.array([[0.0, 1.0, 0.0]]), np.array([1.0]))

    def set_day(self, directions, weights) -> None:
        """Use these sun directions (towards the sun, (K, 3)) and weights (K,) from now on."""
        d = np.asarray(directions, float).reshape(-1, 3)
        w = np.asarray(weights, float).reshape(-1)
        if len(d) == 0:  # polar night: no sun, keep a harmless direction with zero weight
            d, w = np.array([[0.0, 1.0, 0.0]]), np.array([0.0])
        self.total = float(w.sum())
        pmf = w / self.total if self.total > 0 else np.full(len(w), 1.0 / len(w))
        self.dist = mi.DiscreteDistribution(mi.Float(pmf.astype(np.float32)))
        self.dirs = mi.Vector3f(*[mi.Float(d[:, k].astype(np.float32)) for k in range(3)])
        self.count = len(w)

    def sample_direction(self, it, sample, active=True):
        k = self.dist.sample(sample.x, active)
        ds = self._direction_sample(it, dr.gather(mi.Vector3f, self.dirs, k, active))
        ds.emitter = mi.EmitterPtr(self)
        # weight / pmf = total weight (flat spectrum): unbiased for the weighted sum over k
        value = dr.select(active, self.total * self.scale, 0.0)
        return ds, mi.Spectrum(value)

    def to_string(self):
        return f"VegSunPath[directions={self.count}, scale={self.scale}]"


mi.register_emitter("veg_sun_path", lambda props: VegSunPath(props))
