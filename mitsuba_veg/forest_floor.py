"""The forest floor of a stand: a sloped, rolling ground and the logs and rocks lying on it.

- :func:`rolling_ground` makes a :class:`Heightfield`: a regular grid over a plot whose height
  is a plane of a given slope [deg] and aspect [deg, clockwise from north, the way the slope
  faces] plus a random relief of given RMS amplitude [m] and wavelength [m]. Its triangles are
  those of :func:`mitsuba_veg.light.validation.grid_mesh` (two per cell, normals up), and
  :meth:`Heightfield.height` interpolates them exactly: a tree set at ``height(x, z)`` stands on
  the mesh the photons hit.
- :func:`log_mesh` is a closed polygonal cylinder (a lying log), :func:`rock_mesh` an icosphere
  with a smooth random radius, flattened and sunk into the ground (a rock);
  :func:`place_log`, :func:`place_rock` set them on a heightfield and :func:`scatter_floor`
  scatters them over a plot away from the trees. Each is a :class:`FloorObject` with its own
  mesh, so that moss can live on it (:meth:`FloorObject.terrain`).

Frame: +y up, +x east, +z south (north is -z); metres.

Relief: ``h(x, z) = A sqrt(2/M) sum_m cos(k_m . (x, z) + phi_m)`` with M = 64 plane waves of
random direction, wavelengths ``scale x 2^U`` (U uniform in [-1, 1]) and phases: a smooth
random field of RMS A (each wave has mean square 1/2).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import atomic_write
from .errors import ParameterError, check_range
from .light.validation import grid_mesh
from .meshes import triangle_geometry
from .terrain import Terrain

#: plane waves of the relief
RELIEF_WAVES = 64


def _downhill(aspect_deg: float) -> np.ndarray:
    """Horizontal unit vector (x, z) a slope facing ``aspect_deg`` (clockwise from north) goes
    down to: north = -z, east = +x."""
    a = math.radians(aspect_deg)
    return np.array([math.sin(a), -math.cos(a)])


@dataclass
class Heightfield:
    """Heights on a regular grid; the surface is two triangles per cell (module docstring).

    Parameters
    ----------
    x0, z0 : float
        Corner of the grid with the smallest x and z [m].
    dx, dz : float
        Cell size along x and z [m].
    heights : numpy.ndarray
        (nz + 1, nx + 1) heights y [m] of the grid nodes; row j is z = z0 + j dz, column i is
        x = x0 + i dx.
    info : dict, optional
        How it was made (the arguments of :func:`rolling_ground`).
    """

    x0: float
    z0: float
    dx: float
    dz: float
    heights: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def nx(self) -> int:
        """Cells along x."""
        return self.heights.shape[1] - 1

    @property
    def nz(self) -> int:
        """Cells along z."""
        return self.heights.shape[0] - 1

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(x0, z0, x1, z1) of the grid [m]."""
        return (self.x0, self.z0, self.x0 + self.nx * self.dx, self.z0 + self.nz * self.dz)

    @classmethod
    def from_function(cls, bounds, resolution: float, height) -> "Heightfield":
        """A heightfield sampling ``height(X, Z)`` at the grid nodes.

        Parameters
        ----------
        bounds : sequence of float
            ``(x0, z0, x1, z1)`` [m], x1 > x0 and z1 > z0.
        resolution : float
            Largest cell size [m] (cells are the extent divided evenly), > 0.
        height : callable
            ``height(X, Z)`` [m] on arrays of node coordinates [m].

        Returns
        -------
        Heightfield
            The sampled grid.

        Raises
        ------
        ParameterError
            For empty bounds, a resolution <= 0 or more than 16 million cells.
        """
        x0, z0, x1, z1 = (float(b) for b in bounds)
        if not (x1 > x0 and z1 > z0):
            raise ParameterError("bounds", list(bounds), "(x0, z0, x1, z1) with x1 > x0, z1 > z0 "
                                 "[m]")
        check_range("resolution", resolution, 0.0, None, lo_open=True)
        nx = max(1, int(math.ceil((x1 - x0) / float(resolution) - 1e-9)))
        nz = max(1, int(math.ceil((z1 - z0) / float(resolution) - 1e-9)))
        if nx * nz > 16_000_000:
            least = math.sqrt((x1 - x0) * (z1 - z0) / 16e6)
            raise ParameterError("resolution", resolution, f">= {least:.3g} m (at most 16 "
                                 f"million cells)", "use a coarser resolution")
        xs = np.linspace(x0, x1, nx + 1)
        zs = np.linspace(z0, z1, nz + 1)
        X, Z = np.meshgrid(xs, zs)
        H = np.asarray(height(X, Z), float) * np.ones_like(X)
        return cls(x0, z0, (x1 - x0) / nx, (z1 - z0) / nz, H)

    # ---- the mesh ------------------------------------------------------------------------
    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertices and faces of the surface (two triangles per cell, normals up).

        Face ``j nx + i`` is the lower-left triangle of cell (i, j) (corners (i, j), (i, j+1),
        (i+1, j)), face ``nx nz + j nx + i`` its upper-right one.

        Returns
        -------
        vertices : numpy.ndarray
            ((nx + 1)(nz + 1), 3) positions [m].
        faces : numpy.ndarray
            (2 nx nz, 3) vertex indices.
        """
        x0, z0, x1, z1 = self.bounds
        return grid_mesh(self.nx, self.nz, (x0, x1), (z0, z1), 0.0, lambda X, Z: self.heights)

    def _locate(self, x, z):
        x = np.asarray(x, float)
        z = np.asarray(z, float)
        fx = (x - self.x0) / self.dx
        fz = (z - self.z0) / self.dz
        eps = 1e-9
        out = (fx < -eps) | (fx > self.nx + eps) | (fz < -eps) | (fz > self.nz + eps)
        if np.any(out):
            k = int(np.flatnonzero(np.ravel(out))[0])
            raise ParameterError("(x, z)", (float(np.ravel(x)[k]), float(np.ravel(z)[k])),
                                 f"a point on the heightfield, x in [{self.bounds[0]:g}, "
                                 f"{self.bounds[2]:g}], z in [{self.bounds[1]:g}, "
                                 f"{self.bounds[3]:g}] m", "make the ground cover the plot")
        i = np.clip(np.floor(fx).astype(np.int64), 0, self.nx - 1)
        j = np.clip(np.floor(fz).astype(np.int64), 0, self.nz - 1)
        return i, j, fx - i, fz - j

    def height(self, x, z) -> np.ndarray:
        """Height y [m] of the surface at (x, z): linear on the triangle holding the point.

        Parameters
        ----------
        x, z : float or array_like
            Horizontal coordinates [m] (same shape), on the grid.

        Returns
        -------
        numpy.ndarray
            Heights [m], the shape of ``x``.

        Raises
        ------
        ParameterError
            For a point off the grid.
        """
        i, j, u, v = self._locate(x, z)
        H = self.heights
        h00, h10, h01, h11 = H[j, i], H[j, i + 1], H[j + 1, i], H[j + 1, i + 1]
        lower = u + v <= 1.0
        return np.where(lower, h00 + u * (h10 - h00) + v * (h01 - h00),
                        h11 + (1 - u) * (h01 - h11) + (1 - v) * (h10 - h11))

    def face_index(self, x, z) -> np.ndarray:
        """Index of the triangle of :meth:`mesh` under each point.

        Parameters
        ----------
        x, z : float or array_like
            Horizontal coordinates [m], on the grid.

        Returns
        -------
        numpy.ndarray
            int64 face indices, the shape of ``x``.
        """
        i, j, u, v = self._locate(x, z)
        return np.where(u + v <= 1.0, 0, self.nx * self.nz) + j * self.nx + i

    def normal(self, x, z) -> np.ndarray:
        """Unit normal (up side) of the triangle under each point.

        Parameters
        ----------
        x, z : float or array_like
            Horizontal coordinates [m], on the grid.

        Returns
        -------
        numpy.ndarray
            (..., 3) unit normals [-].
        """
        V, F = self.mesh()
        _, n, _ = triangle_geometry(V, F)
        return n[self.face_index(x, z)]

    def terrain(self, name: str = "ground") -> Terrain:
        """The surface as a :class:`mitsuba_veg.terrain.Terrain` (per-triangle areas, normals).

        Parameters
        ----------
        name : str, optional
            Shape id; default ``"ground"``.

        Returns
        -------
        Terrain
            The terrain of :meth:`mesh`.
        """
        V, F = self.mesh()
        return Terrain.from_arrays(V, F, name=name)

    def write_ply(self, path) -> str:
        """Write the surface as a binary PLY (atomically).

        Parameters
        ----------
        path : str or pathlib.Path
            The file.

        Returns
        -------
        str
            The path written.
        """
        return write_ply(path, *self.mesh())


def write_ply(path, vertices, faces) -> str:
    """Write a triangle mesh as a binary PLY file (atomically, parent folders created).

    Parameters
    ----------
    path : str or pathlib.Path
        The file.
    vertices : array_like
        (n, 3) positions [m].
    faces : array_like
        (m, 3) vertex indices.

    Returns
    -------
    str
        The path written.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    import trimesh              # imported where used: the package imports faster

    m = trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces, np.int64), process=False)
    with atomic_write(p) as tmp:
        m.export(str(tmp), file_type="ply")
    return str(p)


