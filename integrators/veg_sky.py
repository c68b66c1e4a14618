"""The Mitsuba emitter ``veg_sky``: a separable clear-sky environment, L(w, lam) = S(lam) f(w).

``S`` is a spectrum (property ``radiance``, W m-2 sr-1 nm-1: the radiance of a *uniform* sky with
the same horizontal irradiance, i.e. DHI/pi) and ``f`` the relative radiance distribution of
:mod:`mitsuba_veg.light.sky` (Perez all-weather, CIE clear skies 12/13 or uniform; zero below the
horizon, normalised so that the emitter's horizontal diffuse irradiance is exactly pi S(lam)).
That module holds the radiance model: the coefficients, f, its normalisation and the sampling
table.

Directions are importance-sampled from a piecewise-constant table of f over a latitude-longitude
grid of the upper hemisphere (cells uniform in cos(theta) and azimuth inside, so that the pdf is
constant per cell in solid angle); weights are exact (L / pdf with the analytic f). A
``uniform`` sky is sampled uniformly in solid angle directly (the table's own distribution,
without its search).

Frame (project convention): +y up, +x east, +z south; the grid's azimuth is clockwise from north
(-z). The plugin takes no ``to_world``.

Properties (the parameter table of VegSky)::

    radiance      spectrum S [W m-2 sr-1 nm-1] (explicit regular/uniform/... spectrum; a
                  plain float becomes a *flat* (uniform) spectrum, not a D65 one); or
    irradiance    spectrum E (horizontal diffuse irradiance [W m-2 nm-1]); S = E/pi.
    sun_direction vector towards the sun (need not be normalised); must be above the horizon for
                  perez (its zenith angle enters the coefficients). Default: zenith.
    distribution  perez (default when perez_epsilon is given), cie_clear (CIE type 12,
                  the default otherwise), cie_turbid (type 13), uniform or custom.
    perez_epsilon, perez_delta   Perez sky clearness (>= 1) and brightness (>= 0).
    a, b, c, d, e coefficients for custom.
    resolution    rows of the sampling table over 0-90 deg zenith (default 128; 4x as many columns).

Note: Mitsuba's scene does not call ``set_scene`` on Python emitters (it is not part of the
Python trampoline in 3.9.1). Call :func:`attach_scene` (or ``emitter.set_scene(scene)``) after
loading a scene before using ``sample_ray``; until then the scene is assumed to fit in the unit
sphere at the origin. ``sample_direction`` does not need it.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.arrays import DiscreteSampler
from mitsuba_veg.errors import ParameterError, SceneError
from mitsuba_veg.light.sky import normalisation, sampling_table, sky_coefficients

from .plugin_table import Parameter, with_parameter_table

__all__ = ["VegSky", "attach_scene"]


def _opaque(v):
    """A width-1 ``mi.Float`` holding ``v``, made opaque (a kernel input, not a literal)."""
    x = mi.Float(float(v))
    dr.make_opaque(x)
    return x



@with_parameter_table
class VegSky(mi.Emitter):
    """Mitsuba emitter ``veg_sky``: a separable clear-sky environment, L(w, lam) = S(lam) f(w)
    (module docstring).

    """

    #: the name the plugin is registered under, and its kind
    PLUGIN, PLUGIN_KIND = "veg_sky", "emitter"
    #: every property the constructor reads (the docstring's table and the docs' plugin page)
    PARAMETERS = (
        Parameter("radiance", "spectrum or float", "(one of radiance / irradiance)",
                  "S, the radiance of a uniform sky with the same horizontal irradiance "
                  "[W m-2 sr-1 nm-1]; a number is a flat spectrum."),
        Parameter("irradiance", "spectrum or float", "(one of radiance / irradiance)",
                  "E, the horizontal diffuse irradiance [W m-2 nm-1]; S = E / pi."),
        Parameter("sun_direction", "vector", "[0, 1, 0]",
                  "Towards the sun (scene frame, +y up); above the horizon for ``perez``."),
        Parameter("distribution", "string", '"perez" with perez_epsilon, else "cie_clear"',
                  "``perez``, ``cie_clear`` (CIE type 12), ``cie_turbid`` (type 13), "
                  "``uniform`` or ``custom``."),
        Parameter("perez_epsilon", "float", "(required by ``perez``)",
                  "Perez sky clearness [-], >= 1."),
        Parameter("perez_delta", "float", "(required by ``perez``)",
                  "Perez sky brightness [-], >= 0."),
        Parameter("a, b, c, d, e", "float", "(required by ``custom``)",
                  "Perez-form coefficients of f."),
        Parameter("resolution", "integer", "128",
                  "Rows of the sampling table over 0-90 deg zenith (4 x as many columns), "
                  "4-2048."),
    )

    #: its arrays are inputs of a frozen function that reaches it (dr.freeze)
    DRJIT_STRUCT = {"m_cos_edges": mi.Float, "m_cell_pdf": mi.Float, "m_distr": DiscreteSampler,
                    "m_coef": list, "m_norm": mi.Float, "m_sun": mi.Vector3f,
                    "m_radiance": mi.Texture, "m_center": mi.Point3f, "m_radius": mi.Float}

    def __init__(self, props: mi.Properties):
        mi.Emitter.__init__(self, props)
        self.m_flags = mi.EmitterFlags.Infinite | mi.EmitterFlags.SpatiallyVarying

        has_r, has_e = "radiance" in props, "irradiance" in props
        if has_r == has_e:
            raise ParameterError("veg_sky radiance/irradiance", "both" if has_r else "neither",
                                 "exactly one of them",
                                 "give 'radiance' (= DHI/pi, W m-2 sr-1 nm-1) as a regular "
                                 "spectrum, or 'irradiance' (= DHI, W m-2 nm-1)")
        key = "radiance" if has_r else "irradiance"
        spec = props[key]
        if isinstance(spec, (int, float)):
            spec = mi.load_dict({"type": "uniform", "value": float(spec)})
        elif not isinstance(spec, mi.Texture) and type(spec).__name__ == "Spectrum":
            # a scene file's <spectrum name="radiance" value="..."/>: Mitsuba makes the texture
            # (uniform for one value, irregular for wavelength:value pairs)
            spec = props.get_unbounded_texture(key)
        if not isinstance(spec, mi.Texture):
            raise ParameterError(f"veg_sky {key}", spec, "a spectrum (e.g. {'type': 'regular', "
                                 "...}, or <spectrum value=\"...\"/> in a scene file) or a "
                                 "number")
        self.m_radiance = spec
        #: the property the spectrum came from, and its name in ``mi.traverse``
        self.spectrum_key = key
        self.m_scale = 1.0 if has_r else 1.0 / math.pi

        sun = np.array(props.get("sun_direction", [0.0, 1.0, 0.0]), dtype=float).reshape(-1)
        if sun.shape != (3,) or not np.all(np.isfinite(sun)) or np.linalg.norm(sun) == 0:
            raise ParameterError("veg_sky sun_direction", sun.tolist(), "a non-zero 3-vector "
                                 "towards the sun")
        sun = sun / np.linalg.norm(sun)
        has_perez = "perez_epsilon" in props
        dist = props.get("distribution", "perez" if has_perez else "cie_clear")
        custom = None
        if dist == "custom":
            custom = [props.get(k, None) for k in "abcde"]
            if any(v is None for v in custom):
                raise ParameterError("veg_sky a..e", custom, "five numbers for 'custom'")
        eps = props.get("perez_epsilon", None)
        delta = props.get("perez_delta", None)
        if dist == "perez" and sun[1] <= 0.0:
            raise ParameterError("veg_sky sun_direction", sun.tolist(), "above the horizon "
                                 "(y > 0) for the Perez sky", "use another distribution or "
                                 "no sky at night")
        zenith = math.acos(min(1.0, max(-1.0, float(sun[1]))))
        coeffs = sky_coefficients(dist, zenith, epsilon=eps, delta=delta, custom=custom)
        rows = int(props.get("resolution", 128))
        if not 4 <= rows <= 2048:
            raise ParameterError("veg_sky resolution", rows, "[4, 2048]", "use 64-256")

        self.rows, self.cols = rows, 4 * rows
        self._tables(dist, coeffs, sun)
        self.m_center = mi.Point3f(0.0, 0.0, 0.0)
        self.m_radius = _opaque(1.0)
        dr.make_opaque(self.m_center)

    def _tables(self, dist, coeffs, sun) -> None:
        """Normalisation, sampling table and opaque coefficients for a sun and distribution
        (arrays of the same sizes for every sun: a rendering kernel is reused)."""
        self.distribution, self.coefficients, self.sun = dist, tuple(coeffs), sun
        self.norm = normalisation(sun, coeffs)
        cos_e, pdf, pmf = sampling_table(sun, coeffs, self.norm, self.rows)
        self.m_cos_edges = mi.Float(cos_e)
        self.m_cell_pdf = mi.Float(pdf)
        # cumulative sums on the host: the same table on every backend (arrays.DiscreteSampler)
        self.m_distr = DiscreteSampler(pmf)
        self.m_coef = [_opaque(v) for v in coeffs]
        self.m_norm = _opaque(self.norm * self.m_scale)
        self.m_sun = mi.Vector3f(*[float(v) for v in sun])
        dr.make_opaque(self.m_sun)

    def set_sky(self, sun_direction, epsilon: float | None = None,
                delta: float | None = None) -> None:
        """Move the sky to another sun (and Perez sky clearness/brightness) in place.

        The tables keep their sizes and the coefficients stay opaque, so a scene rendered
        before renders again with the same compiled kernel (an animation's daily light). A
        ``custom`` sky keeps its coefficients; the spectrum S is unchanged.

        Parameters
        ----------
        sun_direction : array_like
            (3,) direction towards the sun (scene frame, +y up), need not be normalised.
        epsilon, delta : float, optional
            Perez sky clearness and brightness [-] (``distribution="perez"``, where both are
            required).

        Raises
        ------
        ParameterError
            If ``sun_direction`` is not a finite non-zero 3-vector, or is at or below the
            horizon for a Perez sky.
        """
        sun = np.asarray(sun_direction, dtype=float).reshape(-1)
        if sun.shape != (3,) or not np.all(np.isfinite(sun)) or np.linalg.norm(sun) == 0:
            raise ParameterError("veg_sky sun_direction", sun.tolist(), "a non-zero 3-vector "
                                 "towards the sun")
        sun = sun / np.linalg.norm(sun)
        if self.distribution == "perez" and sun[1] <= 0.0:
            raise ParameterError("veg_sky sun_direction", sun.tolist(), "above the horizon "
                                 "(y > 0) for the Perez sky")
        if self.distribution == "custom":
            coeffs = self.coefficients
        else:
            zenith = math.acos(min(1.0, max(-1.0, float(sun[1]))))
            coeffs = sky_coefficients(self.distribution, zenith, epsilon=epsilon, delta=delta)
        self._tables(self.distribution, coeffs, sun)

    # ------------------------------------------------------------------ helpers
    def _f(self, d, active=True):
        """Relative radiance f(d) times S's scale (normalised: int f cos = pi)."""
        a, b, c, dd, e = self.m_coef
        cos_t = d.y
        cos_g = dr.clip(dr.dot(d, self.m_sun), -1.0, 1.0)
        grad = 1.0 + a * dr.exp(b / dr.maximum(cos_t, 0.01))
        ind = 1.0 + c * dr.exp(dd * dr.safe_acos(cos_g)) + e * cos_g * cos_g
        f = dr.maximum(grad * ind, 0.0) * self.m_norm
        return dr.select(active & (cos_t > 0.0), f, 0.0)

    def _spectrum(self, wavelengths, active=True):
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wavelengths = wavelengths
        return self.m_radiance.eval(si, active)

    def _cell_index(self, d):
        cos_t = dr.clip(d.y, 0.0, 1.0)
        theta = dr.safe_acos(cos_t)
        row = mi.UInt32(dr.clip(mi.Int32(theta * (2.0 * self.rows / math.pi)), 0, self.rows - 1))
        phi = dr.atan2(d.x, -d.z)
        phi = dr.select(phi < 0.0, phi + 2.0 * math.pi, phi)
        col = mi.UInt32(dr.clip(mi.Int32(phi * (self.cols / (2.0 * math.pi))), 0, self.cols - 1))
        return row, col, phi, theta

    def _pdf(self, d, active=True):
        if self.distribution == "uniform":   # uniform in solid angle (see _sample)
            return dr.select(active & (d.y > 0.0), 0.5 / math.pi, 0.0)
        row, col, _, _ = self._cell_index(d)
        up = active & (d.y > 0.0)
        pdf = dr.gather(mi.Float, self.m_cell_pdf, row * self.cols + col, up)
        return dr.select(up, pdf, 0.0)

    def _sample(self, sample, active=True):
        """Direction towards the sky, its pdf [sr-1] and uv."""
        if self.distribution == "uniform":
            # a uniform sky's table is uniform in solid angle: drawn directly (no table search)
            cos_t = 1.0 - sample.y
            sin_t = dr.safe_sqrt(1.0 - cos_t * cos_t)
            phi = sample.x * (2.0 * math.pi)
            sp, cp = dr.sincos(phi)
            d = mi.Vector3f(sp * sin_t, cos_t, -cp * sin_t)
            uv = mi.Point2f(sample.x, dr.safe_acos(cos_t) * (2.0 / math.pi))
            return d, dr.select(active & (cos_t > 0.0), 0.5 / math.pi, 0.0), uv
        idx, ux, _ = self.m_distr.sample_reuse(sample.x, active)
        row, col = idx // self.cols, idx % self.cols
        phi = (mi.Float(col) + ux) * (2.0 * math.pi / self.cols)
        c0 = dr.gather(mi.Float, self.m_cos_edges, row, active)
        c1 = dr.gather(mi.Float, self.m_cos_edges, row + 1, active)
        cos_t = dr.lerp(c0, c1, sample.y)
        sin_t = dr.safe_sqrt(1.0 - cos_t * cos_t)
        sp, cp = dr.sincos(phi)
        d = mi.Vector3f(sp * sin_t, cos_t, -cp * sin_t)
        # look the pdf up from the direction (not the sampled cell): identical except for
        # directions within float rounding of a cell edge, and then equal to pdf_direction()
        pdf = self._pdf(d, active)
        uv = mi.Point2f(phi * (0.5 / math.pi), dr.safe_acos(cos_t) * (2.0 / math.pi))
        return d, dr.select(active, pdf, 0.0), uv

    # ------------------------------------------------------------------ Emitter interface
    def set_scene(self, scene):
        """Learn the scene's bounding sphere (for sample_ray); not called by Mitsuba itself.

        Parameters
        ----------
        scene : mi.Scene
            The loaded scene; an empty one gives a sphere of radius 1e-4 m at the origin.
        """
        bbox = scene.bbox()
        if bbox.valid():
            bs = bbox.bounding_sphere()
            center, radius = [float(v) for v in bs.center], float(bs.radius)
            radius = max(1e-4, radius * (1.0 + 1e-4))
        else:
            center, radius = [0.0, 0.0, 0.0], 1e-4
        self.m_center = mi.Point3f(*center)
        self.m_radius = _opaque(radius)
        dr.make_opaque(self.m_center)

    def eval(self, si, active=True):
        """Radiance arriving from the sky along ``-si.wi`` (a ray that escaped the scene).

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
            The escaping ray's interaction (``wi``: direction back along the ray; ``wavelengths``
            [nm]).
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Returns
        -------
        mi.Spectrum
            Radiance S(lambda) f(w) [W m-2 sr-1 nm-1]; 0 below the horizon.
        """
        d = -si.wi
        return self._spectrum(si.wavelengths, active) * self._f(d, active)

    def eval_direction(self, it, ds, active=True):
        """Radiance from the sky in the direction of a direction sample.

        Parameters
        ----------
        it : mi.Interaction3f
            The reference point (its ``wavelengths`` [nm] are used).
        ds : mi.DirectionSample3f
            Direction sample; ``ds.d`` points towards the sky.
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Returns
        -------
        mi.Spectrum
            Radiance S(lambda) f(ds.d) [W m-2 sr-1 nm-1]; 0 below the horizon.
        """
        return self._spectrum(it.wavelengths, active) * self._f(ds.d, active)

    def sample_direction(self, it, sample, active=True):
        """Importance-sample a direction towards the sky from a reference point.

        The direction comes from the piecewise-constant table of f (upper hemisphere only); the
        sample's point lies at twice the bounding-sphere radius along it.

        Parameters
        ----------
        it : mi.Interaction3f
            The reference point (position [m], time, wavelengths [nm]).
        sample : mi.Point2f
            Uniform 2D sample in [0, 1)^2.
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Returns
        -------
        ds : mi.DirectionSample3f
            The sample: ``d`` towards the sky, ``pdf`` in solid angle [sr-1],
            ``uv`` = (azimuth / 2pi, zenith / (pi/2)), ``dist`` [m], ``delta`` False.
        weight : mi.Spectrum
            Radiance / pdf [W m-2 nm-1]; 0 for inactive lanes.
        """
        d, pdf, uv = self._sample(sample, active)
        active = active & (pdf > 0.0)
        radius = dr.maximum(self.m_radius, dr.norm(it.p - self.m_center))
        dist = 2.0 * radius
        ds = dr.zeros(mi.DirectionSample3f)
        ds.p = it.p + d * dist
        ds.n = -d
        ds.uv = uv
        ds.time = it.time
        ds.pdf = dr.select(active, pdf, 0.0)
        ds.delta = mi.Bool(False)
        ds.emitter = mi.EmitterPtr(self)
        ds.d = d
        ds.dist = dist
        weight = self._spectrum(it.wavelengths, active) * (
            self._f(d, active) / dr.select(active, pdf, 1.0))
        return ds, dr.select(active, weight, 0.0)

    def pdf_direction(self, it, ds, active=True):
        """Solid-angle density of :meth:`sample_direction` for a direction.

        Parameters
        ----------
        it : mi.Interaction3f
            The reference point (unused: the density does not depend on it).
        ds : mi.DirectionSample3f
            Direction sample; ``ds.d`` points towards the sky.
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Returns
        -------
        mi.Float
            Density [sr-1]; 0 at and below the horizon.
        """
        return self._pdf(ds.d, active)

    def sample_wavelengths(self, si, sample, active=True):
        """Sample wavelengths from the sky spectrum S for a ray escaping along ``-si.wi``.

        Parameters
        ----------
        si : mi.SurfaceInteraction3f
            The interaction (``wi``: direction back along the ray).
        sample : mi.Float
            Uniform sample in [0, 1) (shifted for the other wavelengths).
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Returns
        -------
        wavelengths : mi.Spectrum
            Sampled wavelengths [nm].
        weight : mi.Spectrum
            The spectrum's sampling weight S(lambda)/p(lambda) times f(-si.wi)
            [W m-2 sr-1].
        """
        wav, w = self.m_radiance.sample_spectrum(si, mi.sample_shifted(sample), active)
        return wav, w * self._f(-si.wi, active)

    def pdf_wavelengths(self, wavelengths, active=True):
        """Density of :meth:`sample_wavelengths` for given wavelengths (that of the spectrum S).

        Parameters
        ----------
        wavelengths : mi.Spectrum
            Wavelengths [nm].
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Returns
        -------
        mi.Spectrum
            Density per wavelength [nm-1].
        """
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wavelengths = wavelengths
        return self.m_radiance.pdf_spectrum(si, active)

    def sample_ray(self, time, wavelength_sample, sample2, sample3, active=True):
        """Sample a ray leaving the sky towards the scene (light tracing, photon passes).

        The direction is importance-sampled from f; the origin lies on a disk of the bounding-sphere
        radius perpendicular to it, one radius out (see :func:`attach_scene`: without it the scene
        is assumed to fit in the unit sphere at the origin).

        Parameters
        ----------
        time : mi.Float
            Time of the ray [s].
        wavelength_sample : mi.Float
            Uniform sample in [0, 1) for the wavelengths.
        sample2 : mi.Point2f
            Uniform 2D sample for the position on the disk.
        sample3 : mi.Point2f
            Uniform 2D sample for the direction.
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Returns
        -------
        ray : mi.Ray3f
            The ray (origin [m], direction into the scene, wavelengths [nm]).
        weight : mi.Spectrum
            ``S(lambda)/p(lambda) * f * pi r^2 / pdf``: the power the ray carries [W]
            (r: bounding-sphere radius [m], pdf: direction density [sr-1]); 0 for inactive
            lanes.
        """
        offset = mi.warp.square_to_uniform_disk_concentric(sample2)
        d, pdf, _ = self._sample(sample3, active)
        active = active & (pdf > 0.0)
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.time = time
        wav, wweight = self.m_radiance.sample_spectrum(
            si, mi.sample_shifted(wavelength_sample), active)
        perp = mi.Frame3f(d).to_world(mi.Vector3f(offset.x, offset.y, 0.0))
        origin = self.m_center + (perp + d) * self.m_radius
        r2 = self.m_radius * self.m_radius
        weight = wweight * (self._f(d, active) * (math.pi * r2) / dr.select(active, pdf, 1.0))
        ray = mi.Ray3f(origin, -d, time, wav)
        return ray, dr.select(active, weight, 0.0)

    def sample_position(self, time, sample, active=True):
        """Not supported: an infinite emitter has no positions to sample.

        Parameters
        ----------
        time : mi.Float
            Time [s] (unused).
        sample : mi.Point2f
            2D sample (unused).
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Raises
        ------
        NotImplementedError
            Always.
        """
        raise NotImplementedError("veg_sky is an infinite emitter: it has no positions to sample")

    def pdf_position(self, ps, active=True):
        """Not supported: an infinite emitter has no positions to sample.

        Parameters
        ----------
        ps : mi.PositionSample3f
            Position sample (unused).
        active : mi.Bool, optional
            Mask of the active lanes; default True.

        Raises
        ------
        NotImplementedError
            Always.
        """
        raise NotImplementedError("veg_sky is an infinite emitter: it has no positions to sample")

    def bbox(self):
        """Bounding box of the emitter: empty (an infinite emitter).

        Returns
        -------
        mi.ScalarBoundingBox3f
            An empty (invalid) box.
        """
        return mi.ScalarBoundingBox3f()

    def traverse(self, callback):
        """Expose the spectrum as a differentiable parameter named after its property.

        ``radiance`` (S [W m-2 sr-1 nm-1]) when the emitter was built with ``radiance``,
        ``irradiance`` (E [W m-2 nm-1], the 1/pi applied in the normalisation) when it was built
        with ``irradiance``: a value set through ``mi.traverse`` means what its name says.

        Parameters
        ----------
        callback : mi.TraversalCallback
            Mitsuba's traversal callback.
        """
        callback.put(self.spectrum_key, self.m_radiance, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=None):
        """Nothing to update: the spectrum is evaluated on the fly (sun and coefficients change
        through :meth:`set_sky`).

        Parameters
        ----------
        keys : list of str, optional
            Names of the changed parameters (unused); default None.
        """
        pass

    def to_string(self):
        """A one-line description of the emitter.

        Returns
        -------
        str
            Distribution, coefficients, sun direction, table resolution (rows x columns) and
            spectrum.
        """
        return (f"VegSky[distribution={self.distribution}, coefficients="
                f"{tuple(round(c, 4) for c in self.coefficients)}, sun_direction="
                f"{self.sun.round(4).tolist()}, resolution={self.rows}x{self.cols}, "
                f"radiance={self.m_radiance}]")


def attach_scene(scene) -> int:
    """Call ``set_scene(scene)`` on every :class:`VegSky` of a loaded scene.

    Needed before ``sample_ray`` (Mitsuba 3.9.1 does not call ``set_scene`` on Python emitters).

    Parameters
    ----------
    scene : mi.Scene
        The loaded scene.

    Returns
    -------
    int
        How many ``veg_sky`` emitters were attached.

    Raises
    ------
    SceneError
        If ``scene`` is not a loaded ``mi.Scene``.
    """
    if not isinstance(scene, mi.Scene):
        raise SceneError(f"attach_scene needs a loaded mitsuba Scene, got {type(scene).__name__}")
    n = 0
    for em in scene.emitters():
        if isinstance(em, VegSky):
            em.set_scene(scene)
            n += 1
    return n



mi.register_emitter("veg_sky", lambda props: VegSky(props))
