"""The site of a run: its light scene and everything about the surfaces that does not change
from day to day, built once (:func:`build_site`) and shared by the daily pipeline and the
tuning model (:func:`prepare_site`).

- the light scene: the scenario's shapes, the world's trees (wood and one leaf mesh,
  :mod:`mitsuba_veg.world.canopy`) and sensors when the scenario has them, the day's sun path
  (``veg_sun_path``) and an isotropic sky (``veg_sky``), both normalised to a unit horizontal
  irradiance; its :class:`SceneIndex` and the photon pass;
- the terrain arrays per element: geology, soil depth h [mm], where moss may live, the moss
  capacity M (eq 3.5), the bare albedo per band, the regions; the spot grid's extent;
- the ground under each tree's crown and in the open (the world's record).

The terrain shapes come first in the scene, so their elements are ``0 .. n_terrain - 1`` of
the index: the soil and the moss work on those only (the trees' half a million bark and leaf
triangles carry no soil).
"""
from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import soil as soil_model
from ..arrays import host_array
from ..errors import ParameterError, check_range
from ..integrators.photon_irradiance import BANDS as BAND_RANGES
from ..integrators.photon_irradiance import PhotonIrradianceIntegrator, scene_index
from ..light import sensors as sensors_mod
from ..meshes import make_mesh
from ..moss.spatial import SpotGrid, max_per_element
from ..scenario import Scenario
from ..terrain import Terrain
from ..world.canopy import Canopy
from ..world.trees import scenario_trees
from .config import BANDS, MossConfig


__all__ = ["Site", "build_site", "prepare_site"]