def relief(X, Z, amplitude: float, scale: float, seed: int = 0,
           waves: int = RELIEF_WAVES) -> np.ndarray:
    """A smooth random relief of RMS ``amplitude``: a sum of random plane waves.

    Parameters
    ----------
    X, Z : array_like
        Horizontal coordinates [m] (same shape).
    amplitude : float
        RMS height A [m], >= 0.
    scale : float
        Central wavelength [m], > 0 (wavelengths scale x 2^U, U uniform in [-1, 1]).
    seed : int, optional
        Seed of the waves; default 0.
    waves : int, optional
        Number of plane waves M; default :data:`RELIEF_WAVES`.

    Returns
    -------
    numpy.ndarray
        Heights [m], the shape of ``X``.
    """
    rng = np.random.default_rng(seed)
    lam = float(scale) * 2.0 ** rng.uniform(-1.0, 1.0, waves)
    th = rng.uniform(0.0, 2 * np.pi, waves)
    phi = rng.uniform(0.0, 2 * np.pi, waves)
    k = 2 * np.pi / lam
    X = np.asarray(X, float)
    Z = np.asarray(Z, float)
    arg = (X[..., None] * (k * np.cos(th)) + Z[..., None] * (k * np.sin(th))) + phi
    return float(amplitude) * math.sqrt(2.0 / waves) * np.cos(arg).sum(-1)


