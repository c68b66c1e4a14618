"""Scene assembly for the final spectral render (``mitsuba_veg.render``).

:func:`build_scene` turns a scenario plus simulation state into one Mitsuba scene:

- **terrain**: every mesh of the scenario's scene with an explicit spectral material. The ground
  (``terrain.ground``) is textured by its geology map (``terrain.geology_texture``: humus, sand,
  asphalt; :mod:`mitsuba_veg.terrain`): one mask per class (bitmap textures over the ground's
  UVs) selects the class's reflectance spectrum through nested ``blendbsdf``s, 1/f noise varies
  each class between a dark and a light spectrum, and a moss-cover texture (the living moss on
  the ground splatted into its UV space) blends in the spectrum of the moss carpet's base so that
  no bare soil shows between the tufts. Other meshes get ``[render.materials] <id> = "name"``
  (:data:`~mitsuba_veg.render.materials.SPECTRA`) or concrete.
- **surround**: an optional flat ring of gravel around the ground out to 2 km, so that views do
  not end at the garden's edge in black (the ``veg_sky`` is zero below the horizon).
- **moss**: one tuft model per living moss (:mod:`.moss`), merged into one mesh per species,
  two-sided, blending the species' dark and light spectra by a per-vertex ``tone`` attribute.
- **trees**: bark tubes and leaves (:mod:`.trees`): leaves binned by autumn logical time, one
  ``veg_leaf`` (PROSPECT-D) BSDF per bin (:mod:`mitsuba_veg.foliage`).
- **light**: the physical sun (``directional``) and sky (``veg_sky``) of
  :func:`mitsuba_veg.light.daylight` for the scenario's site and the render time, with explicit
  spectra over 360-830 nm (all of Mitsuba's range; the far-red band is inside it).
- **camera**: a preset (:mod:`.cameras`) with a ``specfilm`` (:mod:`.film`) that records CIE
  X, Y, Z and the red (655-665 nm) and far-red (725-735 nm) bands in one pass.
"""
from __future__ import annotations

import datetime as _dt
import math
import time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, SceneError, check_range
from ..integrators.veg_sky import VegSky, attach_scene
from ..light.clear_sky import daylight
from ..meshes import make_mesh, triangle_geometry  # noqa: F401 (make_mesh re-exported)
from ..terrain import classify_geology, load_texture_rgb
from ..scenario import site_offset_hours, site_time
from . import materials as mat
from .cameras import sensor_dict
from .film import film_dict
from .moss import MossSet, growth_scale, place_tufts
from .noise import pink_noise_image
from .trees import leaf_bin_arrays, tree_shapes
from .litter import litter_arrays, litter_shapes      # (litter: render/litter.py)

__all__ = ["RenderOptions", "RenderScene", "build_scene", "make_mesh", "render_time",
           "Terrain"]


#: allowed ranges of the image settings (inclusive), shared by :meth:`RenderOptions.validate`
#: and the command line's early check (:func:`mitsuba_veg.render.still.check_image`)
IMAGE_LIMITS = {"width": (8, 16384), "height": (8, 16384), "spp": (1, 1 << 20),
                "max_depth": (1, 100)}