class Site:
    """A run's light scene and surfaces (module docstring). Build with :func:`build_site`.

    Attributes
    ----------
    config : MossConfig
        The run's settings.
    scene : mitsuba.Scene
        The light scene; ``sun`` its ``veg_sun_path`` emitter, ``sky`` its ``veg_sky``,
        ``index`` its :class:`SceneIndex`, ``integrator`` the photon pass.
    terrain_shapes : list of str
        The scenario's mesh ids (their albedo follows the moss cover).
    n_terrain : int
        Elements of the terrain shapes (the first of the index).
    geology, h, living, M : numpy.ndarray
        Per terrain element: geology code, soil depth [mm], moss may live there, moss capacity.
    base_albedo : numpy.ndarray
        (terrain elements, bands) bare albedo at the band centres.
    regions : dict
        Region name -> mask over the terrain elements.
    O0 : numpy.ndarray
        Soil water per terrain element at field capacity [mm].
    trees, canopy, sensors
        The world's trees and their canopy (empty list / None without ``[[trees]]``), the
        scenario's sensors (None without ``[[sensors]]``; ``sensor_owner`` maps the sensor
        mesh's faces to sensors).
    ground_id, ground_slice, crowns, open_ground
        The ground shape, its elements, per tree the ground triangles under the crown
        (centroid within 0.75 crown radii of the crown centre) and those under no crown.
    """

    def __init__(self, config: MossConfig):
        self.config = config
        self.trees: list = []
        self.canopy: Canopy | None = None
        self.sensors = None
        self.sensor_owner = None
        self.tree_seconds = 0.0
        self._grid = None

    # ---- what the daily loop and tuning read --------------------------------------------
    @property
    def n(self) -> int:
        """Elements of the whole light scene."""
        return self.index.n_elements

    def grid_cell(self) -> float:
        """The spot grid's cell, one moss [m].

        Returns
        -------
        float
            ``moss.size`` [m].
        """
        return self.config.grid_cell()

    def new_grid(self) -> SpotGrid:
        """An empty spot grid over the scene (one cell per moss, the population's capacity).

        Returns
        -------
        SpotGrid
            The grid.
        """
        lo, hi = self.terrain_bbox()
        return SpotGrid(lo, hi, self.grid_cell(), int(self.config.moss_cfg["capacity"]))

    def terrain_bbox(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounding box of the terrain's meshes (where moss lives) [m].

        The spot grid's origin follows it, not the whole scene: trees that grow (or are
        placed) change the scene's box, and a grid whose origin moved would put moss that
        kept their positions into other cells.

        Returns
        -------
        tuple of numpy.ndarray
            (min, max) corners; the scene's box where the scene has no terrain meshes.
        """
        vs = [self.index.geometry[s][0] for s in self.terrain_shapes
              if s in self.index.geometry]
        if not vs:
            return np.array(self.index.aim_bbox.min), np.array(self.index.aim_bbox.max)
        v = np.concatenate([np.asarray(x, float).reshape(-1, 3) for x in vs])
        return v.min(0), v.max(0)

    @property
    def grid(self) -> SpotGrid:
        """An empty spot grid for geometry queries (tuning's dispersal kernels)."""
        if self._grid is None:
            self._grid = self.new_grid()
        return self._grid

    def set_albedo(self, albedo: dict) -> None:
        """Replace the bare albedo of terrain shapes in the total band (tuning).

        Parameters
        ----------
        albedo : dict
            ``{shape id: albedo [-]}``.
        """
        for sid, v in albedo.items():
            if sid not in self.terrain_shapes or sid not in self.index.geometry:
                raise ParameterError("albedo", sid, "a terrain mesh id: " +
                                     ", ".join(self.terrain_shapes))
            self.base_albedo[self.index.shape_slice(sid), 0] = float(v)
        self._to_device()

    # ---- building -------------------------------------------------------------------------
    def _build(self, with_trees: bool = True, trees=None, bare: bool = False) -> None:
        cfg = self.config
        scn = cfg.scn
        base = scn.load_scene(daylight=False)
        d = {"type": "scene"}
        for sh in base.shapes():
            d[sh.id()] = sh
        self.terrain_shapes = [sh.id() for sh in base.shapes() if sh.is_mesh()]
        if with_trees and (scn.get("trees") or scn.get("stand")):
            t0 = time.perf_counter()
            self.trees = list(trees) if trees is not None else scenario_trees(scn, base)
            self.tree_seconds = time.perf_counter() - t0
            self.canopy = Canopy(self.trees, cfg.stage_bins)
            d.update(self.canopy.shapes(bare=bare))
        if with_trees:
            self.sensors = sensors_mod.from_scenario(scn, base)
            if self.sensors is not None:
                v, f, self.sensor_owner = self.sensors.mesh()
                d[sensors_mod.SENSOR_SHAPE] = make_mesh(
                    sensors_mod.SENSOR_SHAPE, v, f,
                    {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}})
        d["sun"] = {"type": "veg_sun_path", "id": "sun"}
        d["sky"] = {"type": "veg_sky", "id": "sky", "distribution": "uniform",
                    "radiance": {"type": "uniform", "value": 1.0 / np.pi}}
        self.scene = mi.load_dict(d, optimize=False)
        ems = {e.id(): e for e in self.scene.emitters()}
        self.sun, self.sky = ems["sun"], ems["sky"]
        # the pass's own cache: its tables and pilot find this index instead of a second one
        # a canopy built bare: its elements' areas and normals are those of the full blades
        # (as in a scene built with them, whose blades are taken out later)
        ref = self.canopy.reference_geometry() if bare and self.canopy is not None else None
        self.index = scene_index(self.scene, ref)
        self.integrator = PhotonIrradianceIntegrator()
        self._setup_terrain()
        lo, hi = self.terrain_bbox()
        size = float(cfg.moss_cfg["size"])
        span = float(np.max(hi - lo))
        smallest = span / (SpotGrid.max_cells_per_axis - 3)
        if size < smallest:
            raise ParameterError("moss.size", size, f">= {smallest:.3g} m for this scene "
                                 f"({span:.3g} m across: the spot grid holds at most "
                                 f"{SpotGrid.max_cells_per_axis:,d} cells per axis)",
                                 "use a larger moss size or a smaller scene", str(scn.path))
        self.O0 = soil_model.bucket_capacity(self.h, self.geology).astype(np.float64)
        self._setup_ground()
        self._to_device()

    def _setup_terrain(self):
        cfg = self.config
        scn = cfg.scn
        src = str(scn.path)
        idx = self.index
        ground = scn.get("terrain.ground", "ground")
        meshes = [s for s in idx.shape_ids if s in idx.geometry]
        # the terrain's elements: the first of the index, one block
        sl = [idx.shape_slice(s) for s in self.terrain_shapes if s in idx.geometry]
        self.n_terrain = max((x.stop for x in sl), default=0)
        n = self.n_terrain

        def need_shape(field, sid):
            if sid not in idx.geometry:
                raise ParameterError(field, sid, "a mesh id of the scene: " + ", ".join(meshes),
                                     "use one of the scene's shape ids (loaded with "
                                     "optimize=False)", src)
        need_shape("terrain.ground", ground)
        for sec in ("geology", "soil_depth_mm"):
            for sid in (scn.get(f"terrain.{sec}", {}) or {}):
                need_shape(f"terrain.{sec}.{sid}", sid)
        for name, reg in (scn.get("regions", {}) or {}).items():
            for sid in reg["shapes"]:
                need_shape(f"regions.{name}.shapes", sid)
        self.geology = np.full(n, soil_model.geology_code("asphalt"), np.int64)
        self.h = np.ones(n)
        geo_over = scn.get("terrain.geology", {}) or {}
        depth_over = scn.get("terrain.soil_depth_mm", {}) or {}
        living = cfg.moss_cfg["shapes"] or [s for s in self.terrain_shapes if s in idx.geometry]
        for sid in living:
            if sid not in idx.geometry or sid not in self.terrain_shapes:
                raise ParameterError("moss.shapes", sid, "mesh ids among "
                                     f"{[s for s in self.terrain_shapes if s in idx.geometry]}",
                                     None, src)
        self.living = np.zeros(n, bool)
        for sid in self.terrain_shapes:
            if sid not in idx.geometry:
                continue
            sl_ = idx.shape_slice(sid)
            v, f = idx.geometry[sid]
            if sid == ground:
                shape = [s for s in self.scene.shapes() if s.id() == sid][0]
                terr = Terrain.from_mitsuba(shape)
                tex = scn.get("terrain.geology_texture")
                if tex:
                    path = scn.file("terrain.geology_texture")
                    try:
                        self.geology[sl_] = terr.geology_from_texture(path)
                    except (OSError, ValueError, SyntaxError) as e:  # PIL: unreadable image
                        raise ParameterError("terrain.geology_texture", tex, "a readable PNG/"
                                             "JPEG image", f"replace {path.name} ({e})",
                                             src) from None
                base_y = scn.get("terrain.soil_base_y")
                self.h[sl_] = terr.soil_depth_mm(base_y)
            if sid in geo_over:
                self.geology[sl_] = soil_model.geology_code(geo_over[sid])
            if sid in depth_over:
                self.h[sl_] = check_range(f"terrain.soil_depth_mm.{sid}", depth_over[sid], 1.0,
                                          1000.0, source=src)
            if sid in living:
                self.living[sl_] = True
        self.areas = np.asarray(idx.areas[:n], float)
        self.M = max_per_element(self.areas, self.grid_cell())
        self.base_albedo = self._base_albedo()
        self.regions = {}
        for name, reg in (scn.get("regions", {}) or {}).items():
            mask = np.zeros(n, bool)
            for sid in reg["shapes"]:
                sl_ = idx.shape_slice(sid)
                c = idx.centroids[sl_]
                mask[sl_] = np.all((c >= np.array(reg["min"])) & (c <= np.array(reg["max"])), 1)
            self.regions[name] = mask

    def _base_albedo(self) -> np.ndarray:
        """Albedo of the bare terrain per element and band, from their BSDFs at the band
        centres (diffuse reflectance at the triangle's centroid)."""
        out = np.zeros((self.n_terrain, len(BANDS)))
        lam = [0.5 * (BAND_RANGES[b][0] + BAND_RANGES[b][1]) for b in BANDS]
        for sh in self.scene.shapes():
            if sh.id() not in self.terrain_shapes or sh.id() not in self.index.geometry:
                continue
            sl = self.index.shape_slice(sh.id())
            m = sl.stop - sl.start
            si = dr.zeros(mi.SurfaceInteraction3f, m)
            c = self.index.centroids[sl]
            si.p = mi.Point3f(*[mi.Float(c[:, k].astype(np.float32)) for k in range(3)])
            nrm = self.index.normals[sl]
            si.n = mi.Normal3f(*[mi.Float(nrm[:, k].astype(np.float32)) for k in range(3)])
            si.sh_frame = mi.Frame3f(si.n)
            si.wi = mi.Vector3f(0, 0, 1)
            si.wavelengths = mi.Spectrum(*lam)
            a = sh.bsdf().eval_diffuse_reflectance(si)
            out[sl] = np.stack([np.asarray(a[k]) for k in range(len(BANDS))], 1)
        return np.clip(out, 0.0, 1.0)

    def _setup_ground(self):
        scn = self.config.scn
        self.ground_id = scn.get("terrain.ground", "ground")
        self.ground_slice = self.index.shape_slice(self.ground_id)
        cen = self.index.centroids[self.ground_slice]
        self.crowns = []
        for wt in self.trees:
            r, m = wt.crown_radius(), wt.crown_centre()
            d = np.hypot(cen[:, 0] - m[0], cen[:, 2] - m[1])
            self.crowns.append(d <= max(0.75 * r, 1e-6))
        self.open_ground = ~np.any(self.crowns, axis=0) if self.crowns else \
            np.ones(len(cen), bool)

    def _to_device(self):
        """Device copies of the per-element arrays the day's kernels read."""
        n = self.n_terrain
        self.geology_table = soil_model.ElementGeology(self.geology)
        # (aligned copies: an array mapped from NumPy memory would also follow later writes to
        # it, and its address's alignment is part of the kernels' code: arrays.host_array)
        self.d_living = host_array(mi.Bool, self.living)
        self.d_M = host_array(mi.Float64, self.M)
        self.d_h = host_array(mi.Float64, self.h)
        self.d_areas = host_array(mi.Float64, self.areas)
        self.d_base_albedo = host_array(mi.Float, self.base_albedo)
        self.d_terrain = dr.arange(mi.UInt32, n)
        dr.eval(self.d_living, self.d_M, self.d_h, self.d_areas, self.d_base_albedo)


