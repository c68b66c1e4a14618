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
- **moss**: one tuft model per living moss (:mod:`mitsuba_veg.render.moss`), merged into one mesh per species,
  two-sided, blending the species' dark and light spectra by a per-vertex ``tone`` attribute.
- **trees**: bark tubes and leaves (:mod:`mitsuba_veg.render.trees`): leaves binned by autumn logical time, one
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
from .denoise import AUX_CAMERA, aux_sensor_dict
from .carpet import BUMP_SCALE, carpet_patches, grid_origin, moss_texture
from .moss import MossSet, place_tufts
from .noise import periodic_pink_noise_image
from .cameras import presets
from .trees import far_trees, leaf_bin_arrays, tree_shapes
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
    #: the ground around the scene to the horizon: "auto" (the scenario's ``render.surround``,
    #: else "ground"), "ground" (the ground's own material), a material name, or None / "none"
    surround: str | None = "auto"
    moss_jitter: float = 0.12
    #: draw each moss's carpet patch (its simulated cover); False: tufts only
    moss_carpet: bool = True
    seed: int = 0
    leaf_bins: int = 12
    #: Mitsuba's sampler (``multijitter``, ``ldsampler``, ``independent``, ...)
    sampler: str = "multijitter"
    #: denoise the display image (Open Image Denoise, :mod:`.denoise`); the EXR stays as rendered
    denoise: bool = True
    #: guide the denoiser with albedo and normal buffers (a pass of their own); off by default:
    #: on the measured views they raised the error against a converged render (docs/render.md)
    denoise_guides: bool = False
    #: draw the trees' fallen leaves on the ground (:mod:`mitsuba_veg.render.litter`)
    litter: bool = True
    #: a tree whose median leaf spans fewer pixels than this is drawn at its distant level of
    #: detail (leaf quads, Weber-Penn tubes; :func:`mitsuba_veg.render.trees.far_trees`); 0: none
    lod_pixels: float = 3.0

    @property
    def samples(self) -> int:
        """Samples per pixel as the sampler takes them: ``multijitter`` needs a x b samples
        (a = floor(sqrt(spp)), b = ceil(spp / a)), ``ldsampler`` a square power of two (the next
        power of 4 up); other samplers take ``spp`` as it is."""
        n = int(self.spp)
        if self.sampler == "multijitter":
            a = max(int(math.isqrt(n)), 1)
            return a * -(-n // a)
        if self.sampler == "ldsampler":
            k = 1
            while k < n:
                k *= 4
            return k
        return n

    def validate(self) -> "RenderOptions":
        """Check the settings' ranges.

        width and height 8-16384 [px], spp 1-2^20, max_depth 1-100, hour 0-24 [h],
        moss_jitter 0-2 [-], leaf_bins 1-64, surround ``"auto"``, ``"ground"``, ``"none"``, a
        material of :data:`~mitsuba_veg.render.materials.SPECTRA` or None.

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
        check_range("lod_pixels", self.lod_pixels, 0.0, 1000.0,
                    fix="pixels a leaf must span to be drawn in full (0: every tree in full)")
        if self.surround not in (None, "auto", "ground", "none") and \
                self.surround not in mat.SPECTRA:
            raise ParameterError("surround", self.surround, "'auto', 'ground', 'none', a material "
                                 "name or None", "one of " + ", ".join(sorted(mat.SPECTRA)))
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
    #: the trees drawn at their distant level of detail (:func:`~.trees.far_trees`)
    tree_far: np.ndarray | None = None
    #: the albedo/normal camera of the denoiser (None when the scene does not denoise)
    aux_sensor: mi.Sensor | None = None

    def update(self, moss: MossSet | None = None, trees=None) -> dict:
        """Replace the moss (and, when given, the trees' leaves) of the scene.

        The scene must have been built with ``species`` (and with trees when ``trees`` is given).
        The moss meshes (tufts and carpet) and the leaf-bin meshes get new buffers; the Mitsuba
        objects stay the same.

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
        parts = _moss_parts(moss, self.moss_size, self.options, self.species, self.terrain)
        for sid, part in parts.items():
            if f"{sid}.faces" not in keys:
                raise SceneError(f"update(): the scene has no mesh '{sid}': build it with "
                                 f"species={self.species!r}")
            flat = lambda a: np.ascontiguousarray(a).ravel()  # noqa: E731
            params[f"{sid}.vertex_positions"] = mi.Float(flat(part["v"]))
            params[f"{sid}.faces"] = mi.UInt32(flat(part["f"]))
            params[f"{sid}.vertex_tone"] = mi.Float(flat(part["tone"]))
            if "normals" in part:
                params[f"{sid}.vertex_normals"] = mi.Float(flat(part["normals"]))
                params[f"{sid}.vertex_texcoords"] = mi.Float(flat(part["uv"]))
        info["tufts"] = int(sum(p["count"] for sid, p in parts.items()
                                if not sid.startswith(CARPET_PREFIX)))
        if trees is not None:
            for sid, (v, f) in leaf_bin_arrays(trees, self.options, self.tree_cache,
                                               self.tree_far).items():
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
        # the sun's share of the light samples follows the new light, as in a scene built
        # for it (build_scene), so that both render the same image from the same seed
        emitters = weighted_sun(emitters)
        for name, d in emitters.items():
            kind = d.get("type")
            if kind == "directional":
                key = f"{name}.irradiance.values"
                if key not in keys:
                    raise SceneError(f"set_light(): the scene has no directional '{name}' "
                                     "with a spectrum: build it with daylight emitters")
                if "sampling_weight" in d and f"{name}.sampling_weight" in keys:
                    params[f"{name}.sampling_weight"] = float(d["sampling_weight"])
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


#: distance of the surround's far edge from the ground's centre [m]: from 20 m up its edge lies
#: 0.01 degrees below the horizon (under a pixel of a 1920-px, 50-degree view)
SURROUND_RADIUS = 1.0e5
#: materials chosen from a mesh's name when neither the scenario nor the scene file gives one
#: (shell-style patterns, first match wins)
NAME_MATERIALS = (("log*", "bark"), ("trunk*", "bark"), ("stump*", "wood"), ("branch*", "bark"),
                  ("rock*", "stone"), ("stone*", "stone"), ("boulder*", "stone"),
                  ("house*", "concrete"), ("wall*", "concrete"), ("building*", "concrete"),
                  ("roof*", "concrete"), ("path*", "asphalt"), ("road*", "asphalt"),
                  ("pavement*", "asphalt"), ("sand*", "sand"), ("gravel*", "gravel"))


def _plan_uv(v, metres_per_uv: float) -> np.ndarray:
    """Texture coordinates from the plan: (x, z) / ``metres_per_uv``."""
    v = np.asarray(v, np.float64)
    return (v[:, [0, 2]] / float(metres_per_uv)).astype(np.float32)


def _outer_boundary(v, f):
    """The vertex indices of a mesh's longest boundary loop, in order (None if it has none)."""
    f = np.asarray(f, np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    bnd = e[cnt[inv.ravel()] == 1]
    if len(bnd) < 3:
        return None
    nxt = dict(zip(bnd[:, 0].tolist(), bnd[:, 1].tolist()))
    loops, seen = [], set()
    for s0 in nxt:
        if s0 in seen:
            continue
        loop, p = [], s0
        while p not in seen and p in nxt:
            seen.add(p)
            loop.append(p)
            p = nxt[p]
        if p == s0 and len(loop) >= 3:
            loops.append(loop)
    if not loops:
        return None
    v = np.asarray(v, np.float64)
    # the outer loop encloses the largest area in plan
    def plan_area(lp):
        x, z = v[lp, 0], v[lp, 2]
        return abs(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1)))
    return np.array(max(loops, key=plan_area))


def _strips(rings):
    """Triangles joining consecutive closed loops of equal length (faces up)."""
    verts = np.concatenate(rings)
    n = len(rings[0])
    i = np.arange(n)
    j = (i + 1) % n
    faces = []
    for k in range(len(rings) - 1):
        a, b = k * n, (k + 1) * n
        faces += [np.c_[a + i, b + i, b + j], np.c_[a + i, b + j, a + j]]
    faces = np.concatenate(faces)
    p = verts[faces]
    down = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 1] < 0
    faces[down] = faces[down][:, [0, 2, 1]]
    return verts, faces


