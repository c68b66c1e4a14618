"""The photon kernel of ``veg_photon_irradiance``: emission, the random walk, hits and tallies.

The plugin (:mod:`.photon_irradiance`) inherits :class:`PhotonKernel`; a pass is one or more
launches (:meth:`PhotonKernel._launch`), each one Dr.Jit kernel of emission
(:meth:`PhotonKernel._photons`) and the random walk (:meth:`PhotonKernel._loop`), every input an
argument so that a launch can be frozen (``dr.freeze``) and replayed day after day.

Russian roulette (paper §3.4): at a hit with per-band albedo a_k (from the BSDF sample weight, or
a per-triangle override) the photon continues with probability q = max_k a_k and its band
powers become P_k a_k / q. For a grey surface q = a and the power is unchanged, exactly the
paper's "reflected with probability = reflectance" (1000 photons on a 0.5 surface: 500 go on).
This is the kernel's default mode ("roulette"). Its other mode, "weights", continues every photon
up to ``max_depth`` hits in a cosine-weighted direction on the side it hit and multiplies its
band powers by a_k = pi f_k(wi, wo) (or the override albedo): the same expectation, directions
independent of the albedo. In that mode :meth:`PhotonIrradianceIntegrator.trace_paths` records
the element and side of every hit, which :meth:`PhotonIrradianceIntegrator.replay`
(:mod:`.photon_replay`) evaluates for any albedos, differentiably: one kernel serves both passes,
and the plugin's ``render_forward`` / ``render_backward`` (what ``mi.render(scene, params)``
differentiates) are replays of such paths.

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
- point-like emitters (point, spot, projector): origin at the light, direction uniform in the
  narrower of the cone that subtends the bounding sphere (the whole sphere when the light is
  inside it) and the emitter's own emission cone (:meth:`PhotonIrradianceIntegrator._lobe`).

Which sides of a surface reflect is its BSDF's business, as in Mitsuba: a plain ``diffuse`` is
one-sided (a photon hitting its back face is absorbed), ``twosided`` and the leaf BSDF reflect on
both sides, a per-element albedo override on the side that was hit. Only hits on the front side
(the side the geometric normal faces: moss lives there) count as front irradiance; back-side
flux is recorded separately.

Hits. Rays are cast with ``ray_intersect_preliminary`` (the BVH traversal only). The element of
a hit comes from lookup tables (shape -> first element, instance -> first element, mesh within
a shapegroup -> first element within it), its side from the element's geometric normal (a
per-element table in world space), and the BSDF is sampled about that normal on a surface
interaction holding only what a spatially uniform BSDF reads. Mitsuba's full surface
interaction (shading normals, uv) is computed instead when some BSDF has a spatially varying
texture, or when a mesh has vertex normals in a scene without instances (with instances, the
shading normals of meshes with vertex normals come from per-triangle tables); analytic shapes
(sphere, disk, cylinder) get their normal from the shape. This avoids
Mitsuba's per-instance virtual call: with 1,000 instances a full ``ray_intersect`` was 30-50x
slower than a preliminary one on this 2-core machine.

Per-element tables (``trace(..., modes=, bsdf_override=, record=)``): each element's mode
(surface, sensor, hidden), its BSDF among a fixed list, and its row in the accumulator (or none:
not recorded) are gathered from device arrays outside the loop state, so a daily loop changes
them without recompiling the kernel (a world's leaves: stage optics, fallen leaves, bark not
recorded).

Instances. Each ``instance`` of a ``shapegroup`` of meshes gets its own elements (one per
triangle of every mesh in the group), keyed by the instance id; an analytic shape inside a
shapegroup is refused with an error naming it.
"""
from __future__ import annotations

import gc
import math
from dataclasses import dataclass
from functools import partial

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.arrays import host_array, zero_index
from mitsuba_veg.arrays import opaque as _opaque
from mitsuba_veg.defaults import LIGHT
from mitsuba_veg.errors import ParameterError, SceneError

from .bands import _SLOTS
from .photon_result import fixed_point_scale
from .scene_index import SceneIndex, _reg_id, registry_id, scene_index

__all__ = ["DEFAULT_BATCH", "KERNEL_MODES", "split_photons", "LaneSampler", "LaunchInputs",
           "PassTables", "PhotonKernel", "switch_table", "aim_area"]

_UInt64 = mi.UInt64
#: photons traced per kernel launch (bounded memory; larger counts run in batches)
DEFAULT_BATCH = LIGHT["batch"].default

#: Element modes (``trace(..., modes=...)``): a SURFACE element records the photon and scatters
#: or absorbs it (its BSDF); a SENSOR element records the photon and lets it pass unchanged
#: (same direction, same power, no bounce counted): a virtual sensor; a HIDDEN element lets it
#: pass unrecorded (e.g. a fallen leaf whose triangles stay in the scene).
SURFACE, SENSOR, HIDDEN = 0, 1, 2
_MODE_NAMES = {"surface": SURFACE, "sensor": SENSOR, "hidden": HIDDEN}
#: fewer distinct BSDFs than this are called directly in the kernel (each for every hit,
#: masked), more through ``dr.switch`` (an indirect call per BSDF present in a packet)
_SWITCH_BSDFS = 3
#: accumulator row of an element that is not recorded (``trace(..., record=...)``)
_NO_ROW = 0xFFFFFFFF
#: kernel modes (``trace(..., mode=...)``): Russian roulette (paper 000 §3.4) or weights
KERNEL_MODES = ("roulette", "weights")


def split_photons(power, photons: int) -> np.ndarray:
    """Photons per emitter: ``photons`` shared in proportion to each emitter's power towards
    the geometry, each at least 5 % of them (evenly when no power is known).

    Parameters
    ----------
    power : array_like
        (emitters,) power of each emitter towards the geometry [W].
    photons : int
        Total photons.

    Returns
    -------
    numpy.ndarray
        (emitters,) int64 photon counts, each >= 1.
    """
    power = np.asarray(power, dtype=np.float64).reshape(-1)
    if not np.all(np.isfinite(power)) or power.sum() <= 0:
        share = np.full(len(power), 1.0 / len(power))
    else:
        share = power / power.sum()
        share = np.maximum(share, 0.05 if len(power) > 1 else 1.0)
        share /= share.sum()
    return np.maximum(np.round(share * photons).astype(np.int64), 1)

class LaneSampler:
    """Independent uniform numbers, one PCG32 stream per lane, seeded from a stream number
    and the lane's index (TEA-scrambled): the photon pass's random numbers.

    A Dr.Jit struct rather than a Mitsuba ``Sampler`` object: it is plain state of the launch
    (a loop variable of the random walk), so a frozen launch (``dr.freeze``) replays with a new
    seed; a new Mitsuba object per launch would change the JIT registry that a recording is
    keyed on, and one kept from launch to launch would be an input holding stale state.

    Parameters
    ----------
    seed : mi.UInt32 or int, optional
        Stream number (width 1).
    n : int
        Lanes.
    """

    DRJIT_STRUCT = {"rng": mi.PCG32}

    def __init__(self, seed=None, n: int = 0):
        if seed is None:
            self.rng = mi.PCG32()
            return
        idx = dr.arange(mi.UInt32, n)
        v0, v1 = mi.sample_tea_32(mi.UInt32(seed) * dr.full(mi.UInt32, 1, n), idx)
        self.rng = mi.PCG32(size=n, initstate=(mi.UInt64(v0) << 32) | mi.UInt64(v1),
                            initseq=mi.UInt64(idx))

    def next_1d(self, active=True):
        """A uniform number in [0, 1) per lane.

        Parameters
        ----------
        active : mi.Bool or bool
            Lanes that draw (the others keep their state).

        Returns
        -------
        mi.Float
            The numbers.
        """
        return self.rng.next_float32(active)

    def next_2d(self, active=True):
        """Two uniform numbers in [0, 1) per lane.

        Parameters
        ----------
        active : mi.Bool or bool
            Lanes that draw.

        Returns
        -------
        mi.Point2f
            The numbers.
        """
        a = self.rng.next_float32(active)
        b = self.rng.next_float32(active)
        return mi.Point2f(a, b)


