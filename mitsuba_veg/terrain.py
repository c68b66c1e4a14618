"""Terrain: per-triangle static properties of the ground (and other surfaces) moss lives on.

Paper 000 (§3.5) grows moss on the polygons of a terrain mesh. Everything here is computed
once per mesh with NumPy (no per-triangle Python loops):

- geometry per triangle: ``centroids`` [m], unit ``normals`` [-], ``areas`` [m2], the texture
  coordinates ``uv`` [-] at the centroid;
- geology per triangle from the colour of the terrain texture at the centroid's UV
  (:func:`classify_geology`, :meth:`Terrain.geology_from_texture`): dark brown = humus,
  ochre = sand, grey = asphalt (paper 000 §3.5, table 3.4);
- soil depth ``h`` [mm] per triangle (paper 000 eq 3.8), :meth:`Terrain.soil_depth_mm`.

World frame: +y up (paper 000). Texture convention: Mitsuba's, verified for 3.9.1 -- the PLY
loader keeps ``v`` as stored (only the OBJ loader flips it) and a ``bitmap`` texture puts
``v = 0`` at image row 0 (the *top* row of a PNG); ``u = 0`` is column 0. Wrapping is
``repeat`` (Mitsuba's default ``wrap_mode``), the lookup is nearest-texel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Mapping, Sequence

import mitsuba as mi
import numpy as np

from .errors import ParameterError, SceneError
from .meshes import triangle_geometry

# --------------------------------------------------------------------------------------------
# Geology
# --------------------------------------------------------------------------------------------

#: geology classes, indexed by the integer code used everywhere (0 humus, 1 sand, 2 asphalt);
#: the order matches the rows of paper 000 table 3.4 (F1, F2, theta_SAT)
GEOLOGY: tuple[str, ...] = ("humus", "sand", "asphalt")
#: the integer codes of the geology classes
HUMUS, SAND, ASPHALT = 0, 1, 2

#: reference texture colours [8-bit sRGB-encoded values, as stored in a PNG], one per class in
#: :data:`GEOLOGY` order. Paper 000 only names the colours (dark brown = humus, ochre = sand,
#: grey = asphalt); these values are the ones painted by ``scenes/moss_garden/make_scene.py``.
GEOLOGY_COLOURS: dict[str, tuple[int, int, int]] = {
    "humus": (70, 50, 35),       # dark brown
    "sand": (200, 160, 80),      # ochre
    "asphalt": (110, 110, 110),  # grey
}

#: largest accepted Euclidean distance [8-bit RGB units] between a texel and its nearest
#: reference colour. The references are 104-176 apart, so 80 accepts shading and compression
#: noise but rejects colours that belong to none of them (white, green, black ...).
GEOLOGY_TOLERANCE: float = 80.0

_REF = np.array([GEOLOGY_COLOURS[g] for g in GEOLOGY], dtype=np.float64)   # (3 classes, RGB)


def _as_rgb255(rgb) -> np.ndarray:
    """Colours as float64 (..., 3) in 8-bit units; integers are 0-255, floats 0-1 (scaled)."""
    a = np.asarray(rgb)
    if a.ndim == 0 or a.shape[-1] not in (3, 4):
        raise ParameterError("rgb", f"array of shape {a.shape}", "an array (..., 3) or (..., 4)",
                             "pass RGB (or RGBA, alpha ignored) colours along the last axis")
    a = a[..., :3]
    if np.issubdtype(a.dtype, np.floating):
        if a.size and (np.nanmax(a) > 1.0 or np.nanmin(a) < 0.0):
            raise ParameterError("rgb", f"float values in [{np.nanmin(a):g}, {np.nanmax(a):g}]",
                                 "floats in [0, 1] or integers in [0, 255]",
                                 "pass 8-bit integers (e.g. a uint8 image) or divide by 255")
        return a.astype(np.float64) * 255.0
    return a.astype(np.float64)


def _nearest_geology(rgb255: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(codes int8, distance to the nearest reference colour [8-bit units]) per colour."""
    d = np.linalg.norm(rgb255[..., None, :] - _REF, axis=-1)          # (..., 3 classes)
    codes = np.argmin(d, axis=-1)
    dist = np.take_along_axis(d, codes[..., None], axis=-1)[..., 0]
    return codes.astype(np.int8), dist


def _reference_text() -> str:
    return ", ".join(f"{g} {GEOLOGY_COLOURS[g]}" for g in GEOLOGY)