def rolling_ground(bounds=(0.0, 0.0, 100.0, 100.0), slope_deg: float = 0.0,
                   aspect_deg: float = 180.0, roughness: float = 0.0,
                   roughness_scale: float = 20.0, seed: int = 0, resolution: float = 1.0,
                   y0: float = 0.0) -> Heightfield:
    """A sloped, rolling ground: a tilted plane plus a random relief (module docstring).

    ``y = y0 - tan(slope) ((x - xc) d_x + (z - zc) d_z) + relief(x, z)`` with (xc, zc) the centre
    of the bounds and (d_x, d_z) = (sin aspect, -cos aspect) the downhill direction.

    Parameters
    ----------
    bounds : sequence of float, optional
        ``(x0, z0, x1, z1)`` [m]; default a 100 m square (1 ha).
    slope_deg : float, optional
        Slope angle [deg] in [0, 60]; default 0.
    aspect_deg : float, optional
        Direction the slope faces (goes down to) [deg], clockwise from north (180: south-facing,
        the default).
    roughness : float, optional
        RMS amplitude of the relief [m], >= 0; default 0 (a plane).
    roughness_scale : float, optional
        Central wavelength of the relief [m], > 0; default 20.
    seed : int, optional
        Seed of the relief; default 0.
    resolution : float, optional
        Largest cell size [m]; default 1.
    y0 : float, optional
        Height of the plane at the centre [m]; default 0.

    Returns
    -------
    Heightfield
        The ground (``info`` holds the arguments).

    Raises
    ------
    ParameterError
        For a value outside its range.
    """
    check_range("slope_deg", slope_deg, 0.0, 60.0)
    check_range("aspect_deg", aspect_deg, -360.0, 360.0)
    check_range("roughness", roughness, 0.0, 1e3)
    check_range("roughness_scale", roughness_scale, 0.0, 1e5, lo_open=True)
    x0, z0, x1, z1 = (float(b) for b in bounds)
    xc, zc = 0.5 * (x0 + x1), 0.5 * (z0 + z1)
    d = _downhill(aspect_deg)
    t = math.tan(math.radians(slope_deg))

    def height(X, Z):
        h = y0 - t * ((X - xc) * d[0] + (Z - zc) * d[1])
        if roughness > 0:
            h = h + relief(X, Z, roughness, roughness_scale, seed)
        return h

    hf = Heightfield.from_function(bounds, resolution, height)
    hf.info = {"slope_deg": float(slope_deg), "aspect_deg": float(aspect_deg),
               "roughness": float(roughness), "roughness_scale": float(roughness_scale),
               "seed": int(seed), "resolution": float(resolution), "y0": float(y0)}
    return hf