def scene_bsdf_ids(path) -> set:
    """The ids of the shapes that a Mitsuba XML scene file gives a BSDF of their own (a nested
    ``<bsdf>`` or a ``<ref>`` to one).

    Parameters
    ----------
    path : path-like
        The XML file.

    Returns
    -------
    set of str
        Shape ids.
    """
    import xml.etree.ElementTree as ET
    try:
        root = ET.parse(str(path)).getroot()
    except (ET.ParseError, OSError):
        return set()
    bsdf_ids = {el.get("id") for el in root.iter("bsdf") if el.get("id")}
    out = set()
    for sh in root.iter("shape"):
        sid = sh.get("id")
        if not sid:
            continue
        if sh.find("bsdf") is not None or any(r.get("id") in bsdf_ids for r in sh.findall("ref")):
            out.add(sid)
    return out


def resolve_materials(scn, meshes: dict, ground: str | None, base) -> dict:
    """The render material of every terrain mesh, in this order:

    1. the scenario's ``[render.materials]``: a shape id or a shell-style pattern (``"log_*"``)
       mapped to a material of :data:`~mitsuba_veg.render.materials.SPECTRA` (the first key that
       matches, in the file's order; a key that matches no mesh is refused);
    2. the scene file's own BSDF of that shape (the loaded object, as the file defines it);
    3. a material from the mesh's name (:data:`NAME_MATERIALS`: ``log_*`` bark, ``rock_*``
       stone, ``house``/``wall`` concrete, ...);
    4. its terrain role: the ``[terrain.geology]`` class of the moss model (humus, sand,
       asphalt; humus by default).

    Parameters
    ----------
    scn : Scenario
        The scenario.
    meshes : dict
        The terrain meshes by id.
    ground : str or None
        The ground's id.
    base : mitsuba.Scene
        The loaded scene (its shapes' BSDF objects).

    Returns
    -------
    dict
        ``{id: material name or mitsuba.BSDF}``.

    Raises
    ------
    ParameterError
        If ``[render.materials]`` names an unknown material or a key matches no mesh.
    """
    import fnmatch
    given = dict(scn.get("render.materials", {}) or {})
    for k, v in given.items():
        if v not in mat.SPECTRA:
            raise ParameterError(f"render.materials.{k}", v, "one of " +
                                 ", ".join(sorted(mat.SPECTRA)), None, str(scn.path))
        if not any(fnmatch.fnmatchcase(sid, k) for sid in meshes):
            raise ParameterError("render.materials", k, "a mesh id or pattern of the scene: " +
                                 ", ".join(meshes), "remove it or fix its name", str(scn.path))
    own = scene_bsdf_ids(scn.file("scene.file")) if scn.get("scene.file") else set()
    objs = {sh.id(): sh.bsdf() for sh in base.shapes() if sh.is_mesh()}
    geology = dict(scn.get("terrain.geology", {}) or {})
    out = {}
    for sid in meshes:
        hit = next((v for k, v in given.items() if fnmatch.fnmatchcase(sid, k)), None)
        if hit is None and sid in own and sid in objs:
            hit = objs[sid]
        if hit is None:
            hit = next((m for pat, m in NAME_MATERIALS if fnmatch.fnmatchcase(sid.lower(), pat)),
                       None)
        if hit is None:
            hit = mat.GEOLOGY_MATERIAL.get(geology.get(sid, "humus"), "humus")
        out[sid] = hit
    return out


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
    #: id -> material name (:data:`~mitsuba_veg.render.materials.SPECTRA`) or the scene file's own
    #: BSDF object (:func:`resolve_materials`)
    materials: dict = field(default_factory=dict)

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
        # periodic: the ground's texture repeats over the surround without seams
        noise = periodic_pink_noise_image((512, 512), scale_px=128.0, seed=7)
        noise = np.clip(0.5 + 1.1 * noise, 0.0, 1.0).astype(np.float32)
        if ground is not None and meshes[ground][2] is None:
            # a ground without texture coordinates: its plan (x, z) over its extent, so that
            # the ground's 1/f texture varies over it
            v, f, _, nrm = meshes[ground]
            lo, hi = v.min(0), v.max(0)
            span = float(max(hi[0] - lo[0], hi[2] - lo[2], 1e-6))
            uv = np.c_[(v[:, 0] - lo[0]) / span, (v[:, 2] - lo[2]) / span].astype(np.float32)
            meshes[ground] = (v, f, uv, nrm)
            uv_scale = span
        materials = resolve_materials(scn, meshes, ground, base)
        return Terrain(meshes, ground, masks, noise, base, uv_scale, materials)

    # materials -------------------------------------------------------------------------------
    def _varied(self, name: str, noise: dict | None = None) -> dict:
        """A material's diffuse BSDF, varied by the 1/f noise (or the texture ``noise``) between
        it and its ``_light`` (or ``_dark``) variant where one exists."""
        noise = noise if noise is not None else _bitmap(self.noise, wrap="repeat")
        for other, first in ((name + "_light", True), (name + "_dark", False)):
            if other in mat.SPECTRA:
                a, b = (name, other) if first else (other, name)
                return mat.blend(mat.diffuse(a), mat.diffuse(b), noise)
        return mat.diffuse(name)

    def _mean(self, name: str) -> dict:
        """A material's diffuse BSDF, the even blend of it and its variant where one exists."""
        for other in (name + "_light", name + "_dark"):
            if other in mat.SPECTRA:
                return mat.blend(mat.diffuse(name), mat.diffuse(other), 0.5)
        return mat.diffuse(name)

    def ground_bsdf(self) -> dict:
        """The ground's (one-sided) BSDF dict.

        With geology masks (``terrain.geology_texture``): humus everywhere, sand and asphalt where
        their masks are 1 (nested ``blendbsdf`` nodes); each class varies between its dark and light
        spectrum by the 1/f noise image. Without them, the ground's material
        (:func:`resolve_materials`), varied the same way when it is a named spectrum.

        Returns
        -------
        dict or mitsuba.BSDF
            The BSDF (the scene file's own object where that is the ground's material).
        """
        if self.geology_masks is None:
            m = self.materials.get(self.ground, "humus")
            return self._varied(m) if isinstance(m, str) else m
        hum, sand, asph = self.geology_masks
        b = self._varied("humus")
        if sand.any():
            b = mat.blend(b, self._varied("sand"), _bitmap(sand))
        if asph.any():
            b = mat.blend(b, self._varied("asphalt"), _bitmap(asph))
        return b

    def grid_origin(self, size: float) -> np.ndarray:
        """The origin of the run's spot grid of cell ``size`` [m] (its cells are the moss
        carpet's patches): 1.5 cells below the terrain meshes' bounding box, as the daily loop
        builds it (:func:`mitsuba_veg.render.carpet.grid_origin`).

        Parameters
        ----------
        size : float
            The run's moss size [m].

        Returns
        -------
        numpy.ndarray
            (3,) [m].
        """
        v = np.concatenate([np.asarray(m[0], np.float64).reshape(-1, 3)
                            for m in self.meshes.values()])
        return grid_origin(v.min(0), size)

    # shapes -----------------------------------------------------------------------------------
    def shapes(self, surround: str | None = "ground") -> dict:
        """Mitsuba mesh dicts of the terrain, all two-sided.

        The ground gets :meth:`ground_bsdf`, other meshes their material
        (:func:`resolve_materials`: a named spectrum, varied by noise where it has a variant, or
        the scene file's own BSDF); ``surround`` adds ground around the scene out to
        :data:`SURROUND_RADIUS` (:meth:`surround`).

        Parameters
        ----------
        surround : str or None, optional
            Material of the ground around the scene: ``"ground"`` (default: the ground's own
            material, humus for a geology-textured ground), a material name, or None (no
            surround).

        Returns
        -------
        dict
            ``{id: mesh}`` for ``mi.load_dict``.
        """
        out = {}
        for sid, (v, f, uv, nrm) in self.meshes.items():
            if sid == self.ground:
                bsdf = self.ground_bsdf()
            else:
                m = self.materials.get(sid, "concrete")
                if isinstance(m, str):
                    # the 1/f variation over the mesh's own texture coordinates; without them the
                    # mean of the material's two tones (a projection would streak on walls)
                    bsdf = self._varied(m) if uv is not None else self._mean(m)
                else:
                    bsdf = m
            out[sid] = make_mesh(sid, v, f, {"type": "twosided", "bsdf": bsdf}, uv=uv,
                                 normals=nrm)
        if surround is not None:
            ring = self.surround()
            if ring is not None:
                m = surround
                if surround == "ground":
                    g = self.materials.get(self.ground, "humus")
                    m = "humus" if self.geology_masks is not None or not isinstance(g, str) \
                        else g
                (vn, fn), (vf, ff) = ring
                # the ground's texture at half contrast: it meets the far part's even tone
                # without a visible edge
                soft = _bitmap(0.25 + 0.5 * self.noise, wrap="repeat")
                out["surround"] = make_mesh("surround", vn, fn,
                                            {"type": "twosided", "bsdf": self._varied(m, soft)},
                                            uv=_plan_uv(vn, self.uv_scale))
                # the far ring without texture: a bitmap seen at grazing angles over kilometres
                # would alias into stripes
                out["surround_far"] = make_mesh("surround_far", vf, ff,
                                                {"type": "twosided", "bsdf": self._mean(m)})
        return out

    def surround(self, radius: float | None = None):
        """Ground around the scene to the horizon: a skirt from the ground's rim out to
        ``radius``, in two parts.

        The ground mesh's outer boundary loop is joined to copies of it scaled about the ground's
        centre (1.15 to 7 times its size) whose heights ease (smoothstep) from the rim's own to
        the rim's median height at 2.5 times: no gap at the rim, no ramp edges, flat beyond. The
        far part joins the last copy to a loop at ``radius``: from a camera a few metres up its
        edge lies within a hundredth of a degree of the horizon (the sky is zero below it).

        Parameters
        ----------
        radius : float, optional
            Distance of the far edge from the ground's centre [m] (default
            :data:`SURROUND_RADIUS`).

        Returns
        -------
        tuple or None
            ``((vertices, faces) near, (vertices, faces) far)`` [m], faces up; None without a
            ground or when its boundary is not a closed loop.
        """
        if self.ground is None:
            return None
        R = float(SURROUND_RADIUS if radius is None else radius)
        v, f = self.meshes[self.ground][0].astype(np.float64), self.meshes[self.ground][1]
        loop = _outer_boundary(v, f)
        if loop is None:
            return None
        b = v[loop]
        c = 0.5 * (v.min(0) + v.max(0))
        y = float(np.median(b[:, 1])) - 1e-3
        d = b[:, [0, 2]] - c[[0, 2]]
        r = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
        R = max(R, 4.0 * float(r.max()))
        rings = [b]
        for k in (1.15, 1.4, 1.8, 2.5, 4.0, 7.0):
            t = min((k - 1.0) / 1.5, 1.0)
            ease = t * t * (3.0 - 2.0 * t)
            h = b[:, 1] + (y - b[:, 1]) * ease
            rings.append(np.c_[c[0] + k * d[:, 0], h, c[2] + k * d[:, 1]])
        far = np.c_[c[0] + d[:, 0] / r * R, np.full(len(b), y), c[2] + d[:, 1] / r * R]
        return _strips(rings), _strips([rings[-1], far])

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