def classify_geology(rgb, tolerance: float = GEOLOGY_TOLERANCE) -> np.ndarray:
    """Geology code per colour: the nearest reference colour of :data:`GEOLOGY_COLOURS`.

    Parameters
    ----------
    rgb : array_like
        Colours (..., 3) (or RGBA (..., 4), alpha ignored): 8-bit integers 0-255, or floats in
        [0, 1].
    tolerance : float, optional
        Largest accepted Euclidean RGB distance to the nearest reference [8-bit units]; default
        :data:`GEOLOGY_TOLERANCE` = 80.

    Returns
    -------
    numpy.ndarray of int8
        Codes of shape ``rgb.shape[:-1]`` (0 humus, 1 sand, 2 asphalt; see :data:`GEOLOGY`).

    Raises
    ------
    ParameterError
        If ``rgb`` has the wrong shape or float values outside [0, 1], or a colour is farther than
        ``tolerance`` from every reference (the message names the colour and its index).
    """
    a = _as_rgb255(rgb)
    codes, dist = _nearest_geology(a)
    bad = dist > tolerance
    if np.any(bad):
        idx = np.unravel_index(int(np.argmax(bad)), bad.shape) if bad.ndim else ()
        colour = tuple(int(round(c)) for c in a[idx])
        raise ParameterError(
            f"geology colour at index {tuple(int(i) for i in idx)}", colour,
            f"within {tolerance:g} (RGB distance) of {_reference_text()}",
            f"{int(bad.sum())} colour(s) match no geology: repaint them with one of the "
            f"reference colours or raise the tolerance")
    return codes


def load_texture_rgb(texture) -> np.ndarray:
    """A texture as a uint8 array (H, W, 3): from a file path (PNG, JPEG ...) or an array.

    Parameters
    ----------
    texture : str, os.PathLike or array_like
        Image file path, or an array (H, W), (H, W, 3) or (H, W, 4) (alpha dropped), uint8
        0-255 or floats 0-1.

    Returns
    -------
    numpy.ndarray of uint8
        The image (H, W, 3), 8-bit sRGB-encoded values as stored.

    Raises
    ------
    SceneError
        If the file does not exist.
    ParameterError
        If the array has the wrong shape or float values outside [0, 1].
    """
    if isinstance(texture, (str, PathLike)):
        path = Path(texture)
        if not path.is_file():
            raise SceneError(f"geology texture '{path}' does not exist. Fix: give the path of "
                             f"the terrain's colour texture (e.g. scenes/moss_garden/geology.png)")
        from PIL import Image

        with Image.open(path) as im:
            return np.asarray(im.convert("RGB"), dtype=np.uint8)
    a = np.asarray(texture)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=-1)
    if a.ndim != 3 or a.shape[-1] not in (3, 4) or a.shape[0] == 0 or a.shape[1] == 0:
        raise ParameterError("texture", f"array of shape {a.shape}",
                             "an image (H, W), (H, W, 3) or (H, W, 4)", None)
    return np.round(_as_rgb255(a)).astype(np.uint8)