# --------------------------------------------------------------------------------------------
# Logs and rocks
# --------------------------------------------------------------------------------------------

@dataclass
class FloorObject:
    """A log or rock on the floor: its own closed mesh (moss can live on it).

    Parameters
    ----------
    name : str
        Shape id.
    kind : str
        ``"log"`` or ``"rock"``.
    vertices : numpy.ndarray
        (n, 3) positions [m].
    faces : numpy.ndarray
        (m, 3) vertex indices (outward normals).
    centre : numpy.ndarray
        (3,) reference point [m] (log: axis midpoint; rock: centre).
    radius : float
        Footprint radius [m] (log: half its length; rock: its radius).
    """

    name: str
    kind: str
    vertices: np.ndarray
    faces: np.ndarray
    centre: np.ndarray
    radius: float

    def terrain(self) -> Terrain:
        """The object's surface as a :class:`mitsuba_veg.terrain.Terrain` (moss lives on it).

        Returns
        -------
        Terrain
            Per-triangle areas, normals, centroids; named :attr:`name`.
        """
        return Terrain.from_arrays(self.vertices, self.faces, name=self.name)


def log_mesh(start, end, radius: float, sides: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A closed polygonal cylinder from ``start`` to ``end`` (a log), normals outward.

    Surface area ``L n 2 r sin(pi/n) + 2 (n/2) r^2 sin(2 pi/n)`` (mantle plus two n-gon caps),
    volume ``(n/2) r^2 sin(2 pi/n) L``.

    Parameters
    ----------
    start, end : array_like
        (3,) ends of the axis [m].
    radius : float
        Radius of the corners [m], > 0.
    sides : int, optional
        Corners n of the cross-section (>= 3); default 12.

    Returns
    -------
    vertices : numpy.ndarray
        (2 n + 2, 3) positions [m] (two rings, then the two cap centres).
    faces : numpy.ndarray
        (4 n, 3) vertex indices.

    Raises
    ------
    ParameterError
        For a radius <= 0, fewer than 3 sides or ends that coincide.
    """
    check_range("radius", radius, 0.0, None, lo_open=True)
    n = int(sides)
    if n < 3:
        raise ParameterError("sides", sides, "an integer >= 3")
    a, b = np.asarray(start, float), np.asarray(end, float)
    axis = b - a
    L = float(np.linalg.norm(axis))
    if L <= 0:
        raise ParameterError("start, end", (a.tolist(), b.tolist()), "two different points")
    d = axis / L
    ref = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(d, ref)
    u /= np.linalg.norm(u)
    w = np.cross(d, u)
    ang = 2 * np.pi * np.arange(n) / n
    ring = radius * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w)
    V = np.concatenate([a + ring, b + ring, [a, b]])
    k = np.arange(n)
    k1 = (k + 1) % n
    ca, cb = 2 * n, 2 * n + 1
    # (u, w, d) is right-handed: ring order turns counter-clockwise seen from +d
    mantle = np.concatenate([np.stack([k, k1, n + k1], 1), np.stack([k, n + k1, n + k], 1)])
    cap_a = np.stack([np.full(n, ca), k1, k], 1)
    cap_b = np.stack([np.full(n, cb), n + k, n + k1], 1)
    return V, np.concatenate([mantle, cap_a, cap_b]).astype(np.int64)


def rock_mesh(centre, radius: float, roughness: float = 0.2, flatten: float = 0.6,
              subdivisions: int = 3, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A rock: an icosphere whose radius varies smoothly, flattened along y.

    Each vertex of a unit icosphere (direction q) moves to ``radius (1 + roughness n(q))``, with
    n a sum of 8 random plane waves over the direction (RMS 1), clipped so that the radius stays
    >= 0.2 x ``radius``; then y is multiplied by ``flatten``.

    Parameters
    ----------
    centre : array_like
        (3,) centre [m].
    radius : float
        Mean radius [m], > 0.
    roughness : float, optional
        Relative RMS deviation of the radius [-] in [0, 0.5]; default 0.2.
    flatten : float, optional
        Height over width [-] in (0, 1]; default 0.6.
    subdivisions : int, optional
        Icosphere subdivisions (20 x 4^s triangles); default 3.
    seed : int, optional
        Seed of the shape; default 0.

    Returns
    -------
    vertices : numpy.ndarray
        (n, 3) positions [m].
    faces : numpy.ndarray
        (m, 3) vertex indices (outward normals).
    """
    check_range("radius", radius, 0.0, None, lo_open=True)
    check_range("roughness", roughness, 0.0, 0.5)
    check_range("flatten", flatten, 0.0, 1.0, lo_open=True)
    import trimesh.creation

    sph = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=1.0)
    q = np.asarray(sph.vertices, float)
    rng = np.random.default_rng(seed)
    m = 8
    k = rng.normal(size=(m, 3))
    k *= (rng.uniform(1.5, 3.5, m) / np.linalg.norm(k, axis=1))[:, None]
    phi = rng.uniform(0, 2 * np.pi, m)
    noise = math.sqrt(2.0 / m) * np.cos(q @ k.T + phi).sum(1)
    r = radius * np.maximum(1.0 + roughness * noise, 0.2)
    V = q * r[:, None]
    V[:, 1] *= flatten
    return V + np.asarray(centre, float), np.asarray(sph.faces, np.int64)