# ---- moss ----------------------------------------------------------------------------------------
#: mesh ids of the carpet: ``moss_carpet_<species>``; of the tufts: ``moss_<species>``
CARPET_PREFIX = "moss_carpet_"


def _empty_part(carpet: bool) -> dict:
    """One degenerate triangle far away: an "empty" mesh that keeps the scene's structure."""
    part = {"v": np.full((3, 3), -1e4, np.float32), "f": np.array([[0, 1, 2]], np.uint32),
            "tone": np.zeros(3, np.float32), "count": 0}
    if carpet:
        part.update(normals=np.tile(np.float32([0, 1, 0]), (3, 1)),
                    uv=np.zeros((3, 2), np.float32))
    return part


def _moss_parts(moss: MossSet | None, size: float, options: RenderOptions,
                species: list | None = None, terrain: "Terrain | None" = None) -> dict:
    """``{mesh id: {"v", "f", "tone", "count"[, "normals", "uv"]}}`` per species present: one
    merged tuft mesh (``moss_<species>``) and, with ``options.moss_carpet`` and a terrain, one
    carpet mesh (``moss_carpet_<species>``, with shading normals and texture coordinates); empty
    ones for each key in ``species`` without moss."""
    out = {}
    carpet = bool(options.moss_carpet and terrain is not None)
    origin = terrain.grid_origin(size) if terrain is not None else None
    if moss is not None and len(moss):
        # tufts stand on the carpet's cushion (its edge ~0.05 size, its centre ~0.1 size high)
        for tm in place_tufts(moss, size=size, jitter=options.moss_jitter, seed=options.seed,
                              origin=origin, lift=0.08 * size if carpet else 0.0):
            out[f"moss_{tm.species}"] = {"v": tm.vertices, "f": tm.faces, "tone": tm.tone,
                                         "count": tm.count}
        if carpet:
            for cm in carpet_patches(moss, size, origin, scene=terrain.base_scene,
                                     seed=options.seed):
                out[f"{CARPET_PREFIX}{cm.species}"] = {
                    "v": cm.vertices, "f": cm.faces, "tone": cm.tone, "normals": cm.normals,
                    "uv": cm.uv, "count": cm.count}
    for sp in species or []:
        out.setdefault(f"moss_{sp}", _empty_part(False))
        if carpet:
            out.setdefault(f"{CARPET_PREFIX}{sp}", _empty_part(True))
    return dict(sorted(out.items()))


