"""Photon-irradiance integrator: light tracing from the emitters, flux recorded per triangle.

Paper 000 §3.4 (moss from photon-mapped light): photons leave the light sources, hit the scene,
are *recorded at every hit* and are diffusely re-emitted with probability equal to the surface
reflectance (Russian roulette), otherwise absorbed. The paper counts photons near each soil
element with a KD-tree; here every hit adds its flux to the triangle it hit with a Dr.Jit
``scatter_add``, which gives the incident irradiance of each triangle directly:

    E_tri = (sum of photon flux hitting the triangle's front side) / area_tri      [W m-2]

Everything is vectorised: one pass per emitter is one symbolic Dr.Jit loop (one megakernel).

Spectral bands. A Mitsuba spectral sample carries 4 wavelengths. Each of the 4 slots is given to
one band (e.g. total, PAR, red, far-red): its wavelength is drawn uniformly (stratified over the
photons) inside the band and its weight is the emitter's spectral power times the band width,
so every photon path carries four band-integrated powers [W] at once. Paths are shared between
bands (same geometry), while reflectances are evaluated per band wavelength. More than 4 bands
take several passes.

Russian roulette (paper §3.4): at a hit with per-band albedo a_k (from the BSDF sample weight, or
a per-triangle override) the photon continues with probability q = max_k a_k and its band
powers become P_k a_k / q. For a grey surface q = a and the power is unchanged, exactly the
paper's "reflected with probability = reflectance" (1000 photons on a 0.5 surface: 500 go on).

Emitter sampling ("bounding-sphere aim", done tighter):
- directional and infinite emitters (sun, sky): the direction comes from the emitter
  (``sample_direction``), the origin is uniform over the rectangle that covers the projection of
  the scene geometry's bounding box on the plane perpendicular to the photon direction, so
  every photon crosses the box; weight = radiance/pdf x rectangle area.
- area emitters (the paper's square sun, eq 3.1): a uniform point on the emitter, a direction
  uniform in the cone that subtends the geometry's bounding sphere, weight = L cos(theta) /
  (pdf_pos pdf_dir). This is the paper's cosine emission with "re-draw photons that miss the
  bounding sphere", with the rejection replaced by an importance-sampled, equally unbiased
  estimator (no photon is drawn only to be thrown away).
- point-like emitters (point, spot, projector): origin at the light, direction uniform in the cone
  that subtends the bounding sphere (or the whole sphere when the light is inside it).

Surfaces are treated as two-sided for reflection (a photon hitting a back face reflects to the
back side, as a thin sheet would); only hits on the front side (the side the geometric normal
faces: moss lives there) count as front irradiance. Back-side flux is recorded separately.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import ParameterError, SceneError, check_range

#: Named spectral bands [nm]. "total" is Mitsuba's spectral range (360-830 nm, what its
#: irradiancemeter integrates); "shortwave" is the solar broadband range used for energy budgets.
BANDS: dict[str, tuple[float, float]] = {
    "total": (360.0, 830.0),
    "par": (400.0, 700.0),
    "red": (655.0, 665.0),
    "far_red": (725.0, 735.0),
    "shortwave": (300.0, 3000.0),
    "blue": (400.0, 500.0),
    "green": (500.0, 600.0),
    "nir": (700.0, 1100.0),
}

DEFAULT_BANDS = ("total", "par", "red", "far_red")
COMPONENTS = ("direct", "indirect", "total")
SIDES = ("front", "back")
_SLOTS = 4  # wavelengths carried by one Mitsuba spectral sample
_UInt64 = mi.UInt64
#: photons traced per kernel launch (bounded memory; larger counts run in batches)
DEFAULT_BATCH = 1 << 22


def _scalar(x) -> float:
    """A Python float from a width-1 Dr.Jit array (a reduction result)."""
    return float(np.asarray(x, dtype=np.float64).ravel()[0])


def band_range(band) -> tuple[float, float]:
    """Wavelength range [nm] of a band given by name (see :data:`BANDS`) or as (min, max)."""
    if isinstance(band, str):
        if band not in BANDS:
            raise ParameterError("band", band, f"one of {sorted(BANDS)} or a (min_nm, max_nm) pair",
                                 "use a known band name or pass the wavelength range explicitly")
        return BANDS[band]
    try:
        lo, hi = (float(v) for v in band)
    except (TypeError, ValueError):
        raise ParameterError("band", band, "a band name or a (min_nm, max_nm) pair") from None
    if not (0 < lo < hi):
        raise ParameterError("band", band, "0 < min_nm < max_nm", "swap or fix the bounds")
    return lo, hi


def _band_name(band) -> str:
    if isinstance(band, str):
        return band
    lo, hi = band_range(band)
    return f"{lo:g}-{hi:g}nm"


# --------------------------------------------------------------------------------------------
# Scene analysis: one flat element index over all shapes (triangles of meshes, 1 per other shape)
# --------------------------------------------------------------------------------------------
@dataclass
class SceneIndex:
    """Maps Mitsuba shapes to a flat range of elements (one per triangle, one per non-mesh)."""

    shape_ids: list[str]
    offsets: np.ndarray          # first element of each shape (in scene.shapes() order)
    counts: np.ndarray           # elements per shape
    areas: np.ndarray            # area of every element [m2]
    normals: np.ndarray          # geometric unit normal of every triangle (0 for non-meshes)
    centroids: np.ndarray        # centroid of every triangle [m]
    lookup: mi.UInt32            # registry id of a shape -> its offset
    aim_bbox: mi.ScalarBoundingBox3f  # geometry that photons are aimed at
    n_elements: int = 0
    geometry: dict = field(default_factory=dict)  # shape id -> (vertices, faces) of meshes

    @staticmethod
    def build(scene: mi.Scene) -> "SceneIndex":
        shapes = scene.shapes()
        if len(shapes) == 0:
            raise SceneError("the scene has no shapes: photons would have nothing to hit")
        reg = np.asarray(dr.reinterpret_array(mi.UInt32, scene.shapes_dr()), dtype=np.int64)
        counts, areas, normals, cents, ids, geometry = [], [], [], [], [], {}
        bbox = mi.ScalarBoundingBox3f()
        for sh in shapes:
            ids.append(sh.id())
            if sh.is_mesh() and sh.face_count() > 0:
                v = np.asarray(sh.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
                f = np.asarray(sh.faces_buffer(), dtype=np.int64).reshape(-1, 3)
                p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
                cr = np.cross(p1 - p0, p2 - p0)
                ln = np.linalg.norm(cr, axis=1)
                counts.append(len(f))
                areas.append(0.5 * ln)
                normals.append(cr / np.maximum(ln, 1e-30)[:, None])
                cents.append((p0 + p1 + p2) / 3.0)
                geometry[sh.id()] = (v, f)
            else:
                counts.append(1)
                areas.append(np.array([float(dr.ravel(sh.surface_area())[0])]))
                normals.append(np.zeros((1, 3)))
                b = sh.bbox()
                cents.append(np.array([[(b.min[i] + b.max[i]) / 2 for i in range(3)]]))
            # aim at geometry that can receive light: not at emitter shapes (e.g. a distant
            # area "sun") nor at sensor shapes
            if not (sh.is_emitter() or sh.is_sensor()):
                bbox.expand(sh.bbox())
        if not bbox.valid():
            bbox = scene.bbox()
        counts = np.asarray(counts, dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        lookup = np.zeros(int(reg.max()) + 1, dtype=np.uint32)
        lookup[reg] = offsets
        return SceneIndex(ids, offsets, counts, np.concatenate(areas), np.concatenate(normals),
                          np.concatenate(cents), mi.UInt32(lookup), bbox, int(counts.sum()),
                          geometry)

    def shape_slice(self, shape_id: str) -> slice:
        if shape_id not in self.shape_ids:
            raise SceneError(
                f"no shape with id '{shape_id}' in the scene (shapes: {self.shape_ids}). Mitsuba "
                f">= 3.7 merges meshes with equal BSDFs at load time and drops their ids: load "
                f"the scene with mi.load_dict(..., optimize=False) / mi.load_file(..., "
                f"optimize=False) to keep per-shape results")
        i = self.shape_ids.index(shape_id)
        return slice(int(self.offsets[i]), int(self.offsets[i] + self.counts[i]))


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------
@dataclass
class PhotonIrradianceResult:
    """Per-element flux of a photon pass and what can be derived from it.

    ``flux[e, i, c, s, b]`` is the photon power [W] that hit element ``i`` (a triangle) on side
    ``s`` (0 front, 1 back) for emitter ``e``, component ``c`` (0 direct = first hit, 1 indirect =
    after >= 1 diffuse bounce) and band ``b``. Irradiance = flux / area.
    """

    index: SceneIndex
    bands: tuple[str, ...]
    band_ranges: tuple[tuple[float, float], ...]
    emitters: tuple[str, ...]
    flux: np.ndarray
    photons: np.ndarray            # photons traced per emitter
    rays_traced: int               # ray casts made (every call of ray_intersect, per lane)
    emitted: np.ndarray            # [e, b] power leaving the emitters towards the geometry [W]
    escaped: np.ndarray            # [e, b] power that left the scene without a hit [W]
    absorbed: np.ndarray           # [e, b] power absorbed at hits (Russian roulette) [W]
    truncated: np.ndarray          # [e, b] power still travelling at max_depth / indirect off [W]
    seconds: float = 0.0
    settings: dict = field(default_factory=dict)

    # ---- queries --------------------------------------------------------------------------
    def _band(self, band) -> int:
        name = band if isinstance(band, str) else _band_name(band)
        if name not in self.bands:
            raise ParameterError("band", band, f"one of the traced bands {list(self.bands)}",
                                 "add it to bands=... of photon_irradiance()")
        return self.bands.index(name)

    def _emitters(self, emitter) -> list[int]:
        if emitter is None:
            return list(range(len(self.emitters)))
        if isinstance(emitter, (int, np.integer)):
            if not 0 <= emitter < len(self.emitters):
                raise ParameterError("emitter", emitter, f"0..{len(self.emitters) - 1}")
            return [int(emitter)]
        names = [emitter] if isinstance(emitter, str) else list(emitter)
        out = []
        for n in names:
            if n not in self.emitters:
                raise ParameterError("emitter", n, f"one of {list(self.emitters)}",
                                     "give the emitter an id in the scene, or use its index")
            out.append(self.emitters.index(n))
        return out

    def flux_of(self, shape_id: str, band="total", component="total", side="front",
                emitter=None) -> np.ndarray:
        """Incident power per element of a shape [W]."""
        if component not in COMPONENTS:
            raise ParameterError("component", component, f"one of {COMPONENTS}")
        if side not in SIDES + ("both",):
            raise ParameterError("side", side, "'front', 'back' or 'both'")
        sl = self.index.shape_slice(shape_id)
        b = self._band(band)
        f = self.flux[self._emitters(emitter)][:, sl].sum(axis=0)  # (n, comp, side, band)
        f = f[..., b]
        f = f.sum(axis=1) if component == "total" else f[:, COMPONENTS.index(component)]
        return f.sum(axis=1) if side == "both" else f[:, SIDES.index(side)]

    def irradiance(self, shape_id: str, band="total", component="total", side="front",
                   emitter=None) -> np.ndarray:
        """Incident irradiance per triangle of ``shape_id`` [W m-2] (one value a triangle).

        component: "direct" (first hit from the emitter), "indirect" (after diffuse bounces) or
        "total"; side: "front" (the side the normal faces), "back" or "both"; emitter: None (all),
        an emitter id/index or a list of them.
        """
        sl = self.index.shape_slice(shape_id)
        return self.flux_of(shape_id, band, component, side, emitter) / self.index.areas[sl]

    def element_irradiance(self, band="total", component="total", side="front",
                           emitter=None) -> np.ndarray:
        """Irradiance of every element of the scene (all shapes, in index order) [W m-2]."""
        if component not in COMPONENTS:
            raise ParameterError("component", component, f"one of {COMPONENTS}")
        f = self.flux[self._emitters(emitter)].sum(axis=0)[..., self._band(band)]
        f = f.sum(axis=1) if component == "total" else f[:, COMPONENTS.index(component)]
        f = f.sum(axis=1) if side == "both" else f[:, SIDES.index(side)]
        return f / np.maximum(self.index.areas, 1e-30)

    def photon_flux_density(self, shape_id: str, band="par", component="total", side="front",
                            emitter=None) -> np.ndarray:
        """Photon flux density [umol m-2 s-1] per triangle, converting each band's energy at its
        centre wavelength (exact to < 0.1 % for narrow bands; for PAR it assumes the band's
        spectrum is flat in energy, which for daylight is within ~2 %)."""
        lo, hi = self.band_ranges[self._band(band)]
        lam = 0.5 * (lo + hi) * 1e-9
        quanta_per_joule = lam / (6.62607015e-34 * 2.99792458e8) / 6.02214076e23 * 1e6
        return self.irradiance(shape_id, band, component, side, emitter) * quanta_per_joule

    def red_far_red(self, shape_id: str, component="total", side="front", emitter=None,
                    red="red", far_red="far_red") -> np.ndarray:
        """Red:far-red ratio per triangle as plants sense it: a ratio of photon fluxes
        (655-665 nm over 725-735 nm by default); NaN where no far-red arrives."""
        r = self.photon_flux_density(shape_id, red, component, side, emitter)
        fr = self.photon_flux_density(shape_id, far_red, component, side, emitter)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(fr > 0, r / np.where(fr > 0, fr, 1.0), np.nan)

    def total_flux(self, band="total") -> float:
        """Power that hit any element, both sides, all components [W]."""
        return float(self.flux[..., self._band(band)].sum())

    def to_npz(self, path) -> None:
        """Write every shape's irradiance arrays and the bookkeeping to a .npz file."""
        data = {"bands": np.array(self.bands), "emitters": np.array(self.emitters),
                "band_ranges_nm": np.array(self.band_ranges), "photons": self.photons,
                "rays_traced": np.array(self.rays_traced), "emitted_W": self.emitted,
                "escaped_W": self.escaped, "absorbed_W": self.absorbed,
                "truncated_W": self.truncated}
        for sid in self.index.shape_ids:
            if not sid:
                continue
            sl = self.index.shape_slice(sid)
            data[f"{sid}/area_m2"] = self.index.areas[sl]
            data[f"{sid}/centroid_m"] = self.index.centroids[sl]
            data[f"{sid}/normal"] = self.index.normals[sl]
            for b in self.bands:
                for c in COMPONENTS:
                    data[f"{sid}/{b}/{c}"] = self.irradiance(sid, b, c)
        tmp = str(path) + ".tmp.npz"
        np.savez_compressed(tmp, **data)
        import os
        os.replace(tmp, path)