def build_site(config: MossConfig, with_trees: bool = True, trees=None,
               bare: bool = False) -> Site:
    """Build a run's site (module docstring).

    Parameters
    ----------
    config : MossConfig
        The run's settings.
    with_trees : bool
        Put the scenario's ``[[trees]]`` and ``[[sensors]]`` into the light scene (tuning's
        moss-only model leaves them out).
    trees : list of WorldTree, optional
        The trees as they are now (a world whose trees grew), instead of building the
        scenario's ``[[trees]]``.
    bare : bool
        The leaf mesh with every blade taken out (:meth:`Canopy.shapes`): the scene rebuilt at
        the year's end, whose leaves start bare.

    Returns
    -------
    Site
        The site.
    """
    site = Site(config)
    site._build(with_trees, trees, bare)
    return site


def prepare_site(scenario: Scenario, days: int | None = None) -> Site:
    """The settings and the site of a moss run, as the daily loop builds them (without trees).

    Parameters
    ----------
    scenario : Scenario
        The loaded scenario.
    days : int, optional
        Simulated days [d] (default: the scenario's); the weather has one row per day.

    Returns
    -------
    Site
        Set up (scene, index, terrain arrays, soil water); ``site.config`` the settings.
    """
    return build_site(MossConfig(scenario, days), with_trees=False)