def _moss_bsdf(species: str, carpet: bool) -> dict:
    """The two-sided BSDF of a species' tufts or carpet.

    Tufts blend the species' dark and light spectra by their ``vertex_tone``. The carpet
    shows shoot tips (:func:`~mitsuba_veg.render.carpet.moss_texture`, over its texture
    coordinates in metres / :data:`~mitsuba_veg.render.carpet.TEXTURE_TILE`): on the tips the
    light spectrum (young leaves), between them the blend by ``vertex_tone``; the same texture
    bumps its shading.
    """
    key = species if species in mat.MOSS_MATERIAL else "hypnum_plumaeforme"
    dark = mat.diffuse(mat.MOSS_MATERIAL[key])
    light = mat.diffuse(mat.MOSS_MATERIAL[key] + "_light")
    toned = mat.blend(dark, light, {"type": "mesh_attribute", "name": "vertex_tone"})
    if not carpet:
        return {"type": "twosided", "bsdf": toned}
    tex = _bitmap(moss_texture(), wrap="repeat")
    return {"type": "twosided", "bsdf": {"type": "bumpmap", "arg": tex, "scale": BUMP_SCALE,
                                         "bsdf": mat.blend(toned, light, tex)}}


def moss_shapes(moss: MossSet | None, size: float, options: RenderOptions,
                species: list | None = None, terrain: "Terrain | None" = None
                ) -> tuple[dict, dict]:
    """Merged moss meshes (tufts and carpet, one each per species) and counts.

    Both are two-sided and blend the species' dark and light spectra (species without spectra
    of their own use ``hypnum_plumaeforme``'s; :func:`_moss_bsdf`).

    Parameters
    ----------
    moss : MossSet or None
        The living moss.
    size : float
        Moss size of the run [m].
    options : RenderOptions
        Gives ``moss_jitter``, ``moss_carpet`` and ``seed``.
    species : list of str, optional
        Species keys that always get meshes (empty ones without moss).
    terrain : Terrain, optional
        The terrain: its spot grid places the tufts and the carpet (:mod:`.carpet`); None: tufts
        at the moss positions and no carpet.

    Returns
    -------
    shapes : dict
        ``{"moss_<species>": mesh, "moss_carpet_<species>": mesh}``.
    info : dict
        ``tufts``, ``carpet_patches`` and ``moss_triangles`` counts.
    """
    out, info = {}, {"tufts": 0, "carpet_patches": 0, "moss_triangles": 0}
    for sid, part in _moss_parts(moss, size, options, species, terrain).items():
        carpet = sid.startswith(CARPET_PREFIX)
        sp = sid[len(CARPET_PREFIX if carpet else "moss_"):]
        out[sid] = make_mesh(sid, part["v"], part["f"], _moss_bsdf(sp, carpet),
                             uv=part.get("uv"), normals=part.get("normals"),
                             attributes={"vertex_tone": part["tone"]})
        info["carpet_patches" if carpet else "tufts"] += part["count"]
        info["moss_triangles"] += len(part["f"]) if part["count"] else 0
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


