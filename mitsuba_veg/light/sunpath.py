"""A whole day of sun as one emitter: ``veg_sun_path``, for daily-mean light in one photon pass.

The moss model needs the *daily mean* insolation of each triangle (paper 000 uses daily means
throughout §3.5). The sun moves: the daily-mean beam on a triangle is the time average of
E_n(t) max(0, n·s(t)) V(t) (normal irradiance, incidence, visibility). ``veg_sun_path`` holds the
sun directions s_k of one day (every few minutes while the sun is up) with weights
w_k = E_n,k Δt / 86400, and samples one of them per photon with probability ∝ w_k: a photon pass
with it gives the daily-mean beam irradiance of every triangle at once. The weights are
normalised so that an unobstructed horizontal plane receives a daily-mean beam of exactly
1 W m-2 nm-1: a triangle's result divided by the band width is its *sun fraction* f_sun.

The directions can be changed every day with :meth:`VegSunPath.set_day` without rebuilding the
scene (the photon pass reads them on each call).
"""
from __future__ import annotations

import datetime as _dt

import drjit as dr
import mitsuba as mi
import numpy as np

from .sun_position import sun_direction, sun_position


def relative_dni(elevation_deg):
    """Clear-sky direct-normal irradiance relative to the top of the atmosphere (Meinel & Meinel
    1976: 0.7^(AM^0.678), air mass of Kasten & Young 1989) [-]; 0 below the horizon."""
    el = np.asarray(elevation_deg, float)
    z = np.radians(90.0 - el)
    am = 1.0 / (np.cos(z) + 0.50572 * np.maximum(96.07995 - np.degrees(z), 1e-3) ** -1.6364)
    return np.where(el > 0, 0.7 ** (np.maximum(am, 1.0) ** 0.678), 0.0)


def day_sun_path(latitude, longitude, date, step_minutes: float = 10.0):
    """Sun directions (towards the sun, scene frame) and weights w_k [-] of one day.

    ``date``: a ``datetime.date`` (the day in UTC; the whole 24 h are covered, so the time zone
    does not matter for daily means). Weights: relative DNI × Δt / 86400, normalised so that
    sum_k w_k sin(el_k) = 1 (unit daily-mean beam on the horizontal). Returns (dirs (K, 3),
    weights (K,), elevations (K,)); empty arrays when the sun stays below the horizon.
    """
    if isinstance(date, _dt.datetime):
        date = date.date()
    start = np.datetime64(date.isoformat() + "T00:00:00")
    n = int(round(24 * 60 / step_minutes))
    # sun at the middle of each step; longitude shifts local noon but all 24 h are covered
    times = start + (np.arange(n) * step_minutes + 0.5 * step_minutes).astype("timedelta64[m]")
    az, el = sun_position(latitude, longitude, times.astype("datetime64[s]"))
    az, el = np.asarray(az, float), np.asarray(el, float)
    up = el > 0.0
    if not up.any():
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0)
    w = relative_dni(el[up]) * (step_minutes * 60.0 / 86400.0)
    w = w / np.sum(w * np.sin(np.radians(el[up])))
    return sun_direction(az[up], el[up]), w, el[up]


class VegSunPath(mi.Emitter):
    """Delta-direction emitter with a discrete set of sun directions (see module docstring).

    Properties: ``scale`` (float, 1: spectral irradiance per unit weight [W m-2 nm-1], flat).
    Directions are set with :meth:`set_day` (default: one sun at the zenith). Supports the
    photon pass and ``sample_direction`` (next-event estimation of path tracers); light tracers
    (``sample_ray``, e.g. Mitsuba's ``ptracer``) get no light from it.
    """

    def __init__(self, props: mi.Properties):
        mi.Emitter.__init__(self, props)
        self.m_flags = mi.EmitterFlags.Infinite | mi.EmitterFlags.DeltaDirection
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
        d = dr.gather(mi.Vector3f, self.dirs, k, active)
        ds = dr.zeros(mi.DirectionSample3f)
        ds.d = d
        ds.p = it.p + d * 1e7
        ds.dist = dr.inf
        ds.pdf = 1.0
        ds.delta = True
        ds.emitter = mi.EmitterPtr(self)
        # weight / pmf = total weight (flat spectrum): unbiased for the weighted sum over k
        value = dr.select(active, self.total * self.scale, 0.0)
        return ds, mi.Spectrum(value)

    def pdf_direction(self, it, ds, active=True):
        return mi.Float(0.0)

    def eval(self, si, active=True):
        return mi.Spectrum(0.0)

    def sample_ray(self, time, wavelength_sample, sample2, sample3, active=True):
        # Emission from a scene-sized disk needs the scene's bounds, which Mitsuba does not
        # give Python emitters; this emitter serves the photon pass (which aims photons itself)
        # and integrators that use sample_direction (path tracing). A zero-weight ray keeps
        # symbolic virtual calls over all emitters valid: Dr.Jit traces every live emitter,
        # also ones of other scenes, so raising here broke unrelated renders in the process.
        ds, _ = self.sample_direction(dr.zeros(mi.Interaction3f), sample3, active)
        ray = mi.Ray3f(ds.p, -ds.d, time, mi.Spectrum(wavelength_sample * 470.0 + 360.0))
        return ray, mi.Spectrum(0.0)

    def sample_wavelengths(self, si, sample, active=True):
        return mi.Spectrum(mi.sample_shifted(sample) * 470.0 + 360.0), mi.Spectrum(470.0)

    def traverse(self, callback):
        pass

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        return f"VegSunPath[directions={self.count}, scale={self.scale}]"


mi.register_emitter("veg_sun_path", lambda props: VegSunPath(props))