def place_log(ground, x: float, z: float, length: float, radius: float,
              azimuth_deg: float = 0.0, sides: int = 12, name: str = "log") -> FloorObject:
    """A log lying on the ground, centred over (x, z): each end rests on the surface.

    The axis runs along ``azimuth_deg`` (clockwise from north) and each end's axis point is
    ``radius`` above the ground height there, so the log follows the slope.

    Parameters
    ----------
    ground : Heightfield or object with height(x, z)
        The ground.
    x, z : float
        Centre of the log's footprint [m].
    length : float
        Length [m], > 0.
    radius : float
        Radius [m], > 0.
    azimuth_deg : float, optional
        Direction of the axis [deg] clockwise from north; default 0.
    sides : int, optional
        Corners of the cross-section; default 12.
    name : str, optional
        Shape id; default ``"log"``.

    Returns
    -------
    FloorObject
        The log.
    """
    check_range("length", length, 0.0, None, lo_open=True)
    d = _downhill(azimuth_deg) * 0.5 * float(length)
    ends = np.array([[x - d[0], z - d[1]], [x + d[0], z + d[1]]])
    y = np.asarray(ground.height(ends[:, 0], ends[:, 1]), float) + float(radius)
    a = np.array([ends[0, 0], y[0], ends[0, 1]])
    b = np.array([ends[1, 0], y[1], ends[1, 1]])
    V, F = log_mesh(a, b, radius, sides)
    return FloorObject(name, "log", V, F, 0.5 * (a + b), 0.5 * float(length))