@dataclass
class RenderOptions:
    """Settings of a render (all optional)."""

    width: int = 960
    height: int = 540
    spp: int = 64
    max_depth: int = 6
    camera: str = "overview"
    #: ISO date-time of the light; None: the day being rendered at ``hour`` local time
    when: str | None = None
    hour: float = 10.0
    #: material of the ring around the ground (None: no ring)
    surround: str | None = "gravel"
    moss_jitter: float = 0.35
    seed: int = 0
    leaf_bins: int = 12
    cover_resolution: int = 1024
    sampler: str = "multijitter"
    #: draw the trees' fallen leaves on the ground (:mod:`mitsuba_veg.render.litter`)
    litter: bool = True

    @property
    def samples(self) -> int:
        """Samples per pixel as the sampler takes them: ``multijitter`` needs a x b samples
        (a = floor(sqrt(spp)), b = ceil(spp / a)); other samplers take ``spp`` as it is."""
        n = int(self.spp)
        if self.sampler == "multijitter":
            a = max(int(math.isqrt(n)), 1)
            return a * -(-n // a)
        return n

    def validate(self) -> "RenderOptions":
        """Check the settings' ranges.

        width and height 8-16384 [px], spp 1-2^20, max_depth 1-100, hour 0-24 [h],
        moss_jitter 0-2 [-], leaf_bins 1-64, cover_resolution 16-8192 [px], surround a material of
        :data:`~mitsuba_veg.render.materials.SPECTRA` or None.

        Returns
        -------
        RenderOptions
            ``self``, unchanged.

        Raises
        ------
        ParameterError
            If a setting is out of range.
        """
        check_range("width", self.width, *IMAGE_LIMITS["width"], fix="image width in pixels")
        check_range("height", self.height, *IMAGE_LIMITS["height"], fix="image height in pixels")
        check_range("spp", self.spp, *IMAGE_LIMITS["spp"], fix="samples per pixel, e.g. 64")
        check_range("max_depth", self.max_depth, *IMAGE_LIMITS["max_depth"])
        check_range("hour", self.hour, 0.0, 24.0, fix="local time of day in hours, e.g. 10.5")
        check_range("moss_jitter", self.moss_jitter, 0.0, 2.0)
        check_range("leaf_bins", self.leaf_bins, 1, 64)
        check_range("cover_resolution", self.cover_resolution, 16, 8192)
        if self.surround is not None and self.surround not in mat.SPECTRA:
            raise ParameterError("surround", self.surround, "a material name or None",
                                 "one of " + ", ".join(sorted(mat.SPECTRA)))
        return self


@dataclass
class RenderScene:
    """An assembled scene, its camera and what it holds. :meth:`update` swaps the moss and the
    leaves in place (same Mitsuba objects, new buffers), so that an animation compiles its
    rendering kernel once."""

    scene: mi.Scene
    sensor: mi.Sensor
    options: RenderOptions
    info: dict = field(default_factory=dict)
    terrain: "Terrain | None" = None
    moss_size: float = 0.01
    species: list = field(default_factory=list)
    tree_cache: dict | None = None

    def update(self, moss: MossSet | None = None, trees=None) -> dict:
        """Replace the moss (and, when given, the trees' leaves) of the scene.

        The scene must have been built with ``species`` (and with trees when ``trees`` is given).
        The moss meshes, the ground's moss-cover texture and the leaf-bin meshes get new buffers;
        the Mitsuba objects stay the same.

        Parameters
        ----------
        moss : MossSet, optional
            The living moss to show (None or empty: no moss; every species mesh becomes empty).
        trees : list of Tree, optional
            Trees whose leaf state (autumn tau, fallen, leaf-out scale) to show; None keeps the
            leaves as they are.

        Returns
        -------
        dict
            The new counts: ``{"tufts": int}`` (also merged into :attr:`info`).

        Raises
        ------
        SceneError
            If the scene has no moss mesh for a species of ``moss``.
        """
        params = mi.traverse(self.scene)
        keys = set(params.keys())
        info = {}
        parts = _moss_parts(moss, self.moss_size, self.options, self.species)
        for sid, (v, f, tone, count) in parts.items():
            if f"{sid}.faces" not in keys:
                raise SceneError(f"update(): the scene has no mesh '{sid}': build it with "
                                 f"species={self.species!r}")
            params[f"{sid}.vertex_positions"] = mi.Float(np.ascontiguousarray(v).ravel())
            params[f"{sid}.faces"] = mi.UInt32(np.ascontiguousarray(f).ravel())
            params[f"{sid}.vertex_tone"] = mi.Float(np.ascontiguousarray(tone).ravel())
        info["tufts"] = int(sum(c for *_, c in parts.values()))
        g = self.terrain.ground if self.terrain is not None else None
        ck = f"{g}.bsdf.brdf_0.weight.data"
        if g is not None and ck in keys:
            cover = self.terrain.moss_cover(moss, self.moss_size, self.options.cover_resolution) \
                if moss is not None and len(moss) else None
            shape = tuple(params[ck].shape)
            if cover is None or cover.shape != shape[:2]:
                cover = np.zeros(shape[:2], np.float32) if cover is None else cover
            params[ck] = mi.TensorXf(np.ascontiguousarray(cover.reshape(shape)))
        if trees is not None:
            for sid, (v, f) in leaf_bin_arrays(trees, self.options, self.tree_cache).items():
                if f"{sid}.faces" in keys:
                    params[f"{sid}.vertex_positions"] = mi.Float(np.ascontiguousarray(v).ravel())
                    params[f"{sid}.faces"] = mi.UInt32(np.ascontiguousarray(f).ravel())
            # ---- litter (render/litter.py): the same fixed meshes, new buffers ----
            if self.options.litter and self.terrain is not None:
                la = litter_arrays(trees, self.terrain, self.options, self.tree_cache)
                info["litter"] = la.pop("count")
                for sid, (v, f) in la.items():
                    if f"{sid}.faces" in keys:
                        params[f"{sid}.vertex_positions"] = mi.Float(
                            np.ascontiguousarray(v).ravel())
                        params[f"{sid}.faces"] = mi.UInt32(np.ascontiguousarray(f).ravel())
            # ---- end litter ----
        params.update()
        self.info.update(info)
        return info

    def set_light(self, emitters: dict, when: str | None = None) -> None:
        """Give the scene another daylight in place (an animation's ``--light daily``).

        The sun's direction and spectrum and the sky's spectrum are traversed parameters; the sky's
        sun and Perez distribution are moved with :meth:`VegSky.set_sky`. Array sizes do not change,
        so the rendering kernel compiled for the first frame is reused.

        Parameters
        ----------
        emitters : dict
            ``{"sun": directional dict, "sky": veg_sky dict}`` as :func:`mitsuba_veg.light.daylight`
            makes them for the scene's spectral range (the same number of spectrum values as the
            scene was built with; irradiance [W m-2 nm-1], radiance [W m-2 sr-1 nm-1]).
        when : str, optional
            The light's time, kept in :attr:`info` (``"when"``).

        Raises
        ------
        SceneError
            If the scene lacks an emitter of ``emitters`` or the number of spectrum values differs.
        ParameterError
            If an emitter is neither ``directional`` nor ``veg_sky``.
        """
        params = mi.traverse(self.scene)
        keys = set(params.keys())
        sky_objs = {em.id(): em for em in self.scene.emitters() if isinstance(em, VegSky)}
        for name, d in emitters.items():
            kind = d.get("type")
            if kind == "directional":
                key = f"{name}.irradiance.values"
                if key not in keys:
                    raise SceneError(f"set_light(): the scene has no directional '{name}' "
                                     "with a spectrum: build it with daylight emitters")
                dv = np.asarray(d["direction"], dtype=float)
                dv = [float(x) for x in dv / np.linalg.norm(dv)]
                params[f"{name}.to_world"] = mi.AffineTransform4f().to_frame(
                    mi.Frame3f(mi.Vector3f(*dv)))
                params[key] = _spectrum_values(d["irradiance"], params[key], name)
            elif kind == "veg_sky":
                if name not in sky_objs:
                    raise SceneError(f"set_light(): the scene has no veg_sky '{name}'")
                if sky_objs[name].spectrum_key != "radiance":
                    raise SceneError(f"set_light(): veg_sky '{name}' was built with "
                                     "'irradiance'; build it with daylight emitters ('radiance')")
                params[f"{name}.radiance.values"] = _spectrum_values(
                    d["radiance"], params[f"{name}.radiance.values"], name)
                sky_objs[name].set_sky(d["sun_direction"], d.get("perez_epsilon"),
                                       d.get("perez_delta"))
            else:
                raise ParameterError(f"emitters['{name}'].type", kind,
                                     "'directional' or 'veg_sky' (daylight emitters)")
        params.update()
        if when is not None:
            self.info["when"] = when


def _spectrum_values(spec: dict, current, name: str):
    """The values of a ``regular`` spectrum dict as the traversed array it replaces."""
    vals = spec["values"]
    vals = np.array([float(v) for v in vals.split(",")] if isinstance(vals, str) else vals,
                    dtype=np.float32)
    if len(vals) != dr.width(current):
        raise SceneError(f"set_light(): '{name}' has {dr.width(current)} spectrum values, the "
                         f"new light {len(vals)}: use the same wavelength range")
    return type(current)(vals)


# ---- meshes ------------------------------------------------------------------------------------
def _mesh_arrays(shape):
    p = mi.traverse(shape)
    v = np.asarray(p["vertex_positions"], np.float32).reshape(-1, 3)
    f = np.asarray(p["faces"], np.uint32).reshape(-1, 3)
    uv = None
    if shape.has_vertex_texcoords():
        uv = np.asarray(p["vertex_texcoords"], np.float32).reshape(-1, 2)
    nrm = None
    if shape.has_vertex_normals():
        nrm = np.asarray(p["vertex_normals"], np.float32).reshape(-1, 3)
    return v, f, uv, nrm


def _bitmap(img, raw=True, filter_type="bilinear", wrap="clamp") -> dict:
    a = np.ascontiguousarray(np.asarray(img, np.float32))
    if a.ndim == 2:
        a = a[..., None]
    return {"type": "bitmap", "bitmap": mi.Bitmap(a), "raw": raw, "filter_type": filter_type,
            "wrap_mode": wrap}


# ---- terrain -----------------------------------------------------------------------------------
@dataclass
class Terrain:
    """The scenario's meshes (arrays) and what the ground's material needs, built once per
    scenario and reused for every frame."""

    meshes: dict                      # id -> (v, f, uv, normals)
    ground: str | None
    geology_masks: list | None        # per class (humus, sand, asphalt): (H, W) float masks
    noise: np.ndarray                 # (H, W) 1/f noise in [0, 1]
    base_scene: mi.Scene              # the scenario's geometry (for ray casts)
    uv_scale: float = 1.0             # metres per UV unit on the ground
    materials: dict = field(default_factory=dict)   # id -> material name

    @staticmethod
    def from_scenario(scn) -> "Terrain":
        """Read the scenario's meshes and what the ground's material needs.

        The meshes of the scenario's scene (without daylight), the ground (``terrain.ground``,
        default ``"ground"``, when it is a mesh), its scale (metres per UV unit, from the 3D and UV
        areas), the geology masks of ``terrain.geology_texture`` (when given and the ground has
        UVs), a 512 x 512 1/f noise image and the ``[render.materials]`` of other meshes.

        Parameters
        ----------
        scn : Scenario
            The scenario.

        Returns
        -------
        Terrain
            The terrain, reused for every frame.

        Raises
        ------
        SceneError
            If the scene has no meshes.
        ParameterError
            If ``[render.materials]`` names an unknown material.
        """
        base = scn.load_scene(daylight=False)
        meshes = {}
        for sh in base.shapes():
            if sh.is_mesh():
                meshes[sh.id()] = _mesh_arrays(sh)
        if not meshes:
            raise SceneError(f"{scn.path}: the scene has no meshes to render")
        ground = scn.get("terrain.ground", "ground")
        ground = ground if ground in meshes else None
        masks = None
        uv_scale = 1.0
        if ground is not None and meshes[ground][2] is not None:
            v, f, uv, _ = meshes[ground]
            a3 = triangle_geometry(v, f)[0].sum()
            t = uv[f].astype(np.float64)
            a2 = 0.5 * np.abs((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) -
                              (t[:, 2, 0] - t[:, 0, 0]) * (t[:, 1, 1] - t[:, 0, 1])).sum()
            uv_scale = math.sqrt(a3 / a2) if a2 > 0 else 1.0
            if scn.get("terrain.geology_texture"):
                img = load_texture_rgb(scn.file("terrain.geology_texture"))
                codes = classify_geology(img)
                masks = [(codes == k).astype(np.float32) for k in range(3)]
        noise = pink_noise_image((512, 512), scale_px=96.0, octaves=6, seed=7)
        noise = np.clip(0.5 + 1.1 * noise, 0.0, 1.0).astype(np.float32)
        mats = dict(scn.get("render.materials", {}) or {})
        for k, v in mats.items():
            if v not in mat.SPECTRA:
                raise ParameterError(f"render.materials.{k}", v, "one of " +
                                     ", ".join(sorted(mat.SPECTRA)), None, str(scn.path))
        return Terrain(meshes, ground, masks, noise, base, uv_scale, mats)

    # ground material --------------------------------------------------------------------------
    def ground_bsdf(self, cover: np.ndarray | None) -> dict:
        """The ground's BSDF dict: geology classes, 1/f variation and moss cover.

        Humus everywhere, sand and asphalt where their masks are 1 (nested ``blendbsdf``s); each
        class varies between its dark and light spectrum by the noise image; the moss-carpet base
        spectrum is blended in by ``cover``. Without geology masks the ground's
        ``[render.materials]`` material (default humus) is used.

        Parameters
        ----------
        cover : numpy.ndarray or None
            Moss cover (H, W) in [0, 1] [-] over the ground's UV space (:meth:`moss_cover`), or
            None.

        Returns
        -------
        dict
            The (one-sided) BSDF dict.
        """
        noise = _bitmap(self.noise, wrap="repeat")

        def varied(name):
            light = name + "_light"
            if light not in mat.SPECTRA:
                return mat.diffuse(name)
            return mat.blend(mat.diffuse(name), mat.diffuse(light), noise)

        if self.geology_masks is None:
            b = varied(self.materials.get(self.ground, "humus"))
        else:
            hum, sand, asph = self.geology_masks
            # humus everywhere, sand where its mask is 1, asphalt where its mask is 1
            b = varied("humus")
            if sand.any():
                b = mat.blend(b, varied("sand"), _bitmap(sand))
            if asph.any():
                b = mat.blend(b, varied("asphalt"), _bitmap(asph))
        if cover is not None:
            b = mat.blend(b, mat.diffuse("moss_base"), _bitmap(cover))
        return b

    def moss_cover(self, moss: MossSet, size: float, resolution: int = 1024) -> np.ndarray | None:
        """Moss cover of the ground in its UV space (H, W) in [0, 1].

        Each moss on the ground (found by a 6 mm ray from 2 mm above it, down its normal) is
        splatted into a ``resolution`` x ``resolution`` image with weight ``growth_scale(G)^2`` and
        blurred with a Gaussian of sigma 0.45 ``size`` (the tuft's footprint).

        Parameters
        ----------
        moss : MossSet
            The living moss.
        size : float
            Moss size of the run [m].
        resolution : int, optional
            Image size [px] (default 1024).

        Returns
        -------
        numpy.ndarray or None
            Cover (resolution, resolution) float32 in [0, 1] [-]; None when there is no ground with
            UVs, no moss, or no moss on the ground.
        """
        if self.ground is None or self.meshes[self.ground][2] is None or len(moss) == 0:
            return None
        o = moss.pos + moss.nrm * 2e-3
        ray = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, k].astype(np.float32)) for k in range(3)]),
                       mi.Vector3f(*[mi.Float((-moss.nrm[:, k]).astype(np.float32))
                                     for k in range(3)]))
        ray.maxt = mi.Float(6e-3)
        si = self.base_scene.ray_intersect(ray)
        valid = np.asarray(si.is_valid())
        gid = np.array([s.id() == self.ground for s in self.base_scene.shapes()])
        reg = np.asarray(dr.reinterpret_array(mi.UInt32, self.base_scene.shapes_dr()))
        shp = np.asarray(dr.reinterpret_array(mi.UInt32, si.shape))
        on = valid & np.isin(shp, reg[gid])
        if not on.any():
            return None
        uv = np.stack([np.asarray(si.uv.x), np.asarray(si.uv.y)], 1)[on]
        R = int(resolution)
        img = np.zeros((R, R))
        col = np.clip((uv[:, 0] * R).astype(np.int64), 0, R - 1)
        row = np.clip((uv[:, 1] * R).astype(np.int64), 0, R - 1)
        w = growth_scale(moss.growth[on]) ** 2
        np.add.at(img, (row, col), w)
        # a disc of the tuft's footprint: Gaussian blur with sigma ~ 0.45 size (FFT)
        sigma = 0.45 * size / (self.uv_scale / R)
        img = _gauss_blur(img, sigma) * (2 * math.pi * sigma ** 2) * 0.9
        return np.clip(img, 0.0, 1.0).astype(np.float32)

    # shapes -----------------------------------------------------------------------------------
    def shapes(self, cover=None, surround: str | None = "gravel") -> dict:
        """Mitsuba mesh dicts of the terrain, all two-sided.

        The ground gets :meth:`ground_bsdf`, other meshes their ``[render.materials]`` spectrum
        (default concrete); ``surround`` adds a flat ring out to 2 km around the ground, 1 mm below
        its rim.

        Parameters
        ----------
        cover : numpy.ndarray, optional
            Moss cover of the ground (:meth:`moss_cover`), or None.
        surround : str or None, optional
            Material of the ring around the ground (default ``"gravel"``; None: no ring).

        Returns
        -------
        dict
            ``{id: mesh}`` for ``mi.load_dict``.
        """
        out = {}
        for sid, (v, f, uv, nrm) in self.meshes.items():
            if sid == self.ground:
                bsdf = self.ground_bsdf(cover)
            else:
                bsdf = mat.diffuse(self.materials.get(sid, "concrete"))
            out[sid] = make_mesh(sid, v, f, {"type": "twosided", "bsdf": bsdf}, uv=uv,
                                 normals=nrm)
        if surround is not None:
            ring = self._surround()
            if ring is not None:
                out["surround"] = make_mesh("surround", ring[0], ring[1],
                                            {"type": "twosided", "bsdf": mat.diffuse(surround)})
        return out

    def _surround(self, radius: float = 2000.0):
        if self.ground is None:
            return None
        v = self.meshes[self.ground][0].astype(np.float64)
        lo, hi = v.min(0), v.max(0)
        # the ground's rim height: vertices on its bounding rectangle
        rim = (np.isclose(v[:, 0], lo[0]) | np.isclose(v[:, 0], hi[0]) |
               np.isclose(v[:, 2], lo[2]) | np.isclose(v[:, 2], hi[2]))
        y = float(np.median(v[rim, 1])) - 1e-3 if rim.any() else float(lo[1])
        x0, x1, z0, z1 = lo[0], hi[0], lo[2], hi[2]
        R = radius
        inner = [(x0, z0), (x1, z0), (x1, z1), (x0, z1)]
        outer = [(-R, -R), (R, -R), (R, R), (-R, R)]
        verts = np.array([[x, y, z] for x, z in inner + outer])
        faces = []
        for i in range(4):
            j = (i + 1) % 4
            faces += [[i, 4 + i, 4 + j], [i, 4 + j, j]]
        faces = np.array(faces)
        # orient upwards (+y normals)
        p = verts[faces]
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        faces[n[:, 1] < 0] = faces[n[:, 1] < 0][:, [0, 2, 1]]
        return verts, faces

    def bbox(self):
        """Bounding box of all meshes.

        Returns
        -------
        lo, hi : numpy.ndarray
            Lower and upper corners (3,) [m].
        """
        v = np.concatenate([m[0] for m in self.meshes.values()])
        return v.min(0).astype(float), v.max(0).astype(float)

    def ground_bbox(self):
        """Bounding box of the ground (of all meshes when there is no ground).

        Returns
        -------
        lo, hi : numpy.ndarray
            Lower and upper corners (3,) [m].
        """
        if self.ground is None:
            return self.bbox()
        v = self.meshes[self.ground][0]
        return v.min(0).astype(float), v.max(0).astype(float)


