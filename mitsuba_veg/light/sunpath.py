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

from ..arrays import DiscreteSampler, host_array, opaque
from ..errors import ParameterError, check_range
from .clear_sky import clear_sky_broadband
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


def day_sun_paths(latitude, longitude, start, days: int, step_minutes: float = 10.0) -> DaySunPaths:
    """The sun paths of ``days`` consecutive days in one vectorised call: day ``k`` is exactly
    :func:`day_sun_path` of ``start + k`` (the same steps of the same UTC days, the same
    SPCTRAL2 DNI and normalisation), computed for all days at once at a run's set-up instead
    of once a day.

    Parameters
    ----------
    latitude, longitude : float
        The site [deg].
    start : datetime.date or str
        The first day (UTC).
    days : int
        Number of days (1-3660).
    step_minutes : float
        Time step [min] (a divisor of 24 h).

    Returns
    -------
    DaySunPaths
        Packed directions, weights and elevations with per-day offsets.
    """
    d0 = _start_date(start)
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
        """Density of a direction sample: 0 (delta directions cannot be hit by chance).

        Parameters
        ----------
        it : mitsuba.Interaction3f
            The reference point.
        ds : mitsuba.DirectionSample3f
            The direction sample.
        active : mitsuba.Bool
            Active lanes.

        Returns
        -------
        mitsuba.Float
            0 [sr-1].
        """
        return mi.Float(0.0)

    def eval(self, si, active=True):
        """Radiance seen along a ray that hits the emitter: 0 (a delta emitter is never hit).

        Parameters
        ----------
        si : mitsuba.SurfaceInteraction3f
            The escaped ray's interaction.
        active : mitsuba.Bool
            Active lanes.

        Returns
        -------
        mitsuba.Spectrum
            0 [W m-2 sr-1 nm-1].
        """
        return mi.Spectrum(0.0)

    def sample_ray(self, time, wavelength_sample, sample2, sample3, active=True):
        """A zero-weight emission ray (see the class docstring: no scene bounds here).

        Parameters
        ----------
        time : mitsuba.Float
            Ray time [s].
        wavelength_sample : mitsuba.Float
            Uniform sample for the wavelength.
        sample2 : mitsuba.Point2f
            Unused (position sample).
        sample3 : mitsuba.Point2f
            Direction sample.
        active : mitsuba.Bool
            Active lanes.

        Returns
        -------
        ray : mitsuba.Ray3f
            A ray against one of the sun directions, wavelength in 360-830 nm [nm].
        weight : mitsuba.Spectrum
            0.
        """
        ds, _ = self.sample_direction(dr.zeros(mi.Interaction3f), sample3, active)
        ray = mi.Ray3f(ds.p, -ds.d, time, mi.Spectrum(wavelength_sample * 470.0 + 360.0))
        return ray, mi.Spectrum(0.0)

    def sample_wavelengths(self, si, sample, active=True):
        """Wavelengths uniform in 360-830 nm.

        Parameters
        ----------
        si : mitsuba.SurfaceInteraction3f
            Unused.
        sample : mitsuba.Float
            Uniform sample.
        active : mitsuba.Bool
            Active lanes.

        Returns
        -------
        wavelengths : mitsuba.Spectrum
            Wavelengths [nm].
        weight : mitsuba.Spectrum
            1 / pdf = 470 [nm].
        """
        return mi.Spectrum(mi.sample_shifted(sample) * 470.0 + 360.0), mi.Spectrum(470.0)

    def traverse(self, callback):
        """No differentiable parameters (the directions change with :meth:`set_day`).

        Parameters
        ----------
        callback : mitsuba.TraversalCallback
            Mitsuba's traversal callback (not called).
        """
        pass

    def parameters_changed(self, keys):
        """Nothing to update.

        Parameters
        ----------
        keys : list of str
            The changed parameters (none exist).
        """
        pass