def place_rock(ground, x: float, z: float, radius: float, embed: float = 0.3,
               flatten: float = 0.6, roughness: float = 0.2, subdivisions: int = 3,
               seed: int = 0, name: str = "rock") -> FloorObject:
    """A rock set into the ground at (x, z): ``embed`` of its height is below the surface.

    Centre height: ``ground(x, z) + H (0.5 - embed)`` with H = 2 flatten radius (so, before its
    random relief, the rock's lowest point is ``embed H`` below the ground).

    Parameters
    ----------
    ground : Heightfield or object with height(x, z)
        The ground.
    x, z : float
        Position [m].
    radius : float
        Mean radius [m], > 0.
    embed : float, optional
        Share of its height below the ground [-] in [0, 0.9]; default 0.3.
    flatten : float, optional
        Height over width [-]; default 0.6.
    roughness : float, optional
        Relative RMS deviation of the radius [-]; default 0.2.
    subdivisions : int, optional
        Icosphere subdivisions; default 3.
    seed : int, optional
        Seed of the shape; default 0.
    name : str, optional
        Shape id; default ``"rock"``.

    Returns
    -------
    FloorObject
        The rock.
    """
    check_range("embed", embed, 0.0, 0.9)
    h = 2.0 * float(flatten) * float(radius)
    c = np.array([x, float(np.ravel(ground.height(x, z))[0]) + h * (0.5 - float(embed)), z])
    V, F = rock_mesh(c, radius, roughness, flatten, subdivisions, seed)
    return FloorObject(name, "rock", V, F, c, float(radius))


def scatter_floor(ground, plot=None, logs: int = 0, rocks: int = 0, seed: int = 0,
                  avoid=None, clearance: float = 1.0, log_length=(2.0, 8.0),
                  log_radius=(0.1, 0.35), rock_radius=(0.2, 0.8)) -> list[FloorObject]:
    """Scatter logs and rocks over a plot, each clear of the given points (tree bases).

    Sizes are uniform in the given ranges, positions uniform in the plot (rejection), axis
    azimuths uniform. An object whose footprint circle (log: half its length; rock: its
    radius) comes within ``clearance`` of a point of ``avoid`` or of an earlier object, or
    leaves the plot, is redrawn (up to 200 tries each).

    Parameters
    ----------
    ground : Heightfield
        The ground (its bounds are the default plot).
    plot : sequence of float, optional
        ``(x0, z0, x1, z1)`` [m]; default the ground's bounds.
    logs, rocks : int, optional
        How many of each; default 0.
    seed : int, optional
        Seed; default 0.
    avoid : array_like, optional
        (k, 2) points (x, z) [m] to keep clear of (tree bases); default none.
    clearance : float, optional
        Gap kept to those points and between objects [m]; default 1.
    log_length, log_radius, rock_radius : tuple of float, optional
        (min, max) sizes [m].

    Returns
    -------
    list of FloorObject
        Logs (``log_0`` ...) then rocks (``rock_0`` ...).

    Raises
    ------
    ParameterError
        When an object finds no free place in 200 tries (too many objects for the plot).
    """
    rng = np.random.default_rng(seed)
    b = np.asarray(ground.bounds if plot is None else plot, float)
    pts = np.zeros((0, 2)) if avoid is None else np.asarray(avoid, float).reshape(-1, 2)
    rad = np.zeros(len(pts))
    out: list[FloorObject] = []
    for kind, count in (("log", int(logs)), ("rock", int(rocks))):
        for i in range(count):
            for _ in range(200):
                if kind == "log":
                    L = rng.uniform(*log_length)
                    r, reach = rng.uniform(*log_radius), 0.5 * L
                else:
                    r = rng.uniform(*rock_radius)
                    reach = r
                x = rng.uniform(b[0] + reach, b[2] - reach) if b[2] - b[0] > 2 * reach else None
                z = rng.uniform(b[1] + reach, b[3] - reach) if b[3] - b[1] > 2 * reach else None
                if x is None or z is None:
                    continue
                gap = np.hypot(pts[:, 0] - x, pts[:, 1] - z) - rad - reach
                if np.all(gap >= clearance):
                    break
            else:
                raise ParameterError(f"{kind}s", count, "as many as fit the plot with the "
                                     f"clearance {clearance:g} m", "place fewer or smaller "
                                     "objects, or lower the clearance")
            name = f"{kind}_{i}"
            if kind == "log":
                obj = place_log(ground, x, z, L, r, rng.uniform(0.0, 360.0), name=name)
            else:
                obj = place_rock(ground, x, z, r, seed=int(rng.integers(2 ** 31)), name=name)
            out.append(obj)
            pts = np.vstack([pts, [x, z]])
            rad = np.append(rad, reach)
    return out


__all__ = ["RELIEF_WAVES", "Heightfield", "write_ply", "relief", "rolling_ground",
           "FloorObject", "log_mesh", "rock_mesh", "place_log", "place_rock", "scatter_floor"]