@dataclass
class LaunchInputs:
    """The per-call numbers of one kernel launch as one device array (kernel inputs, one host
    copy): ``p`` UInt32, the ``n_u`` integers (wavelength shifts, first lane, emitter offsets
    and strata, max depth, stream) and then the bits of the floats (band ranges and widths,
    strata and photon-count reciprocals, fixed-point cap); ``zero`` (an evaluated 0: the index
    base of their gathers). Made by :meth:`PhotonIrradianceIntegrator.launch_inputs`."""

    p: object
    n_u: int
    zero: object

    def u(self, j: int):
        """Integer ``j`` of the launch.

        Parameters
        ----------
        j : int
            Its position among the integers.

        Returns
        -------
        mi.UInt32
            A gather that runs inside the kernel that reads it.
        """
        return dr.gather(mi.UInt32, self.p, self.zero + j)

    def f(self, j: int):
        """Float ``j`` of the launch.

        Parameters
        ----------
        j : int
            Its position among the floats.

        Returns
        -------
        mi.Float
            A gather (of its bits) that runs inside the kernel that reads it.
        """
        return dr.reinterpret_array(mi.Float, dr.gather(mi.UInt32, self.p,
                                                        self.zero + (self.n_u + j)))


@dataclass
class PassTables:
    """The per-element tables of a photon pass, on the device (see ``trace``).

    Built by :meth:`PhotonIrradianceIntegrator.pass_tables`; a daily loop builds them once and
    replaces the arrays that change (``modes``, ``bsdf_table``, ``refl``) every day: new
    contents, same kernel.
    """

    rows: np.ndarray | None          # host: accumulator row per element, -1 not recorded
    row_arr: object                  # mi.UInt32 per element (_NO_ROW: not recorded) or None
    n_rec: int                       # recorded elements
    modes: object                    # mi.UInt32 per element (SURFACE/SENSOR/HIDDEN) or None
    bsdf_table: object               # mi.UInt32 BSDF registry id per element (0: own) or None
    bsdfs: list                      # [(registry id, BSDF)] the kernel dispatches to
    refl: list                       # per band group: mi.Float (rows x 4) or None: the first
    #                                  elements up to the last one with an override (the
    #                                  terrain's: the world's leaves and wood need no rows)
    slot_of: object = None           # mi.UInt32: BSDF registry id -> position in ``bsdfs``


