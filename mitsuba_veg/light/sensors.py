"""Virtual light sensors recorded by the photon pass: cosine, hemispherical and spherical.

A sensor is a small mesh added to the light scene in *sensor mode*
(:data:`integrators.photon_irradiance.SENSOR`): it records the photons that cross its front
faces and lets them pass unchanged (no shadow, no absorption, no bounce counted), so any number
of sensors costs no extra ray tracing and does not change the light of the scene.

Kinds (``size`` = side of the square or diameter of the sphere [m]; ``normal`` = the axis):

``cosine``
    A flat two-triangle square facing ``normal`` (a planar, cosine-corrected sensor such as a
    PAR quantum sensor). Reading = power through its front / its area = the planar irradiance
    from the half-space the normal points into (``normal`` up: downwelling, "sky view";
    ``normal`` down: upwelling, "ground view"). Response to a beam at angle θ from the normal:
    cos θ (0 behind it).
``spherical``
    A closed UV sphere (fluence-rate / scalar irradiance sensor, light "as a plant sees it").
    For any convex body the projected area averaged over all directions is S/4 (Cauchy), so
    reading = intercepted power / (S/4) = the scalar irradiance E0 = ∫ L dω over all 4π
    directions. Response: 1 for every direction (to the sphere's faceting: see
    :func:`projected_area`).
``hemispherical``
    The half of that sphere on the ``normal`` side (a dome, open at the base). Reading =
    intercepted power / (π r²) (its projected area along the axis), so a beam along the axis
    reads its normal irradiance. Response to a beam at angle θ from the axis:
    (1 + cos θ) / 2 (1 along the axis, 1/2 from the side, 0 from behind), i.e. the reading is
    (E0 + E_net) / 2 with E_net = E_down - E_up the net planar irradiance along the axis. The
    two halves of a spherical sensor add up to it (the "sky-view" and "ground-view" domes).

Sensor size trade-off: a sensor of area A in a scene whose photons are spread over an area
A_aim (the footprint of the scene's geometry seen from the light) receives about N A / A_aim of
N photons, so its relative noise is ~ sqrt(A_aim / (N A)); a larger sensor averages light over
its size (a 0.1 m sensor resolves shade patterns coarser than ~0.1 m). The default 0.1 m is a
hand-held sensor's scale; use larger sensors (or more photons) for smooth maps of big scenes.

Readings per sensor (:class:`SensorReadings`), each split into ``direct`` (unscattered light of
directional, delta-direction emitters: the sun's beam), ``diffuse`` (everything else: the sky
and all scattered light) and ``total``:

- ``par``: PAR photon flux density (400-700 nm) [µmol m-2 s-1];
- ``red``, ``far_red``: photon flux densities 655-665 nm and 725-735 nm [µmol m-2 s-1];
- ``rfr``: red:far-red photon ratio [-];
- ``shortwave``: 300-3000 nm irradiance [W m-2].

Photon units from band energies at the band's centre wavelength
(:func:`mitsuba_veg.units.umol_per_joule`): exact to < 0.1 % for the 10 nm bands,
within ~1 % for PAR of daylight (docs/sensors.md).

Example::

    import mitsuba_veg as mv
    s = mv.light.sensors
    sensors = s.point("open", (2, 0.5, 0)) + s.point("fluence", (2, 0.5, 0), kind="spherical") \\
        + s.ground_grid(scene, "bed", spacing=0.25, height=0.5)
    r = s.read(scene, sensors, photons=2_000_000)
    r.value("open", "par")        # PPFD [µmol m-2 s-1]
    r.table()                     # tidy pandas DataFrame: sensor, band, component, value, unit
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

import mitsuba as mi

from mitsuba_veg.atomic import atomic_write
from mitsuba_veg.errors import ParameterError, SceneError, check_range
from mitsuba_veg.integrators.scene_index import emitter_name
from mitsuba_veg.meshes import make_mesh, triangle_geometry
from mitsuba_veg.units import umol_per_joule

from .photon import BANDS, photon_irradiance

__all__ = ["KINDS", "QUANTITIES", "UNITS", "COMPONENTS", "PASS_BANDS", "SensorSet",
           "SensorReadings", "point", "grid", "ground_grid", "read", "scene_with_sensors",
           "readings_from_result", "projected_area", "from_scenario", "SENSOR_SHAPE"]

#: sensor kinds (index = integer code in :attr:`SensorSet.kind`)
KINDS = ("cosine", "hemispherical", "spherical")
#: bands traced by the sensor pass (names of :data:`integrators.photon_irradiance.BANDS`)
PASS_BANDS = ("par", "red", "far_red", "shortwave")
#: quantities of a reading, in order
QUANTITIES = ("par", "red", "far_red", "rfr", "shortwave")
#: the unit of each quantity
UNITS = {"par": "umol m-2 s-1", "red": "umol m-2 s-1", "far_red": "umol m-2 s-1", "rfr": "-",
         "shortwave": "W m-2"}
#: components of a reading
COMPONENTS = ("direct", "diffuse", "total")
#: id of the mesh that holds every sensor of a light scene
SENSOR_SHAPE = "veg_sensors"
#: default sensor size [m]
DEFAULT_SIZE = 0.1
#: most sensors in one set (a grid finer than this is refused with the fix)
MAX_SENSORS = 200_000
#: latitude bands (even: the equator is an edge ring) and segments of the sphere template
SPHERE_BANDS, SPHERE_SEGMENTS = 10, 20


# --------------------------------------------------------------------------------------------
# Templates (unit size, axis +y) and frames
# --------------------------------------------------------------------------------------------
def _orient_outwards(v, f, centre):
    """Faces wound so that the geometric normal cross(v1-v0, v2-v0) points away from centre
    (for a flat template: along +y)."""
    _, n, centroids = triangle_geometry(v, f)
    flip = np.einsum("ij,ij->i", n, centroids - centre) < 0
    f = f.copy()
    f[flip] = f[flip][:, ::-1]
    return f


def _square_template():
    v = np.array([[-0.5, 0.0, -0.5], [0.5, 0.0, -0.5], [0.5, 0.0, 0.5], [-0.5, 0.0, 0.5]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    return v, _orient_outwards(v, f, np.array([0.0, -1.0, 0.0]))


def _sphere_template(bands: int = SPHERE_BANDS, segments: int = SPHERE_SEGMENTS):
    """UV sphere of diameter 1 around the origin, axis +y: (vertices, faces, upper) with
    ``upper`` True for the faces of the +y half (the equator is a ring of edges)."""
    th = np.linspace(0.0, math.pi, bands + 1)[1:-1]           # polar angles of the rings
    ph = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    ring = np.stack([np.sin(th)[:, None] * np.cos(ph)[None], np.cos(th)[:, None] + 0 * ph,
                     np.sin(th)[:, None] * np.sin(ph)[None]], -1).reshape(-1, 3)
    v = 0.5 * np.concatenate([[[0.0, 1.0, 0.0]], ring, [[0.0, -1.0, 0.0]]])
    top, bottom = 0, len(v) - 1
    r = lambda i, j: 1 + i * segments + (j % segments)  # noqa: E731
    j = np.arange(segments)
    faces = [np.stack([np.full(segments, top), r(0, j), r(0, j + 1)], 1)]
    for i in range(bands - 2):
        faces.append(np.stack([r(i, j), r(i + 1, j), r(i + 1, j + 1)], 1))
        faces.append(np.stack([r(i, j), r(i + 1, j + 1), r(i, j + 1)], 1))
    faces.append(np.stack([r(bands - 2, j), np.full(segments, bottom), r(bands - 2, j + 1)], 1))
    f = _orient_outwards(v, np.concatenate(faces), np.zeros(3))
    upper = v[f].mean(axis=1)[:, 1] > 0
    return v, f, upper


def projected_area(kind: str, direction, size: float = 1.0,
                   normal=(0.0, 1.0, 0.0)) -> tuple[float, float]:
    """Area a sensor presents to a beam, and the area its reading divides by.

    The projected area of the sensor's recording faces seen by light travelling against
    ``direction``, and the normalising area of its reading. Their ratio is the sensor's angular
    response (ideal: cos θ, (1 + cos θ)/2, 1 for cosine, hemispherical, spherical; the sphere's
    faceting makes the real one differ slightly).

    Parameters
    ----------
    kind : str
        ``"cosine"``, ``"hemispherical"`` or ``"spherical"``.
    direction : sequence of 3 float
        From the sensor towards the light [-] (normalised here).
    size : float
        Side of the square / diameter of the sphere [m].
    normal : sequence of 3 float
        The sensor's axis [-] (normalised here).

    Returns
    -------
    projected, normalising : float
        Projected area of the recording faces [m2] and the area the reading divides by [m2].
    """
    k = _kind_code(kind)
    v, f, nrm_area = _template(k)
    s = np.asarray(direction, float)
    s = s / np.linalg.norm(s)
    n = np.asarray(normal, float)
    frame = _frames(n[None] / np.linalg.norm(n))[0]          # rows t, n, b
    vw = v @ frame * size
    area, nrm, _ = triangle_geometry(vw, f)
    proj = float(np.sum(area * np.maximum(nrm @ s, 0.0)))
    return proj, nrm_area * size * size


_TEMPLATES: dict = {}


def _template(k: int):
    """(vertices, faces, normalising area at size 1) of kind code k."""
    if k not in _TEMPLATES:
        if k == 0:
            v, f = _square_template()
            a = triangle_geometry(v, f)[0]
            _TEMPLATES[k] = (v, f, float(a.sum()))
        else:
            v, f, upper = _sphere_template()
            a, n, _ = triangle_geometry(v, f)
            if k == 1:   # dome: the upper half; normalised by its projected area along +y
                f = f[upper]
                _TEMPLATES[k] = (v, f, float(np.sum(a[upper] * np.maximum(n[upper, 1], 0))))
            else:        # sphere: S / 4 (Cauchy: mean projected area of a convex body)
                _TEMPLATES[k] = (v, f, float(a.sum()) / 4.0)
    return _TEMPLATES[k]


def _frames(normals):
    """Orthonormal frames (n, 3, 3) with rows (t, n, b), t x n = b (local x, y, z -> world)."""
    n = np.asarray(normals, float)
    a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    t = np.cross(a, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(t, n)
    return np.stack([t, n, b], axis=1)


def _kind_code(kind) -> int:
    if isinstance(kind, (int, np.integer)) and 0 <= int(kind) < len(KINDS):
        return int(kind)
    if kind not in KINDS:
        raise ParameterError("kind", kind, ", ".join(KINDS),
                             "cosine: planar sensor; spherical: fluence rate; hemispherical: dome")
    return KINDS.index(kind)


# --------------------------------------------------------------------------------------------
# Sets of sensors
# --------------------------------------------------------------------------------------------
@dataclass
class SensorSet:
    """Sensors: one row each. Concatenate sets with ``+``.

    Attributes
    ----------
    names : np.ndarray of str
        Unique sensor names (grid sensors: ``GRID_iii_jjj``).
    kind : np.ndarray of int
        Index into :data:`KINDS`.
    position : np.ndarray, shape (n, 3)
        Centre [m].
    normal : np.ndarray, shape (n, 3)
        Unit axis (front side of a cosine sensor, dome axis; spheres use it for their mesh only).
    size : np.ndarray
        Side of the square / diameter of the sphere [m].
    group : np.ndarray of str
        Name of the grid (or of the point sensor) a sensor belongs to.
    ij : np.ndarray, shape (n, 2)
        Grid indices (-1 for point sensors).
    """

    names: np.ndarray
    kind: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    size: np.ndarray
    group: np.ndarray
    ij: np.ndarray

    def __len__(self) -> int:
        return len(self.names)

    def __add__(self, other: "SensorSet") -> "SensorSet":
        if not isinstance(other, SensorSet):
            return NotImplemented
        out = SensorSet(*[np.concatenate([getattr(self, k), getattr(other, k)])
                          for k in ("names", "kind", "position", "normal", "size", "group", "ij")])
        out.check()
        return out

    def check(self) -> "SensorSet":
        """Refuse duplicate names, more than :data:`MAX_SENSORS` sensors and overlapping sensors.

        Two sensors overlap when their surfaces coincide (:meth:`overlap`): a photon crossing
        there is recorded by one of them only (the pass goes on from the first hit), so both
        would read too little, silently.

        Returns
        -------
        SensorSet
            This set, unchanged.

        Raises
        ------
        ParameterError
            For a duplicate name, too many sensors or two overlapping sensors.
        """
        u, c = np.unique(self.names, return_counts=True)
        if (c > 1).any():
            raise ParameterError("sensor name", str(u[c > 1][0]), "names unique among the "
                                 "sensors", "rename one of the sensors (grids add _iii_jjj)")
        if len(self) > MAX_SENSORS:
            raise ParameterError("sensors", len(self), f"at most {MAX_SENSORS:,d} sensors",
                                 "use a larger grid spacing or fewer grids")
        pair = self.overlap()
        if pair is not None:
            i, j = pair
            where = ", ".join(f"{x:g}" for x in self.position[i])
            raise ParameterError("sensors", f"{self.names[i]} and {self.names[j]}",
                                 "sensors whose surfaces do not coincide (these two share "
                                 f"their surface at [{where}] m: a photon crossing it is "
                                 "recorded by one of them only, so both would read too "
                                 "little)", "move one of them or give it another size (a "
                                 "hemispherical sensor is half of a spherical one of the same "
                                 "place and size; domes facing opposite ways may share a "
                                 "place); a grid needs a spacing >= its sensors' size")
        return self

    def overlap(self) -> tuple[int, int] | None:
        """The first two sensors whose surfaces coincide, or None.

        Coinciding surfaces: two curved sensors (spherical or hemispherical) with the same
        centre and size, except two domes facing opposite ways (the two halves of a sphere),
        or two cosine squares in one plane whose areas overlap. Surfaces that only cross
        (a square through a sphere, spheres of different sizes) are recorded independently.

        Returns
        -------
        tuple of int or None
            Their rows (i < j), or None.
        """
        n = len(self)
        if n < 2:
            return None
        from scipy.spatial import cKDTree

        pos = np.asarray(self.position, float)
        size = np.asarray(self.size, float)
        tol = 1e-4 * (1.0 + np.abs(pos).max()) + 1e-3 * size.min()
        r = float(size.max()) * math.sqrt(2.0) + tol
        pairs = cKDTree(pos).query_pairs(r, output_type="ndarray")
        if not len(pairs):
            return None
        i, j = pairs[:, 0], pairs[:, 1]
        ki, kj = self.kind[i], self.kind[j]
        d = pos[j] - pos[i]
        ni, nj = self.normal[i], self.normal[j]
        dot = np.einsum("ij,ij->i", ni, nj)
        curved = (ki > 0) & (kj > 0) & (np.linalg.norm(d, axis=1) <= tol) & \
            (np.abs(size[i] - size[j]) <= tol) & ~((ki == 1) & (kj == 1) & (dot < -1 + 1e-6))
        fr = _frames(ni)
        half = (size[i] + size[j]) / 2 - tol
        flat = (ki == 0) & (kj == 0) & (np.abs(dot) > 1 - 1e-6) & \
            (np.abs(np.einsum("ij,ij->i", ni, d)) <= tol) & \
            (np.abs(np.einsum("ij,ij->i", fr[:, 0], d)) < half) & \
            (np.abs(np.einsum("ij,ij->i", fr[:, 2], d)) < half)
        hit = np.flatnonzero(curved | flat)
        if not len(hit):
            return None
        k = hit[np.lexsort((j[hit], i[hit]))[0]]
        return int(min(i[k], j[k])), int(max(i[k], j[k]))

    def index(self, name) -> int:
        """Row of a sensor.

        Parameters
        ----------
        name : str or int
            A sensor name, or a row (checked against the number of sensors).

        Returns
        -------
        int
            The sensor's row.
        """
        if isinstance(name, (int, np.integer)):
            if not 0 <= int(name) < len(self):
                raise ParameterError("sensor", name, f"0..{len(self) - 1}")
            return int(name)
        hit = np.flatnonzero(self.names == name)
        if not len(hit):
            raise ParameterError("sensor", name, f"one of the sensors ({', '.join(self.names[:8])}"
                                 f"{', ...' if len(self) > 8 else ''})")
        return int(hit[0])

    @property
    def groups(self) -> list[str]:
        """Group names in first-appearance order."""
        _, first = np.unique(self.group, return_index=True)
        return [str(self.group[i]) for i in sorted(first)]

    def normalising_area(self) -> np.ndarray:
        """Area each reading divides the recorded power by (module docstring).

        Returns
        -------
        numpy.ndarray
            (n,) areas [m2]: the square's area, π r² for a dome, S/4 for a sphere.
        """
        a = np.array([_template(k)[2] for k in range(len(KINDS))])
        return a[self.kind] * self.size ** 2

    def mesh(self):
        """All sensors as one mesh.

        Returns
        -------
        vertices : numpy.ndarray
            (V, 3) positions [m].
        faces : numpy.ndarray
            (F, 3) vertex indices.
        owner : numpy.ndarray
            (F,) the sensor (row) of each face.
        """
        vs, fs, owner, nv = [], [], [], 0
        for k in range(len(KINDS)):
            idx = np.flatnonzero(self.kind == k)
            if not len(idx):
                continue
            tv, tf, _ = _template(k)
            fr = _frames(self.normal[idx])                                  # (m, 3, 3)
            v = np.einsum("vj,mjk->mvk", tv, fr) * self.size[idx, None, None] \
                + self.position[idx, None, :]
            f = tf[None] + (nv + np.arange(len(idx)) * len(tv))[:, None, None]
            vs.append(v.reshape(-1, 3))
            fs.append(f.reshape(-1, 3))
            owner.append(np.repeat(idx, len(tf)))
            nv += len(idx) * len(tv)
        if not vs:
            raise ParameterError("sensors", 0, "at least one sensor", "add a point or a grid")
        return np.concatenate(vs), np.concatenate(fs), np.concatenate(owner)


def _vec3(name, v, unit=True):
    a = np.asarray(v, float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ParameterError(name, v, "[x, y, z]: three finite numbers")
    if unit:
        n = np.linalg.norm(a)
        if n == 0:
            raise ParameterError(name, v, "a non-zero direction", "e.g. [0, 1, 0] (up)")
        a = a / n
    return a


def _one_set(names, kind, pos, normal, size, group, ij) -> SensorSet:
    n = len(pos)
    return SensorSet(np.asarray(names, dtype=object).astype(str), np.full(n, _kind_code(kind)),
                     np.asarray(pos, float).reshape(n, 3),
                     np.broadcast_to(np.asarray(normal, float), (n, 3)).copy(),
                     np.full(n, float(size)), np.full(n, str(group), dtype=object).astype(str),
                     np.asarray(ij, int).reshape(n, 2)).check()


def _size(size):
    check_range("size", size, 0.001, 10.0, fix="sensor side/diameter in metres, e.g. 0.1")
    return float(size)


def point(name: str, position, normal=(0.0, 1.0, 0.0), kind: str = "cosine",
          size: float = DEFAULT_SIZE) -> SensorSet:
    """One sensor.

    Parameters
    ----------
    name : str
        Its name in results and tables.
    position : sequence of 3 float
        Centre [m] (project frame: +y up, +x east, +z south).
    normal : sequence of 3 float
        Axis: the front side of a cosine sensor, the dome's axis [-] (normalised here).
    kind : str
        ``"cosine"``, ``"hemispherical"`` or ``"spherical"`` (module docstring).
    size : float
        Side of the square / diameter of the sphere [m], 0.001-10.

    Returns
    -------
    SensorSet
        The one sensor.
    """
    if not isinstance(name, str) or not name.strip():
        raise ParameterError("name", name, "a non-empty string")
    return _one_set([name], kind, _vec3("position", position, unit=False)[None],
                    _vec3("normal", normal), _size(size), name, [[-1, -1]])


def _axis_points(length, spacing):
    """Cell-centred positions along [0, length] every ``spacing`` (centred, >= 1) [m]."""
    n = max(1, int(math.floor(length / spacing + 1e-9)))
    return (length - (n - 1) * spacing) / 2.0 + spacing * np.arange(n)


def _check_count(field, n, spacing):
    if n > MAX_SENSORS:
        raise ParameterError(field, spacing, f"a spacing giving at most {MAX_SENSORS:,d} "
                             f"sensors (this one gives {n:,d})", "use a larger spacing")


def grid(name: str, origin, u, v, spacing: float, normal=None, kind: str = "cosine",
         size: float = DEFAULT_SIZE) -> SensorSet:
    """Sensors on a plane rectangle ``origin + a u + b v`` (a, b in [0, 1]), e.g. on a wall.

    Parameters
    ----------
    name : str
        Grid name; sensors are named ``NAME_iii_jjj`` (i along u, j along v).
    origin : sequence of 3 float
        A corner of the rectangle [m].
    u, v : sequence of 3 float
        Its edges [m] (need not be orthogonal, must not be parallel).
    spacing : float
        Distance between sensors along each edge [m]; sensors sit at cell centres, the grid
        centred in the rectangle.
    normal : sequence of 3 float, optional
        Sensor axis (default u x v normalised).
    kind : str
        As :func:`point`.
    size : float
        As :func:`point` [m].

    Returns
    -------
    SensorSet
        One sensor per grid cell.
    """
    o = _vec3("origin", origin, unit=False)
    uu, vv = _vec3("u", u, unit=False), _vec3("v", v, unit=False)
    nrm = np.cross(uu, vv)
    if np.linalg.norm(nrm) < 1e-9 * max(np.linalg.norm(uu) * np.linalg.norm(vv), 1e-30):
        raise ParameterError("u, v", (list(u), list(v)), "two non-parallel, non-zero edges",
                             "e.g. u = [4, 0, 0], v = [0, 2, 0] for a 4 m x 2 m wall")
    check_range("spacing", spacing, 1e-3, 1e4, fix="grid spacing in metres, e.g. 0.25")
    nrm = _vec3("normal", nrm if normal is None else normal)
    lu, lv = np.linalg.norm(uu), np.linalg.norm(vv)
    a, b = _axis_points(lu, spacing), _axis_points(lv, spacing)
    _check_count("spacing", len(a) * len(b), spacing)
    A, B = np.meshgrid(np.arange(len(a)), np.arange(len(b)), indexing="ij")
    A, B = A.ravel(), B.ravel()
    pos = o + a[A, None] * (uu / lu) + b[B, None] * (vv / lv)
    names = np.char.add(np.char.add(f"{name}_", np.char.zfill(A.astype(str), 3)),
                        np.char.add("_", np.char.zfill(B.astype(str), 3)))
    return _one_set(names, kind, pos, nrm, _size(size), name, np.stack([A, B], 1))


def ground_grid(scene, name: str, spacing: float, height: float = 0.5, x=None, z=None,
                ground: str = "ground", kind: str = "cosine", size: float = DEFAULT_SIZE,
                normal=(0.0, 1.0, 0.0)) -> SensorSet:
    """A regular grid of sensors ``height`` above the terrain (e.g. 0.25 m apart, 0.5 m up).

    The terrain height under each grid point is found by casting a ray straight down onto the
    shape ``ground`` alone (trees and walls above it are ignored); points with no ground below
    them are left out.

    Parameters
    ----------
    scene : mi.Scene
        The scene holding the ground mesh (any emitters are ignored).
    name : str
        Grid name; sensors are ``NAME_iii_jjj`` (i along x, j along z).
    spacing : float
        Grid spacing in x and z [m].
    height : float
        Height of the sensor centres above the ground [m], -100..1000.
    x, z : pair of float, optional
        Extent [m] (default: the ground's bounding box).
    ground : str
        Shape id of the terrain.
    kind : str
        As :func:`point`.
    size : float
        As :func:`point` [m].
    normal : sequence of 3 float
        As :func:`point`.

    Returns
    -------
    SensorSet
        One sensor per grid point with ground below it.
    """

    check_range("spacing", spacing, 1e-3, 1e4, fix="grid spacing in metres, e.g. 0.25")
    check_range("height", height, -100.0, 1000.0, fix="height above the ground in metres")
    shapes = {sh.id(): sh for sh in scene.shapes()}
    if ground not in shapes:
        raise ParameterError("ground", ground, f"a shape id of the scene ({', '.join(shapes)})",
                             "name the terrain mesh (scenario: terrain.ground)")
    g = shapes[ground]
    bb = g.bbox()
    lo, hi = np.array(bb.min, float), np.array(bb.max, float)
    ext = {}
    for key, val, ax in (("x", x, 0), ("z", z, 2)):
        if val is None:
            ext[key] = (lo[ax], hi[ax])
            continue
        a = np.asarray(val, float).reshape(-1)
        if a.shape != (2,) or not np.all(np.isfinite(a)) or a[1] <= a[0]:
            raise ParameterError(key, val, "[min, max] in metres with min < max")
        ext[key] = (float(a[0]), float(a[1]))
    xs = ext["x"][0] + _axis_points(ext["x"][1] - ext["x"][0], spacing)
    zs = ext["z"][0] + _axis_points(ext["z"][1] - ext["z"][0], spacing)
    _check_count("spacing", len(xs) * len(zs), spacing)
    I, J = np.meshgrid(np.arange(len(xs)), np.arange(len(zs)), indexing="ij")
    I, J = I.ravel(), J.ravel()
    only = mi.load_dict({"type": "scene", ground: g}, optimize=False)
    top = float(hi[1]) + 1.0
    n = len(I)
    origin = mi.Point3f(mi.Float(xs[I].astype(np.float32)), mi.Float(np.full(n, top, np.float32)),
                        mi.Float(zs[J].astype(np.float32)))
    ray = mi.Ray3f(origin, mi.Vector3f(0.0, -1.0, 0.0))
    si = only.ray_intersect_preliminary(ray)
    t = np.asarray(si.t, float)
    ok = np.isfinite(t)
    if not ok.any():
        raise ParameterError("x, z", (ext["x"], ext["z"]), "an extent over the ground "
                             f"'{ground}'", "leave x/z out to cover the whole ground")
    pos = np.stack([xs[I], top - t + float(height), zs[J]], 1)[ok]
    I, J = I[ok], J[ok]
    names = np.char.add(np.char.add(f"{name}_", np.char.zfill(I.astype(str), 3)),
                        np.char.add("_", np.char.zfill(J.astype(str), 3)))
    return _one_set(names, kind, pos, _vec3("normal", normal), _size(size), name,
                    np.stack([I, J], 1))


# --------------------------------------------------------------------------------------------
# Scenario entries ([[sensors]])
# --------------------------------------------------------------------------------------------
#: fields each layout uses (besides name, kind, layout, size, normal)
_LAYOUT_FIELDS = {"point": {"position"}, "ground_grid": {"spacing", "height", "x", "z", "ground"},
                  "plane_grid": {"origin", "u", "v", "spacing"}}
_REQUIRED = {"point": ("position",), "ground_grid": ("spacing",),
             "plane_grid": ("origin", "u", "v", "spacing")}


def from_scenario(scn, scene=None) -> SensorSet | None:
    """The sensors of a scenario's ``[[sensors]]`` entries.

    Checks the fields each layout needs and refuses ones it would ignore
    (``ParameterError`` naming ``sensors[k].FIELD``).

    Parameters
    ----------
    scn : Scenario
        The loaded scenario.
    scene : mitsuba.Scene, optional
        The loaded scene, needed for ``ground_grid`` entries.

    Returns
    -------
    SensorSet or None
        All entries' sensors; None when the scenario has none.
    """
    entries = scn.get("sensors")
    if not entries:
        return None
    if isinstance(entries, dict):
        entries = [entries]
    src = str(scn.path)
    out = None
    for k, e in enumerate(entries):
        layout = e.get("layout", "point")
        where = f"sensors[{k}]"
        if "name" not in e:
            raise ParameterError(f"{where}.name", None, "a name", "add name = \"...\"", src)
        for req in _REQUIRED[layout]:
            if req not in e:
                raise ParameterError(f"{where}.{req}", None, f"present for layout '{layout}'",
                                     f"add {req} (docs/sensors.md)", src)
        other = set(e) - {"name", "kind", "layout", "size", "normal"} - _LAYOUT_FIELDS[layout]
        if other:
            f = sorted(other)[0]
            raise ParameterError(f"{where}.{f}", e[f], f"fields of layout '{layout}': "
                                 + ", ".join(sorted(_LAYOUT_FIELDS[layout])),
                                 f"remove {f} or set layout to the one that uses it", src)
        kw = dict(kind=e.get("kind", "cosine"), size=e.get("size", DEFAULT_SIZE))
        try:
            if layout == "point":
                s = point(e["name"], e["position"], e.get("normal", (0.0, 1.0, 0.0)), **kw)
            elif layout == "plane_grid":
                s = grid(e["name"], e["origin"], e["u"], e["v"], e["spacing"],
                         normal=e.get("normal"), **kw)
            else:
                if scene is None:
                    raise SceneError("ground_grid sensors need the loaded scene")
                s = ground_grid(scene, e["name"], e["spacing"], e.get("height", 0.5),
                                x=e.get("x"), z=e.get("z"),
                                ground=e.get("ground", scn.get("terrain.ground", "ground")),
                                normal=e.get("normal", (0.0, 1.0, 0.0)), **kw)
        except ParameterError as err:
            raise ParameterError(f"{where}.{err.field}", err.value, err.allowed, err.fix,
                                 src) from None
        out = s if out is None else out + s
    return out


# --------------------------------------------------------------------------------------------
# Reading the sensors with the photon pass
# --------------------------------------------------------------------------------------------
def scene_with_sensors(scene, sensors: SensorSet, emitters: dict | None = None):
    """A new scene with the sensors as one mesh.

    The shapes of ``scene``, its emitters (or ``emitters`` instead) and the sensors as one mesh
    :data:`SENSOR_SHAPE` (trace it with ``modes={SENSOR_SHAPE: "sensor"}``).

    Parameters
    ----------
    scene : mitsuba.Scene
        Shapes and emitters (not changed).
    sensors : SensorSet
        The sensors (at least one).
    emitters : dict, optional
        Emitter dicts/objects by id replacing the scene's emitters.

    Returns
    -------
    scene : mitsuba.Scene
        The new scene.
    face_owner : numpy.ndarray
        (F,) the sensor (row) of each face of the sensor mesh.
    """


    if sensors is None or not len(sensors):
        raise ParameterError("sensors", 0, "at least one sensor")
    d = {"type": "scene"}
    for i, sh in enumerate(scene.shapes()):
        sid = sh.id() or f"shape{i}"
        if sid == SENSOR_SHAPE:
            continue
        d[sid] = sh
    if emitters is None:
        for i, em in enumerate(scene.emitters()):
            if mi.has_flag(em.flags(), mi.EmitterFlags.Surface):
                continue  # area lights come with their shapes
            d[emitter_name(em, i)] = em
    else:
        d.update(emitters)
    v, f, owner = sensors.mesh()
    d[SENSOR_SHAPE] = make_mesh(SENSOR_SHAPE, v, f, albedo=0.0)
    return mi.load_dict(d, optimize=False), owner


def _umol():
    return {b: umol_per_joule(*BANDS[b]) for b in ("par", "red", "far_red")}


def quantities_from_watts(w: np.ndarray) -> np.ndarray:
    """Readings from band irradiances.

    Photon units from band energies at the band's centre wavelength
    (:func:`mitsuba_veg.units.umol_per_joule`).

    Parameters
    ----------
    w : numpy.ndarray
        ``w[..., b]`` band irradiances [W m-2] in :data:`PASS_BANDS` order.

    Returns
    -------
    numpy.ndarray
        ``[..., q]`` in :data:`QUANTITIES` order: photon flux densities [µmol m-2 s-1], R:FR [-]
        (NaN without far-red), shortwave [W m-2].
    """
    u = _umol()
    par, red, fr = w[..., 0] * u["par"], w[..., 1] * u["red"], w[..., 2] * u["far_red"]
    with np.errstate(divide="ignore", invalid="ignore"):
        rfr = np.where(fr > 0, red / np.where(fr > 0, fr, 1.0), np.nan)
    return np.stack([par, red, fr, rfr, w[..., 3]], axis=-1)


def sensor_watts(result, sensors: SensorSet, owner, beam=None) -> np.ndarray:
    """Band irradiances of every sensor from a photon pass.

    Parameters
    ----------
    result : PhotonIrradianceResult
        A pass over a scene from :func:`scene_with_sensors`, with bands including
        :data:`PASS_BANDS`.
    sensors : SensorSet
        The sensors of that scene.
    owner : numpy.ndarray
        (F,) the sensor of each face of the sensor mesh (from :func:`scene_with_sensors`).
    beam : iterable of str, optional
        The result's emitters (ids) whose first-hit light is "direct" (default: none;
        :func:`beam_emitters` lists a scene's delta-direction emitters).

    Returns
    -------
    numpy.ndarray
        (n, 2, 4) band irradiances [W m-2]; axis 1 = (direct, diffuse), axis 2 =
        :data:`PASS_BANDS`.
    """
    sl = result.index.shape_slice(SENSOR_SHAPE)
    missing = [b for b in PASS_BANDS if b not in result.bands]
    if missing:
        raise ParameterError("bands", list(result.bands), f"the sensor bands {PASS_BANDS}",
                             f"trace {missing} too")
    bi = [result.bands.index(b) for b in PASS_BANDS]
    f = result.flux[:, sl, :, 0][..., bi]                 # (E, faces, comp, band), front side
    beam = set(beam or ())
    is_beam = np.array([e in beam for e in result.emitters])
    direct = f[is_beam, :, 0, :].sum(axis=0) if is_beam.any() else np.zeros(f.shape[1::2])
    total = f.sum(axis=(0, 2))
    n = len(sensors)
    out = np.zeros((n, 2, f.shape[-1]))
    np.add.at(out[:, 0], owner, direct)
    np.add.at(out[:, 1], owner, total - direct)
    return out / sensors.normalising_area()[:, None, None]


def beam_emitters(scene) -> list[str]:
    """The scene's delta-direction emitters (the sun's beam: "direct" light).

    Parameters
    ----------
    scene : mitsuba.Scene
        The scene.

    Returns
    -------
    list of str
        Their ids (``emitter<i>`` for an emitter without one).
    """
    return [emitter_name(em, i) for i, em in enumerate(scene.emitters())
            if mi.has_flag(em.flags(), mi.EmitterFlags.DeltaDirection)]


@dataclass
class SensorReadings:
    """Readings of a set of sensors.

    ``values[s, q, c]``: sensor ``s`` (:attr:`sensors` order), quantity ``q``
    (:data:`QUANTITIES`, units :data:`UNITS`), component ``c`` (:data:`COMPONENTS`).
    ``watts[s, c, b]``: band irradiances [W m-2] (c: direct, diffuse; b: :data:`PASS_BANDS`).
    """

    sensors: SensorSet
    values: np.ndarray
    watts: np.ndarray
    result: object = None
    settings: dict = field(default_factory=dict)

    @classmethod
    def from_watts(cls, sensors, watts, result=None, settings=None) -> "SensorReadings":
        """Readings from direct/diffuse band irradiances.

        Parameters
        ----------
        sensors : SensorSet
            The sensors.
        watts : numpy.ndarray
            (n, 2, bands) direct/diffuse band irradiances [W m-2] (:data:`PASS_BANDS`).
        result : PhotonIrradianceResult, optional
            The pass they come from.
        settings : dict, optional
            The pass's settings (photons, seed, ...).

        Returns
        -------
        SensorReadings
            With the total component added.
        """
        w3 = np.concatenate([watts, watts.sum(axis=1, keepdims=True)], axis=1)  # + total
        q = quantities_from_watts(w3)                                          # (n, 3, Q)
        return cls(sensors, np.moveaxis(q, 1, 2), watts, result, dict(settings or {}))

    def value(self, sensor, quantity: str = "par", component: str = "total"):
        """One reading.

        Parameters
        ----------
        sensor : str or int
            Sensor name or row.
        quantity : str
            One of :data:`QUANTITIES`.
        component : str
            One of :data:`COMPONENTS`.

        Returns
        -------
        float
            The reading, units :data:`UNITS` (e.g. PAR [µmol m-2 s-1]).
        """
        if quantity not in QUANTITIES:
            raise ParameterError("quantity", quantity, ", ".join(QUANTITIES))
        if component not in COMPONENTS:
            raise ParameterError("component", component, ", ".join(COMPONENTS))
        return float(self.values[self.sensors.index(sensor), QUANTITIES.index(quantity),
                                 COMPONENTS.index(component)])

    def array(self, quantity: str = "par", component: str = "total") -> np.ndarray:
        """One reading of every sensor.

        Parameters
        ----------
        quantity : str
            One of :data:`QUANTITIES`.
        component : str
            One of :data:`COMPONENTS`.

        Returns
        -------
        numpy.ndarray
            (n,) readings in :attr:`sensors` order, units :data:`UNITS`.
        """
        if quantity not in QUANTITIES or component not in COMPONENTS:
            raise ParameterError("quantity/component", (quantity, component),
                                 f"{QUANTITIES} / {COMPONENTS}")
        return self.values[:, QUANTITIES.index(quantity), COMPONENTS.index(component)]

    def table(self, time=None):
        """The readings as a tidy table.

        Parameters
        ----------
        time : str, optional
            Value of a ``time`` column (left out when None).

        Returns
        -------
        pandas.DataFrame
            Columns (time,) sensor, band, component, value, unit.
        """
        return tidy_table(self.values[None], self.sensors.names,
                          None if time is None else [time])


def tidy_table(values, names, times=None):
    """Tidy table of readings, one row per (time, sensor, quantity, component), vectorised.

    Parameters
    ----------
    values : array_like
        ``values[t, s, q, c]``: time, sensor, quantity (:data:`QUANTITIES`), component
        (:data:`COMPONENTS`), units :data:`UNITS`.
    names : sequence of str
        Sensor names.
    times : sequence, optional
        One time per t (the ``time`` column is left out when None).

    Returns
    -------
    pandas.DataFrame
        Columns (time,) sensor, band, component, value, unit.
    """
    import pandas as pd

    v = np.asarray(values)
    nt, ns, nq, nc = v.shape
    shape = (nt, ns, nq, nc)
    cols = {}
    if times is not None:
        cols["time"] = np.broadcast_to(np.asarray(times)[:, None, None, None], shape).ravel()
    cols["sensor"] = pd.Categorical.from_codes(
        np.broadcast_to(np.arange(ns)[None, :, None, None], shape).ravel(), list(names))
    cols["band"] = pd.Categorical.from_codes(
        np.broadcast_to(np.arange(nq)[None, None, :, None], shape).ravel(), list(QUANTITIES))
    cols["component"] = pd.Categorical.from_codes(
        np.broadcast_to(np.arange(nc)[None, None, None, :], shape).ravel(), list(COMPONENTS))
    cols["value"] = v.ravel()
    units = sorted(set(UNITS.values()))
    ucode = np.array([units.index(UNITS[q]) for q in QUANTITIES])
    cols["unit"] = pd.Categorical.from_codes(
        np.broadcast_to(ucode[None, None, :, None], shape).ravel(), units)
    return pd.DataFrame(cols)


def _csv_field(text: str) -> str:
    text = str(text)
    return '"' + text.replace('"', '""') + '"' if any(c in text for c in ',"\n') else text


def write_tidy_csv(path, values, names, times=None) -> str:
    """The tidy table of readings (see :func:`tidy_table`) as CSV, written atomically.

    Writes the repeated (sensor, band, component, unit) text once per row pattern: 1.73
    million rows in 0.9 s against 16.2 s for ``DataFrame.to_csv`` (measured on the 2-core
    machine). Values with 6 significant digits, NaN empty.

    Parameters
    ----------
    path : str or pathlib.Path
        The CSV file.
    values : array_like
        ``values[t, s, q, c]`` as :func:`tidy_table`.
    names : sequence of str
        Sensor names.
    times : sequence of str, optional
        One ISO 8601 string per t (column left out when None).

    Returns
    -------
    str
        The path written.
    """
    v = np.asarray(values, dtype=float)
    nt, ns, nq, nc = v.shape
    pre = [f"{_csv_field(n)},{q},{c}," for n in names for q in QUANTITIES for c in COMPONENTS]
    post = [f",{UNITS[q]}" for _ in names for q in QUANTITIES for _c in COMPONENTS]
    head = ("time," if times is not None else "") + "sensor,band,component,value,unit\n"
    with atomic_write(path, f"{path}.tmp") as tmp, open(tmp, "w") as fh:
        fh.write(head)
        for t in range(nt):
            vals = ["" if x != x else "%.6g" % x for x in v[t].ravel().tolist()]
            lead = f"{_csv_field(times[t])}," if times is not None else ""
            fh.write("".join(f"{lead}{a}{x}{b}\n" for a, x, b in zip(pre, vals, post)))
    return str(path)


def read(scene, sensors: SensorSet, photons: int = 1_000_000, seed: int = 0,
         max_depth: int = 8, indirect: bool = True, emitters=None,
         progress: bool = False) -> SensorReadings:
    """Read ``sensors`` in ``scene`` with one photon pass.

    Parameters
    ----------
    scene : mi.Scene
        Shapes and emitters (e.g. :func:`mitsuba_veg.light.daylight` sun and sky); it is not
        changed (a copy with the sensors is traced).
    sensors : SensorSet
        From :func:`point`, :func:`grid`, :func:`ground_grid` (``+`` to combine).
    photons : int
        Photons of the pass, as :func:`mitsuba_veg.light.photon_irradiance`.
    seed : int
        Random seed.
    max_depth : int
        Bounces per photon.
    indirect : bool
        Trace scattered light (False: direct light only).
    emitters : sequence of str, optional
        Emitter ids to trace (default all).
    progress : bool
        Show a progress bar.

    Returns
    -------
    SensorReadings
        ``direct`` = unscattered light of delta-direction emitters (the sun's beam),
        ``diffuse`` = the rest (sky, scattered light).
    """

    sc, owner = scene_with_sensors(scene, sensors)
    res = photon_irradiance(sc, photons=photons, seed=seed, max_depth=max_depth,
                            bands=PASS_BANDS, indirect=indirect, emitters=emitters,
                            progress=progress, modes={SENSOR_SHAPE: "sensor"})
    w = sensor_watts(res, sensors, owner, beam=beam_emitters(sc))
    return SensorReadings.from_watts(sensors, w, res, dict(photons=int(photons), seed=int(seed),
                                                           max_depth=int(max_depth),
                                                           indirect=bool(indirect)))


def readings_from_result(result, sensors: SensorSet, owner, beam=()) -> SensorReadings:
    """:class:`SensorReadings` of a pass over a scene from :func:`scene_with_sensors`.

    Parameters
    ----------
    result : PhotonIrradianceResult
        The pass.
    sensors : SensorSet
        The sensors of that scene.
    owner : numpy.ndarray
        (F,) the sensor of each face of the sensor mesh.
    beam : iterable of str
        Emitter ids whose first-hit light is "direct" (see :func:`sensor_watts`).

    Returns
    -------
    SensorReadings
        The readings (direct, diffuse, total).
    """
    return SensorReadings.from_watts(sensors, sensor_watts(result, sensors, owner, beam), result)
