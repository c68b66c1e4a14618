"""The package's sun emitters ``veg_sun_path`` and ``veg_sun_steps``: delta directions towards
a discrete set of suns with weights (base class :class:`DeltaSun`).

``veg_sun_path`` (:class:`VegSunPath`): a whole day of sun as one emitter, for daily-mean light
in one photon pass. The moss model needs the *daily mean* insolation of each triangle (paper 000
uses daily means throughout §3.5). The sun moves: the daily-mean beam on a triangle is the time
average of E_n(t) max(0, n·s(t)) V(t) (normal irradiance, incidence, visibility).
``veg_sun_path`` holds the sun directions s_k of one day (every few minutes while the sun is up)
with weights w_k = E_n,k Δt / 86400 (:func:`mitsuba_veg.light.sunpath.day_sun_path`), and samples
one of them per photon with probability ∝ w_k: a photon pass with it gives the daily-mean beam
irradiance of every triangle at once. The weights are normalised so that an unobstructed
horizontal plane receives a daily-mean beam of exactly 1 W m-2 nm-1: a triangle's result
divided by the band width is its *sun fraction* f_sun. The directions can be changed every day
with :meth:`VegSunPath.set_day` without rebuilding the scene (the photon pass reads them on each
call).

``veg_sun_steps`` (:class:`VegSunSteps`): the sun over one time step of a sensor study
(:mod:`mitsuba_veg.light.sensor_study`), the step's directions with weights and a spectrum, set
with :meth:`VegSunSteps.set_directions` without a rebuild or a recompile.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.arrays import DiscreteSampler, host_array, opaque
from mitsuba_veg.errors import ParameterError

from .plugin_table import Parameter, with_parameter_table

__all__ = ["DeltaSun", "VegSunPath", "VegSunSteps", "SLOTS"]

#: sun directions one ``veg_sun_steps`` step can hold (a day at 10-minute sub-steps has at most
#: 144)
SLOTS = 256


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


@with_parameter_table
class VegSunPath(DeltaSun):
    """Mitsuba emitter ``veg_sun_path``: a delta-direction emitter with a discrete set of sun
    directions (module docstring).

    Directions are set with :meth:`set_day` (default: one sun at the zenith). Supports the
    photon pass and ``sample_direction`` (next-event estimation of path tracers); light tracers
    (``sample_ray``, e.g. Mitsuba's ``ptracer``) get no light from it.
    """

    #: the name the plugin is registered under, and its kind
    PLUGIN, PLUGIN_KIND = "veg_sun_path", "emitter"
    #: every property the constructor reads (the docstring's table and the docs' plugin page)
    PARAMETERS = (
        Parameter("scale", "float", "1.0",
                  "Spectral irradiance per unit weight [W m-2 nm-1] (flat spectrum)."),
    )

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



@with_parameter_table
class VegSunSteps(DeltaSun):
    """Mitsuba emitter ``veg_sun_steps``: the sun over one time step, a discrete set of
    directions with weights and a spectrum.

    :meth:`set_directions` sets the step's directions (towards the sun)
    and weights; a photon picks direction k with probability w_k / Σw and carries Σw × the
    spectrum, so a pass gives Σ_k w_k × (the light of a sun in direction k). The tables have a
    fixed size (:data:`SLOTS`) and opaque values: changing them does not recompile the kernel.
    For the photon pass (``sample_direction``); ``sample_ray`` returns zero-weight rays.
    """

    #: the name the plugin is registered under, and its kind
    PLUGIN, PLUGIN_KIND = "veg_sun_steps", "emitter"
    #: every property the constructor reads (the docstring's table and the docs' plugin page)
    PARAMETERS = (
        Parameter("irradiance", "spectrum or float", "1.0",
                  "Beam irradiance on a plane normal to the sun per unit weight [W m-2 nm-1]; a "
                  "number is a flat spectrum."),
    )

    def __init__(self, props: mi.Properties):
        DeltaSun.__init__(self, props)
        spec = props.get("irradiance", 1.0)
        if isinstance(spec, (int, float)):
            spec = mi.load_dict({"type": "uniform", "value": float(spec)})
        self.m_spec = spec
        self.set_directions(np.array([[0.0, 1.0, 0.0]]), np.array([1.0]))

    def set_directions(self, directions, weights, seed: int = 0) -> None:
        """Set the step's sun directions and weights (no rebuild, no recompile).

        Parameters
        ----------
        directions : array_like
            (K, 3) unit vectors towards the sun, K <= :data:`SLOTS`.
        weights : array_like
            (K,) weights w_k >= 0 [-] (Δt/T DNI_PAR(k) / DNI_PAR,ref in
            :func:`mitsuba_veg.light.sensor_study.run_series`).
        seed : int
            Sets the random shift of the direction sequence (see :meth:`sample_direction`).
        """
        d = np.asarray(directions, float).reshape(-1, 3)
        w = np.asarray(weights, float).reshape(-1)
        if len(d) != len(w) or len(w) > SLOTS or (w < 0).any() or not np.isfinite(w).all():
            raise ParameterError("sun directions", (len(d), len(w)), f"as many finite weights "
                                 f">= 0 as directions, at most {SLOTS}")
        total = float(w.sum())
        cdf = np.ones(SLOTS)
        dd = np.tile([0.0, 1.0, 0.0], (SLOTS, 1))
        if total > 0:
            cdf[:len(w)] = np.cumsum(w) / total
            dd[:len(d)] = d
        self.m_cdf = mi.Float(cdf.astype(np.float32))
        self.m_dirs = mi.Vector3f(*[mi.Float(dd[:, k].astype(np.float32)) for k in range(3)])
        self.m_total = dr.opaque(mi.Float, total)
        self.m_shift = dr.opaque(mi.UInt32, int(np.random.default_rng(seed).integers(0, 2**32)))
        self.total = total

    def sample_direction(self, it, sample, active=True):
        """One of the step's sun directions, with probability w_k / Σw over the random shift.

        Parameters
        ----------
        it : mitsuba.Interaction3f
            The reference point (its wavelengths evaluate the spectrum).
        sample : mitsuba.Point2f
            Uniform sample (only its width is used: see the comment in the body).
        active : mitsuba.Bool
            Active lanes.

        Returns
        -------
        ds : mitsuba.DirectionSample3f
            The delta direction towards the sun.
        weight : mitsuba.Spectrum
            Σw × the ``irradiance`` spectrum [W m-2 nm-1].
        """
        # The direction of photon i is not drawn independently but from a randomly shifted
        # Weyl sequence over the photon index, frac(i (sqrt(2) - 1) + shift), so that each
        # direction's photons are spread evenly over the pass's jittered-grid origin strata.
        # Over the random shift each photon's direction follows the weights (unbiased). It
        # helps little once a sensor gets under one photon per direction (a day of 144
        # directions: the count on a small sensor is then Poisson-like, docs/sensors.md).
        i = dr.arange(mi.UInt32, dr.width(sample.x))
        bits = i * dr.opaque(mi.UInt32, 1779033704) + self.m_shift
        u = mi.Float(bits >> 8) * dr.opaque(mi.Float, 2.0 ** -24)
        k = dr.binary_search(0, SLOTS - 1,
                             lambda i: dr.gather(mi.Float, self.m_cdf, i) <= u)
        ds = self._direction_sample(it, dr.gather(mi.Vector3f, self.m_dirs, k, active))
        ds.emitter = mi.EmitterPtr(self)
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wavelengths = it.wavelengths
        value = self.m_spec.eval(si, active) * self.m_total
        return ds, dr.select(active, value, 0.0)

    def to_string(self):
        """Mitsuba's description of the emitter.

        Returns
        -------
        str
            The total weight of the step.
        """
        return f"VegSunSteps[total weight={self.total:g}]"



mi.register_emitter("veg_sun_path", lambda props: VegSunPath(props))
mi.register_emitter("veg_sun_steps", lambda props: VegSunSteps(props))
