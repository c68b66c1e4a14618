"""Surroundings of growing trees: terrain and buildings as triangle meshes (+y up, metres).

Paper 001 (§2.3.2) models the surroundings of a tree as a height field (a 20 x 20 grid): every grid
point's received light (upper hemisphere) is the light it reflects, and a sky ray from a leaf
sphere that hits the grid takes that value (interpolated from the two nearest grid points), with
the indirect level C2 as its intensity. Here the surroundings are any triangle meshes (a ground
grid, a slope, boxes for buildings, meshes from a Mitsuba scene or a file), traced by Mitsuba:

- each obstacle triangle gets a *reflected light* factor ``env`` in [0, 1]: its sky-light
  irradiance relative to open flat ground, from the same H x V sky as the leaf spheres (cells
  weighted by cos to the triangle normal; rays hitting another obstacle take C2 x that
  obstacle's env from a first pass, one bounce). Open flat ground has env = 1, so a ground
  plane reproduces the paper's "ideal" environment exactly (lower hemisphere = C2);
- a leaf-sphere ray that hits an obstacle's front receives ``C2 x env x light_factor`` (the
  paper's rule, upper-hemisphere rays included), a ray that hits an obstacle's back (the leaf
  sphere is inside a wall or below the terrain) receives nothing.

Paper 002 uses the same obstacles as opaque voxels (:meth:`Environment.voxel_mask`).

Obstacle meshes are subdivided to ``max_edge`` so that per-triangle env resolves shadows (the
paper's grid is 20 x 20).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.light.validation import box_mesh, grid_mesh
from mitsuba_veg.meshes import make_mesh

from ..errors import ParameterError, check_range
from ..meshes import triangle_geometry
from .leaflight import obstacle_sky_light


__all__ = ["Obstacle", "Environment"]

@dataclass
class Obstacle:
    """One obstacle mesh: vertices (n, 3) [m], faces (m, 3), reflected-light factor."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    light_factor: float = 1.0      # scales the light the obstacle reflects (albedo relative to
                                   # the ground of the paper; 1 = as the paper)


def _subdivide(V, F, max_edge):
    if max_edge is None or len(F) == 0:
        return V, F
    import trimesh.remesh

    e = np.linalg.norm(V[F[:, [1, 2, 0]]] - V[F], axis=2).max()
    if e <= max_edge:
        return V, F
    V2, F2 = trimesh.remesh.subdivide_to_size(V, F, max_edge=max_edge, max_iter=12)
    return np.asarray(V2, float), np.asarray(F2, np.int64)