def texel_index(uv: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(row, column) of the texel that Mitsuba's nearest lookup uses for each ``uv``.

    Mitsuba convention: ``v = 0`` is image row 0 (the top row of the file), ``u = 0`` column 0;
    ``repeat`` wrapping. Texel ``c`` covers ``u`` in [c/W, (c+1)/W).

    Parameters
    ----------
    uv : numpy.ndarray
        Texture coordinates (n, 2) [-].
    height : int
        Image height H [pixels].
    width : int
        Image width W [pixels].

    Returns
    -------
    row : numpy.ndarray of int64
        Image row per ``uv`` (n,), in [0, H).
    col : numpy.ndarray of int64
        Image column per ``uv`` (n,), in [0, W).
    """
    uv = np.asarray(uv, dtype=np.float64)
    col = np.mod(np.floor(uv[:, 0] * width), width).astype(np.int64)
    row = np.mod(np.floor(uv[:, 1] * height), height).astype(np.int64)
    return row, col


# --------------------------------------------------------------------------------------------
# Soil depth (paper 000 eq 3.8)
# --------------------------------------------------------------------------------------------

#: soil depth bounds [mm] (paper 000 eq 3.8: 1 mm where there is no soil, capped at 1000 mm)
SOIL_DEPTH_MIN_MM: float = 1.0
#: (upper bound)
SOIL_DEPTH_MAX_MM: float = 1000.0
#: faces steeper than this [deg] (angle between the normal and +y) carry no soil: walls,
#: cliffs, overhangs and undersides get :data:`SOIL_DEPTH_MIN_MM`
SOIL_MAX_SLOPE_DEG: float = 60.0


# --------------------------------------------------------------------------------------------
# Terrain
# --------------------------------------------------------------------------------------------

@dataclass(eq=False)
class Terrain:
    """A triangle mesh with its per-triangle static properties (computed once, NumPy).

    Inputs (world frame, +y up):

    - ``vertices`` [m], float64 (V, 3);
    - ``faces``: vertex indices, int64 (F, 3), counter-clockwise seen from the front side;
    - ``vertex_uv`` [-]: per-vertex texture coordinates (V, 2), or ``None``;
    - ``name``: the shape id (e.g. ``"ground"``), for messages and regions.

    Derived per triangle (F rows):

    - ``centroids`` [m] (F, 3): mean of the three vertices;
    - ``normals`` [-] (F, 3): unit geometric normals ``(v1 - v0) x (v2 - v0)`` normalised
      (Mitsuba's face-normal convention); all zero for degenerate (zero-area) triangles;
    - ``areas`` [m2] (F,);
    - ``uv`` [-] (F, 2): texture coordinates at the centroid (mean of the vertex UVs, exact since
      UVs are linear on a triangle), or ``None`` without ``vertex_uv``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_uv: np.ndarray | None = None
    name: str = ""
    centroids: np.ndarray = field(init=False, repr=False)
    normals: np.ndarray = field(init=False, repr=False)
    areas: np.ndarray = field(init=False, repr=False)
    uv: np.ndarray | None = field(init=False, repr=False)

    def __post_init__(self):
        label = f"Terrain '{self.name}'" if self.name else "Terrain"
        v = np.asarray(self.vertices, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ParameterError(f"{label}.vertices", f"array of shape {v.shape}", "(V, 3)")
        f = np.asarray(self.faces)
        if f.size == 0:
            f = f.reshape(0, 3)
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            raise ParameterError(f"{label}.faces", f"array of shape {f.shape}, dtype {f.dtype}",
                                 "integer vertex indices (F, 3)", "triangulate the mesh first")
        f = f.astype(np.int64)
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ParameterError(f"{label}.faces", f"indices in [{f.min()}, {f.max()}]",
                                 f"[0, {len(v) - 1}] (V = {len(v)} vertices)")
        if not np.all(np.isfinite(v)):
            raise ParameterError(f"{label}.vertices", "non-finite values", "finite numbers")
        self.vertices, self.faces = v, f
        if self.vertex_uv is not None:
            t = np.asarray(self.vertex_uv, dtype=np.float64)
            if t.shape != (len(v), 2):
                raise ParameterError(f"{label}.vertex_uv", f"array of shape {t.shape}",
                                     f"({len(v)}, 2): one (u, v) per vertex")
            self.vertex_uv = t
        self.areas, self.normals, self.centroids = triangle_geometry(v, f)
        self.uv = None if self.vertex_uv is None else self.vertex_uv[f].mean(axis=1)

    # -- construction ----------------------------------------------------------------------
    @classmethod
    def from_arrays(cls, vertices, faces, uv=None, name: str = "") -> "Terrain":
        """A terrain from vertex positions, faces and optional per-vertex UVs.

        Parameters
        ----------
        vertices : array_like
            Vertex positions (V, 3) [m], world frame (+y up).
        faces : array_like of int
            Vertex indices (F, 3), counter-clockwise seen from the front side.
        uv : array_like, optional
            Per-vertex texture coordinates (V, 2) [-]; default None (no UVs).
        name : str, optional
            Shape id for messages and regions; default ``""``.

        Returns
        -------
        Terrain
            The terrain with its per-triangle properties.
        """
        return cls(vertices, faces, uv, name)

    @classmethod
    def from_trimesh(cls, mesh, name: str | None = None) -> "Terrain":
        """A terrain from a ``trimesh.Trimesh``.

        Per-vertex UVs are taken from ``mesh.visual.uv`` if any.

        Parameters
        ----------
        mesh : trimesh.Trimesh
            The mesh; vertices in [m], world frame (+y up).
        name : str, optional
            Shape id; default None takes ``mesh.metadata["name"]`` (or ``""``).

        Returns
        -------
        Terrain
            The terrain with its per-triangle properties.
        """
        uv = getattr(getattr(mesh, "visual", None), "uv", None)
        if name is None:
            name = str(mesh.metadata.get("name", "")) if hasattr(mesh, "metadata") else ""
        return cls(np.asarray(mesh.vertices), np.asarray(mesh.faces),
                   None if uv is None else np.asarray(uv), name)

    @classmethod
    def from_mitsuba(cls, shape) -> "Terrain":
        """A terrain from a loaded Mitsuba mesh (``mi.Mesh``, e.g. of ``scene.shapes()``).

        Positions are in world space (Mitsuba applies ``to_world`` at load time); texture
        coordinates are read if the mesh has them. Load scenes with ``optimize=False`` or
        meshes with equal BSDFs are merged and lose their ids (see ``MITSUBA_NOTES.md``).

        Parameters
        ----------
        shape : mi.Mesh
            The triangle mesh; its id becomes the terrain's name.

        Returns
        -------
        Terrain
            The terrain (vertices [m] in world space).

        Raises
        ------
        SceneError
            If ``shape`` is not a triangle mesh.
        """
        if not (isinstance(shape, mi.Mesh) or (hasattr(shape, "is_mesh") and shape.is_mesh())):
            raise SceneError(f"shape '{shape.id()}' is a {type(shape).__name__}, not a triangle "
                             f"mesh. Fix: give the terrain as a mesh (ply/obj/serialized)")
        v = np.array(shape.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
        f = np.array(shape.faces_buffer(), dtype=np.int64).reshape(-1, 3)
        uv = None
        if shape.has_vertex_texcoords():
            uv = np.array(shape.vertex_texcoords_buffer(), dtype=np.float64).reshape(-1, 2)
        return cls(v, f, uv, shape.id())

    @classmethod
    def from_scene(cls, scene, shape_id: str) -> "Terrain":
        """The mesh with id ``shape_id`` of a loaded ``mi.Scene`` (load with optimize=False).

        Parameters
        ----------
        scene : mi.Scene
            The loaded scene.
        shape_id : str
            Id of the terrain shape in the scene file.

        Returns
        -------
        Terrain
            The terrain of that shape.

        Raises
        ------
        SceneError
            If the scene has no shape with that id (or it is not a mesh).
        """
        shapes = {s.id(): s for s in scene.shapes()}
        if shape_id not in shapes:
            raise SceneError(
                f"the scene has no shape with id '{shape_id}' (ids: "
                f"{', '.join(repr(k) for k in shapes) or 'none'}). Fix: give the terrain shape "
                f"that id in the scene file, and load the scene with optimize=False (Mitsuba "
                f"merges meshes with equal BSDFs, dropping their ids)")
        return cls.from_mitsuba(shapes[shape_id])

    # -- basic properties ------------------------------------------------------------------
    @property
    def n_triangles(self) -> int:
        """Number of triangles F."""
        return len(self.faces)

    @property
    def total_area(self) -> float:
        """Sum of the triangle areas [m2]."""
        return float(self.areas.sum())

    def in_box(self, box_min: Sequence[float], box_max: Sequence[float]) -> np.ndarray:
        """Triangles whose centroid lies in an axis-aligned box.

        The test is ``box_min <= centroid <= box_max`` (inclusive, per axis x, y, z).

        Parameters
        ----------
        box_min : sequence of float
            Lower corner ``[x, y, z]`` [m].
        box_max : sequence of float
            Upper corner ``[x, y, z]`` [m].

        Returns
        -------
        numpy.ndarray of bool
            Mask (F,), True for triangles in the box.

        Raises
        ------
        ParameterError
            If a corner is not three numbers or ``box_min > box_max`` on an axis.
        """
        lo = np.asarray(box_min, dtype=np.float64)
        hi = np.asarray(box_max, dtype=np.float64)
        if lo.shape != (3,) or hi.shape != (3,) or np.any(lo > hi):
            raise ParameterError("box", (list(lo.ravel()), list(hi.ravel())),
                                 "min = [x, y, z] <= max = [x, y, z] in metres")
        return np.all((self.centroids >= lo) & (self.centroids <= hi), axis=1)

    # -- geology ---------------------------------------------------------------------------
    def geology_from_texture(self, texture, tolerance: float = GEOLOGY_TOLERANCE) -> np.ndarray:
        """Geology code per triangle (int8, F): 0 humus, 1 sand, 2 asphalt (:data:`GEOLOGY`).

        Each triangle takes the class of the texel under its centroid's UV (nearest texel,
        Mitsuba's convention, see :func:`texel_index`), so the classes follow exactly what
        Mitsuba shows when it textures the mesh.

        Parameters
        ----------
        texture : str, os.PathLike or array_like
            Path of the terrain's colour texture or an image array (see :func:`load_texture_rgb`).
        tolerance : float, optional
            Largest accepted Euclidean RGB distance to a reference colour [8-bit units]; default
            :data:`GEOLOGY_TOLERANCE` = 80.

        Returns
        -------
        numpy.ndarray of int8
            Geology code per triangle (F,).

        Raises
        ------
        SceneError
            If the terrain has no texture coordinates.
        ParameterError
            If a texel matches no reference colour within ``tolerance`` (the message names the
            pixel, its colour and the triangle).
        """
        if self.uv is None:
            raise SceneError(
                f"terrain '{self.name}' has no texture coordinates, so its geology cannot be "
                f"read from a texture. Fix: export the mesh with UVs (PLY vertex properties u, v)")
        img = load_texture_rgb(texture)
        h, w = img.shape[:2]
        row, col = texel_index(self.uv, h, w)
        rgb = img[row, col].astype(np.float64)
        codes, dist = _nearest_geology(rgb)
        bad = dist > tolerance
        if np.any(bad):
            i = int(np.argmax(bad))
            src = texture if isinstance(texture, (str, PathLike)) else "texture array"
            raise ParameterError(
                f"{src}: pixel (row {row[i]}, column {col[i]}) colour", tuple(int(c) for c in rgb[i]),
                f"within {tolerance:g} (RGB distance) of {_reference_text()}",
                f"{int(bad.sum())} of {len(bad)} triangles of '{self.name}' (e.g. triangle {i} at "
                f"uv = ({self.uv[i, 0]:.4f}, {self.uv[i, 1]:.4f})) fall on colours that match no "
                f"geology: repaint those pixels with a reference colour or raise the tolerance")
        return codes

    # -- soil depth ------------------------------------------------------------------------
    def soil_depth_mm(self, base_y: float | None = None, *, override_mm: float | None = None,
                      max_slope_deg: float = SOIL_MAX_SLOPE_DEG,
                      min_mm: float = SOIL_DEPTH_MIN_MM,
                      max_mm: float = SOIL_DEPTH_MAX_MM) -> np.ndarray:
        """Soil depth h [mm] per triangle (float64, F), paper 000 eq 3.8.

        h is the thickness of soil under the triangle, measured straight down (along -y) from
        the centroid to the soil base, a horizontal level ``y = base_y`` [m]::

            h = clamp(1000 * (y_centroid - base_y), min_mm, max_mm)   if n_y >= cos(max_slope)
            h = min_mm                                                otherwise

        - ``base_y`` defaults to the lowest vertex of this mesh ("down to the lowest level of
          the terrain"). For a terrain modelled as a closed block with a flat bottom this is the
          next surface below along -y. Give ``base_y`` explicitly for an open heightfield (the
          soil layer's bottom): with the default the lowest triangles get almost no soil.
        - Faces steeper than ``max_slope_deg`` (60 deg: n_y < 0.5) -- walls, cliffs, overhangs,
          undersides (n_y < 0) and degenerate triangles -- hold no soil: ``min_mm`` (1 mm, the
          paper's value for walls).
        - Capped at ``max_mm`` (1000 mm, paper); at least ``min_mm`` (also where the centroid
          is at or below the base).

        Parameters
        ----------
        base_y : float, optional
            Height of the soil base [m]; default None: the lowest vertex of this mesh.
        override_mm : float, optional
            One explicit depth for every triangle [mm], > 0 (e.g. 1 mm for a roof or wall that has
            no soil at all); default None (computed depths).
        max_slope_deg : float, optional
            Steepest face that holds soil [degrees] (angle between normal and +y), in [0, 90];
            default :data:`SOIL_MAX_SLOPE_DEG` = 60.
        min_mm : float, optional
            Smallest depth, used where there is no soil [mm]; default :data:`SOIL_DEPTH_MIN_MM` = 1.
        max_mm : float, optional
            Largest depth [mm]; default :data:`SOIL_DEPTH_MAX_MM` = 1000.

        Returns
        -------
        numpy.ndarray
            Soil depth per triangle (F,) [mm].

        Raises
        ------
        ParameterError
            If ``override_mm`` is not a finite number > 0, ``max_slope_deg`` is outside [0, 90] or
            not ``0 < min_mm <= max_mm``.
        """
        if override_mm is not None:
            h = float(override_mm)
            if not (math.isfinite(h) and h > 0):
                raise ParameterError(f"soil depth override for '{self.name}' [mm]", override_mm,
                                     "a number > 0", "use 1 mm for surfaces without soil")
            return np.full(self.n_triangles, h)
        if not (0.0 <= max_slope_deg <= 90.0):
            raise ParameterError("max_slope_deg", max_slope_deg, "[0, 90]")
        if not (0.0 < min_mm <= max_mm):
            raise ParameterError("min_mm, max_mm", (min_mm, max_mm), "0 < min_mm <= max_mm")
        if base_y is None:
            base_y = float(self.vertices[:, 1].min()) if len(self.vertices) else 0.0
        h = np.clip(1000.0 * (self.centroids[:, 1] - float(base_y)), min_mm, max_mm)
        flat = self.normals[:, 1] >= math.cos(math.radians(max_slope_deg)) - 1e-12
        flat &= self.areas > 0.0
        return np.where(flat, h, min_mm)


# --------------------------------------------------------------------------------------------
# Whole scenes
# --------------------------------------------------------------------------------------------

def terrains_from_scene(scene, ids: Sequence[str] | None = None) -> dict[str, Terrain]:
    """``{shape id: Terrain}`` for the meshes of a loaded ``mi.Scene`` (all, or ``ids``).

    Load the scene with ``optimize=False`` so that shapes keep their ids.

    Parameters
    ----------
    scene : mi.Scene
        The loaded scene.
    ids : sequence of str, optional
        Shape ids to take; default None: every mesh of the scene.

    Returns
    -------
    dict of str to Terrain
        One terrain per shape id.

    Raises
    ------
    SceneError
        If a requested id is not a mesh of the scene.
    """
    if ids is None:
        return {s.id(): Terrain.from_mitsuba(s) for s in scene.shapes()
                if s.is_mesh()}
    return {i: Terrain.from_scene(scene, i) for i in ids}


def soil_depths_mm(terrains: Mapping[str, Terrain], soil_shapes: Sequence[str] = ("ground",),
                   base_y: float | None = None,
                   overrides: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
    """Soil depth h [mm] per triangle for every shape of a scene (paper 000 eq 3.8).

    - Shapes in ``overrides`` (``{id: h [mm]}``) get that constant depth.
    - Shapes in ``soil_shapes`` (the ground) follow :meth:`Terrain.soil_depth_mm` with a common
      ``base_y`` [m]: given, or the lowest vertex of all soil shapes.
    - Every other shape (roof, walls, rocks ...) has no soil below: 1 mm.

    Parameters
    ----------
    terrains : mapping of str to Terrain
        The scene's shapes, by id.
    soil_shapes : sequence of str, optional
        Ids of the shapes that hold soil; default ``("ground",)``.
    base_y : float, optional
        Common soil base height [m]; default None: the lowest vertex of the soil shapes.
    overrides : mapping of str to float, optional
        Constant depth per shape id [mm]; default None.

    Returns
    -------
    dict of str to numpy.ndarray
        Soil depth per triangle [mm], one array (F,) per shape id of ``terrains``.

    Raises
    ------
    SceneError
        If an id of ``soil_shapes`` or ``overrides`` is not in ``terrains``.
    """
    overrides = dict(overrides or {})
    unknown = [k for k in list(overrides) + list(soil_shapes) if k not in terrains]
    if unknown:
        raise SceneError(f"soil depth: no shape with id {', '.join(map(repr, unknown))} (shapes: "
                         f"{', '.join(map(repr, terrains))}). Fix: use the scene's shape ids")
    soil = [terrains[k] for k in soil_shapes if k not in overrides]
    if base_y is None and soil:
        base_y = min(float(t.vertices[:, 1].min()) for t in soil if len(t.vertices))
    out = {}
    for k, t in terrains.items():
        if k in overrides:
            out[k] = t.soil_depth_mm(override_mm=overrides[k])
        elif k in soil_shapes:
            out[k] = t.soil_depth_mm(base_y)
        else:
            out[k] = t.soil_depth_mm(override_mm=SOIL_DEPTH_MIN_MM)
    return out


__all__ = ["GEOLOGY", "HUMUS", "SAND", "ASPHALT", "GEOLOGY_COLOURS", "GEOLOGY_TOLERANCE",
           "SOIL_DEPTH_MIN_MM", "SOIL_DEPTH_MAX_MM", "SOIL_MAX_SLOPE_DEG",
           "classify_geology", "load_texture_rgb", "texel_index", "Terrain",
           "terrains_from_scene", "soil_depths_mm"]
