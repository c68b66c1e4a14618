"""Site preparation for a moss run, shared by the daily loop and the tuning model
(:func:`mitsuba_veg.tune.smooth.prepare`): the light scene with its sun-path and sky emitters, the
scene index, the terrain arrays (geology, soil depth, where moss may live, moss capacity per
triangle, bare albedo per band, regions), the spot grid and the soil water at field capacity."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import soil as soil_model
from ..errors import ParameterError, check_range
from ..integrators.photon_irradiance import BANDS as B
from ..integrators.photon_irradiance import PhotonIrradianceIntegrator, SceneIndex
from ..moss.spatial import SpotGrid, max_per_element
from ..scenario import Scenario
from ..terrain import Terrain
from .config import BANDS, MossConfig


class MossSite(MossConfig):
    """A moss run's settings (:class:`MossConfig`) and, after :meth:`setup_site`, its site.

    Attributes (after :meth:`setup_site`)
    -------------------------------------
    scene : mitsuba.Scene
        The light scene; ``sun`` its ``veg_sun_path`` emitter, ``index`` its
        :class:`SceneIndex`, ``integrator`` the photon pass.
    terrain_shapes : list of str
        The scenario's mesh ids (their albedo follows the moss cover).
    geology, h, living, M : numpy.ndarray
        Per triangle: geology code, soil depth [mm], moss may live there, moss capacity.
    base_albedo : numpy.ndarray
        (triangles, bands) bare albedo at the band centres.
    regions : dict
        Region name -> triangle mask.
    grid : SpotGrid
        One cell per moss.
    O : numpy.ndarray
        Soil water per triangle [mm], at field capacity.
    """

    def setup_site(self) -> None:
        """Build the light scene (the scenario's shapes, :meth:`_extra_shapes`, the day's sun
        path and the sky), its index, the terrain arrays, the spot grid and the soil water at
        field capacity."""
        base = self.scn.load_scene(daylight=False)
        d = {"type": "scene"}
        for sh in base.shapes():
            d[sh.id()] = sh
        self.terrain_shapes = [sh.id() for sh in base.shapes() if sh.is_mesh()]
        d.update(self._extra_shapes(base))
        d["sun"] = {"type": "veg_sun_path", "id": "sun"}
        d["sky"] = {"type": "veg_sky", "id": "sky", "distribution": "uniform",
                    "radiance": {"type": "uniform", "value": 1.0 / np.pi}}
        self.scene = mi.load_dict(d, optimize=False)
        self.sun = [e for e in self.scene.emitters() if e.id() == "sun"][0]
        self.index = SceneIndex.build(self.scene)
        self.integrator = PhotonIrradianceIntegrator()
        self._setup_terrain()
        lo, hi = np.array(self.index.aim_bbox.min), np.array(self.index.aim_bbox.max)
        size = float(self.moss_cfg["size"])
        span = float(np.max(hi - lo))
        smallest = span / (SpotGrid.max_cells_per_axis - 3)
        if size < smallest:
            raise ParameterError("moss.size", size, f">= {smallest:.3g} m for this scene "
                                 f"({span:.3g} m across: the spot grid holds at most "
                                 f"{SpotGrid.max_cells_per_axis:,d} cells per axis)",
                                 "use a larger moss size or a smaller scene",
                                 str(self.scn.path))
        self.grid = SpotGrid(lo, hi, size, int(self.moss_cfg["capacity"]))
        self.O = soil_model.bucket_capacity(self.h, self.geology).astype(np.float64)  # saturated

    def _extra_shapes(self, base) -> dict:
        """Shapes added to the light scene besides the scenario's (a world adds its trees)."""
        return {}

    def _setup_terrain(self):
        src = str(self.scn.path)
        idx = self.index
        n = idx.n_elements
        ground = self.scn.get("terrain.ground", "ground")
        meshes = [s for s in idx.shape_ids if s in idx.geometry]

        def need_shape(field, sid):
            if sid not in idx.geometry:
                raise ParameterError(field, sid, "a mesh id of the scene: " + ", ".join(meshes),
                                     "use one of the scene's shape ids (loaded with "
                                     "optimize=False)", src)
        need_shape("terrain.ground", ground)
        for sec in ("geology", "soil_depth_mm"):
            for sid in (self.scn.get(f"terrain.{sec}", {}) or {}):
                need_shape(f"terrain.{sec}.{sid}", sid)
        for name, reg in (self.scn.get("regions", {}) or {}).items():
            for sid in reg["shapes"]:
                need_shape(f"regions.{name}.shapes", sid)
        self.geology = np.full(n, soil_model.geology_code("asphalt"), np.int64)
        self.h = np.ones(n)
        geo_over = self.scn.get("terrain.geology", {}) or {}
        depth_over = self.scn.get("terrain.soil_depth_mm", {}) or {}
        living = self.moss_cfg["shapes"] or [s for s in self.terrain_shapes if s in idx.geometry]
        self.living = np.zeros(n, bool)
        for sid in idx.shape_ids:
            if sid not in idx.geometry:
                continue
            sl = idx.shape_slice(sid)
            v, f = idx.geometry[sid]
            terr = Terrain.from_arrays(v, f, name=sid)
            if sid == ground:
                shape = [s for s in self.scene.shapes() if s.id() == sid][0]
                terr = Terrain.from_mitsuba(shape)
                tex = self.scn.get("terrain.geology_texture")
                if tex:
                    path = self.scn.file("terrain.geology_texture")
                    try:
                        self.geology[sl] = terr.geology_from_texture(path)
                    except (OSError, ValueError, SyntaxError) as e:  # PIL: unreadable image
                        raise ParameterError("terrain.geology_texture", tex, "a readable PNG/JPEG "
                                             "image", f"replace {path.name} ({e})", src) from None
                base_y = self.scn.get("terrain.soil_base_y")
                self.h[sl] = terr.soil_depth_mm(base_y)
            if sid in geo_over:
                self.geology[sl] = soil_model.geology_code(geo_over[sid])
            if sid in depth_over:
                self.h[sl] = check_range(f"terrain.soil_depth_mm.{sid}", depth_over[sid], 1.0,
                                         1000.0, source=src)
            if sid in living:
                self.living[sl] = True
        for sid in living:
            if sid not in idx.geometry:
                raise ParameterError("moss.shapes", sid, f"mesh ids among {list(idx.geometry)}",
                                     None, src)
        self.living_dr = mi.Bool(self.living)
        self.M = max_per_element(idx.areas, self.grid_cell())
        self.base_albedo = self._base_albedo()
        self.regions = {}
        for name, reg in (self.scn.get("regions", {}) or {}).items():
            mask = np.zeros(n, bool)
            for sid in reg["shapes"]:
                sl = idx.shape_slice(sid)
                c = idx.centroids[sl]
                mask[sl] = np.all((c >= np.array(reg["min"])) & (c <= np.array(reg["max"])), 1)
            self.regions[name] = mask

    def _base_albedo(self) -> np.ndarray:
        """Albedo of the bare surfaces per element and band, from their BSDFs at the band
        centres (diffuse reflectance at the triangle's centroid)."""
        n = self.index.n_elements
        out = np.zeros((n, len(BANDS)))
        lam = [0.5 * (B[b][0] + B[b][1]) for b in BANDS]
        for sh in self.scene.shapes():
            if sh.id() not in self.terrain_shapes:
                continue  # only the terrain's albedo is replaced (moss cover)
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


def prepare_site(scenario: Scenario, days: int | None = None) -> MossSite:
    """The settings and the site of a moss run, as the daily loop builds them.

    Parameters
    ----------
    scenario : Scenario
        The loaded scenario.
    days : int, optional
        Simulated days [d] (default: the scenario's); the weather has one row per day.

    Returns
    -------
    MossSite
        Set up (scene, index, terrain arrays, spot grid, soil water).
    """
    site = MossSite(scenario, days)
    site.setup_site()
    return site