class VegSunPath(DeltaSun):
    """Mitsuba emitter ``veg_sun_path``: a delta-direction emitter with a discrete set of sun
    directions (module docstring).

    .. list-table::
       :header-rows: 1

       * - Property
         - Type
         - Default
         - Description
       * - scale
         - float
         - 1.0
         - Spectral irradiance per unit weight [W m-2 nm-1] (flat spectrum).

    Directions are set with :meth:`set_day` (default: one sun at the zenith). Supports the
    photon pass and ``sample_direction`` (next-event estimation of path tracers); light tracers
    (``sample_ray``, e.g. Mitsuba's ``ptracer``) get no light from it.
    """

    #: its arrays are inputs of a frozen function that reaches it (dr.freeze: a frozen photon
    #: pass replays with each day's sun path)
    DRJIT_STRUCT = {"dirs": mi.Vector3f, "m_value": mi.Float, "dist": DiscreteSampler}

    def __init__(self, props: mi.Properties):
        DeltaSun.__init__(self, props)
        self.scale = float(props.get("scale", 1.0))
        self.set_day(np.array([[0.0, 1.0, 0.0]]), np.array([1.0]))

    def set_day(self, directions, weights, size: int | None = None) -> None:
        """Use these sun directions and weights from now on.

        Parameters
        ----------
        directions : array_like
            (K, 3) unit vectors towards the sun (scene frame); none (K = 0) in polar night.
        weights : array_like
            (K,) weights w_k [-] (as :func:`day_sun_path`'s); photons sample direction k with
            probability w_k / Σ w.
        size : int, optional
            Pad the table to ``size`` directions with zero weights (never sampled): the same
            array sizes every day, as a frozen pass needs (default: K).
        """
        d = np.asarray(directions, float).reshape(-1, 3)
        w = np.asarray(weights, float).reshape(-1)
        if len(d) == 0:  # polar night: no sun, keep a harmless direction with zero weight
            d, w = np.array([[0.0, 1.0, 0.0]]), np.array([0.0])
        if size is not None and size > len(d):
            d = np.concatenate([d, np.tile([[0.0, 1.0, 0.0]], (size - len(d), 1))])
            w = np.concatenate([w, np.zeros(size - len(w))])
        self.total = float(w.sum())
        pmf = w if self.total > 0 else np.ones(len(w))
        # cumulative sums on the host: the same table on every backend (arrays.DiscreteSampler)
        self.dist = DiscreteSampler(pmf)
        self.dirs = mi.Vector3f(*[host_array(mi.Float, d[:, k]) for k in range(3)])
        # an input of the kernel, not a literal: a new day's total compiles nothing
        self.m_value = opaque(mi.Float, self.total * self.scale)
        dr.eval(self.dirs)
        self.count = len(w)

    def sample_direction(self, it, sample, active=True):
        """One of the day's sun directions, chosen with probability ∝ w_k.

        Parameters
        ----------
        it : mitsuba.Interaction3f
            The reference point.
        sample : mitsuba.Point2f
            Uniform sample (``x`` picks the direction).
        active : mitsuba.Bool
            Active lanes.

        Returns
        -------
        ds : mitsuba.DirectionSample3f
            The delta direction towards the sun.
        weight : mitsuba.Spectrum
            Σ_k w_k × ``scale`` [W m-2 nm-1] (weight / pmf: unbiased for the weighted sum).
        """
        k = self.dist.sample(sample.x, active)
        ds = self._direction_sample(it, dr.gather(mi.Vector3f, self.dirs, k, active))
        ds.emitter = mi.EmitterPtr(self)
        # weight / pmf = total weight (flat spectrum): unbiased for the weighted sum over k
        value = dr.select(active, self.m_value, 0.0)
        return ds, mi.Spectrum(value)

    def to_string(self):
        """Mitsuba's description of the emitter.

        Returns
        -------
        str
            The number of directions and the scale.
        """
        return f"VegSunPath[directions={self.count}, scale={self.scale}]"


mi.register_emitter("veg_sun_path", lambda props: VegSunPath(props))