@dataclass
class Environment:
    """Obstacles around trees (terrain, buildings). Build with the class methods / ``add_*``.

    ``ground_y`` [m] is where trees stand when there is no terrain under them.
    """

    obstacles: list = field(default_factory=list)
    ground_y: float = 0.0
    _cache: dict = field(default_factory=dict, repr=False)

    # ---- construction ----------------------------------------------------------------------
    @staticmethod
    def coerce(scene) -> "Environment | None":
        """Turn any accepted description of the surroundings into an Environment (or None).

        Accepts None, an Environment, a Mitsuba scene (its meshes), a trimesh, a (V, F) pair or a
        list of them.

        Parameters
        ----------
        scene : None, Environment, mi.Scene, trimesh.Trimesh, tuple or list
            The surroundings: None for no obstacles; an Environment (returned as is); a Mitsuba
            scene (its non-emitter, non-sensor meshes, :meth:`from_mitsuba`); a trimesh, a Mitsuba
            mesh or a (vertices (n, 3) [m], faces (m, 3) int) pair; or a list of meshes / pairs.

        Returns
        -------
        Environment or None
            The environment, or None when ``scene`` is None.

        Raises
        ------
        ParameterError
            If an item is none of the accepted kinds (:meth:`add`).
        """
        if scene is None or isinstance(scene, Environment):
            return scene
        if isinstance(scene, mi.Scene):
            return Environment.from_mitsuba(scene)
        env = Environment()
        items = scene if isinstance(scene, (list, tuple)) and not _is_vf(scene) else [scene]
        for i, it in enumerate(items):
            env.add(it, name=f"obstacle{i}")
        return env

    def add(self, mesh, name="obstacle", light_factor=1.0, max_edge=None):
        """Add a trimesh, a Mitsuba mesh or a (vertices, faces) pair as an obstacle.

        An empty mesh (no faces) is skipped. The mesh is subdivided to ``max_edge`` so that the
        per-triangle reflected light resolves shadows; the caches are cleared.

        Parameters
        ----------
        mesh : trimesh.Trimesh, mi.Mesh or tuple
            The obstacle: anything with ``vertices`` and ``faces``, a Mitsuba mesh (its id names the
            obstacle) or a (vertices (n, 3) [m], faces (m, 3) int) pair.
        name : str, optional
            Obstacle name used in error messages (default ``"obstacle"``).
        light_factor : float, optional
            Scales the light the obstacle reflects [-] (albedo relative to the ground of paper 001;
            1 = as the paper, the default); >= 0.
        max_edge : float, optional
            Subdivide triangles until no edge is longer than this [m]; default None: no subdivision.

        Returns
        -------
        Environment
            ``self``, for chaining.

        Raises
        ------
        ParameterError
            If ``mesh`` is of no accepted kind, a face index is out of range, or ``light_factor``
            is negative.
        """
        if _is_vf(mesh):
            V, F = mesh
        elif hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
            V, F = mesh.vertices, mesh.faces
        elif hasattr(mesh, "vertex_positions_buffer"):
            V = np.asarray(mesh.vertex_positions_buffer(), float).reshape(-1, 3)
            F = np.asarray(mesh.faces_buffer(), np.int64).reshape(-1, 3)
            name = mesh.id() or name
        else:
            raise ParameterError("scene", type(mesh).__name__,
                                 "an Environment, a Mitsuba scene, a trimesh or (vertices, faces)")
        V = np.asarray(V, float).reshape(-1, 3)
        F = np.asarray(F, np.int64).reshape(-1, 3)
        if len(F) == 0:
            return self
        if F.min() < 0 or F.max() >= len(V):
            raise ParameterError(f"{name}.faces", "indices out of range",
                                 f"0 .. {len(V) - 1} (vertex count)")
        check_range(f"{name}.light_factor", light_factor, 0.0, None)
        V, F = _subdivide(V, F, max_edge)
        self.obstacles.append(Obstacle(name, V, F, float(light_factor)))
        self._cache.clear()
        return self

    @staticmethod
    def from_mitsuba(scene) -> "Environment":
        """An Environment of a Mitsuba scene's meshes (emitters and sensors left out).

        Parameters
        ----------
        scene : mi.Scene
            The scene; each mesh shape with faces becomes an obstacle named by its id.

        Returns
        -------
        Environment
            The environment.
        """
        env = Environment()
        for sh in scene.shapes():
            if sh.is_mesh() and sh.face_count() > 0 and not sh.is_emitter() \
                    and not sh.is_sensor():
                env.add(sh, name=sh.id() or f"mesh{len(env.obstacles)}")
        return env

    def add_ground(self, size=40.0, y=0.0, n=20, center=(0.0, 0.0), light_factor=1.0):
        """Add a flat square ground grid (n x n cells) of side ``size`` [m] at height ``y``.

        Also sets ``ground_y`` to ``y``.

        Parameters
        ----------
        size : float, optional
            Side of the square [m] (default 40); > 0.
        y : float, optional
            Height of the ground [m] (default 0).
        n : int, optional
            Cells per side (default 20, the paper's 20 x 20 grid).
        center : tuple of float, optional
            Centre (x, z) of the square [m] (default the origin).
        light_factor : float, optional
            Reflected-light factor of the ground [-] (default 1, as the paper).

        Returns
        -------
        Environment
            ``self``, for chaining.
        """
        check_range("ground.size", size, 0.0, None, lo_open=True)
        h = size / 2
        V, F = grid_mesh(int(n), int(n), (center[0] - h, center[0] + h),
                         (center[1] - h, center[1] + h), y=y)
        self.ground_y = float(y)
        return self.add((V, F), "ground", light_factor)

    def add_slope(self, angle_deg=20.0, size=40.0, n=20, downhill=(1.0, 0.0), y0=0.0,
                  light_factor=1.0):
        """Add a tilted plane going down towards a horizontal direction.

        The plane (a square grid of side ``size`` centred on the origin) is tilted by ``angle_deg``
        and goes down towards the horizontal direction ``downhill`` (x, z); it has height ``y0`` at
        the origin. Also sets ``ground_y`` to ``y0``.

        Parameters
        ----------
        angle_deg : float, optional
            Slope angle [degrees] (default 20), in [0, 80].
        size : float, optional
            Side of the square [m] (default 40).
        n : int, optional
            Cells per side (default 20).
        downhill : tuple of float, optional
            Horizontal direction (x, z) the slope goes down to (default +x); need not be unit.
        y0 : float, optional
            Height at the origin [m] (default 0).
        light_factor : float, optional
            Reflected-light factor of the slope [-] (default 1).

        Returns
        -------
        Environment
            ``self``, for chaining.
        """
        check_range("slope.angle_deg", angle_deg, 0.0, 80.0)
        dx, dz = np.asarray(downhill, float) / max(np.hypot(*downhill), 1e-12)
        t = math.tan(math.radians(angle_deg))
        h = size / 2
        V, F = grid_mesh(int(n), int(n), (-h, h), (-h, h), y=y0,
                         height=lambda X, Z: -t * (X * dx + Z * dz))
        self.ground_y = float(y0)
        return self.add((V, F), "slope", light_factor)

    def add_box(self, lo, hi, name="building", max_edge=1.0, light_factor=1.0):
        """Add an axis-aligned box (a building, a wall) from corner ``lo`` to ``hi`` [m].

        Parameters
        ----------
        lo, hi : array_like
            (3,) lower and upper corners (x, y, z) [m]; ``hi > lo`` on every axis.
        name : str, optional
            Obstacle name (default ``"building"``).
        max_edge : float, optional
            Subdivide the box's faces to this edge length [m] (default 1).
        light_factor : float, optional
            Reflected-light factor of the box [-] (default 1).

        Returns
        -------
        Environment
            ``self``, for chaining.

        Raises
        ------
        ParameterError
            If ``hi <= lo`` on some axis.
        """
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        if np.any(hi <= lo):
            raise ParameterError(f"{name}.hi", hi.tolist(), f"> lo = {lo.tolist()} on every axis")
        V, F = box_mesh(lo, hi)
        return self.add((V, F), name, light_factor, max_edge=max_edge)

    @staticmethod
    def flat_ground(size=40.0, y=0.0, n=20) -> "Environment":
        """A new Environment holding only a flat ground grid (:meth:`add_ground`).

        Parameters
        ----------
        size : float, optional
            Side of the square ground [m] (default 40).
        y : float, optional
            Height of the ground [m] (default 0).
        n : int, optional
            Cells per side (default 20).

        Returns
        -------
        Environment
            The environment.
        """
        return Environment().add_ground(size, y, n)

    # ---- geometry --------------------------------------------------------------------------
    def __len__(self):
        return len(self.obstacles)

    def triangles(self):
        """All obstacle triangles, concatenated (cached).

        Returns
        -------
        V : numpy.ndarray
            (n, 3) vertices [m].
        F : numpy.ndarray
            (m, 3) int64 faces (indices into ``V``).
        normals : numpy.ndarray
            (m, 3) unit face normals [-].
        centroids : numpy.ndarray
            (m, 3) face centroids [m].
        areas : numpy.ndarray
            (m,) face areas [m2].
        obstacle : numpy.ndarray
            (m,) int index of the obstacle of each face.
        light_factor : numpy.ndarray
            (m,) reflected-light factor of each face's obstacle [-].
        """
        if "tri" not in self._cache:
            Vs, Fs, obj, off = [], [], [], 0
            for i, o in enumerate(self.obstacles):
                Vs.append(o.vertices)
                Fs.append(o.faces + off)
                obj.append(np.full(len(o.faces), i))
                off += len(o.vertices)
            V = np.concatenate(Vs) if Vs else np.zeros((0, 3))
            F = np.concatenate(Fs) if Fs else np.zeros((0, 3), np.int64)
            areas, normals, centroids = triangle_geometry(V, F)
            obj = np.concatenate(obj) if obj else np.zeros(0, np.int64)
            lf = np.array([o.light_factor for o in self.obstacles])[obj] if len(obj) else \
                np.zeros(0)
            self._cache["tri"] = (V, F, normals, centroids, areas, obj, lf)
        return self._cache["tri"]

    def bbox(self):
        """Axis-aligned bounding box of all obstacles.

        Returns
        -------
        tuple of numpy.ndarray or None
            (lo, hi), each (3,) [m]; None when there are no obstacle vertices.
        """
        V = self.triangles()[0]
        if len(V) == 0:
            return None
        return V.min(0), V.max(0)

    def mitsuba_meshes(self) -> dict:
        """The obstacles as Mitsuba meshes (built once).

        Returns
        -------
        dict
            ``{"obstacle_<i>": mi.Mesh}``, one entry per obstacle.
        """
        if "mi" not in self._cache:
            self._cache["mi"] = {f"obstacle_{i}": make_mesh(f"obstacle_{i}", o.vertices, o.faces)
                                 for i, o in enumerate(self.obstacles)}
        return self._cache["mi"]

    def scene(self):
        """A Mitsuba scene of the obstacles only (built once).

        Returns
        -------
        mi.Scene
            The scene (no emitter, no sensor).
        """
        if "scene" not in self._cache:
            d = {"type": "scene"}
            d.update(self.mitsuba_meshes())
            self._cache["scene"] = mi.load_dict(d, optimize=False)
        return self._cache["scene"]

    def height_at(self, x, z, default=None):
        """Terrain height [m] under (x, z).

        The first obstacle surface hit by a ray cast straight down from 1 m above the obstacles'
        bounding box (whichever way the surface faces), or ``default`` where the ray hits nothing.

        Parameters
        ----------
        x, z : float or array_like
            Horizontal coordinates [m] (scalars or (k,) arrays).
        default : float, optional
            Height where there is no obstacle [m]; default None: ``ground_y``.

        Returns
        -------
        numpy.ndarray
            (k,) heights [m] (k = 1 for scalar inputs).
        """
        x = np.atleast_1d(np.asarray(x, float))
        z = np.atleast_1d(np.asarray(z, float))
        default = self.ground_y if default is None else default
        if not self.obstacles:
            return np.full(len(x), default)
        top = float(self.bbox()[1][1]) + 1.0
        o = mi.Point3f(mi.Float(x.astype(np.float32)), mi.Float(np.full(len(x), top, np.float32)),
                       mi.Float(z.astype(np.float32)))
        si = self.scene().ray_intersect_preliminary(mi.Ray3f(o, mi.Vector3f(0, -1, 0)))
        t = np.asarray(si.t, float)
        return np.where(np.isfinite(t), top - t, default)

    def inside(self, points) -> np.ndarray:
        """Which points are inside an obstacle.

        A point is inside when the first surface straight above it faces up (we see its back):
        below a terrain surface, inside a closed building.

        Parameters
        ----------
        points : array_like
            (k, 3) points [m].

        Returns
        -------
        numpy.ndarray
            (k,) bool, True for points inside an obstacle (all False without obstacles).
        """
        pts = np.asarray(points, np.float32).reshape(-1, 3)
        if not self.obstacles or len(pts) == 0:
            return np.zeros(len(pts), bool)
        o = mi.Point3f(*[mi.Float(np.ascontiguousarray(pts[:, k])) for k in range(3)])
        si = self.scene().ray_intersect(mi.Ray3f(o, mi.Vector3f(0, 1, 0)),
                                        ray_flags=mi.RayFlags.Minimal, coherent=False)
        dr.eval(si.t, si.n)
        return np.asarray(si.is_valid()) & (np.asarray(si.n.y) > 0)

    def blocked(self, start, direction, length) -> np.ndarray:
        """Which straight segments cross an obstacle surface.

        Parameters
        ----------
        start : array_like
            (n, 3) segment starts [m].
        direction : array_like
            (n, 3) unit directions [-].
        length : array_like
            (n,) segment lengths [m].

        Returns
        -------
        numpy.ndarray
            (n,) bool, True where the segment hits an obstacle within its length.
        """
        start = np.asarray(start, np.float32).reshape(-1, 3)
        if not self.obstacles or len(start) == 0:
            return np.zeros(len(start), bool)
        d = np.asarray(direction, np.float32).reshape(-1, 3)
        o = mi.Point3f(*[mi.Float(np.ascontiguousarray(start[:, k])) for k in range(3)])
        dd = mi.Vector3f(*[mi.Float(np.ascontiguousarray(d[:, k])) for k in range(3)])
        ray = mi.Ray3f(o, dd)
        ray.maxt = mi.Float(np.asarray(length, np.float32).ravel())
        pi = self.scene().ray_intersect_preliminary(ray, coherent=False)
        dr.eval(pi.t)
        return np.asarray(pi.is_valid())

    # ---- light (paper 001) -------------------------------------------------------------------
    def reflected_light(self, sky, passes: int = 2) -> np.ndarray:
        """Per-triangle reflected-light factor env (see module docstring), cached per sky.

        Computed by :func:`~mitsuba_veg.trees.leaflight.obstacle_sky_light`: sky irradiance of each
        triangle relative to open flat ground (1 for open flat ground).

        Parameters
        ----------
        sky : mitsuba_veg.trees.leaflight.Sky
            The H x V sky of paper 001 (same as the leaf spheres').
        passes : int, optional
            Light passes (default 2): the first gives 0 to rays that hit another obstacle, each
            later pass gives them C2 x the previous pass's env x light_factor of the hit triangle
            (one bounce per extra pass).

        Returns
        -------
        numpy.ndarray
            (m,) env of every obstacle triangle [-], in the order of :meth:`triangles`.
        """
        key = ("env", sky.H, sky.V, sky.C, passes)
        if key in self._cache:
            return self._cache[key]
        env = obstacle_sky_light(self, sky, passes)
        self._cache[key] = env
        return env

    # ---- voxels (paper 002) ------------------------------------------------------------------
    def voxel_mask(self, origin, size, shape) -> np.ndarray:
        """Boolean (nx, ny, nz) mask of voxels filled by obstacles (paper 002).

        Voxels whose centre is inside a closed mesh or below a terrain surface (first hit upwards is
        a back face, :meth:`inside`), and voxels that contain a surface sample of a steep face
        (thin walls; about 4 samples per voxel face area, seeded, so the mask is deterministic).

        Parameters
        ----------
        origin : array_like
            (3,) corner of voxel (0, 0, 0) [m].
        size : float
            Voxel edge length [m].
        shape : tuple of int
            Grid shape (nx, ny, nz).

        Returns
        -------
        numpy.ndarray
            (nx, ny, nz) bool, True for voxels filled by an obstacle.
        """
        nx, ny, nz = shape
        mask = np.zeros(shape, bool)
        if not self.obstacles:
            return mask
        origin = np.asarray(origin, float)
        ix, iy, iz = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
        c = origin + (np.stack([ix, iy, iz], -1).reshape(-1, 3) + 0.5) * size
        mask |= self.inside(c).reshape(shape)
        # surface samples of steep faces (thin walls), ~4 per voxel face area; level faces
        # (terrain, roofs) are resolved by the centre test
        V, F, nrm, _, areas, _, _ = self.triangles()
        steep = np.abs(nrm[:, 1]) < 0.9
        F, areas = F[steep], areas[steep]
        rng = np.random.default_rng(0)
        per = np.maximum(1, np.ceil(4 * areas / size ** 2)).astype(np.int64)
        tri = np.repeat(np.arange(len(F)), per)
        u, v = rng.random(len(tri)), rng.random(len(tri))
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        p0, p1, p2 = V[F[tri, 0]], V[F[tri, 1]], V[F[tri, 2]]
        pts = p0 + u[:, None] * (p1 - p0) + v[:, None] * (p2 - p0)
        idx = np.floor((pts - origin) / size).astype(np.int64)
        ok = np.all((idx >= 0) & (idx < np.array(shape)), axis=1)
        idx = idx[ok]
        mask[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        return mask


def _is_vf(x) -> bool:
    """Is ``x`` one (vertices, faces) pair (not a list of meshes)?"""
    if not (isinstance(x, (tuple, list)) and len(x) == 2):
        return False
    try:
        a, b = np.asarray(x[0], float), np.asarray(x[1])
    except (ValueError, TypeError):
        return False
    return a.ndim == 2 and a.shape[-1] == 3 and b.ndim == 2 and b.shape[-1] == 3 \
        and np.issubdtype(b.dtype, np.number)