# --------------------------------------------------------------------------------------------
# The integrator
# --------------------------------------------------------------------------------------------
class PhotonIrradianceIntegrator(mi.SamplingIntegrator):
    """Mitsuba integrator ``veg_photon_irradiance``: photon tracing with per-triangle records.

    Properties (all optional): ``photons`` (int, 1,000,000), ``max_depth`` (int, 8: surface hits
    per photon), ``indirect`` (bool, true), ``seed`` (int, 0).

    Use :meth:`trace` (or :func:`mitsuba_veg.light.photon_irradiance`) to run a pass. When used
    as a camera integrator with ``mi.render`` it shows the front irradiance [W m-2] of the last
    pass ("total" band, all emitters) on the surfaces a camera ray hits, a false-colour-ready
    visualisation of the light map.
    """

    def __init__(self, props=None):
        super().__init__(props if props is not None else mi.Properties())
        props = props if props is not None else mi.Properties()
        self.photons = int(props.get("photons", 1_000_000))
        self.max_depth = int(props.get("max_depth", 8))
        self.indirect = bool(props.get("indirect", True))
        self.seed = int(props.get("seed", 0))
        self._vis = None  # (lookup, per-element irradiance) of the last pass for render()
        self._index_cache: dict[int, SceneIndex] = {}

    # ---- camera visualisation ---------------------------------------------------------------
    def sample(self, scene, sampler, ray, medium=None, active=True):
        si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.Minimal, coherent=True, active=active)
        value = mi.Float(0.0)
        if self._vis is not None:
            lookup, irr = self._vis
            sid = dr.reinterpret_array(mi.UInt32, si.shape)
            idx = dr.gather(mi.UInt32, lookup, sid, si.is_valid()) + si.prim_index
            value = dr.gather(mi.Float, irr, idx, si.is_valid() & (dr.width(irr) > 0))
        return mi.Spectrum(value), si.is_valid(), []

    def aov_names(self):
        return []

    def to_string(self):
        return (f"PhotonIrradianceIntegrator[photons={self.photons}, max_depth={self.max_depth},"
                f" indirect={self.indirect}, seed={self.seed}]")

    # ---- the photon pass --------------------------------------------------------------------
    def trace(self, scene: mi.Scene, photons: int | None = None, seed: int | None = None,
              max_depth: int | None = None, bands=DEFAULT_BANDS, indirect: bool | None = None,
              reflectance: dict | None = None, emitters=None, batch: int = DEFAULT_BATCH,
              progress: bool = False) -> PhotonIrradianceResult:
        """Trace a photon pass over ``scene`` and return per-triangle fluxes.

        photons: total photon count, shared among the emitters in proportion to the power they
        send towards the geometry (each emitter gets at least 5 %). reflectance: optional
        ``{shape_id: array}`` of per-triangle albedos overriding the BSDF (Lambertian), shape
        (n_triangles,) for grey or (n_triangles, n_bands) per band; NaN entries keep the BSDF.
        emitters: optional list of emitter ids/indices to trace (default: all).
        """
        photons = self.photons if photons is None else photons
        seed = self.seed if seed is None else seed
        max_depth = self.max_depth if max_depth is None else max_depth
        indirect = self.indirect if indirect is None else indirect
        check_range("photons", photons, 1, None, fix="use a positive photon count, e.g. 1000000")
        check_range("max_depth", max_depth, 1, 1000, fix="max_depth counts surface hits, >= 1")
        check_range("seed", seed, 0, 2**31 - 1)
        check_range("batch", batch, 1024, None)
        photons, max_depth, seed, batch = int(photons), int(max_depth), int(seed), int(batch)
        if isinstance(bands, str):
            bands = (bands,)
        bands = tuple(bands)
        if not bands:
            raise ParameterError("bands", bands, "at least one band", "e.g. bands=('total',)")
        ranges = tuple(band_range(b) for b in bands)
        names = tuple(_band_name(b) for b in bands)
        if len(set(names)) != len(names):
            raise ParameterError("bands", bands, "distinct bands")

        t0 = _time.perf_counter()
        # the cache holds the scene itself: keyed by id() alone, a new scene allocated where a
        # freed one was would get the old scene's index
        cached = self._index_cache.get("scene")
        if cached is scene:
            index = self._index_cache["index"]
        else:
            index = SceneIndex.build(scene)
            self._index_cache = {"scene": scene, "index": index}
        all_emitters = scene.emitters()
        if len(all_emitters) == 0:
            raise SceneError("the scene has no emitters: add a sun (e.g. mitsuba_veg.light."
                             "daylight(...)) or any Mitsuba emitter")
        em_idx = self._select_emitters(all_emitters, emitters)
        em_names = tuple(all_emitters[i].id() or f"emitter{i}" for i in em_idx)

        n_el, n_b = index.n_elements, len(bands)
        groups = [list(range(i, min(i + _SLOTS, n_b))) for i in range(0, n_b, _SLOTS)]
        refl = self._reflectance_table(index, reflectance, n_b)

        # photon budget per emitter: proportional to the power each sends at the geometry
        power = np.array([self._pilot_power(scene, all_emitters[i], index, ranges[0])
                          for i in em_idx])
        if not np.all(np.isfinite(power)) or power.sum() <= 0:
            share = np.full(len(em_idx), 1.0 / len(em_idx))
        else:
            share = power / power.sum()
            share = np.maximum(share, 0.05 if len(em_idx) > 1 else 1.0)
            share /= share.sum()
        counts = np.maximum(np.round(share * photons).astype(np.int64), 1)

        flux = np.zeros((len(em_idx), n_el, 2, 2, n_b))
        book = np.zeros((4, len(em_idx), n_b))  # emitted, escaped, absorbed, truncated
        rays = 0
        bar = None
        if progress:
            from tqdm.auto import tqdm
            bar = tqdm(total=int(counts.sum()) * len(groups), unit="photon", unit_scale=True,
                       desc="photons")
        for e_i, e in enumerate(em_idx):
            emitter = all_emitters[e]
            for g_i, group in enumerate(groups):
                slot_ranges = [ranges[b] for b in group]
                slot_ranges += [slot_ranges[0]] * (_SLOTS - len(slot_ranges))
                refl_g = None if refl is None else refl[:, group + [group[0]] * (_SLOTS - len(group))]
                done = 0
                while done < counts[e_i]:
                    n = int(min(batch, counts[e_i] - done))
                    # a distinct, reproducible stream per (seed, emitter, band group, batch)
                    stream = (((seed * 31 + e) * 17 + g_i) * 1_000_003 + done // batch) & 0x7FFFFFFF
                    acc, bk, r = self._pass(scene, emitter, index, n, int(counts[e_i]), stream,
                                            slot_ranges, refl_g, max_depth, indirect)
                    flux[e_i, ..., group] += np.moveaxis(acc[..., :len(group)], -1, 0)
                    book[:, e_i, group] += bk[:, :len(group)]
                    rays += r
                    done += n
                    if bar is not None:
                        bar.update(n)
        if bar is not None:
            bar.close()
        res = PhotonIrradianceResult(
            index=index, bands=names, band_ranges=ranges, emitters=em_names, flux=flux,
            photons=counts, rays_traced=int(rays), emitted=book[0], escaped=book[1],
            absorbed=book[2], truncated=book[3], seconds=_time.perf_counter() - t0,
            settings=dict(photons=photons, seed=seed, max_depth=max_depth, indirect=indirect,
                          bands=list(names)))
        # front irradiance of the first band, all emitters and components: what render() shows
        irr_front = flux[..., 0].sum(axis=(0, 2))[:, 0] / np.maximum(index.areas, 1e-30)
        self._vis = (index.lookup, mi.Float(irr_front.astype(np.float32)))
        return res

    # ---- helpers ----------------------------------------------------------------------------
    @staticmethod
    def _select_emitters(all_emitters, emitters):
        if emitters is None:
            return list(range(len(all_emitters)))
        names = [e.id() for e in all_emitters]
        out = []
        for e in ([emitters] if isinstance(emitters, (str, int)) else emitters):
            if isinstance(e, (int, np.integer)) and 0 <= e < len(all_emitters):
                out.append(int(e))
            elif isinstance(e, str) and e in names:
                out.append(names.index(e))
            else:
                raise ParameterError("emitters", e, f"an index 0..{len(all_emitters) - 1} or an "
                                     f"id among {names}")
        return out

    @staticmethod
    def _reflectance_table(index: SceneIndex, reflectance, n_b):
        """Per-element override albedo (n_el, n_b) as mi.Float-ready numpy, NaN = use the BSDF."""
        if not reflectance:
            return None
        table = np.full((index.n_elements, n_b), np.nan, dtype=np.float32)
        for sid, arr in reflectance.items():
            sl = index.shape_slice(sid)
            n = sl.stop - sl.start
            a = np.asarray(arr, dtype=np.float64)
            if a.ndim == 0:
                a = np.full(n, float(a))
            if a.ndim == 1:
                a = np.repeat(a[:, None], n_b, axis=1)
            if a.shape != (n, n_b):
                raise ParameterError(f"reflectance['{sid}']", f"array of shape {np.shape(arr)}",
                                     f"shape ({n},) or ({n}, {n_b}): one albedo per triangle "
                                     f"(per band)")
            finite = a[np.isfinite(a)]
            if finite.size and (finite.min() < 0 or finite.max() > 1):
                raise ParameterError(f"reflectance['{sid}']",
                                     f"values in [{finite.min():g}, {finite.max():g}]", "[0, 1]",
                                     "albedos are fractions of the incident power")
            table[sl] = a
        return table

    # emitter classification ----------------------------------------------------------------
    @staticmethod
    def _kind(emitter) -> str:
        f = emitter.flags()
        if mi.has_flag(f, mi.EmitterFlags.Infinite) or mi.has_flag(f, mi.EmitterFlags.DeltaDirection):
            if mi.has_flag(f, mi.EmitterFlags.Surface):
                raise SceneError(f"emitter '{emitter.id()}' ({emitter.class_name()}) is a surface "
                                 "with delta directions, which the photon pass does not support; "
                                 "use a 'directional' emitter for parallel light")
            return "directional"
        if mi.has_flag(f, mi.EmitterFlags.Surface):
            return "area"
        if mi.has_flag(f, mi.EmitterFlags.DeltaPosition):
            return "point"
        raise SceneError(f"emitter '{emitter.id()}' ({emitter.class_name()}) has flags {int(f)} "
                         "that the photon pass does not know how to sample")

    def _pilot_power(self, scene, emitter, index, rng_nm) -> float:
        """Estimated power [W] that an emitter sends towards the geometry (for the budget)."""
        n = 4096
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(12345, n)
        lam = mi.Float(rng_nm[0]) + (rng_nm[1] - rng_nm[0]) * sampler.next_1d()
        wav = mi.Spectrum(lam, lam, lam, lam)
        _, _, w, _ = self._emit(scene, emitter, index, sampler, wav, mi.Bool(True))
        return _scalar(dr.mean(w[0])) * (rng_nm[1] - rng_nm[0])

    def _emit(self, scene, emitter, index, sampler, wav, active, strata=None):
        """Sample photon origins/directions: returns (origin, direction, weight, time).

        weight = spectral power per photon at ``wav`` [W nm-1] x number of photons, i.e. the
        Monte-Carlo estimate of the emitter's spectral power towards the geometry.
        """
        kind = self._kind(emitter)
        time = sampler.next_1d()  # spreads photons over a `timed_sunsky`'s shutter
        bb = index.aim_bbox
        bmin, bmax = np.array(bb.min), np.array(bb.max)
        center = [float(c) for c in 0.5 * (bmin + bmax)]
        radius = max(0.5 * float(np.linalg.norm(bmax - bmin)), 1e-6)
        if kind == "directional":
            it = dr.zeros(mi.Interaction3f)
            it.p = mi.Point3f(*center)
            it.time = time
            it.wavelengths = wav
            ds, w = emitter.sample_direction(it, sampler.next_2d(), active)
            d = -ds.d  # photons travel away from the source
            frame = mi.Frame3f(d)
            # project the 8 box corners on (s, t, d); the rectangle covers the box's shadow
            smin = tmin = dmin = mi.Float(1e30)
            smax = tmax = mi.Float(-1e30)
            for cx in (bmin[0], bmax[0]):
                for cy in (bmin[1], bmax[1]):
                    for cz in (bmin[2], bmax[2]):
                        c = mi.Vector3f(float(cx), float(cy), float(cz))
                        ps, pt, pd = dr.dot(c, frame.s), dr.dot(c, frame.t), dr.dot(c, d)
                        smin, smax = dr.minimum(smin, ps), dr.maximum(smax, ps)
                        tmin, tmax = dr.minimum(tmin, pt), dr.maximum(tmax, pt)
                        dmin = dr.minimum(dmin, pd)
            pad = 1e-4 * radius  # keeps photons grazing the box's faces
            smin, tmin, smax, tmax = smin - pad, tmin - pad, smax + pad, tmax + pad
            u = sampler.next_2d()
            if strata is not None:
                # jittered-grid stratification of the origins over the rectangle: the direct
                # light of a sun is then almost noise-free
                idx, m = strata
                m_u = dr.opaque(mi.UInt32, m)
                cell = mi.Point2f(mi.Float(idx % m_u), mi.Float(idx // m_u))
                u = dr.select(idx < m_u * m_u, (cell + u) * dr.opaque(mi.Float, 1.0 / m), u)
            su = dr.lerp(smin, smax, u.x)
            tv = dr.lerp(tmin, tmax, u.y)
            o = frame.s * su + frame.t * tv + d * (dmin - 0.01 * radius - 1e-3)
            area = (smax - smin) * (tmax - tmin)
            return mi.Point3f(o), d, w * area, time
        if kind == "area":
            ps, w_pos = emitter.sample_position(time, sampler.next_2d(), active)
            to_c = mi.Vector3f(*center) - ps.p
            dist = dr.norm(to_c)
            inside = dist <= radius * 1.0001
            cos_a = dr.safe_sqrt(1 - dr.square(radius / dr.maximum(dist, 1e-30)))
            cone_frame = mi.Frame3f(to_c / dr.maximum(dist, 1e-30))
            s2 = sampler.next_2d()
            d_cone = cone_frame.to_world(mi.warp.square_to_uniform_cone(s2, cos_a))
            pdf_cone = mi.warp.square_to_uniform_cone_pdf(mi.Vector3f(0, 0, 1), cos_a)
            n_frame = mi.Frame3f(ps.n)
            d_hemi = n_frame.to_world(mi.warp.square_to_cosine_hemisphere(s2))
            d = dr.select(inside, d_hemi, d_cone)
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.p, si.n, si.uv, si.time, si.wavelengths = ps.p, ps.n, ps.uv, time, wav
            si.sh_frame = mi.Frame3f(ps.n)
            si.wi = si.sh_frame.to_local(d)
            L = emitter.eval(si, active)
            cos_t = dr.dot(d, ps.n)
            # cosine hemisphere: L cos / (cos/pi) = pi L ; cone: L cos / pdf_cone
            w_dir = dr.select(inside, dr.pi, dr.select(cos_t > 0, cos_t / pdf_cone, 0.0))
            w = L * (w_dir * w_pos)
            return ps.p + ps.n * (1e-5 * radius), d, w, time
        # point-like
        it = dr.zeros(mi.Interaction3f)
        it.p, it.time, it.wavelengths = mi.Point3f(*center), time, wav
        ds0, _ = emitter.sample_direction(it, mi.Point2f(0.5, 0.5), active)
        p = ds0.p
        to_c = mi.Vector3f(*center) - p
        dist = dr.norm(to_c)
        inside = dist <= radius * 1.0001
        cos_a = dr.safe_sqrt(1 - dr.square(radius / dr.maximum(dist, 1e-30)))
        s2 = sampler.next_2d()
        d_cone = mi.Frame3f(to_c / dr.maximum(dist, 1e-30)).to_world(
            mi.warp.square_to_uniform_cone(s2, cos_a))
        d = dr.select(inside, mi.warp.square_to_uniform_sphere(s2), d_cone)
        pdf = dr.select(inside, mi.warp.square_to_uniform_sphere_pdf(d),
                        mi.warp.square_to_uniform_cone_pdf(mi.Vector3f(0, 0, 1), cos_a))
        it2 = dr.zeros(mi.Interaction3f)
        it2.p, it2.time, it2.wavelengths = p + d, time, wav  # unit distance: weight = I(d)
        _, I = emitter.sample_direction(it2, mi.Point2f(0.5, 0.5), active)
        return p, d, I / pdf, time

    # the kernel -----------------------------------------------------------------------------
    def _pass(self, scene, emitter, index, n, n_total, stream, slot_ranges, refl, max_depth,
              indirect):
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(stream, n)
        idx = dr.arange(mi.UInt32, n)
        # Band wavelengths from a randomly shifted Weyl (golden-ratio) sequence over the photon
        # index, in exact 32-bit fixed point: evenly spread over each band (low variance), each
        # photon's wavelength uniform (unbiased), and, unlike index-ordered strata, not
        # correlated with the jittered-grid origin strata (which also follow the index).
        shifts = np.random.default_rng(stream).integers(0, 2**32, size=_SLOTS, dtype=np.uint64)
        lam, widths = [], []
        for k, (lo, hi) in enumerate(slot_ranges):
            bits = idx * dr.opaque(mi.UInt32, 2654435769) + dr.opaque(mi.UInt32, int(shifts[k]))
            uk = mi.Float(bits >> 8) * dr.opaque(mi.Float, 2.0 ** -24)
            lam.append(dr.opaque(mi.Float, lo) + dr.opaque(mi.Float, hi - lo) * uk)
            widths.append(hi - lo)
        wav = mi.Spectrum(*lam)
        active = mi.Bool(True)
        m = int(math.isqrt(n))
        o, d, w, time = self._emit(scene, emitter, index, sampler, wav, active,
                                   strata=(idx, m))
        # power per photon [W]: spectral power x band width / photons of this emitter
        throughput = mi.Spectrum(
            *[w[k] * dr.opaque(mi.Float, widths[k] / n_total) for k in range(_SLOTS)])
        # (a sun's weight is the same for all photons: broadcast it to one value per photon)
        throughput = mi.Spectrum(dr.select(dr.isfinite(throughput), throughput, 0.0)) \
            * dr.full(mi.Float, 1.0, n)
        emitted = [dr.sum(throughput[k]) for k in range(_SLOTS)]  # before the loop mutates it
        ray = mi.Ray3f(o, d, time, wav)

        n_el = index.n_elements
        # Fixed-point accumulation: integer atomics are associative, so the result does not
        # depend on the order in which threads add (float atomics would differ in the last bits
        # from run to run, and a resumed simulation must be bit-identical). A photon's power is
        # quantised to 2^-40 of the largest initial power (per slot); 2^22 photons x 2^40 fits in
        # 64 bits with room to spare.
        dr.eval(throughput, ray)
        pmax = max(_scalar(dr.max(throughput[k])) for k in range(_SLOTS))
        scale = float(2.0 ** 40 / pmax) if pmax > 0 else 1.0
        acc = dr.zeros(_UInt64, n_el * 2 * 2 * _SLOTS)
        lookup = index.lookup
        refl_arr = None if refl is None else mi.Float(np.ascontiguousarray(refl, np.float32).ravel())
        esc = dr.zeros(mi.Spectrum, n)
        absd = dr.zeros(mi.Spectrum, n)
        depth = mi.UInt32(0)
        active = dr.any(throughput > 0)
        max_d = dr.opaque(mi.UInt32, max_depth)
        one_hit = not indirect

        throughput_left, rays_lane, esc, absd = self._loop(
            scene, sampler, ray, throughput, active, depth, max_d, acc, esc, absd, lookup,
            refl_arr, one_hit, dr.opaque(mi.Float, scale))
        # one kernel: evaluate every output of the symbolic loop together (evaluating them one by
        # one would re-run the loop for each)
        dr.eval(acc, throughput_left, rays_lane, esc, absd, emitted)
        bk = np.zeros((4, _SLOTS))
        bk[0] = [_scalar(emitted[k]) for k in range(_SLOTS)]
        bk[1] = [_scalar(dr.sum(esc[k])) for k in range(_SLOTS)]
        bk[2] = [_scalar(dr.sum(absd[k])) for k in range(_SLOTS)]
        bk[3] = [_scalar(dr.sum(throughput_left[k])) for k in range(_SLOTS)]
        acc_np = (np.asarray(acc, dtype=np.uint64).astype(np.float64) / scale).reshape(
            n_el, 2, 2, _SLOTS)
        return acc_np, bk, int(_scalar(dr.sum(mi.Float(rays_lane))))

    @dr.syntax
    def _loop(self, scene, sampler, ray, throughput, active, depth, max_d, acc, esc, absd,
              lookup, refl_arr, one_hit, scale):
        nrays = mi.UInt32(0)
        bsdf_ctx = mi.BSDFContext(mi.TransportMode.Importance)
        while dr.hint(active, label="veg_photon_irradiance"):
            si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False,
                                     active=active)
            nrays += dr.select(active, mi.UInt32(1), mi.UInt32(0))
            hit = active & si.is_valid()
            # escaped photons leave with their power
            esc = mi.Spectrum(esc + dr.select(active & ~hit, throughput, 0.0))
            throughput = mi.Spectrum(dr.select(active & ~hit, 0.0, throughput))

            # record the incident power at the hit element: [elem][comp][side][slot]
            sid = dr.reinterpret_array(mi.UInt32, si.shape)
            elem = dr.gather(mi.UInt32, lookup, sid, hit) + si.prim_index
            back = dr.dot(si.n, ray.d) > 0
            comp = dr.select(depth > 0, mi.UInt32(1), mi.UInt32(0))
            side = dr.select(back, mi.UInt32(1), mi.UInt32(0))
            base = ((elem * 2 + comp) * 2 + side) * _SLOTS
            for k in range(_SLOTS):
                q_k = _UInt64(dr.round(throughput[k] * scale))
                dr.scatter_add(acc, q_k, base + k, hit)

            if one_hit:
                active = mi.Bool(False)
            else:
                # mirror back-face hits so that every surface reflects on both sides
                wi_world = -ray.d
                si.wi = si.to_local(wi_world)
                flip = si.wi.z < 0
                si.wi = dr.select(flip, mi.Vector3f(si.wi.x, si.wi.y, -si.wi.z), si.wi)
                bsdf = si.bsdf(ray)
                bs, bw = bsdf.sample(bsdf_ctx, si, sampler.next_1d(hit), sampler.next_2d(hit), hit)
                wo_local = bs.wo
                albedo = mi.Spectrum(bw)
                if refl_arr is not None:
                    ov = [dr.gather(mi.Float, refl_arr, elem * _SLOTS + k, hit) for k in range(_SLOTS)]
                    use_ov = hit & ~dr.isnan(ov[0])
                    wo_cos = mi.warp.square_to_cosine_hemisphere(sampler.next_2d(hit))
                    wo_local = dr.select(use_ov, wo_cos, wo_local)
                    albedo = mi.Spectrum(dr.select(use_ov, mi.Spectrum(*ov), albedo))
                    bs.pdf = dr.select(use_ov, 1.0, bs.pdf)
                albedo = mi.Spectrum(dr.select(dr.isfinite(albedo) & (bs.pdf > 0), albedo, 0.0))
                # mirror the outgoing direction back for flipped hits
                wo_local = dr.select(flip, mi.Vector3f(wo_local.x, wo_local.y, -wo_local.z),
                                     wo_local)
                q = dr.minimum(dr.max(albedo), 1.0)
                go = hit & (sampler.next_1d(hit) < q)
                new_thr = throughput * albedo / dr.maximum(q, 1e-12)
                absd = mi.Spectrum(absd + dr.select(go, throughput - new_thr,
                                                    dr.select(hit, throughput, 0.0)))
                throughput = mi.Spectrum(dr.select(go, new_thr, dr.select(hit, 0.0, throughput)))
                ray = si.spawn_ray(si.to_world(wo_local))
                depth += 1
                active = go & (depth < max_d)
        return throughput, nrays, esc, absd