def _gauss_blur(img, sigma):
    if sigma < 0.3:
        return img
    h, w = img.shape
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    g = np.exp(-2 * (math.pi * sigma) ** 2 * (fx ** 2 + fy ** 2))
    return np.fft.irfft2(np.fft.rfft2(img) * g, s=img.shape)


# ---- moss ----------------------------------------------------------------------------------------
_EMPTY = (np.full((3, 3), -1e4, np.float32), np.array([[0, 1, 2]], np.uint32),
          np.zeros(3, np.float32), 0)   # one degenerate triangle far away: an "empty" mesh


def _moss_parts(moss: MossSet | None, size: float, options: RenderOptions,
                species: list | None = None) -> dict:
    """{mesh id: (vertices, faces, tone, tuft count)}: one merged mesh per species present,
    and an empty one for each key in ``species`` without moss."""
    out = {}
    if moss is not None and len(moss):
        for tm in place_tufts(moss, size=size, jitter=options.moss_jitter, seed=options.seed):
            out[f"moss_{tm.species}"] = (tm.vertices, tm.faces, tm.tone, tm.count)
    for sp in species or []:
        out.setdefault(f"moss_{sp}", _EMPTY)
    return dict(sorted(out.items()))


def moss_shapes(moss: MossSet | None, size: float, options: RenderOptions,
                species: list | None = None) -> tuple[dict, dict]:
    """Merged tuft meshes (one per species) and counts.

    Each mesh is two-sided and blends the species' dark and light spectra by its per-vertex
    ``vertex_tone`` (species without spectra of their own use ``hypnum_plumaeforme``'s).

    Parameters
    ----------
    moss : MossSet or None
        The living moss.
    size : float
        Moss size of the run [m].
    options : RenderOptions
        Gives ``moss_jitter`` and ``seed``.
    species : list of str, optional
        Species keys that always get a mesh (an empty one without moss).

    Returns
    -------
    shapes : dict
        ``{"moss_<species>": mesh}``.
    info : dict
        ``tufts`` and ``moss_triangles`` counts.
    """
    out, info = {}, {"tufts": 0, "moss_triangles": 0}
    for sid, (v, f, tone, count) in _moss_parts(moss, size, options, species).items():
        sp = sid[len("moss_"):]
        key = sp if sp in mat.MOSS_MATERIAL else "hypnum_plumaeforme"
        dark = mat.diffuse(mat.MOSS_MATERIAL[key])
        light = mat.diffuse(mat.MOSS_MATERIAL[key] + "_light")
        bsdf = {"type": "twosided", "bsdf": mat.blend(dark, light, {
            "type": "mesh_attribute", "name": "vertex_tone"})}
        out[sid] = make_mesh(sid, v, f, bsdf, attributes={"vertex_tone": tone})
        info["tufts"] += count
        info["moss_triangles"] += len(f) if count else 0
    return out, info


