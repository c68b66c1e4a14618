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

The plugin (this module) holds the properties, Mitsuba's ``render`` / ``render_forward`` /
``render_backward``, :meth:`PhotonIrradianceIntegrator.trace` (a pass in batches, its result) and
:meth:`PhotonIrradianceIntegrator.trace_paths` (recorded weights-mode paths). The random walk
itself (emission, Russian roulette or weights, hits, per-element tables, instances) is
:mod:`.photon_kernel`; the element layout :mod:`.scene_index`; the result :mod:`.photon_result`;
the differentiable replay :mod:`.photon_replay`; the bands :mod:`.bands`.
"""
from __future__ import annotations

import time as _time

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.arrays import opaque as _opaque
from mitsuba_veg.defaults import LIGHT, check_light
from mitsuba_veg.errors import ParameterError, SceneError, check_range

# the pass's parts, one module each: bands, scene index, result, kernel, replay (names used by
# other modules are imported from here too: the plugin module is the integrator's public face)
from .bands import (BANDS, COMPONENTS, DEFAULT_BANDS, SIDES, _SLOTS,  # noqa: F401
                    _band_name, _scalar, band_range, parse_bands)
from . import photon_replay as _replay
from .photon_kernel import (DEFAULT_BATCH, HIDDEN, KERNEL_MODES, SENSOR, SURFACE,  # noqa: F401
                            _NO_ROW, _SWITCH_BSDFS, LaneSampler, LaunchInputs, PassTables,
                            PhotonKernel, aim_area, split_photons, switch_table)
from .photon_result import (DeviceTallies, PhotonIrradianceResult,  # noqa: F401
                            PhotonPathRecord, fixed_point_scale)
from .scene_index import (SceneIndex, _reg_id, emitter_name, registry_id,  # noqa: F401
                          scene_index)
from .plugin_table import Parameter, with_parameter_table

__all__ = ["PhotonIrradianceIntegrator"]

_UInt64 = mi.UInt64


@with_parameter_table
class PhotonIrradianceIntegrator(PhotonKernel):
    r"""Mitsuba integrator ``veg_photon_irradiance``: photon tracing with per-element records.

    Traces photons from the scene's emitters (paper 000 §3.4, see the module docstring) and
    records the power that hits every element: each triangle of each mesh, each triangle of each
    instance (keyed by instance id) and each analytic shape as one element. ``mi.render(scene)``
    with this integrator (or :meth:`render`) runs the pass with the plugin's properties and
    returns a tensor of irradiance [W m-2]:

    ``image[element, band, component, side]`` with component 0 = direct (first hit), 1 =
    indirect (after >= 1 bounce) and side 0 = front (the side the geometric normal faces), 1 =
    back; summed over emitters. The element order is ``scene.shapes()`` order (triangles of a
    shape or instance consecutive); :attr:`result` (a :class:`PhotonIrradianceResult`) holds the
    last pass with the element layout, per-emitter flux and the energy bookkeeping.
    :func:`mitsuba_veg.light.photon_irradiance` is a thin wrapper over the same path.

    Example (XML)::

        <integrator type="veg_photon_irradiance">
            <integer name="photons" value="2000000"/>
            <string name="bands" value="par,red,far_red"/>
        </integrator>

    ``mi.render`` needs a sensor in the scene (Mitsuba's rule; the element output does not use
    it); :meth:`render` and :meth:`trace` do not.

    Derivatives, the Mitsuba way: ``mi.render(scene, params)`` with gradients enabled on BSDF
    reflectances or emitter parameters of ``params = mi.traverse(scene)``, then ``dr.backward``
    (or ``dr.forward``) of a loss, reaches :meth:`render_backward` (:meth:`render_forward`):
    replays of weights-mode paths (:meth:`trace_paths`, :meth:`replay`), exact derivatives of
    the replayed estimate for Lambertian BSDFs; geometry is not differentiated.
    """

    #: the name the plugin is registered under, and its kind
    PLUGIN, PLUGIN_KIND = "veg_photon_irradiance", "integrator"
    #: every property the constructor reads (the docstring's table and the docs' plugin page)
    PARAMETERS = (
        Parameter("photons", "integer", str(LIGHT["photons"].default),
                  "Photons per pass, shared among the emitters by the power they send towards "
                  "the geometry (each >= 5 %), 1 - 1e9. With ``output=\"elements\"`` this is the "
                  "pass's whole effort: ``mi.render(..., spp=N)`` is refused (a photon pass has "
                  "no samples per pixel); with ``output=\"image\"``, ``spp`` is the camera's "
                  "samples per pixel of the light map."),
        Parameter("max_depth", "integer", str(LIGHT["max_depth"].default),
                  "Most surface hits per photon (1 = direct light only), 1-1000."),
        Parameter("seed", "integer", str(LIGHT["seed"].default),
                  "Random seed, 0 - 2^31 - 1; ``mi.render(scene, seed=k)`` traces with "
                  "``seed + k``."),
        Parameter("indirect", "boolean", str(LIGHT["indirect"].default).lower(),
                  "false: record only the first hit (no inter-reflection)."),
        Parameter("bands", "string", '"total,par,red,far_red"',
                  "Comma-separated band names of ``BANDS`` or ranges ``\"500-510\"`` [nm]."),
        Parameter("emitters", "string", '"" (all)', "Comma-separated ids of the emitters to trace."),
        Parameter("batch", "integer", str(LIGHT["batch"].default),
                  "Photons per kernel launch, >= 1024 (bounds memory; any size is exact)."),
        Parameter("mode", "string", '"roulette"',
                  "\"roulette\": a photon goes on after a hit with probability max_k a_k (paper "
                  "000 §3.4). \"weights\": every photon goes on (cosine-weighted) up to "
                  "``max_depth`` hits, its power multiplied by the albedo (same expectation; what "
                  "the differentiable pass replays)."),
        Parameter("output", "string", '"elements"',
                  "\"elements\": the element tensor above. \"image\": run the pass, then show "
                  "the sensor's view of the front irradiance [W m-2] of the first band (a light "
                  "map)."),
    )

    def __init__(self, props=None):
        super().__init__(props if props is not None else mi.Properties())
        props = props if props is not None else mi.Properties()
        # defaults and ranges: mitsuba_veg.defaults.LIGHT (one table for every front end)
        self.photons = int(props.get("photons", LIGHT["photons"].default))
        self.max_depth = int(props.get("max_depth", LIGHT["max_depth"].default))
        self.indirect = bool(props.get("indirect", LIGHT["indirect"].default))
        self.seed = int(props.get("seed", LIGHT["seed"].default))
        self.bands = parse_bands(props.get("bands", ",".join(DEFAULT_BANDS)))
        em = str(props.get("emitters", "")).strip()
        self.emitters = tuple(s.strip() for s in em.split(",") if s.strip()) or None
        self.batch = int(props.get("batch", DEFAULT_BATCH))
        self.output = str(props.get("output", "elements"))
        self.mode = str(props.get("mode", "roulette"))
        if self.mode not in KERNEL_MODES:
            raise ParameterError("mode", self.mode, "'roulette' or 'weights'",
                                 "<string name=\"mode\" value=\"roulette\"/>")
        if self.output not in ("elements", "image"):
            raise ParameterError("output", self.output, "'elements' or 'image'",
                                 "<string name=\"output\" value=\"elements\"/>")
        for name in ("photons", "max_depth", "seed", "batch"):
            check_light(name, getattr(self, name))
        self.result: PhotonIrradianceResult | None = None  # the last pass
        self._frozen = None   # the frozen launch (trace(..., frozen=True))
        self._lobes: dict = {}   # emission cones of point-like emitters (:meth:`_lobe`)
        self._vis = None  # (lookup, per-element irradiance) shown by the image output

    # ---- Mitsuba's render interface ---------------------------------------------------------
    def render(self, scene, sensor=None, seed=0, spp=0, develop=True, evaluate=True):
        """Run the photon pass with the plugin's properties; return the element tensor.

        Parameters
        ----------
        scene : mi.Scene
            The scene (load with ``optimize=False`` to keep per-shape ids).
        sensor : mi.Sensor or int, optional
            Used only by ``output="image"``.
        seed : int
            Added to the ``seed`` property (``mi.render(scene, seed=k)`` gives independent
            passes).
        spp : int
            ``output="image"``: the camera's samples per pixel (0: 1). ``output="elements"``:
            must be 0 (the ``photons`` property sets the effort; another value is refused).
        develop, evaluate : bool
            As for Mitsuba integrators.

        Returns
        -------
        mi.TensorXf
            ``output="elements"``: irradiance [W m-2], shape (elements, bands, 2 components
            (direct, indirect), 2 sides (front, back)). ``output="image"``: the sensor's image of
            the front irradiance of the first band [W m-2].
        """
        k = int(np.asarray(dr.ravel(seed))[0]) if not isinstance(seed, int) else int(seed)
        if self.output == "elements" and int(spp or 0) != 0:
            raise ParameterError(
                "spp", int(spp), "0 (mi.render's default) for output='elements'",
                "a photon pass has no samples per pixel: set its effort with the integrator's "
                f"photons property, e.g. <integer name=\"photons\" value=\"{4 * self.photons}\"/>")
        res = self.trace(scene, seed=(self.seed + k) & 0x7FFFFFFF)
        if self.output == "elements":
            return mi.TensorXf(res.tensor().astype(np.float32))
        irr = res.element_irradiance(band=res.bands[0], side="front")
        self._vis = (res.index.lookup, mi.Float(irr.astype(np.float32)))
        if sensor is None:
            sensor = 0
        if isinstance(sensor, int):
            if len(scene.sensors()) == 0:
                raise SceneError("output='image' needs a sensor in the scene")
            sensor = scene.sensors()[sensor]
        return mi.SamplingIntegrator.render(self, scene, sensor, seed=k, spp=max(int(spp), 1),
                                            develop=develop, evaluate=evaluate)

    def sample(self, scene, sampler, ray, medium=None, active=True):
        """Camera rays of the image output: the front irradiance of the hit element [W m-2].

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        sampler : mi.Sampler
            Mitsuba's sampler (unused: the value is a lookup).
        ray : mi.RayDifferential3f
            Camera rays.
        medium : mi.Medium, optional
            Unused.
        active : mi.Bool
            Active lanes.

        Returns
        -------
        tuple
            (``mi.Spectrum`` front irradiance of the first band [W m-2], ``mi.Bool`` hit,
            empty list of AOVs).
        """
        si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.Minimal, coherent=True, active=active)
        value = mi.Float(0.0)
        if self._vis is not None:
            lookup, irr = self._vis
            valid = si.is_valid()
            idx = dr.gather(mi.UInt32, lookup, dr.reinterpret_array(mi.UInt32, si.shape), valid) \
                + dr.gather(mi.UInt32, lookup, dr.reinterpret_array(mi.UInt32, si.instance),
                            valid) + si.prim_index
            value = dr.gather(mi.Float, irr, idx, valid & (idx < dr.width(irr)))
        return mi.Spectrum(value), si.is_valid(), []

    def aov_names(self):
        """No AOVs.

        Returns
        -------
        list
            An empty list.
        """
        return []

    def to_string(self):
        """Plugin name and properties (what ``print(integrator)`` shows).

        Returns
        -------
        str
            ``PhotonIrradianceIntegrator[...]`` with the properties.
        """
        return (f"PhotonIrradianceIntegrator[photons={self.photons}, max_depth={self.max_depth},"
                f" indirect={self.indirect}, seed={self.seed}, bands={list(self.bands)}, "
                f"mode={self.mode}, output={self.output}]")

    # ---- the photon pass --------------------------------------------------------------------
    def trace(self, scene: mi.Scene, photons: int | None = None, seed: int | None = None,
              max_depth: int | None = None, bands=None, indirect: bool | None = None,
              reflectance: dict | None = None, emitters=None, batch: int | None = None,
              progress: bool = False, modes: dict | None = None,
              bsdf_override: dict | None = None, record=None,
              mode: str | None = None, tables: "PassTables | None" = None,
              counts=None, frozen: bool = False, wait: bool = True) -> PhotonIrradianceResult:
        """Trace a photon pass over ``scene`` and return per-element fluxes.

        Arguments left at None take the plugin's properties.

        Parameters
        ----------
        scene : mi.Scene
            The scene; its shape ids key the results.
        photons : int, optional
            Total photon count, shared among the emitters in proportion to the power they send
            towards the geometry (each emitter gets at least 5 %).
        seed : int, optional
            Random seed (same seed, same result, bit for bit).
        max_depth : int, optional
            Most surface hits per photon.
        bands : sequence, optional
            Band names or (min, max) ranges [nm].
        indirect : bool, optional
            False records the first hit only.
        reflectance : dict, optional
            ``{shape_id: array}`` of per-triangle albedos overriding the BSDF (Lambertian),
            shape (n_triangles,) for grey or (n_triangles, n_bands) per band; NaN entries keep
            the BSDF.
        emitters : sequence, optional
            Emitter ids/indices to trace (default: all).
        batch : int, optional
            Photons per kernel launch.
        progress : bool
            Show a progress bar.
        modes : dict, optional
            ``{shape_id: mode}`` with mode ``"surface"`` (default), ``"sensor"`` (records, then
            the photon passes unchanged: a virtual sensor that casts no shadow) or ``"hidden"``
            (passes unrecorded), or an integer array (n_triangles,) of :data:`SURFACE`,
            :data:`SENSOR`, :data:`HIDDEN`. A photon crossing a sensor or hidden element keeps
            its direction, power and bounce count; changing the modes does not recompile the
            kernel.
        bsdf_override : dict, optional
            ``{shape_id: (bsdfs, index)}``: a list of Mitsuba BSDF objects and an integer array
            (n_triangles,) choosing one of them per triangle (-1 keeps the shape's own BSDF).
            Used for leaves whose optics change by autumn stage: a day's new choice is a new
            table, not a new scene, and the kernel is recompiled only when the *set* of BSDF
            objects changes (see :meth:`_bsdf_table`).
        record : sequence of str, optional
            Ids of the shapes (or instances) whose flux is kept (default: all). Photons
            interact with every shape as usual; the others are just not recorded, so the
            pass's accumulator, read-back and result cover the recorded elements only (a world
            records its terrain and leaves, not the bark's half a million triangles).
            :attr:`PhotonIrradianceResult.rows` maps elements to rows of its ``flux``.
        mode : str, optional
            The kernel's mode: ``"roulette"`` (paper 000 §3.4: after a hit the photon goes on
            in a BSDF-sampled direction with probability q = max_k a_k and power P_k a_k / q)
            or ``"weights"`` (every photon goes on up to ``max_depth`` hits in a cosine-weighted
            direction on the side it hit, power P_k a_k with a_k = pi f_k(wi, wo) or the
            ``reflectance`` override; the same expectation for reflecting surfaces, no
            transmission: a leaf's transmitted light is left out).

        tables : PassTables, optional
            Per-element tables already on the device (:meth:`pass_tables`); replaces
            ``reflectance``, ``modes``, ``bsdf_override`` and ``record``.
        counts : sequence of int, optional
            Photons per traced emitter (default: ``photons`` shared by the power each emitter
            sends towards the geometry, measured by a small pilot pass and read back).
        frozen : bool
            Replay the launch's recorded kernels (``dr.freeze``) instead of tracing its Python
            again (a daily loop: the same scene and tables every day, new contents). Python
            emitters and BSDFs in the scene must list their arrays in ``DRJIT_STRUCT`` (the
            package's do).
        wait : bool
            Return when the pass's kernels have run (default): the result's ``seconds`` [s]
            is then the pass's time. False returns once they are launched (Dr.Jit runs them
            asynchronously), for a caller that launches more work on the tallies and waits
            itself (the daily loop's light stage); ``seconds`` is then the launch's time.

        Arguments left at None also fall back to the plugin's attributes :attr:`modes`,
        :attr:`bsdf_override` and :attr:`record`.

        All emitters are traced in one kernel launch (per band group and batch of ``batch``
        photons): lanes ``[c_0 + ... + c_(k-1), ... + c_k)`` carry emitter ``k``'s photons. The
        tallies stay on the device (:class:`DeviceTallies`) until the result is read.

        Returns
        -------
        PhotonIrradianceResult
            Also kept as :attr:`result`.
        """
        photons = self.photons if photons is None else photons
        seed = self.seed if seed is None else seed
        max_depth = self.max_depth if max_depth is None else max_depth
        indirect = self.indirect if indirect is None else indirect
        bands = self.bands if bands is None else bands
        emitters = self.emitters if emitters is None else emitters
        batch = self.batch if batch is None else batch
        mode = self.mode if mode is None else mode
        if mode not in KERNEL_MODES:
            raise ParameterError("mode", mode, "'roulette' or 'weights'",
                                 "trace(..., mode='roulette')")
        for name, v in (("photons", photons), ("max_depth", max_depth), ("seed", seed),
                        ("batch", batch)):
            check_light(name, v)
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
        # the last pass goes before the next one is made beside it (its tallies are 3.4 GB
        # on a hectare; freed first, their memory serves the new pass)
        self.result = None

        t0 = _time.perf_counter()
        # the cache holds the scene itself: keyed by id() alone, a new scene allocated where a
        # freed one was would get the old scene's index
        index = scene_index(scene)
        all_emitters = scene.emitters()
        if len(all_emitters) == 0:
            raise SceneError("the scene has no emitters: add a sun (e.g. mitsuba_veg.light."
                             "daylight(...)) or any Mitsuba emitter")
        em_idx = self._select_emitters(all_emitters, emitters)
        em_names = tuple(emitter_name(all_emitters[i], i) for i in em_idx)
        ems = [all_emitters[i] for i in em_idx]

        n_b = len(bands)
        groups = [list(range(i, min(i + _SLOTS, n_b))) for i in range(0, n_b, _SLOTS)]
        if tables is None:
            tables = self.pass_tables(scene, n_b, reflectance=reflectance, modes=modes,
                                      bsdf_override=bsdf_override, record=record)
        if counts is None:
            counts = self.photon_counts(scene, ems, photons, ranges[0])
        counts = np.asarray(counts, dtype=np.int64).reshape(-1)
        if len(counts) != len(ems) or np.any(counts < 1):
            raise ParameterError("counts", counts.tolist(), f"{len(ems)} photon counts >= 1 "
                                 "(one per traced emitter)")
        n_total = int(counts.sum())
        dev = DeviceTallies(len(ems), tables.n_rec, groups, n_b)
        bar = None
        if progress:
            from tqdm.auto import tqdm
            bar = tqdm(total=n_total * len(groups), unit="photon", unit_scale=True,
                       desc="photons")
        for g_i, group in enumerate(groups):
            slot_ranges = [ranges[b] for b in group]
            slot_ranges += [slot_ranges[0]] * (_SLOTS - len(slot_ranges))
            done = 0
            while done < n_total:
                n = int(min(batch, n_total - done))
                # a distinct, reproducible stream per (seed, first emitter, band group, batch)
                stream = (((seed * 31 + em_idx[0]) * 17 + g_i) * 1_000_003 + done // batch) \
                    & 0x7FFFFFFF
                acc, unit, book, rays = self._pass(
                    scene, ems, index, done, n, counts, stream, slot_ranges, tables.refl[g_i],
                    max_depth, indirect, tables, mode, len(group), frozen=frozen)
                dev.add_batch(g_i, acc, unit, book, rays)
                done += n
                if bar is not None:
                    # the bar's rate counts photons traced, not launched: the batch's kernels
                    # run on Dr.Jit's threads after the launch returns
                    dr.sync_thread()
                    bar.update(n)
        if bar is not None:
            bar.close()
        # the kernels were launched, not run (Dr.Jit evaluates asynchronously): the pass's
        # time ends when its tallies are on the device, as the caller would read them
        if wait:
            dr.sync_thread()
        res = PhotonIrradianceResult(
            index=index, bands=names, band_ranges=ranges, emitters=em_names,
            photons=counts, seconds=_time.perf_counter() - t0,
            settings=dict(photons=photons, seed=seed, max_depth=max_depth, indirect=indirect,
                          bands=list(names), mode=mode), rows=tables.rows, device=dev)
        self.result = res
        return res

    def trace_paths(self, scene: mi.Scene, emitter, photons: int, seed: int = 0,
                    max_depth: int = 8, band=(360.0, 830.0),
                    index: SceneIndex | None = None, attach: bool = False) -> PhotonPathRecord:
        """Trace one emitter's photons in the "weights" mode and record every hit (no flux).

        The same kernel as :meth:`trace` (:meth:`_loop`): the same emission (aim, jittered
        origins, Weyl-sequence band wavelengths), ``ray_intersect_preliminary`` and element
        tables (instances included), two-sided cosine-weighted continuation up to
        ``max_depth`` hits, no Russian roulette, and the element and side of each hit stored
        per depth. Because no direction depends on an albedo, the flux of the recorded paths
        is a polynomial in the albedos (paper 000 §3.4 with weights instead of roulette):

            P_0 = w_0,   P_{k+1} = P_k a(e_k),   flux(e) = sum over hits k on e of P_k  [W]

        which :meth:`replay` evaluates (and differentiates).

        Parameters
        ----------
        scene : mi.Scene
            The scene (loaded with ``optimize=False``).
        emitter : mi.Emitter or str or int
            One emitter of ``scene``: the object, its id or its index.
        photons : int
            Photons to trace, 16 .. 2^26 (one kernel launch; memory ~ 4 bytes x photons x
            ``max_depth`` for the records).
        seed : int
            Random seed (its low 31 bits; same seed, same paths).
        max_depth : int
            Hits per photon, 1 .. 64.
        band : tuple of float
            (min_nm, max_nm) [nm]: each photon carries 4 stratified wavelengths in the band and
            the emitter's power integrated over it.
        index : SceneIndex, optional
            The scene's element index (default: built and cached for the scene).
        attach : bool
            Compute ``w0`` again with Dr.Jit AD enabled (the same emission, the same numbers):
            attached to the emitter's parameters that carry gradients.

        Returns
        -------
        PhotonPathRecord
            ``w0`` [W] per photon, ``elem`` and ``front`` per depth (the recorded depths: up
            to the deepest cast), ``rays`` (ray casts made), the index's ``n_elements`` and
            ``areas``.
        """
        check_range("photons", photons, 16, 2**26, fix="a photon count such as 200000")
        check_range("max_depth", max_depth, 1, 64)
        lo, hi = band_range(band)
        t0 = _time.perf_counter()
        index = scene_index(scene) if index is None else index
        if isinstance(emitter, mi.Emitter):
            em = emitter
            name = em.id() or "emitter"
        else:
            all_em = scene.emitters()
            i = self._select_emitters(all_em, [emitter])[0]
            em, name = all_em[i], emitter_name(all_em[i], i)
        n, depth_max = int(photons), int(max_depth)
        stream = int(seed) & 0x7FFFFFFF
        inp = self.launch_inputs(n, [n], 0, stream, [(lo, hi)] * _SLOTS)
        sampler, ray, _, w, _ = self._photons(scene, [em], index, n, inp,
                                              lobes=[self._lobe(em)])
        # initial power [W]: the 4 band wavelengths' estimates averaged
        w0 = (w[0] + w[1] + w[2] + w[3]) * _opaque(mi.Float, 0.25 * (hi - lo) / n)
        w0 = dr.select(dr.isfinite(w0), w0, 0.0) * dr.full(mi.Float, 1.0, n)
        active = w0 > 0
        dr.eval(w0, ray, active)
        paths = dr.full(mi.UInt32, _NO_ROW, n * depth_max)
        lane = dr.arange(mi.UInt32, n)
        _, rays_lane, _, _ = self._loop(
            scene, sampler, ray, mi.Spectrum(w0), active, mi.UInt32(0),
            _opaque(mi.UInt32, depth_max), None, dr.zeros(mi.Spectrum, n),
            dr.zeros(mi.Spectrum, n), index, self._tables(index), None, False,
            mi.Float(1.0), mi.Float(1.0), None, None, index.bsdf_objects, None, weights=True,
            paths=paths, lane=lane, n_lanes=_opaque(mi.UInt32, n))
        dr.eval(paths, rays_lane)
        rays = int(_scalar(dr.sum(_UInt64(rays_lane))))
        cast = int(_scalar(dr.max(rays_lane))) if n else 0   # deepest cast: depths recorded
        if attach:
            with dr.resume_grad():
                w = self._photons(scene, [em], index, n, inp, lobes=[self._lobe(em)])[3]
                w0 = (w[0] + w[1] + w[2] + w[3]) * _opaque(mi.Float, 0.25 * (hi - lo) / n)
                w0 = dr.select(dr.isfinite(w0), w0, 0.0) * dr.full(mi.Float, 1.0, n)
        elems, fronts = [], []
        for k in range(cast):
            v = dr.gather(mi.UInt32, paths, lane + _opaque(mi.UInt32, k * n))
            valid = v != _NO_ROW
            e = dr.select(valid, v >> 1, _NO_ROW)
            front = valid & ((v & 1) == 0)
            dr.eval(e, front)
            elems.append(e)
            fronts.append(front)
        dr.sync_thread()   # the depths' kernels run before the time is taken
        return PhotonPathRecord(emitter=name, photons=n, max_depth=depth_max, band=(lo, hi),
                                w0=w0, elem=elems, front=fronts, n_elements=index.n_elements,
                                areas=np.asarray(index.areas, np.float64), rays=rays,
                                seconds=_time.perf_counter() - t0)

    def replay(self, record: PhotonPathRecord, albedo, strength=1.0, side: str = "front",
               component: str = "both", irradiance: bool = False):
        """Flux (or irradiance) per element of recorded paths for given albedos, differentiable.

        P_0 = s w_0, P_(k+1) = P_k a(e_k, side_k), flux(e) += P_k at every hit
        (:mod:`~mitsuba_veg.integrators.photon_replay`): Dr.Jit gathers and scatter-adds,
        differentiable in both AD modes with respect to the albedos, the strength and (for a
        record traced with ``attach=True``) the emitter's parameters.

        Parameters
        ----------
        record : PhotonPathRecord
            Paths from :meth:`trace_paths`.
        albedo : Float64 or tuple of Float64
            Albedo per element [-] (reflects on the side hit), or a ``(front, back)`` pair.
        strength : float or Float64
            Emitter strength factor [-].
        side : str
            ``"front"``, ``"back"`` or ``"both"``: the hits recorded.
        component : str
            ``"direct"``, ``"indirect"`` or ``"both"``.
        irradiance : bool
            Divide by the element areas: irradiance [W m-2] instead of flux [W].

        Returns
        -------
        Float64
            Flux [W] or irradiance [W m-2] per element, the float type of ``albedo``.
        """
        f = _replay.irradiance if irradiance else _replay.replay
        return f(record, albedo, strength, side, component)

    # ---- Mitsuba's differentiable entry points ------------------------------------------------
    def render_forward(self, scene, params, sensor=0, seed=0, spp=0):
        """Forward-mode derivative of :meth:`render`'s element tensor (``mi.render`` calls it).

        The derivative of the expected irradiance with respect to the parameters of ``params``
        that carry gradients (``dr.enable_grad`` + ``dr.set_grad`` on ``mi.traverse(scene)``
        entries, then ``params.update()``): the BSDFs' reflectances and the emitters' radiance,
        irradiance, intensity or scale. It is estimated by replaying weights-mode paths
        (:meth:`trace_paths`, :meth:`replay`) traced with ``seed`` (independent of the primal
        pass's): every photon goes on up to ``max_depth`` hits and its power is a polynomial in
        the albedos, so the derivative is exact for that sample of paths. Albedos are the BSDFs'
        band means (:func:`~mitsuba_veg.integrators.photon_replay.bsdf_albedo`: exact for
        Lambertian BSDFs with reflectances flat within each band). Geometry (vertex positions,
        ``to_world``, emitter positions) is not differentiated: such a parameter with gradients
        is refused.

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        params : mi.SceneParameters
            ``mi.traverse(scene)`` with gradients enabled where derivatives are wanted.
        sensor : int or mi.Sensor
            Unused (the element output does not use a sensor).
        seed : int
            Seed of the paths (added to the ``seed`` property).
        spp : int
            Must be 0, as for :meth:`render`.

        Returns
        -------
        mi.TensorXf
            The derivative of the element tensor, shape (elements, bands, 2, 2) [W m-2 per unit
            of the parameters' tangents].
        """
        with dr.resume_grad():
            img = self._render_ad(scene, params, seed, spp)
            # (no parameter with gradients: a zero derivative, as Mitsuba's integrators give)
            dr.forward_to(img, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
            return dr.grad(img)

    def render_backward(self, scene, params, grad_in, sensor=0, seed=0, spp=0):
        """Reverse-mode derivative of :meth:`render`'s element tensor (``mi.render`` calls it).

        Accumulates ``grad_in`` (shape (elements, bands, 2, 2)) times the derivative of the
        element tensor into the gradients of the parameters of ``params`` that carry gradients;
        the estimate is :meth:`render_forward`'s.

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        params : mi.SceneParameters
            ``mi.traverse(scene)`` with gradients enabled where derivatives are wanted.
        grad_in : mi.TensorXf
            Gradient of the objective with respect to the element tensor.
        sensor : int or mi.Sensor
            Unused.
        seed : int
            Seed of the paths (added to the ``seed`` property).
        spp : int
            Must be 0.
        """
        with dr.resume_grad():
            img = self._render_ad(scene, params, seed, spp)
            dr.set_grad(img, grad_in)
            dr.enqueue(dr.ADMode.Backward, img)
            dr.traverse(dr.ADMode.Backward, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
        dr.eval()

    #: last names of scene parameters that move geometry: the replay keeps its paths fixed
    _GEOMETRY_KEYS = ("vertex_positions", "vertex_normals", "vertex_texcoords", "faces",
                      "to_world", "position", "center", "radius", "direction", "target")

    def _render_ad(self, scene, params, seed, spp):
        """The element tensor of a weights-mode replay, attached to ``params`` (see
        :meth:`render_forward`)."""
        if self.output != "elements":
            raise ParameterError("output", self.output, "'elements' for derivatives",
                                 "differentiate the element tensor; the light map image is a "
                                 "lookup of it")
        if int(spp or 0) != 0:
            raise ParameterError("spp", int(spp), "0 for output='elements'",
                                 "set the effort with the integrator's photons property")
        for key in (params.keys() if params is not None else ()):
            if key.rsplit(".", 1)[-1] in self._GEOMETRY_KEYS and dr.grad_enabled(params[key]):
                raise ParameterError(
                    "params", key, "reflectance or emitter parameters",
                    "the photon pass differentiates albedos and emitted power along fixed "
                    "paths, not geometry: disable gradients on this parameter")
        k = int(np.asarray(dr.ravel(seed))[0]) if not isinstance(seed, int) else int(seed)
        stream = (self.seed + k) & 0x7FFFFFFF
        index = scene_index(scene)
        all_em = scene.emitters()
        sel = self._select_emitters(all_em, self.emitters)
        ems = [all_em[i] for i in sel]
        ranges = [band_range(b) for b in self.bands]
        counts = self.photon_counts(scene, ems, self.photons, ranges[0])
        depth = self.max_depth if self.indirect else 1
        n, nb = index.n_elements, len(ranges)
        out = dr.zeros(mi.Float, n * nb * 4)
        q = dr.arange(mi.UInt32, 4 * n)                    # (element, component, side) slots
        e = q // 4
        target = e * (nb * 4) + (q % 4)
        inv_area = dr.gather(mi.Float, mi.Float(1.0 / np.maximum(index.areas, 1e-30)), e)
        for j, band in enumerate(ranges):
            albedo = _replay.bsdf_albedo(scene, index, band)
            for i, em in enumerate(ems):
                rec = self.trace_paths(scene, em, int(counts[i]),
                                       seed=stream * 7919 + 104729 * j + 31 * i + 17,
                                       max_depth=depth, band=band, index=index, attach=True)
                # the four components of every element in one replay of the paths
                x = _replay.replay_slots(rec, albedo, 1.0) * inv_area
                dr.scatter_add(out, x, target + j * 4)
        return mi.TensorXf(out, (n, nb, 2, 2))


mi.register_integrator("veg_photon_irradiance", lambda props: PhotonIrradianceIntegrator(props))