def weighted_sun(emitters: dict) -> dict:
    """The daylight with the sun's ``sampling_weight`` set to its share of the light.

    The path tracer picks one emitter per light sample in proportion to the emitters' sampling
    weights (1 each by default): half the samples of a sunlit pixel then went to the sky, which
    gives a sixth of its light on a clear morning. The sun's weight is the ratio of its horizontal
    irradiance to the sky's (their spectra's means over 360-830 nm; between 1 and 20), so light
    samples follow the light. The image's expectation is unchanged; its noise at 32 samples per
    pixel fell from 7.6 % to 5.4 % on the courtyard's midsummer overview (docs/render.md).

    Parameters
    ----------
    emitters : dict
        ``{"sun": directional dict, "sky": veg_sky dict}`` (:func:`sky_emitters`); other
        emitter dicts pass unchanged.

    Returns
    -------
    dict
        A copy with ``emitters["sun"]["sampling_weight"]`` set.
    """
    out = {k: dict(v) for k, v in emitters.items()}
    sun, sky = out.get("sun"), out.get("sky")
    if not (sun and sky and sun.get("type") == "directional" and "radiance" in sky):
        return out

    def mean(spec):
        v = spec.get("values") if isinstance(spec, dict) else spec
        if isinstance(v, str):
            return float(np.mean([float(x) for x in v.split(",")]))
        return float(np.mean(np.atleast_1d(spec.get("value", 0.0) if isinstance(spec, dict)
                                           else spec)))
    d = np.asarray(sun["direction"], float)
    cos_z = max(-d[1] / max(np.linalg.norm(d), 1e-12), 0.0)
    e_sun, e_sky = mean(sun["irradiance"]) * cos_z, np.pi * mean(sky["radiance"])
    if e_sky > 0:
        sun["sampling_weight"] = float(np.clip(e_sun / e_sky, 1.0, 20.0))
    return out


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
    info = {"tufts": 0, "carpet_patches": 0, "moss_triangles": 0, "trees": 0, "leaves": 0,
            "tree_triangles": 0}
    d = {"type": "scene",
         "integrator": {"type": "path", "max_depth": int(options.max_depth),
                        "rr_depth": 4, "hide_emitters": False}}
    if (moss is not None and len(moss)) or species:
        ms, mi_info = moss_shapes(moss, moss_size, options, species, terrain)
        d.update(ms)
        info.update(mi_info)
    t2 = time.perf_counter()
    surround = options.surround
    if surround == "auto":
        surround = scn.get("render.surround") or "ground"
        if surround != "ground" and surround != "none" and surround not in mat.SPECTRA:
            raise ParameterError("render.surround", surround, "'ground', 'none' or a material",
                                 "one of " + ", ".join(sorted(mat.SPECTRA)), str(scn.path))
    d.update(terrain.shapes(None if surround == "none" else surround))
    tree_far = None
    if trees:
        tree_cache = {} if tree_cache is None else tree_cache
        cam = presets(scn, terrain, moss, trees, only=options.camera).get(options.camera)
        tree_far = far_trees(trees, cam, options.width, options.lod_pixels)
        ts, t_info = tree_shapes(trees, options, cache=tree_cache, far=tree_far)
        d.update(ts)
        info.update(t_info)
        if options.litter:      # the fallen leaves on the ground (render/litter.py)
            ls, l_info = litter_shapes(trees, terrain, options, cache=tree_cache)
            d.update(ls)
            info.update(l_info)
    t3 = time.perf_counter()
    when = render_time(scn, date, options)
    em = emitters if emitters is not None else sky_emitters(scn, when)
    d.update(weighted_sun(em))
    d["camera"] = sensor_dict(scn, terrain, options, film_dict(options), moss, trees)
    if options.denoise and options.denoise_guides:
        d[AUX_CAMERA] = aux_sensor_dict(d["camera"])
    scene = mi.load_dict(d, optimize=False)
    attach_scene(scene)
    sensors = {s.id(): s for s in scene.sensors()}
    sensor = sensors["camera"]
    t4 = time.perf_counter()
    info.update({"when": when, "camera": options.camera,
                 "triangles": int(sum(s.face_count() for s in scene.shapes() if s.is_mesh())),
                 "seconds": {"terrain": t1 - t0, "moss": t2 - t1, "trees": t3 - t2,
                             "load": t4 - t3, "total": t4 - t0}})
    return RenderScene(scene, sensor, options, info, terrain, float(moss_size),
                       list(species or []), tree_cache, tree_far, sensors.get(AUX_CAMERA))