# ---- light ---------------------------------------------------------------------------------------
def _timezone(scn) -> _dt.timezone:
    return _dt.timezone(_dt.timedelta(hours=site_offset_hours(scn.get("site") or {})))


def render_time(scn, date: _dt.date | None, options: RenderOptions) -> str:
    """ISO date-time of the render's daylight.

    ``options.when``, else the scenario's ``render.when``, else ``date`` at ``options.hour`` local
    time (time zone ``site.timezone`` [h] or longitude/15); without a date the scenario's
    ``light.when``, else 21 June 2026.

    Parameters
    ----------
    scn : Scenario
        The scenario (``render.when``, ``light.when``, ``site.timezone``, ``site.longitude``).
    date : datetime.date or None
        The day being rendered.
    options : RenderOptions
        Gives ``when`` and ``hour`` [h].

    Returns
    -------
    str
        ISO 8601 date-time (with a UTC offset when built from ``date``).
    """
    if options.when:      # without a UTC offset: local time at the site
        return site_time(options.when, scn.get("site") or {})
    if scn.get("render.when"):
        return str(scn.get("render.when"))
    if date is None:
        w = scn.get("light.when")
        if w:
            return str(w)
        date = _dt.date(2026, 6, 21)
    # rounded to the minute once (10.999 h is 11:00, not 10:60); hour 24 is the next midnight
    t = _dt.datetime(date.year, date.month, date.day, tzinfo=_timezone(scn)) \
        + _dt.timedelta(minutes=round(options.hour * 60.0))
    return t.isoformat()


