"""The Mitsuba sensor ``veg_fisheye``: a circular fisheye lens (a hemispherical canopy camera).

The image is a disc inscribed in the film (its diameter the film's shorter side, centred);
pixels outside it get no rays (weight 0, black). A point at normalised radius r (0 at the
centre, 1 at the disc's edge) sees the zenith angle θ from the optical axis

- ``equidistant`` (the default, "f-θ", most canopy-photo lenses): r = θ / θ_max;
- ``equisolid`` (equal-area): r = sin(θ/2) / sin(θ_max/2), every pixel the same solid angle;

with θ_max = fov / 2, and the azimuth of the point in the image plane. Frame: the optical
axis is the sensor's local +z, the image's top its local +y and the image's right its local −x,
as for Mitsuba's ``perspective`` camera: ``to_world = look_at(origin, origin + direction, up)``
gives the same image orientation. The default (origin at 0, ``direction`` [0, 1, 0], ``up``
[0, 0, −1]) looks at the zenith with north (−z) at the top and east (+x) on the left: a levelled
canopy photograph taken from below, as field software reads it.

A Python ``mi.Sensor`` renders with the ``path`` and ``aov`` integrators and with the package's
spectral film (wavelengths are sampled by the sensor's film response,
``Sensor.sample_wavelengths``). :func:`zenith_of_radius` and :func:`radius_of_zenith` are the
projection as functions of NumPy or Dr.Jit arrays (:mod:`mitsuba_veg.light.fisheye` maps pixels
with them).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import ParameterError

from .plugin_table import Parameter, with_parameter_table

__all__ = ["VegFisheye", "PROJECTIONS", "zenith_of_radius", "radius_of_zenith"]

#: the lens projections
PROJECTIONS = ("equidistant", "equisolid")


def _check_projection(projection: str) -> str:
    if projection not in PROJECTIONS:
        raise ParameterError("veg_fisheye projection", projection, ", ".join(PROJECTIONS),
                             "equidistant for an f-theta canopy lens, equisolid for an "
                             "equal-area one")
    return projection


def zenith_of_radius(r, projection: str, theta_max: float):
    """The angle from the optical axis of a point of the image disc.

    Parameters
    ----------
    r : numpy.ndarray or Dr.Jit array
        Normalised radius in the image [-] (0 at the centre, 1 at the disc's edge).
    projection : str
        ``"equidistant"`` (r = θ/θ_max) or ``"equisolid"`` (r = sin(θ/2)/sin(θ_max/2)).
    theta_max : float
        Half the field of view [rad], (0, π/2].

    Returns
    -------
    numpy.ndarray or Dr.Jit array
        θ [rad] (same kind as ``r``).
    """
    _check_projection(projection)
    if projection == "equidistant":
        return r * theta_max
    s = math.sin(0.5 * theta_max)
    if dr.is_array_v(r):
        return 2.0 * dr.safe_asin(dr.clip(r * s, 0.0, 1.0))
    return 2.0 * np.arcsin(np.clip(np.asarray(r, float) * s, 0.0, 1.0))


def radius_of_zenith(theta, projection: str, theta_max: float):
    """The normalised image radius of a direction at ``theta`` from the optical axis.

    Parameters
    ----------
    theta : numpy.ndarray or Dr.Jit array
        Angle from the optical axis [rad].
    projection : str
        ``"equidistant"`` or ``"equisolid"``.
    theta_max : float
        Half the field of view [rad].

    Returns
    -------
    numpy.ndarray or Dr.Jit array
        r [-] (> 1 outside the image disc).
    """
    _check_projection(projection)
    if projection == "equidistant":
        return theta / theta_max
    s = math.sin(0.5 * theta_max)
    if dr.is_array_v(theta):
        return dr.sin(0.5 * theta) / s
    return np.sin(0.5 * np.asarray(theta, float)) / s


def _vector(props, name, default):
    v = np.asarray(props[name] if name in props else default, float).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ParameterError(f"veg_fisheye {name}", v.tolist(), "three finite numbers")
    return v


@with_parameter_table
class VegFisheye(mi.Sensor):
    """Mitsuba sensor ``veg_fisheye``: a circular fisheye lens (module docstring).
    """

    #: the name the plugin is registered under, and its kind
    PLUGIN, PLUGIN_KIND = "veg_fisheye", "sensor"
    #: every property the constructor reads (the docstring's table and the docs' plugin page)
    PARAMETERS = (
        Parameter("projection", "string", '"equidistant"',
                  "``equidistant`` (r = θ/θ_max) or ``equisolid`` (r = sin(θ/2)/sin(θ_max/2))."),
        Parameter("fov", "float", "180",
                  "Full field of view of the image disc [deg], (0, 180]; θ_max = fov/2."),
        Parameter("to_world", "transform", "look_at(origin, origin + direction, up)",
                  "Sensor to world: local +z the optical axis, +y the image's top (not with "
                  "origin, direction or up)."),
        Parameter("origin", "point", "[0, 0, 0]",
                  "Centre of the lens [m] (scene frame: +y up, +x east, +z south)."),
        Parameter("direction", "vector", "[0, 1, 0]",
                  "Optical axis (the zenith for a canopy photo); need not be normalised."),
        Parameter("up", "vector", "[0, 0, -1]",
                  "Direction shown at the image's top (north); not parallel to ``direction``."),
        Parameter("film", "film", "hdrfilm 768 x 576",
                  "Any film (the package's spectral ``specfilm`` of mitsuba_veg.render.film "
                  "too); the image disc's diameter is its shorter side. Read by mi.Sensor's "
                  "constructor."),
        Parameter("sampler", "sampler", "independent, 4 spp",
                  "Samples per pixel. Read by mi.Sensor's constructor."),
    )

    #: properties the base class ``mi.Sensor`` reads (the film and the sampler: objects, named
    #: ``_arg_<i>`` in a scene file); tests/test_plugins.py counts them as read
    BASE_PROPERTIES = ("film", "sampler")

    def __init__(self, props: mi.Properties):
        mi.Sensor.__init__(self, props)
        self.projection = _check_projection(str(props.get("projection", "equidistant")))
        fov = float(props.get("fov", 180.0))
        if not (0.0 < fov <= 180.0) or not math.isfinite(fov):
            raise ParameterError("veg_fisheye fov", fov, "(0, 180] degrees",
                                 "180 for a full hemispherical photograph")
        self.fov = fov
        self.theta_max = math.radians(0.5 * fov)
        placed = [k for k in ("origin", "direction", "up") if k in props]
        if "to_world" in props:
            if placed:
                raise ParameterError("veg_fisheye to_world", placed, "either to_world or "
                                     "origin/direction/up", "give one of the two")
            m = np.array(props.get("to_world").matrix, float)
        else:
            o = _vector(props, "origin", [0.0, 0.0, 0.0])
            d = _vector(props, "direction", [0.0, 1.0, 0.0])
            u = _vector(props, "up", [0.0, 0.0, -1.0])
            if np.linalg.norm(d) == 0 or np.linalg.norm(np.cross(d, u)) < 1e-9 * \
                    max(np.linalg.norm(d) * np.linalg.norm(u), 1e-30):
                raise ParameterError("veg_fisheye direction/up", (d.tolist(), u.tolist()),
                                     "a non-zero optical axis and an up vector not parallel "
                                     "to it", "e.g. direction [0, 1, 0], up [0, 0, -1]")
            m = np.array(mi.ScalarTransform4f().look_at(origin=o.tolist(),
                                                        target=(o + d).tolist(),
                                                        up=u.tolist()).matrix, float)
        self.matrix = m                      # 4 x 4 sensor-to-world (rigid)
        self.m_origin = mi.Point3f(*[float(x) for x in m[:3, 3]])
        self.m_axes = [mi.Vector3f(*[float(x) for x in m[:3, k]]) for k in range(3)]
        dr.make_opaque(self.m_origin, *self.m_axes)
        film = self.film()
        self.m_full = np.array(film.size(), int)
        self.m_crop_size = np.array(film.crop_size(), int)
        self.m_crop_offset = np.array(film.crop_offset(), int)
        self.m_radius_px = 0.5 * float(min(self.m_full))

    # ------------------------------------------------------------------ mapping
    def direction_at(self, pos, active=True):
        """World direction seen at a position of the film, and whether it lies on the disc.

        Parameters
        ----------
        pos : mi.Point2f
            Position on the film [px] (0..width, 0..height; pixel centres at +0.5).
        active : mi.Bool or bool
            Lanes to compute.

        Returns
        -------
        d : mi.Vector3f
            Unit direction [-] in the scene frame.
        valid : mi.Bool
            True inside the image disc (r <= 1).
        """
        cx, cy = 0.5 * float(self.m_full[0]), 0.5 * float(self.m_full[1])
        x = (pos.x - cx) / self.m_radius_px          # image right
        y = (cy - pos.y) / self.m_radius_px          # image top
        r = dr.sqrt(x * x + y * y)
        theta = zenith_of_radius(r, self.projection, self.theta_max)
        st, ct = dr.sincos(theta)
        inv = dr.select(r > 0.0, 1.0 / dr.maximum(r, 1e-30), 0.0)
        local = mi.Vector3f(-st * x * inv, st * y * inv, ct)   # right = local -x (Mitsuba)
        a0, a1, a2 = self.m_axes
        d = dr.normalize(a0 * local.x + a1 * local.y + a2 * local.z)
        return d, active & (r <= 1.0)

    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        """A ray through a position of the film.

        Parameters
        ----------
        time : mi.Float
            Time of the ray [s].
        sample1 : mi.Float
            Uniform sample in [0, 1) for the wavelengths (the film's response).
        sample2 : mi.Point2f
            Position in the film's crop window [0, 1)^2.
        sample3 : mi.Point2f
            Aperture sample (unused: a pinhole lens).
        active : mi.Bool or bool
            Active lanes.

        Returns
        -------
        ray : mi.Ray3f
            From the lens centre [m] along the direction of that pixel; wavelengths [nm].
        weight : mi.Spectrum
            The wavelength sampling weight inside the image disc, 0 outside it.
        """
        pos = mi.Point2f(sample2.x * float(self.m_crop_size[0]) + float(self.m_crop_offset[0]),
                         sample2.y * float(self.m_crop_size[1]) + float(self.m_crop_offset[1]))
        d, valid = self.direction_at(pos, active)
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.time = time
        # wavelengths for every lane: a lane outside the disc still carries its ray through
        # the integrator, and NaN wavelengths there (times a zero weight) would be NaN in the
        # film, spread into the disc's edge by the reconstruction filter
        wav, w = self.sample_wavelengths(si, sample1, active)
        ray = mi.Ray3f(self.m_origin, dr.select(valid, d, self.m_axes[2]), time, wav)
        return ray, dr.select(valid, w, 0.0)

    def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
        """:meth:`sample_ray` as a ray differential (without differentials).

        Parameters
        ----------
        time : mi.Float
            Time [s].
        sample1 : mi.Float
            Wavelength sample.
        sample2 : mi.Point2f
            Film position [0, 1)^2.
        sample3 : mi.Point2f
            Aperture sample (unused).
        active : mi.Bool or bool
            Active lanes.

        Returns
        -------
        ray : mi.RayDifferential3f
            The ray (``has_differentials`` False).
        weight : mi.Spectrum
            As :meth:`sample_ray`.
        """
        ray, w = self.sample_ray(time, sample1, sample2, sample3, active)
        return mi.RayDifferential3f(ray), w

    def bbox(self):
        """The lens centre as a box.

        Returns
        -------
        mi.ScalarBoundingBox3f
            A box holding the lens centre [m].
        """
        return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(*[float(v) for v in self.matrix[:3, 3]]))

    def traverse(self, callback):
        """No differentiable parameters (the lens is set at construction).

        Parameters
        ----------
        callback : mi.TraversalCallback
            Mitsuba's traversal callback (unused).
        """
        pass

    def parameters_changed(self, keys=None):
        """Nothing to update.

        Parameters
        ----------
        keys : list of str, optional
            Changed parameters (unused).
        """
        pass

    def to_string(self):
        """A one-line description.

        Returns
        -------
        str
            Projection, field of view, lens centre, axis and film size.
        """
        return (f"VegFisheye[projection={self.projection}, fov={self.fov:g}, origin="
                f"{self.matrix[:3, 3].round(4).tolist()}, axis="
                f"{self.matrix[:3, 2].round(4).tolist()}, film={self.m_full.tolist()}]")


mi.register_sensor("veg_fisheye", lambda props: VegFisheye(props))