class PhotonKernel(mi.SamplingIntegrator):
    """The photon kernel: the base class of the plugin
    :class:`~.photon_irradiance.PhotonIrradianceIntegrator` (a Mitsuba integrator class cannot
    take a second, plain Python base: the kernel sits between it and ``mi.SamplingIntegrator``).

    Its methods read the plugin's ``batch`` and keep two caches on it: ``_frozen`` (the frozen
    launch) and ``_lobes`` (the emission cones of point-like emitters, :meth:`_lobe`).
    """

    #: The random walk in two parts (True), in one loop (False, the default), or "auto": two
    #: parts on CUDA. In one loop a group of lanes (a CPU packet, a GPU warp) runs until its
    #: last photon ends, mostly idle after the first hit (a fifth of the world's photons go on
    #: after their first cast, with 30 % of the pass's casts); the second part gathers the
    #: photons that go on into dense lanes. The numbers are the same either way (every lane
    #: carries its state, the tallies are integer sums). On the 2-core CPU the split walk was
    #: slower (world 857 against 805 ms of kernel time, garden 1.27x): Dr.Jit's CPU packets
    #: lose little to lanes that have ended. On a GPU it is not measured yet
    #: (``benchmarks/photon_throughput.py --split``), so one loop stays the default there too.
    split_walk = False

    def pass_tables(self, scene: mi.Scene, n_bands: int, reflectance: dict | None = None,
                    modes: dict | None = None, bsdf_override: dict | None = None,
                    record=None) -> PassTables:
        """The per-element tables of a pass, uploaded to the device (see :meth:`trace`).

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        n_bands : int
            Bands of the pass (the reflectance table has one column per band).
        reflectance, modes, bsdf_override, record : optional
            As for :meth:`trace`.

        Returns
        -------
        PassTables
            The device tables.
        """
        index = scene_index(scene)
        groups = [list(range(i, min(i + _SLOTS, n_bands))) for i in range(0, n_bands, _SLOTS)]
        refl = self._reflectance_table(index, reflectance, n_bands)
        refl_g = []
        for group in groups:
            if refl is None:
                refl_g.append(None)
                continue
            cols = refl[:, group + [group[0]] * (_SLOTS - len(group))]
            refl_g.append(mi.Float(np.ascontiguousarray(cols, np.float32).ravel()))
        mode_arr = self._mode_table(index, modes)
        bsdf_arr, bsdfs = self._bsdf_table(index, bsdf_override)
        rows, row_arr = self._record_table(index, record)
        n_rec = index.n_elements if rows is None else int((rows >= 0).sum())
        return PassTables(rows, row_arr, n_rec, mode_arr, bsdf_arr, bsdfs, refl_g,
                          switch_table(bsdfs))

    def photon_counts(self, scene: mi.Scene, emitters, photons: int, band) -> np.ndarray:
        """Photons per emitter: ``photons`` shared by the power each emitter sends towards the
        geometry (a 4096-sample pilot per emitter, read back), each at least 5 % of them.

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        emitters : sequence of mi.Emitter
            The emitters to trace.
        photons : int
            Total photons.
        band : tuple of float
            (min, max) [nm] of the band the power is measured in.

        Returns
        -------
        numpy.ndarray
            (emitters,) int64 photon counts (each >= 1).
        """
        index = scene_index(scene)
        pilots = [self._pilot_power(scene, e, index, band) for e in emitters]
        dr.eval(pilots)  # one launch for all emitters, then deterministic reductions
        # (means on the host, in float64: a device float reduction need not be repeatable)
        power = np.array([float(np.mean(np.asarray(p, np.float64))) for p in pilots]) \
            * (band[1] - band[0])
        return split_photons(power, photons)

    def pilot_power(self, scene: mi.Scene, emitter, band) -> float:
        """The power an emitter sends towards the geometry in ``band`` [W] (the 4096-sample
        pilot of :meth:`photon_counts`, read back).

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        emitter : mi.Emitter
            One of its emitters.
        band : tuple of float
            (min, max) [nm].

        Returns
        -------
        float
            Estimated power [W].
        """
        p = self._pilot_power(scene, emitter, scene_index(scene), band)
        return float(np.mean(np.asarray(p, np.float64))) * (band[1] - band[0])

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
    def _mode_table(index: SceneIndex, modes):
        """Per-element modes as a device array (None when no modes are given)."""
        if not modes:
            return None
        table = np.zeros(index.n_elements, dtype=np.uint32)
        for sid, m in modes.items():
            sl = index.shape_slice(sid)
            n = sl.stop - sl.start
            if isinstance(m, str):
                if m not in _MODE_NAMES:
                    raise ParameterError(f"modes['{sid}']", repr(m), "'surface', 'sensor' or "
                                         "'hidden'", "or an array of SURFACE/SENSOR/HIDDEN")
                table[sl] = _MODE_NAMES[m]
                continue
            a = np.asarray(m)
            if a.ndim == 0:
                a = np.full(n, a)
            if a.shape != (n,) or not np.isin(a, (SURFACE, SENSOR, HIDDEN)).all():
                raise ParameterError(f"modes['{sid}']", f"array of shape {a.shape}",
                                     f"shape ({n},) with values 0 (surface), 1 (sensor), "
                                     f"2 (hidden)")
            table[sl] = a
        # a given table is used even when every element is a surface: a loop whose modes
        # come and go (leaves falling) keeps one kernel
        return mi.UInt32(table)

    @staticmethod
    def _record_table(index: SceneIndex, record):
        """Accumulator row of every element (numpy, -1 = not recorded) and its device table
        (``_NO_ROW`` for -1); (None, None) when every element is recorded."""
        if record is None:
            return None, None
        if isinstance(record, str):
            record = [record]
        keep = np.zeros(index.n_elements, bool)
        for sid in record:
            if sid in index.sub_slices:
                raise ParameterError("record", sid, "shape or instance ids (whole shapes)",
                                     "record the whole instance")
            keep[index.shape_slice(sid)] = True
        if keep.all():
            return None, None
        rows = np.where(keep, np.cumsum(keep) - 1, -1)
        table = np.where(keep, rows, _NO_ROW).astype(np.uint32)
        return rows, mi.UInt32(table)

    @staticmethod
    def _bsdf_table(index: SceneIndex, bsdf_override):
        """Per-element BSDF choice as a device array of BSDF registry ids (0: the shape's own)
        and the list of BSDFs the kernel dispatches to (the scene's plus the overrides').

        Why a table of BSDF objects rather than a table of spectra: the element's optics stay
        those of its Mitsuba BSDF (``veg_leaf``'s PROSPECT-D R(λ) and T(λ), the same object the
        renderer uses), any BSDF type works, and a day's change is one integer per triangle.
        The kernel calls the listed BSDFs (directly for fewer than :data:`_SWITCH_BSDFS`, else
        through ``dr.switch``), so the list, sorted by registry id, is part of the kernel: it
        must stay the same from day to day (a few stage BSDFs built once), while the table is
        data.
        """
        if not bsdf_override:
            return None, index.bsdf_objects
        table = np.zeros(index.n_elements, dtype=np.uint32)
        objs = dict(index.bsdf_objects)
        for sid, spec in bsdf_override.items():
            sl = index.shape_slice(sid)
            n = sl.stop - sl.start
            try:
                bsdfs, choice = spec
                bsdfs = list(bsdfs)
            except (TypeError, ValueError):
                raise ParameterError(f"bsdf_override['{sid}']", type(spec).__name__,
                                     "a pair (list of BSDF objects, per-triangle index array)")
            if not bsdfs or not all(isinstance(b, mi.BSDF) for b in bsdfs):
                raise ParameterError(f"bsdf_override['{sid}']", "a list of "
                                     f"{[type(b).__name__ for b in bsdfs]}",
                                     "a non-empty list of Mitsuba BSDF objects",
                                     "build them once with mi.load_dict")
            a = np.asarray(choice)
            if a.ndim == 0:
                a = np.full(n, a)
            if a.shape != (n,) or not np.issubdtype(a.dtype, np.integer) or \
                    (a.size and (a.min() < -1 or a.max() >= len(bsdfs))):
                raise ParameterError(f"bsdf_override['{sid}']", f"index array of shape {a.shape}"
                                     f" ({a.dtype})", f"shape ({n},), integers in -1 .. "
                                     f"{len(bsdfs) - 1} (-1: the shape's own BSDF)")
            reg = np.array([_reg_id(b) for b in bsdfs] + [0], dtype=np.uint32)
            table[sl] = reg[a]          # -1 -> the trailing 0
            for r, b in zip(reg[:-1], bsdfs):
                objs.setdefault(int(r), b)
        return mi.UInt32(table), sorted(objs.items(), key=lambda kv: kv[0])

    @staticmethod
    def _reflectance_table(index: SceneIndex, reflectance, n_b):
        """Per-element override albedo (rows, n_b) as mi.Float-ready numpy, NaN = use the
        BSDF: the elements from the first up to the last with an override (the kernel reads no
        row for the others; a hectare's 21.6 M elements made 350 MB of NaN for 0.1 M ground
        triangles)."""
        if not reflectance:
            return None
        slices = {sid: index.shape_slice(sid) for sid in reflectance}
        n_rows = max(sl.stop for sl in slices.values())
        table = np.full((n_rows, n_b), np.nan, dtype=np.float32)
        for sid, arr in reflectance.items():
            sl = slices[sid]
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

    def _pilot_power(self, scene, emitter, index, rng_nm):
        """Samples of the spectral power [W nm-1] that an emitter sends towards the geometry
        (their mean sets the photon budget), unevaluated."""
        n = 4096
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(12345, n)
        lam = mi.Float(rng_nm[0]) + (rng_nm[1] - rng_nm[0]) * sampler.next_1d()
        wav = mi.Spectrum(lam, lam, lam, lam)
        _, _, w, _ = self._emit(scene, emitter, index, sampler, wav, mi.Bool(True),
                                lobe=self._lobe(emitter))
        return mi.Float(w[0])

    def _lobe(self, emitter):
        """The cone that holds every direction a point-like emitter (``point``, ``spot``,
        ``projector``) sends light in: (axis x, y, z, cos of its half angle), or None when it
        lights the whole sphere (or is not point-like).

        Found once per emitter (and again when Mitsuba's description of it changes: position,
        ``to_world``, cone, fov, all of which it lists) from its intensity at 65,536 directions spread evenly over the sphere (a
        Fibonacci lattice): the axis is the mean of the lit directions, the half angle the widest lit
        one plus two lattice spacings (1.6 deg), so no lit direction falls outside. A spot's
        photons are then drawn in its cone, not over the sphere (a 30 deg spot: 6.7 % of the
        sphere's photons would reach its cone).
        """
        if self._kind(emitter) != "point":
            return None
        # Mitsuba's description holds all that shapes the cone (a projector's fov, which
        # ``traverse`` does not list) and follows ``traverse`` updates; no device read per pass
        key = (registry_id(emitter), str(emitter))
        if key in self._lobes:
            return self._lobes[key]
        n = 1 << 16
        i = np.arange(n) + 0.5
        z = 1.0 - 2.0 * i / n
        r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
        phi = np.pi * (1.0 + np.sqrt(5.0)) * i
        d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
        it0 = dr.zeros(mi.Interaction3f)
        it0.wavelengths = mi.Spectrum(450.0, 550.0, 650.0, 700.0)
        ds0, _ = emitter.sample_direction(it0, mi.Point2f(0.5, 0.5), True)
        p = np.array([float(np.asarray(ds0.p[k]).ravel()[0]) for k in range(3)])
        it = dr.zeros(mi.Interaction3f, n)
        q = (p + d).astype(np.float32)
        it.p = mi.Point3f(*[mi.Float(q[:, k]) for k in range(3)])
        it.wavelengths = mi.Spectrum(450.0, 550.0, 650.0, 700.0)
        _, I = emitter.sample_direction(it, mi.Point2f(0.5, 0.5), True)
        lit = np.zeros(n, bool)
        for k in range(4):
            lit |= np.asarray(I[k]).ravel() > 0
        lobe = None
        if lit.any() and not lit.all():
            axis = d[lit].mean(axis=0)
            norm = np.linalg.norm(axis)
            if norm > 1e-6:
                axis /= norm
                theta = float(np.arccos(np.clip((d[lit] @ axis).min(), -1.0, 1.0))) \
                    + 2.0 * np.sqrt(4.0 * np.pi / n)
                if theta < np.pi:
                    lobe = (float(axis[0]), float(axis[1]), float(axis[2]),
                            float(np.cos(theta)))
        self._lobes[key] = lobe
        return lobe

    def _emit(self, scene, emitter, index, sampler, wav, active, strata=None, lobe=None):
        """Sample photon origins/directions: returns (origin, direction, weight, time).

        weight = spectral power per photon at ``wav`` [W nm-1] x number of photons, i.e. the
        Monte-Carlo estimate of the emitter's spectral power towards the geometry. ``lobe``:
        a point-like emitter's emission cone (:meth:`_lobe`).
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
            frame, smin, smax, tmin, tmax, dmin = _aim_rectangle(d, bmin, bmax, radius)
            u = sampler.next_2d()
            if strata is not None:
                # jittered-grid stratification of the origins over the rectangle: the direct
                # light of a sun is then almost noise-free. ``strata`` = (index, m) or (index,
                # m, 1/m) with per-lane device arrays (several emitters in one launch)
                if len(strata) == 3:
                    idx, m_u, inv_m = strata
                else:
                    idx, m = strata
                    m_u, inv_m = _opaque(mi.UInt32, m), _opaque(mi.Float, 1.0 / m)
                # (the divisor at least 1: the LLVM backend's padding lanes of a launch whose
                # width is not a multiple of the vector width gather 0, and an integer
                # division by 0 traps the process)
                m_d = dr.maximum(m_u, mi.UInt32(1))
                cell = mi.Point2f(mi.Float(idx % m_d), mi.Float(idx // m_d))
                u = dr.select(idx < m_u * m_u, (cell + u) * inv_m, u)
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
        if lobe is not None:
            # the emitter's own cone where it is narrower than the geometry's (a spot inside
            # the scene): no light leaves outside it, so nothing is missed
            cos_l = float(lobe[3])
            use = dr.select(inside, -1.0, cos_a) < cos_l
            d_l = mi.Frame3f(mi.Vector3f(*lobe[:3])).to_world(
                mi.warp.square_to_uniform_cone(s2, cos_l))
            d = dr.select(use, d_l, d)
            pdf = dr.select(use, mi.warp.square_to_uniform_cone_pdf(mi.Vector3f(0, 0, 1), cos_l),
                            pdf)
        it2 = dr.zeros(mi.Interaction3f)
        it2.p, it2.time, it2.wavelengths = p + d, time, wav  # unit distance: weight = I(d)
        _, I = emitter.sample_direction(it2, mi.Point2f(0.5, 0.5), active)
        return p, d, I / pdf, time

    # the kernel -----------------------------------------------------------------------------
    @staticmethod
    def launch_inputs(n: int, counts, start: int, stream: int, slot_ranges,
                      cap: float = 0.0, max_depth: int = 1) -> "LaunchInputs":
        """Every number of one launch that may change from call to call (photon split, stream,
        bands, fixed-point cap), in two host copies: kernel inputs, not literals.

        Parameters
        ----------
        n : int
            Photons of the launch.
        counts : sequence of int
            Photons per emitter over the whole pass.
        start : int
            First lane of the launch in the pass.
        stream : int
            Random stream (seeds the sampler and the band wavelengths' shifts).
        slot_ranges : sequence of (float, float)
            Band of each of the 4 wavelength slots [nm].
        cap : float
            Largest single fixed-point record (:func:`fixed_point_scale`).
        max_depth : int
            Most hits per photon.

        Returns
        -------
        LaunchInputs
            The arrays (see :class:`LaunchInputs`).
        """
        counts = [int(c) for c in counts]
        E = len(counts)
        shifts = np.random.default_rng(stream).integers(0, 2**32, size=_SLOTS, dtype=np.uint64)
        m_e = [int(math.isqrt(n)) if E == 1 else int(math.isqrt(c)) for c in counts]
        cum = np.cumsum(counts)
        pu = [int(v) for v in shifts] + [int(start)] + [int(c) for c in cum[:-1]] + m_e + \
            [int(max_depth), int(stream) & 0xFFFFFFFF]
        pf = [lo for lo, _ in slot_ranges] + [hi - lo for lo, hi in slot_ranges] + \
            [1.0 / m for m in m_e] + [1.0 / c for c in counts] + [float(cap)]
        # one host copy (each is a task of its own when it is freed)
        bits = np.asarray(pf, np.float32).view(np.uint32)
        return LaunchInputs(host_array(mi.UInt32, np.concatenate([np.asarray(pu, np.uint64)
                                                                  .astype(np.uint32), bits])),
                            len(pu), zero_index())

    def _photons(self, scene, emitters, index, n, inp: "LaunchInputs", slot_ranges_n=_SLOTS,
                 lobes=None):
        """One launch's photons (lanes of the pass ``inp`` describes; the lanes
        ``[c_0 + .. + c_(k-1), .. + c_k)`` of the pass are emitter ``k``'s), unevaluated:
        (sampler, ray, power, weight, emitter per lane or None for a single emitter).

        ``power`` [W] per photon and band slot (emitter weight x band width / its photon
        count), ``weight`` the emitter's raw sample weight (:meth:`_emit`) [W nm-1 x photons].
        Every per-pass number (counts, offsets, stream) comes from ``inp``'s arrays: a new
        day's photon split compiles nothing, and the launch can be frozen.
        """
        if isinstance(emitters, mi.Emitter):
            emitters = [emitters]
        E = len(emitters)
        lobes = lobes if lobes is not None else [None] * E

        pu, pf = inp.u, inp.f
        o_m, o_im, o_in = 5 + (E - 1), 2 * _SLOTS, 2 * _SLOTS + E
        sampler = LaneSampler(pu(o_m + E + 1), n)
        idx = dr.arange(mi.UInt32, n)
        # Band wavelengths from a randomly shifted Weyl (golden-ratio) sequence over the photon
        # index, in exact 32-bit fixed point: evenly spread over each band (low variance), each
        # photon's wavelength uniform (unbiased), and, unlike index-ordered strata, not
        # correlated with the jittered-grid origin strata (which also follow the index).
        lam, widths = [], []
        for k in range(_SLOTS):
            bits = idx * 2654435769 + pu(k)
            uk = mi.Float(bits >> 8) * (2.0 ** -24)
            lam.append(pf(k) + pf(_SLOTS + k) * uk)
            widths.append(pf(_SLOTS + k))
        wav = mi.Spectrum(*lam)
        active = mi.Bool(True)
        if E == 1:
            # strata over this launch's lanes (a batch covers the whole rectangle)
            o, d, w, time = self._emit(scene, emitters[0], index, sampler, wav, active,
                                       strata=(idx, pu(o_m), pf(o_im)), lobe=lobes[0])
            inv_n = pf(o_in)
            e_lane = None
        else:
            g = idx + pu(4)
            e_lane = dr.zeros(mi.UInt32, n)
            first = dr.zeros(mi.UInt32, n)
            m_u = pu(o_m) * dr.full(mi.UInt32, 1, n)
            inv_m = pf(o_im) * dr.full(mi.Float, 1.0, n)
            inv_n = pf(o_in) * dr.full(mi.Float, 1.0, n)
            for k in range(1, E):
                c_k = pu(5 + k - 1)
                on = g >= c_k
                e_lane = dr.select(on, mi.UInt32(k), e_lane)
                first = dr.select(on, c_k, first)
                m_u = dr.select(on, pu(o_m + k), m_u)
                inv_m = dr.select(on, pf(o_im + k), inv_m)
                inv_n = dr.select(on, pf(o_in + k), inv_n)
            j = g - first
            o = d = w = time = None
            for k, em in enumerate(emitters):
                on = e_lane == k
                ok, dk, wk, tk = self._emit(scene, em, index, sampler, wav, on,
                                            strata=(j, m_u, inv_m), lobe=lobes[k])
                if o is None:
                    o, d, w, time = mi.Point3f(ok), mi.Vector3f(dk), mi.Spectrum(wk), tk
                else:
                    o = dr.select(on, ok, o)
                    d = dr.select(on, dk, d)
                    w = dr.select(on, mi.Spectrum(wk), w)
                    time = dr.select(on, tk, time)
        # power per photon [W]: spectral power x band width / photons of this emitter
        throughput = mi.Spectrum(*[w[k] * (widths[k] * inv_n) for k in range(_SLOTS)])
        # (a sun's weight is the same for all photons: broadcast it to one value per photon)
        throughput = mi.Spectrum(dr.select(dr.isfinite(throughput), throughput, 0.0)) \
            * dr.full(mi.Float, 1.0, n)
        ray = mi.Ray3f(o, d, time, wav)
        return sampler, ray, throughput, w, e_lane

    def _pass(self, scene, emitters, index, start, n, counts, stream, slot_ranges, refl,
              max_depth, indirect, tables: PassTables, mode="roulette", slots=_SLOTS,
              frozen: bool = False):
        """One kernel launch: lanes ``start .. start + n - 1`` of the pass (every traced
        emitter, :meth:`_photons`), the random walk of :meth:`_loop`. Returns the fixed-point
        tallies (acc, unit per emitter, book, rays per emitter), all on the device.

        ``frozen``: replay the launch's recorded kernels (``dr.freeze``) instead of tracing
        its Python again; every input is an argument of :meth:`_launch` (the scene, the
        emitters and BSDFs, the tables, the launch's numbers), so a day with other numbers,
        tables and sun path replays the same recording.
        """
        hits = 1 if not indirect else max_depth
        _, cap = fixed_point_scale(n, hits, 1.0)
        inp = self.launch_inputs(n, counts, start, stream, slot_ranges, cap, max_depth)
        # (the emission cones are plain numbers: a changed one records the launch again)
        lobes = tuple(self._lobe(e) for e in emitters)
        split = self.split_walk if self.split_walk != "auto" else dr.backend_v(mi.Float) \
            == dr.JitBackend.CUDA
        args = (scene, list(emitters), index, tables, refl, inp, int(n), len(counts),
                int(max_depth), bool(indirect), mode, int(slots), float(cap), lobes,
                bool(split))
        if frozen:
            if self._frozen is None:
                self._frozen = dr.freeze(PhotonKernel._launch, warn_after=50)
                # a recording's key holds every Mitsuba object of the pointer registry
                # (shapes, emitters: Dr.Jit traverses them all for the scene's virtual calls),
                # garbage ones too: a collection after the first recording (an earlier scene's
                # objects in reference cycles) would make the next call record again. So the
                # garbage goes before the first recording (once: a collection every day would
                # cost a GPU pass's time)
                gc.collect()
            # no cyclic garbage collection while a launch is recorded or replayed: a collection
            # that frees other Dr.Jit objects (an earlier scene's) in the middle of a recording
            # aborted the process once in the test suite (Mitsuba 3.9.1, Dr.Jit 1.5.0)
            was = gc.isenabled()
            gc.disable()
            try:
                return self._frozen(self, *args)
            finally:
                if was:
                    gc.enable()
        return self._launch(*args)

    def _launch(self, scene, emitters, index, tables, refl, inp, n, E, max_depth, indirect,
                mode, slots, cap, lobes=None, split=False):
        """The kernels of one launch (see :meth:`_pass`): a function of its arguments only.
        ``split``: the walk in two parts (:attr:`split_walk`)."""
        sampler, ray, throughput, _, e_lane = self._photons(scene, emitters, index, n, inp,
                                                            lobes=lobes)
        big = min(2.0 ** 40, cap / 16.0)
        # the largest initial power per emitter (bits of non-negative floats order like them)
        peak = dr.maximum(dr.maximum(throughput[0], throughput[1]),
                          dr.maximum(throughput[2], throughput[3]))
        pmax_bits = dr.zeros(mi.UInt32, E)
        e_or0 = mi.UInt32(0) if e_lane is None else e_lane
        dr.scatter_reduce(dr.ReduceOp.Max, pmax_bits, dr.reinterpret_array(mi.UInt32, peak),
                          e_or0, mode=dr.ReduceMode.Local)
        dr.eval(throughput, ray, pmax_bits, *([] if e_lane is None else [e_lane]))
        pm = mi.Float64(dr.reinterpret_array(mi.Float, pmax_bits))
        good = (pm > 0) & dr.isfinite(pm)
        # the scale the kernel uses (float32) and its exact inverse: the unit [W]
        scale_e = mi.Float(dr.select(good, big / pm, 1.0))
        unit = 1.0 / mi.Float64(scale_e)
        # both in one kernel (the gather below would evaluate the scale in a kernel of its
        # own, and the unit would be one more at the end)
        dr.eval(scale_e, unit)
        scale = dr.gather(mi.Float, scale_e, e_or0)
        acc = dr.zeros(_UInt64, E * tables.n_rec * 2 * 2 * _SLOTS)
        book = dr.zeros(_UInt64, E * 4 * _SLOTS)
        rays = dr.zeros(_UInt64, E)
        # in memory before the loop (a zero literal would be allocated twice by it)
        dr.make_opaque(acc, book, rays)
        capf = inp.f(2 * _SLOTS + 2 * E)
        max_d = inp.u(5 + (E - 1) + E)
        # emitted power, fixed point per (emitter, slot), in the launch that traces
        for k in range(_SLOTS):
            q = _UInt64(dr.round(dr.minimum(throughput[k] * scale, capf)))
            dr.scatter_add(book, q, e_or0 * (4 * _SLOTS) + k, mode=dr.ReduceMode.Local)
        esc = dr.zeros(mi.Spectrum, n)
        absd = dr.zeros(mi.Spectrum, n)
        active = dr.any(throughput > 0)
        walk = partial(self._loop, scene, max_d=max_d, acc=acc, index=index,
                       normals=index.kernel_normals, refl_arr=refl, one_hit=not indirect,
                       cap=capf, modes=tables.modes, bsdf_table=tables.bsdf_table,
                       bsdfs=tables.bsdfs, rows=tables.row_arr, weights=mode == "weights",
                       slots=slots, n_rec=tables.n_rec, slot_of=tables.slot_of)

        def book_lanes(thr_left, rays_lane, esc, absd, e, sc, done=True):
            # what each photon took out of the walk (escaped, absorbed, left at the depth
            # limit) and its casts, per emitter; ``done``: the lanes whose walk ended here
            for j, x in enumerate((esc, absd, thr_left)):
                for k in range(_SLOTS):
                    q = _UInt64(dr.round(dr.minimum(x[k] * sc, capf)))
                    dr.scatter_add(book, q, e * (4 * _SLOTS) + (j + 1) * _SLOTS + k, done,
                                   mode=dr.ReduceMode.Local)
            dr.scatter_add(rays, _UInt64(rays_lane), e, done, mode=dr.ReduceMode.Local)

        if not split:
            thr_left, rays_lane, esc, absd = walk(
                sampler=sampler, ray=ray, throughput=throughput, active=active,
                depth=mi.UInt32(0), esc=esc, absd=absd, scale=scale, e_lane=e_lane)
            book_lanes(thr_left, rays_lane, esc, absd, e_or0, scale)
            # one kernel: the loop and every tally it feeds
            dr.eval(acc, book, rays, unit)
            return acc, unit, book, rays
        # In two parts (split_walk): every photon's first cast, then the photons that go on,
        # gathered into dense lanes. Each lane carries its whole state (ray, power, generator,
        # depth, sums) into the second part, and the tallies are integer sums: the same
        # numbers as one loop.
        thr_left, rays_lane, esc, absd, ray, depth, prev, going = walk(
            sampler=sampler, ray=ray, throughput=throughput, active=active,
            depth=mi.UInt32(0), esc=esc, absd=absd, scale=scale, e_lane=e_lane, n_iter=1)
        book_lanes(thr_left, rays_lane, esc, absd, e_or0, scale, ~going)
        dr.eval(thr_left, rays_lane, esc, absd, ray, depth, prev, going, sampler, acc, book,
                rays)
        # (lane 0 always: never an empty part, which a recorded launch could not replay; a
        # stopped lane 0 walks no further and is booked once, above)
        on = dr.compress(going | (dr.arange(mi.UInt32, n) == 0))
        s_on = LaneSampler()
        s_on.rng = dr.gather(mi.PCG32, sampler.rng, on)
        go_on = dr.gather(mi.Bool, going, on)
        e_on = e_or0 if e_lane is None else dr.gather(mi.UInt32, e_lane, on)
        sc_on = scale if e_lane is None else dr.gather(mi.Float, scale, on)
        out = walk(sampler=s_on, ray=dr.gather(mi.Ray3f, ray, on),
                   throughput=dr.gather(mi.Spectrum, thr_left, on), active=go_on,
                   depth=dr.gather(mi.UInt32, depth, on), esc=dr.gather(mi.Spectrum, esc, on),
                   absd=dr.gather(mi.Spectrum, absd, on), scale=sc_on,
                   e_lane=None if e_lane is None else e_on,
                   prev=dr.gather(mi.UInt32, prev, on),
                   nrays=dr.gather(mi.UInt32, rays_lane, on))
        book_lanes(*out, e_on, sc_on, go_on)
        # one kernel: the walk's second part and every tally it feeds
        dr.eval(acc, book, rays, unit)
        return acc, unit, book, rays

    @staticmethod
    def _tables(index):
        """Per-element geometric normals (flat array, 3 per element) for the kernel."""
        return index.kernel_normals

    @dr.syntax
    def _loop(self, scene, sampler, ray, throughput, active, depth, max_d, acc, esc, absd,
              index, normals, refl_arr, one_hit, scale, cap, modes=None, bsdf_table=None,
              bsdfs=(), rows=None, weights=False, paths=None, lane=None, n_lanes=None,
              slots=_SLOTS, e_lane=None, n_rec=0, slot_of=None, prev=None, nrays=None,
              n_iter=None):
        """The random walk: one symbolic loop (a single kernel), in one of two modes.

        ``weights=False`` ("roulette", paper 000 §3.4): at a hit the BSDF is sampled and the
        photon goes on with probability q = max_k a_k, its band powers becoming P_k a_k / q.
        ``weights=True`` ("weights"): every photon goes on up to ``max_d`` hits in a
        cosine-weighted direction about the side it hit (two-sided), its band powers becoming
        P_k a_k with a_k = pi f_k(wi, wo) (the BSDF's value for that direction over the cosine
        pdf, or the per-element override albedo): the same expectation, and the directions do
        not depend on the albedo. With ``acc=None`` nothing is recorded in ``acc`` and the
        power stays the initial one (only the paths are wanted); with ``paths`` (UInt32 of
        ``n_lanes x max_d``, filled with ``_NO_ROW``) the k-th hit of photon ``lane`` stores
        ``2 element + side`` (side 1 = back) at ``k n_lanes + lane``: what :meth:`replay`
        evaluates.

        Hits are found with ``ray_intersect_preliminary`` (the BVH traversal only). The element
        comes from the lookup table, the side from the element's geometric normal (a table,
        world space, instances included), and the BSDF is sampled on a surface interaction
        made of just what a spatially uniform BSDF reads (position, normal frame, wi,
        wavelengths). Analytic shapes get their normal from the shape itself; scenes with
        spatially varying BSDFs (textures, mesh attributes) use Mitsuba's full interaction.
        With ``modes`` (per-element :data:`SENSOR` / :data:`HIDDEN`), a photon crossing such
        an element is recorded (sensor) or not (hidden) and goes on unchanged from the hit.
        With ``bsdf_table`` (per-element BSDF registry id, 0 = the shape's own), the element's
        BSDF is gathered from the table; ``bsdfs`` lists every BSDF the kernel dispatches to.
        With ``rows`` (per-element accumulator row, ``0xFFFFFFFF`` = not recorded) only the
        recorded elements have a place in ``acc``. All tables are device arrays outside the
        loop state: new contents, same kernel. Only the first ``slots`` band slots are added
        to ``acc`` (a pass of fewer than 4 bands makes fewer atomic adds per hit).

        ``scale`` is the fixed-point scale per lane (an array: one per emitter); with
        ``e_lane`` (the emitter of each lane) emitter k's records go to rows
        ``k n_rec + row``. A hit on the mesh triangle that the photon last left is a
        self-intersection of the spawned ray (a planar triangle cannot be hit again by a ray
        that left it, only float rounding of the spawn point can do that): it is crossed like a hidden
        element, unrecorded, without a bounce. Hits on meshes with vertex normals (scenes
        without instances) use Mitsuba's full surface interaction for the BSDF's shading
        frame; every other hit a minimal one built from the element's geometric normal.

        A walk can be cut into parts (:meth:`_launch`): ``n_iter`` stops every lane after that
        many casts and returns, after the four values, the rest of its state (ray, depth, the
        element last left, whether it goes on); ``prev`` and ``nrays`` continue such a state.
        """
        nrays = mi.UInt32(0) if nrays is None else mi.UInt32(nrays)
        bsdf_ctx = mi.BSDFContext(mi.TransportMode.Importance)
        lookup, blookup = index.lookup, index.bsdf_lookup
        has_instances = len(index.instances) > 0
        has_vn = index.vn_table is not None   # shading normals from tables (instanced scenes)
        full_lookup = index.full_lookup
        # every hit needs the full interaction (a spatially varying BSDF in an instanced scene),
        # or only hits on the shapes listed in ``full_lookup``
        full = index.needs_full_interaction and full_lookup is None
        some_full = full_lookup is not None
        has_e = e_lane is not None
        prev = dr.full(mi.UInt32, _NO_ROW, dr.width(throughput)) if prev is None \
            else mi.UInt32(prev)
        # the casts this part may make (no limit: the whole walk)
        it, lim = mi.UInt32(0), mi.UInt32(0xFFFFFFFF if n_iter is None else n_iter)
        # read-only objects stay out of the loop state: traversing a scene with 1,000
        # instances for it cost ~0.1 s per pass
        has_modes = modes is not None
        has_override = bsdf_table is not None
        has_rows = rows is not None
        has_acc = acc is not None
        has_paths = paths is not None
        # registry id of a BSDF -> its position in ``bsdfs`` (len(bsdfs): none of them)
        use_switch = len(bsdfs) >= _SWITCH_BSDFS
        slot_of, samplers, evals = self._switch_targets(bsdfs, bsdf_ctx, slot_of) if use_switch \
            else (None, None, None)
        while dr.hint(active & (it < lim), label="veg_photon_irradiance",
                      exclude=[scene, index, bsdfs, lookup, blookup, normals, modes,
                               bsdf_table, rows, slot_of, samplers, evals, full_lookup,
                               e_lane]):
            pi = scene.ray_intersect_preliminary(ray, coherent=False, active=active)
            nrays += dr.select(active, mi.UInt32(1), mi.UInt32(0))
            hit = active & pi.is_valid()
            # escaped photons leave with their power
            esc = mi.Spectrum(esc + dr.select(active & ~hit, throughput, 0.0))
            throughput = mi.Spectrum(dr.select(active & ~hit, 0.0, throughput))

            sid = dr.reinterpret_array(mi.UInt32, pi.shape)
            elem = dr.gather(mi.UInt32, lookup, sid, hit) + pi.prim_index
            bsdf_id = dr.gather(mi.UInt32, blookup, sid, hit)
            if dr.hint(has_instances, mode='scalar'):
                # inside an instance the backends name the mesh differently: OptiX gives the
                # mesh as ``shape`` (its lookup entries: offset within the group, BSDF) and
                # shape_index 0; Embree a null shape and the mesh's place in its group as
                # shape_index (the group tables)
                iid = dr.reinterpret_array(mi.UInt32, pi.instance)
                in_inst = hit & (iid > 0)
                by_slot = in_inst & (sid == 0)
                slot = dr.gather(mi.UInt32, index.group_base, iid, by_slot) + pi.shape_index
                elem += dr.select(in_inst, dr.gather(mi.UInt32, lookup, iid, in_inst), 0) \
                    + dr.select(by_slot, dr.gather(mi.UInt32, index.group_local, slot, by_slot), 0)
                bsdf_id = dr.select(by_slot, dr.gather(mi.UInt32, index.group_bsdf, slot, by_slot),
                                    bsdf_id)
            analytic = mi.Bool(False)
            if dr.hint(full, mode='scalar'):
                si = pi.compute_surface_interaction(ray, mi.RayFlags.All, hit)
                ng = mi.Vector3f(si.n)
                for reg, shape in index.analytic:
                    analytic = analytic | (hit & (sid == reg))
            else:
                ng = mi.Vector3f(dr.gather(mi.Float, normals, elem * 3, hit),
                                 dr.gather(mi.Float, normals, elem * 3 + 1, hit),
                                 dr.gather(mi.Float, normals, elem * 3 + 2, hit))
                for reg, shape in index.analytic:
                    on = hit & (sid == reg)
                    si_a = shape.compute_surface_interaction(ray, pi, mi.RayFlags.Minimal, on)
                    ng = dr.select(on, si_a.n, ng)
                    elem = dr.select(on, dr.gather(mi.UInt32, lookup, sid, on), elem)
                    analytic = analytic | on

            if dr.hint(has_override, mode='scalar'):
                # the element's own BSDF choice (e.g. a leaf's autumn stage) where it has one
                ov_id = dr.gather(mi.UInt32, bsdf_table, elem, hit)
                bsdf_id = dr.select(ov_id != 0, ov_id, bsdf_id)

            # the triangle the photon just left, hit again: a self-intersection (docstring)
            again = hit & (elem == prev) & ~analytic
            rec, passing = hit & ~again, mi.Bool(again)
            if dr.hint(has_modes, mode='scalar'):
                # sensors record and pass; hidden elements only pass; surfaces go on below
                mode = dr.gather(mi.UInt32, modes, elem, hit)
                passing = passing | (hit & (mode != SURFACE))
                rec = rec & (mode != HIDDEN)
            # the photon goes on from the hit point in its direction, offset off the
            # element along its normal (as Mitsuba's spawn_ray) so it does not hit it again
            p_hit = ray(pi.t)
            off = (1.0 + dr.max(dr.abs(p_hit))) * mi.math.RayEpsilon
            pass_o = p_hit + ng * dr.select(dr.dot(ng, ray.d) > 0, off, -off)
            pass_ray = mi.Ray3f(pass_o, ray.d, ray.time, ray.wavelengths)
            hit = hit & ~passing

            # record the incident power at the hit element: [elem][comp][side][slot]
            back = dr.dot(ng, ray.d) > 0
            comp = dr.select(depth > 0, mi.UInt32(1), mi.UInt32(0))
            side = dr.select(back, mi.UInt32(1), mi.UInt32(0))
            row = mi.UInt32(elem)
            if dr.hint(has_rows, mode='scalar'):
                row = dr.gather(mi.UInt32, rows, elem, rec)
                rec = rec & (row != _NO_ROW)
            if dr.hint(has_e, mode='scalar'):
                row = row + e_lane * n_rec
            if dr.hint(has_acc, mode='scalar'):
                base = ((row * 2 + comp) * 2 + side) * _SLOTS
                for k in range(slots):   # band slots beyond the pass's bands: not read back
                    # capped: no record can make a 64-bit sum wrap (see fixed_point_scale)
                    q_k = _UInt64(dr.round(dr.minimum(throughput[k] * scale, cap)))
                    # plain atomics: hits rarely share an element within a packet, so the
                    # packet-local pre-reduction of the default mode costs more than it saves
                    dr.scatter_add(acc, q_k, base + k, rec, mode=dr.ReduceMode.Direct)
            if dr.hint(has_paths, mode='scalar'):
                # the path's k-th hit: element and side, at [k][lane]
                dr.scatter(paths, elem * 2 + side, depth * n_lanes + lane, hit)

            if dr.hint(one_hit, mode='scalar'):
                active = mi.Bool(passing)
                ray = mi.Ray3f(dr.select(passing, pass_ray, ray))
            else:
                if dr.hint(full, mode='scalar'):
                    si.wi = si.to_local(-ray.d)
                else:
                    # the frame of the geometric normal
                    si = dr.zeros(mi.SurfaceInteraction3f)
                    si.t = pi.t
                    si.p = ray(pi.t)
                    si.n = ng
                    if dr.hint(has_vn, mode='scalar'):
                        # shading normal of meshes with vertex normals, as Mitsuba's mesh
                        # interpolates it (barycentric weights 1 - u - v, u, v), moved to
                        # world space by the instance's normal transform
                        reg = dr.select(in_inst, iid, sid)
                        vb = dr.gather(mi.UInt32, index.vn_base, reg, hit)
                        on_vn = hit & (vb != _NO_ROW)
                        row = (vb + elem - dr.gather(mi.UInt32, lookup, reg, on_vn)) * 9
                        b1, b2 = pi.prim_uv.x, pi.prim_uv.y
                        b0 = 1.0 - b1 - b2
                        n_o = [b0 * dr.gather(mi.Float, index.vn_table, row + c, on_vn)
                               + b1 * dr.gather(mi.Float, index.vn_table, row + 3 + c, on_vn)
                               + b2 * dr.gather(mi.Float, index.vn_table, row + 6 + c, on_vn)
                               for c in range(3)]
                        m = [dr.gather(mi.Float, index.vn_matrix, reg * 9 + c, on_vn)
                             for c in range(9)]
                        n_s = mi.Vector3f(*[m[3 * r] * n_o[0] + m[3 * r + 1] * n_o[1]
                                            + m[3 * r + 2] * n_o[2] for r in range(3)])
                        ok = on_vn & dr.isfinite(n_s.x) & (dr.squared_norm(n_s) > 0)
                        si.sh_frame = mi.Frame3f(dr.select(ok, dr.normalize(n_s), ng))
                    else:
                        si.sh_frame = mi.Frame3f(ng)
                    si.time = ray.time
                    si.wavelengths = ray.wavelengths
                    si.shape = pi.shape
                    si.instance = pi.instance
                    si.prim_index = pi.prim_index
                    if dr.hint(some_full, mode='scalar'):
                        # meshes with vertex normals: Mitsuba's interaction (shading frame)
                        need = hit & (dr.gather(mi.UInt32, full_lookup, sid, hit) != 0)
                        si_f = pi.compute_surface_interaction(ray, mi.RayFlags.All, need)
                        si = dr.select(need, si_f, si)
                    si.wi = si.sh_frame.to_local(-ray.d)
                # a back-face hit: the BSDF sees it as such (Mitsuba's semantics: ``diffuse``
                # absorbs it, ``twosided`` and the leaf BSDF reflect on that side); a
                # per-element albedo override reflects on the side that was hit
                flip = si.wi.z < 0
                if dr.hint(weights, mode='scalar'):
                    # weights: a cosine-weighted direction on the side that was hit, whatever
                    # the albedo; the power is multiplied by it (no roulette)
                    wo_local = mi.warp.square_to_cosine_hemisphere(sampler.next_2d(hit))
                    wo_local = dr.select(flip, mi.Vector3f(wo_local.x, wo_local.y, -wo_local.z),
                                         wo_local)
                    albedo = mi.Spectrum(1.0)
                    if dr.hint(has_acc, mode='scalar'):
                        # (a module function: a reference to ``self`` in the loop body would
                        # make Dr.Jit traverse the integrator for the loop state, ~90 ms a pass)
                        albedo = _cosine_albedo(si, wo_local, bsdf_id, bsdfs, bsdf_ctx, hit,
                                                slot_of, evals)
                        if dr.hint(refl_arr is not None, mode='scalar'):
                            # the table's rows end at the last element with an override
                            in_tab = hit & (elem < dr.width(refl_arr) // _SLOTS)
                            ov = [dr.gather(mi.Float, refl_arr, elem * _SLOTS + k, in_tab)
                                  for k in range(_SLOTS)]
                            use_ov = in_tab & ~dr.isnan(ov[0])
                            albedo = mi.Spectrum(dr.select(use_ov, mi.Spectrum(*ov), albedo))
                        albedo = mi.Spectrum(dr.select(dr.isfinite(albedo), albedo, 0.0))
                    go = mi.Bool(hit)
                    new_thr = throughput * albedo
                else:
                    s1, s2 = sampler.next_1d(hit), sampler.next_2d(hit)
                    # dispatch over the scene's distinct BSDFs only (a virtual call on a
                    # BSDFPtr would trace every BSDF Mitsuba holds: each instance has one)
                    if dr.hint(use_switch, mode='scalar'):
                        # each packet calls the BSDFs its lanes hit (~14 % faster on the
                        # world's 8 BSDFs than calling all of them masked)
                        k = dr.gather(mi.UInt32, slot_of, bsdf_id, hit)
                        bs, bw = dr.switch(k, samplers, si, s1, s2, hit & (k < len(bsdfs)))
                    else:
                        # two cheap BSDFs: each called for every hit, masked
                        bs, bw = dr.zeros(mi.BSDFSample3f), dr.zeros(mi.Spectrum)
                        for reg, b in bsdfs:
                            on = hit & (bsdf_id == reg)
                            bs_b, bw_b = b.sample(bsdf_ctx, si, s1, s2, on)
                            bs = dr.select(on, bs_b, bs)
                            bw = dr.select(on, bw_b, bw)
                    wo_local = bs.wo
                    albedo = mi.Spectrum(bw)
                    if dr.hint(refl_arr is not None, mode='scalar'):
                        in_tab = hit & (elem < dr.width(refl_arr) // _SLOTS)
                        ov = [dr.gather(mi.Float, refl_arr, elem * _SLOTS + k, in_tab)
                              for k in range(_SLOTS)]
                        use_ov = in_tab & ~dr.isnan(ov[0])
                        wo_cos = mi.warp.square_to_cosine_hemisphere(sampler.next_2d(hit))
                        wo_cos = dr.select(flip, mi.Vector3f(wo_cos.x, wo_cos.y, -wo_cos.z),
                                           wo_cos)
                        wo_local = dr.select(use_ov, wo_cos, wo_local)
                        albedo = mi.Spectrum(dr.select(use_ov, mi.Spectrum(*ov), albedo))
                        bs.pdf = dr.select(use_ov, 1.0, bs.pdf)
                    albedo = mi.Spectrum(dr.select(dr.isfinite(albedo) & (bs.pdf > 0), albedo,
                                                   0.0))
                    q = dr.minimum(dr.max(albedo), 1.0)
                    go = hit & (sampler.next_1d(hit) < q)
                    new_thr = throughput * albedo / dr.maximum(q, 1e-12)
                absd = mi.Spectrum(absd + dr.select(go, throughput - new_thr,
                                                    dr.select(hit, throughput, 0.0)))
                throughput = mi.Spectrum(dr.select(go, new_thr, dr.select(hit, 0.0, throughput)))
                ray = si.spawn_ray(si.to_world(wo_local))
                depth += 1
                active = go & (depth < max_d)
                # a crossed sensor/hidden element (or a self-intersection) costs no bounce
                ray = mi.Ray3f(dr.select(passing, pass_ray, ray))
                depth = dr.select(passing, depth - 1, depth)
                active = active | passing
                prev = dr.select(hit, elem, prev)
            it += 1
        out = (throughput, nrays, esc, absd)
        return out if n_iter is None else out + (ray, depth, prev, active)

    @classmethod
    def _switch_targets(cls, bsdfs, ctx, slot_of=None):
        """What the kernel's ``dr.switch`` over ``bsdfs`` needs: a device table from a BSDF's
        registry id to its position in ``bsdfs`` (:func:`switch_table`, unless given), and the
        ``sample`` and ``eval`` functions of each BSDF."""
        return (switch_table(bsdfs) if slot_of is None else slot_of,
                [cls._bsdf_sample(b, ctx) for _, b in bsdfs],
                [cls._bsdf_eval(b, ctx) for _, b in bsdfs])

    @staticmethod
    def _bsdf_sample(bsdf, ctx):
        """``bsdf.sample`` as a function of the arrays only (a ``dr.switch`` target)."""
        def sample(si, s1, s2, active):
            bs, bw = bsdf.sample(ctx, si, s1, s2, active)
            return bs, mi.Spectrum(bw)
        return sample

    @staticmethod
    def _bsdf_eval(bsdf, ctx):
        """``bsdf.eval`` as a function of the arrays only (a ``dr.switch`` target)."""
        def evaluate(si, wo, active):
            return mi.Spectrum(bsdf.eval(ctx, si, wo, active))
        return evaluate


def switch_table(bsdfs) -> mi.UInt32:
    """Device table from a BSDF's registry id to its position in ``bsdfs`` (``len(bsdfs)``
    for any other id): the index of the kernel's ``dr.switch`` over them.

    Parameters
    ----------
    bsdfs : list of (int, mi.BSDF)
        The BSDFs the kernel dispatches to, with their registry ids.

    Returns
    -------
    mi.UInt32
        The table.
    """
    regs = [int(r) for r, _ in bsdfs]
    table = np.full(max(regs + [0]) + 1, len(bsdfs), dtype=np.uint32)
    table[regs] = np.arange(len(regs), dtype=np.uint32)
    return mi.UInt32(table)


def _aim_rectangle(d, bmin, bmax, radius):
    """The rectangle, perpendicular to the photon direction ``d``, that covers the shadow of
    the box [bmin, bmax]: (frame, smin, smax, tmin, tmax, dmin) in the frame of ``d`` (the 8
    corners projected, padded by 1e-4 of the box's half diagonal ``radius``)."""
    frame = mi.Frame3f(d)
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
    return frame, smin - pad, smax + pad, tmin - pad, tmax + pad, dmin


def aim_area(index: "SceneIndex", directions) -> np.ndarray:
    """Area of the photon pass's aiming rectangle for parallel light along each direction:
    what one photon of a directional emitter represents (its weight is the emitter's
    irradiance times this area) [m2].

    Parameters
    ----------
    index : SceneIndex
        The scene's index (its aim box).
    directions : array_like
        (n, 3) unit directions the photons travel in.

    Returns
    -------
    numpy.ndarray
        (n,) rectangle areas [m2] (one kernel for all directions).
    """
    dd = np.asarray(directions, np.float32).reshape(-1, 3)
    if len(dd) == 0:
        return np.zeros(0)
    bb = index.aim_bbox
    bmin, bmax = np.array(bb.min), np.array(bb.max)
    radius = max(0.5 * float(np.linalg.norm(bmax - bmin)), 1e-6)
    d = mi.Vector3f(*[mi.Float(dd[:, k]) for k in range(3)])
    _, smin, smax, tmin, tmax, _ = _aim_rectangle(d, bmin, bmax, radius)
    return np.asarray((smax - smin) * (tmax - tmin), dtype=np.float64)


def _cosine_albedo(si, wo_local, bsdf_id, bsdfs, ctx, active, slot_of=None, evals=None):
    """Per-band albedo pi f(wi, wo) of each hit's BSDF for a cosine-sampled ``wo_local``
    (the BSDF value times cos / cosine pdf): the weight of the "weights" mode."""
    if slot_of is not None:
        k = dr.gather(mi.UInt32, slot_of, bsdf_id, active)
        f = dr.switch(k, evals, si, wo_local, active & (k < len(bsdfs)))
    else:
        f = dr.zeros(mi.Spectrum)
        for reg, b in bsdfs:
            on = active & (bsdf_id == reg)
            f = dr.select(on, b.eval(ctx, si, wo_local, on), f)
    return mi.Spectrum(f * (dr.pi / dr.maximum(dr.abs(wo_local.z), 1e-12)))