def sky_emitters(scn, when: str) -> dict:
    """The physical sun and sky of the scenario's site at ``when``, over 360-830 nm.

    Parameters
    ----------
    scn : Scenario
        The scenario (``site.latitude``, ``site.longitude`` [degrees]).
    when : str
        ISO date-time of the light.

    Returns
    -------
    dict
        ``{"sun": directional dict, "sky": veg_sky dict}`` (:func:`mitsuba_veg.light.daylight`).

    Raises
    ------
    ParameterError
        If the sun is below the horizon at ``when``.
    """
    em = daylight(float(scn.get("site.latitude")), float(scn.get("site.longitude")), when,
                  wavelength_range=(360.0, 830.0))
    if not em:
        raise ParameterError("render time", when, "a time when the sun is above the horizon",
                             "choose another hour (--hour) or date (--when)", str(scn.path))
    return em


# ---- the scene -----------------------------------------------------------------------------------
def build_scene(scn, moss: MossSet | None = None, *, moss_size: float = 0.01,
                trees=None, date: _dt.date | None = None,
                options: RenderOptions | None = None, terrain: Terrain | None = None,
                tree_cache=None, emitters: dict | None = None,
                species: list | None = None) -> RenderScene:
    """Assemble the render scene (module docstring).

    Parameters
    ----------
    scn : Scenario
        The scenario.
    moss : MossSet, optional
        The living moss to show.
    moss_size : float, optional
        Moss size of the run [m] (default 0.01).
    trees : list of Tree, optional
        A list of :class:`~mitsuba_veg.trees.Tree` (leaves may carry ``autumn_tau`` and
        ``fallen`` attrs).
    date : datetime.date, optional
        The day being rendered (its light at ``options.hour``, see :func:`render_time`).
    options : RenderOptions, optional
        Render settings (default ``RenderOptions()``), validated.
    terrain : Terrain, optional
        A prebuilt :class:`Terrain` to reuse across frames.
    tree_cache : dict, optional
        Tree geometry cache (:func:`~mitsuba_veg.render.trees.tree_geometry`), kept in the result.
    emitters : dict, optional
        Sun and sky dicts to use instead of the daylight of ``date`` (an animation keeps one light
        so that every frame reuses the same compiled kernel).
    species : list of str, optional
        Species keys that always get a moss mesh (an empty one when no moss of theirs lives), for
        the same reason.

    Returns
    -------
    RenderScene
        The scene, its camera sensor, the options and ``info`` (counts, ``when``, ``camera``,
        ``triangles`` and build ``seconds`` [s]).
    """
    options = (options or RenderOptions()).validate()
    t0 = time.perf_counter()
    terrain = terrain or Terrain.from_scenario(scn)
    t1 = time.perf_counter()
    info = {"tufts": 0, "moss_triangles": 0, "trees": 0, "leaves": 0, "tree_triangles": 0}
    d = {"type": "scene",
         "integrator": {"type": "path", "max_depth": int(options.max_depth),
                        "rr_depth": 4, "hide_emitters": False}}
    cover = None
    if moss is not None and len(moss):
        cover = terrain.moss_cover(moss, moss_size, options.cover_resolution)
    if (moss is not None and len(moss)) or species:
        ms, mi_info = moss_shapes(moss, moss_size, options, species)
        d.update(ms)
        info.update(mi_info)
    if species and cover is None:
        cover = np.zeros((8, 8), np.float32)
    t2 = time.perf_counter()
    d.update(terrain.shapes(cover, options.surround))
    if trees:
        tree_cache = {} if tree_cache is None else tree_cache
        ts, t_info = tree_shapes(trees, options, cache=tree_cache)
        d.update(ts)
        info.update(t_info)
        if options.litter:      # the fallen leaves on the ground (render/litter.py)
            ls, l_info = litter_shapes(trees, terrain, options, cache=tree_cache)
            d.update(ls)
            info.update(l_info)
    t3 = time.perf_counter()
    when = render_time(scn, date, options)
    em = emitters if emitters is not None else sky_emitters(scn, when)
    d.update(em)
    d["camera"] = sensor_dict(scn, terrain, options, film_dict(options))
    scene = mi.load_dict(d, optimize=False)
    attach_scene(scene)
    sensor = [s for s in scene.sensors() if s.id() == "camera"][0]
    t4 = time.perf_counter()
    info.update({"when": when, "camera": options.camera,
                 "triangles": int(sum(s.face_count() for s in scene.shapes() if s.is_mesh())),
                 "seconds": {"terrain": t1 - t0, "moss": t2 - t1, "trees": t3 - t2,
                             "load": t4 - t3, "total": t4 - t0}})
    return RenderScene(scene, sensor, options, info, terrain, float(moss_size),
                       list(species or []), tree_cache)
