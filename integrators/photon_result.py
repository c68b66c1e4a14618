"""The result of a photon pass: per-element flux by emitter, component, side and band, the
energy bookkeeping and the tallies on the device (64-bit fixed point); and the paths of the
"weights" mode that the differentiable pass replays."""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.arrays import zero_index
from mitsuba_veg.atomic import atomic_write
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.units import umol_per_joule

from .bands import COMPONENTS, SIDES, _SLOTS, _band_name

__all__ = ["fixed_point_scale", "PhotonIrradianceResult", "DeviceTallies", "PhotonPathRecord"]

def fixed_point_scale(photons: int, hits: int, pmax: float) -> tuple[float, float]:
    """Scale and cap of the 64-bit fixed-point flux accumulator.

    Every record adds ``min(round(power * scale), cap)`` to an unsigned 64-bit sum. One photon
    records at most ``hits`` times, so no sum can exceed ``photons * hits * cap``, which this
    cap keeps below 2^64 (no wrap-around, whatever the batch size, depth or emitter power). The
    scale maps the largest initial photon power ``pmax`` [W] to ``min(2^40, cap / 16)``: a
    photon would have to gain 16x its initial power (only a BSDF that creates energy can) before
    its records are capped.

    Parameters
    ----------
    photons : int
        Photons of the kernel launch (the batch).
    hits : int
        Most records one photon can make (``max_depth``, or 1 without indirect light).
    pmax : float
        Largest initial photon power of the batch [W].

    Returns
    -------
    scale : float
        Fixed-point units per watt [W^-1].
    cap : float
        Largest single record [fixed-point units], exactly representable in float32.
    """
    cap = float(np.float32(((1 << 64) - 1) // max(int(photons) * int(hits), 1)))
    while int(cap) * int(photons) * int(hits) > (1 << 64) - 1:  # float32 rounded up
        cap = float(np.nextafter(np.float32(cap), np.float32(0)))
    unit = min(2.0 ** 40, cap / 16.0)
    scale = unit / pmax if pmax > 0 and math.isfinite(pmax) else 1.0
    return scale, cap


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------
class PhotonIrradianceResult:
    """Per-element flux of a photon pass and what can be derived from it.

    ``flux[e, i, c, s, b]`` is the photon power [W] that hit element ``i`` (a triangle) on side
    ``s`` (0 front, 1 back) for emitter ``e``, component ``c`` (0 direct = first hit, 1 indirect =
    after >= 1 diffuse bounce) and band ``b``. Irradiance = flux / area.

    The pass leaves its tallies on the device (64-bit fixed-point sums and one unit [W] per
    emitter): :meth:`device_flux` reads any part of them as a Dr.Jit expression (a daily loop
    feeds its soil and moss without a host round trip), while :attr:`flux` and the
    bookkeeping (``emitted``, ``escaped``, ``absorbed``, ``truncated`` [W] per emitter and
    band, ``rays_traced``) are read back once, on first use. ``seconds`` [s] is the pass's wall
    time, its kernels' run included (``trace(..., wait=False)``: their launch only); reading
    the flux back and converting it is not part of it.
    """

    def __init__(self, index, bands, band_ranges, emitters, flux=None, photons=None,
                 rays_traced=None, emitted=None, escaped=None, absorbed=None, truncated=None,
                 seconds: float = 0.0, settings: dict | None = None, rows=None, device=None):
        self.index = index
        self.bands = tuple(bands)
        self.band_ranges = tuple(band_ranges)
        self.emitters = tuple(emitters)
        self.photons = np.asarray(photons) if photons is not None else None
        self.seconds = seconds
        self.settings = dict(settings or {})
        #: row of :attr:`flux` of every element, -1 where the element was not recorded
        #: (``trace(..., record=...)``); None: every element recorded, row = element
        self.rows = rows
        #: the pass's tallies on the device (:class:`DeviceTallies`), or None
        self.device = device
        self._flux = flux
        self._book = None if emitted is None else (emitted, escaped, absorbed, truncated,
                                                   rays_traced)

    # ---- host views, read back on first use ------------------------------------------------
    @property
    def flux(self) -> np.ndarray:
        """Flux [W], shape (emitters, recorded elements, 2 components, 2 sides, bands)."""
        if self._flux is None:
            self._flux = self.device.host_flux()
        return self._flux

    def _bookkeeping(self):
        if self._book is None:
            self._book = self.device.host_bookkeeping()
        return self._book

    @property
    def emitted(self) -> np.ndarray:
        """[e, b] power leaving the emitters towards the geometry [W]."""
        return self._bookkeeping()[0]

    @property
    def escaped(self) -> np.ndarray:
        """[e, b] power that left the scene without a hit [W]."""
        return self._bookkeeping()[1]

    @property
    def absorbed(self) -> np.ndarray:
        """[e, b] power absorbed at hits (Russian roulette) [W]."""
        return self._bookkeeping()[2]

    @property
    def truncated(self) -> np.ndarray:
        """[e, b] power still travelling at ``max_depth`` / with indirect light off [W]."""
        return self._bookkeeping()[3]

    @property
    def rays_traced(self) -> int:
        """Ray casts made (every call of ``ray_intersect``, per lane)."""
        return int(self._bookkeeping()[4])

    @property
    def n_rows(self) -> int:
        """Recorded elements (rows of :attr:`flux`)."""
        return self.index.n_elements if self.rows is None else int((self.rows >= 0).sum())

    def device_flux(self, emitter: int, band: int, rows, component: str = "total",
                    side: str = "front"):
        """Flux of accumulator ``rows`` [W] as a Dr.Jit expression (nothing is read back).

        Parameters
        ----------
        emitter : int
            Emitter index (in :attr:`emitters`).
        band : int
            Band index (in :attr:`bands`).
        rows : mi.UInt32
            Accumulator rows (elements, or :attr:`rows` of them with ``record``).
        component : str
            ``"direct"``, ``"indirect"`` or ``"total"``.
        side : str
            ``"front"``, ``"back"`` or ``"both"``.

        Returns
        -------
        mi.Float64
            Flux [W] per row.
        """
        comps = (0, 1) if component == "total" else (COMPONENTS.index(component),)
        sides = (0, 1) if side == "both" else (SIDES.index(side),)
        return self.device.flux(emitter, band, rows, comps, sides)

    def device_bookkeeping(self):
        """The bookkeeping on the device (nothing is read back).

        Returns
        -------
        tuple
            (book, rays): ``mi.Float64`` of (emitters, 4, bands) [W] flattened (emitted,
            escaped, absorbed, truncated) and ``mi.UInt64`` ray casts per emitter.
        """
        return self.device.bookkeeping()

    def _rows(self, sl: slice, shape_id: str = "") -> slice:
        """Rows of :attr:`flux` of the elements ``sl`` (a whole recorded shape)."""
        if self.rows is None:
            return sl
        r = self.rows[sl]
        if r.size and r[0] < 0:
            raise ParameterError("shape", shape_id, "a shape recorded by the pass (trace(..., "
                                 "record=...) left it out)", "add it to record=...")
        return slice(int(r[0]), int(r[-1]) + 1) if r.size else slice(0, 0)

    def shape_flux(self, shape_id: str) -> np.ndarray:
        """Flux of a shape's elements [W]: a view of :attr:`flux`.

        Parameters
        ----------
        shape_id : str
            A shape or instance id recorded by the pass.

        Returns
        -------
        np.ndarray
            Flux [W], shape (emitters, n, 2 components, 2 sides, bands).
        """
        return self.flux[:, self._rows(self.index.shape_slice(shape_id), shape_id)]

    # ---- layout -------------------------------------------------------------------------
    @property
    def single_element_shapes(self) -> dict:
        """Shapes recorded as one element each (analytic shapes: sphere, disk, cylinder, ...):
        ``{shape id: Mitsuba class name}``. Meshes (Mitsuba 3.9 loads ``rectangle`` and
        ``cube`` as meshes) and instanced meshes are resolved per triangle."""
        return dict(self.index.single_element)

    @property
    def instances(self) -> dict:
        """Instances resolved per triangle: ``{instance id: shapegroup id}``. Query them by
        instance id, or ``"instance_id/shape_id"`` for one mesh of the group."""
        return dict(self.index.instances)

    def tensor(self, emitter=None) -> np.ndarray:
        """Irradiance of every element [W m-2]: shape (elements, bands, 2, 2).

        Axes: element (``scene.shapes()`` order, see :meth:`shape_slice`), band (:attr:`bands`),
        component (0 direct, 1 indirect), side (0 front, 1 back); summed over the emitters (or
        those given). This is what ``mi.render`` returns for the integrator.

        Parameters
        ----------
        emitter : str or int or sequence, optional
            Emitter id, index or a list of them (default: the sum over all traced emitters).

        Returns
        -------
        np.ndarray
            Irradiance [W m-2], shape (elements, bands, 2, 2); 0 for unrecorded elements.
        """
        f = self.flux[self._emitters(emitter)].sum(axis=0)          # (n, comp, side, band)
        if self.rows is not None:                                    # unrecorded: 0
            full = np.zeros((self.index.n_elements,) + f.shape[1:])
            full[self.rows >= 0] = f
            f = full
        return np.moveaxis(f, -1, 1) / np.maximum(self.index.areas, 1e-30)[:, None, None, None]

    def shape_slice(self, shape_id: str) -> slice:
        """Elements of a shape id, instance id or ``"instance_id/shape_id"`` in :meth:`tensor`.

        Parameters
        ----------
        shape_id : str
            A shape id, an instance id or an ``"instance_id/shape_id"`` key.

        Returns
        -------
        slice
            The shape's rows of :meth:`tensor`.
        """
        return self.index.shape_slice(shape_id)

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
        """Incident power per element of a shape [W].

        Parameters
        ----------
        shape_id : str
            A shape id, an instance id or an ``"instance_id/shape_id"`` key.
        band : str or tuple
            A traced band: its name (e.g. ``"par"``) or its (min_nm, max_nm) range [nm].
        component : str
            ``"direct"`` (first hit), ``"indirect"`` (after >= 1 bounce) or ``"total"``.
        side : str
            ``"front"`` (the side the geometric normal faces), ``"back"`` or ``"both"``.
        emitter : str or int or sequence, optional
            Emitter id, index or a list of them (default: the sum over all traced emitters).

        Returns
        -------
        np.ndarray
            Flux [W], one value per element of the shape.
        """
        if component not in COMPONENTS:
            raise ParameterError("component", component, f"one of {COMPONENTS}")
        if side not in SIDES + ("both",):
            raise ParameterError("side", side, "'front', 'back' or 'both'")
        sl = self._rows(self.index.shape_slice(shape_id), shape_id)
        b = self._band(band)
        f = self.flux[self._emitters(emitter), sl, ..., b].sum(axis=0)  # (n, comp, side)
        f = f.sum(axis=1) if component == "total" else f[:, COMPONENTS.index(component)]
        return f.sum(axis=1) if side == "both" else f[:, SIDES.index(side)]

    def irradiance(self, shape_id: str, band="total", component="total", side="front",
                   emitter=None) -> np.ndarray:
        """Incident irradiance per triangle of ``shape_id`` [W m-2] (one value a triangle).

        component: "direct" (first hit from the emitter), "indirect" (after diffuse bounces) or
        "total"; side: "front" (the side the normal faces), "back" or "both"; emitter: None (all),
        an emitter id/index or a list of them. A triangle of zero area (e.g. a collapsed leaf
        slot of a world's canopy) gets NaN.

        Parameters
        ----------
        shape_id : str
            A shape id, an instance id or an ``"instance_id/shape_id"`` key.
        band : str or tuple
            A traced band: its name (e.g. ``"par"``) or its (min_nm, max_nm) range [nm].
        component : str
            ``"direct"`` (first hit), ``"indirect"`` (after >= 1 bounce) or ``"total"``.
        side : str
            ``"front"`` (the side the geometric normal faces), ``"back"`` or ``"both"``.
        emitter : str or int or sequence, optional
            Emitter id, index or a list of them (default: the sum over all traced emitters).

        Returns
        -------
        np.ndarray
            Irradiance [W m-2], one value per triangle (NaN for zero area).
        """
        sl = self.index.shape_slice(shape_id)
        a = self.index.areas[sl]
        f = self.flux_of(shape_id, band, component, side, emitter)
        return np.divide(f, a, out=np.full(f.shape, np.nan), where=a > 0)

    def element_irradiance(self, band="total", component="total", side="front",
                           emitter=None) -> np.ndarray:
        """Irradiance of every element of the scene (all shapes, in index order) [W m-2];
        0 for elements the pass did not record.

        Parameters
        ----------
        band : str or tuple
            A traced band: its name (e.g. ``"par"``) or its (min_nm, max_nm) range [nm].
        component : str
            ``"direct"`` (first hit), ``"indirect"`` (after >= 1 bounce) or ``"total"``.
        side : str
            ``"front"`` (the side the geometric normal faces), ``"back"`` or ``"both"``.
        emitter : str or int or sequence, optional
            Emitter id, index or a list of them (default: the sum over all traced emitters).

        Returns
        -------
        np.ndarray
            Irradiance [W m-2], one value per element.
        """
        if component not in COMPONENTS:
            raise ParameterError("component", component, f"one of {COMPONENTS}")
        if side not in SIDES + ("both",):
            raise ParameterError("side", side, "'front', 'back' or 'both'")
        # pick the band, component and side before summing: no copy of the whole flux array
        c = slice(None) if component == "total" else COMPONENTS.index(component)
        s = slice(None) if side == "both" else SIDES.index(side)
        f = self.flux[self._emitters(emitter), :, c, s, self._band(band)]
        f = f.reshape(f.shape[0], f.shape[1], -1).sum(axis=(0, 2))
        if self.rows is not None:
            full = np.zeros(self.index.n_elements)
            full[self.rows >= 0] = f
            f = full
        return f / np.maximum(self.index.areas, 1e-30)

    def photon_flux_density(self, shape_id: str, band="par", component="total", side="front",
                            emitter=None) -> np.ndarray:
        """Photon flux density [umol m-2 s-1] per triangle, converting each band's energy at its
        centre wavelength (exact to < 0.1 % for narrow bands; for PAR it assumes the band's
        spectrum is flat in energy, which for daylight is within ~2 %).

        Parameters
        ----------
        shape_id : str
            A shape id, an instance id or an ``"instance_id/shape_id"`` key.
        band : str or tuple
            A traced band: its name (e.g. ``"par"``) or its (min_nm, max_nm) range [nm].
        component : str
            ``"direct"`` (first hit), ``"indirect"`` (after >= 1 bounce) or ``"total"``.
        side : str
            ``"front"`` (the side the geometric normal faces), ``"back"`` or ``"both"``.
        emitter : str or int or sequence, optional
            Emitter id, index or a list of them (default: the sum over all traced emitters).

        Returns
        -------
        np.ndarray
            Photon flux density [umol m-2 s-1], one value per triangle.
        """
        return self.irradiance(shape_id, band, component, side, emitter) \
            * umol_per_joule(*self.band_ranges[self._band(band)])

    def red_far_red(self, shape_id: str, component="total", side="front", emitter=None,
                    red="red", far_red="far_red") -> np.ndarray:
        """Red:far-red ratio per triangle as plants sense it: a ratio of photon fluxes
        (655-665 nm over 725-735 nm by default); NaN where no far-red arrives.

        Parameters
        ----------
        shape_id : str
            A shape id, an instance id or an ``"instance_id/shape_id"`` key.
        component : str
            ``"direct"`` (first hit), ``"indirect"`` (after >= 1 bounce) or ``"total"``.
        side : str
            ``"front"`` (the side the geometric normal faces), ``"back"`` or ``"both"``.
        emitter : str or int or sequence, optional
            Emitter id, index or a list of them (default: the sum over all traced emitters).
        red, far_red : str or tuple
            The traced bands used as red and far-red (names or (min_nm, max_nm) [nm]).

        Returns
        -------
        np.ndarray
            R:FR [-] (photon flux ratio), one value per triangle.
        """
        r = self.photon_flux_density(shape_id, red, component, side, emitter)
        fr = self.photon_flux_density(shape_id, far_red, component, side, emitter)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(fr > 0, r / np.where(fr > 0, fr, 1.0), np.nan)

    def total_flux(self, band="total") -> float:
        """Power that hit any element, both sides, all components [W].

        Parameters
        ----------
        band : str or tuple
            A traced band: its name (e.g. ``"par"``) or its (min_nm, max_nm) range [nm].

        Returns
        -------
        float
            Total recorded flux [W], summed over emitters.
        """
        return float(self.flux[..., self._band(band)].sum())

    def to_npz(self, path) -> None:
        """Write every shape's irradiance arrays and the bookkeeping to a .npz file.

        Keys ``{shape}/{band}/{component}`` (front irradiance [W m-2], one value a triangle),
        ``{shape}/area_m2``, ``{shape}/centroid_m``, ``{shape}/normal``. With instances, also
        ``elements/...`` (the same for every element of the scene, in :meth:`tensor` order)
        and ``instances/ids``, ``instances/first_element``, ``instances/element_count``, and
        one value per instance for every instance: ``instances/area_m2`` and
        ``instances/{band}/{component}`` (area-weighted mean front irradiance [W m-2]);
        per-instance per-triangle keys (``{instance}/...``) are written for up to 100
        instances only (beyond, the ``elements/...`` rows of ``first_element`` ..
        ``first_element + element_count`` hold them).

        Parameters
        ----------
        path : str or os.PathLike
            Output file (written atomically).
        """
        data = {"bands": np.array(self.bands), "emitters": np.array(self.emitters),
                "band_ranges_nm": np.array(self.band_ranges), "photons": self.photons,
                "rays_traced": np.array(self.rays_traced), "emitted_W": self.emitted,
                "escaped_W": self.escaped, "absorbed_W": self.absorbed,
                "truncated_W": self.truncated}
        inst = self.index.instances
        if inst:
            ids = list(inst)
            data["instances/ids"] = np.array(ids)
            data["instances/group"] = np.array([inst[i] for i in ids])
            sls = [self.index.shape_slice(i) for i in ids]
            data["instances/first_element"] = np.array([sl.start for sl in sls])
            data["instances/element_count"] = np.array([sl.stop - sl.start for sl in sls])
            data["elements/area_m2"] = self.index.areas
            data["elements/centroid_m"] = self.index.centroids
            data["elements/normal"] = self.index.normals
            starts = np.array([sl.start for sl in sls], dtype=np.int64)
            ends = np.array([sl.stop for sl in sls], dtype=np.int64)

            def per_instance(x):   # sums over each instance's elements (other shapes between)
                cs = np.concatenate([[0.0], np.cumsum(x, dtype=np.float64)])
                return cs[ends] - cs[starts]
            area = per_instance(self.index.areas)
            data["instances/area_m2"] = area
            for b in self.bands:
                for c in COMPONENTS:
                    e = self.element_irradiance(b, c)
                    data[f"elements/{b}/{c}"] = e
                    data[f"instances/{b}/{c}"] = per_instance(e * self.index.areas) \
                        / np.maximum(area, 1e-300)
        for sid in self.index.shape_ids:
            if not sid or (sid in inst and len(inst) > 100):
                continue
            if self.rows is not None and self.rows[self.index.shape_slice(sid)][:1].min(
                    initial=0) < 0:
                continue  # not recorded
            sl = self.index.shape_slice(sid)
            data[f"{sid}/area_m2"] = self.index.areas[sl]
            data[f"{sid}/centroid_m"] = self.index.centroids[sl]
            data[f"{sid}/normal"] = self.index.normals[sl]
            for b in self.bands:
                for c in COMPONENTS:
                    data[f"{sid}/{b}/{c}"] = self.irradiance(sid, b, c)
        with atomic_write(path, str(path) + ".tmp.npz") as tmp:
            np.savez_compressed(tmp, **data)


class DeviceTallies:
    """The tallies of a photon pass on the device, per band group of 4 slots.

    ``acc[g]`` holds the group's flux of every (emitter, row, component, side, slot) as 64-bit
    fixed-point sums (``unit[g]``: watts per unit, one per emitter) or, after several batches,
    as watts (``unit[g]`` None). ``book[g]`` holds (emitted, escaped, absorbed, truncated)
    per (emitter, slot) the same way; ``rays`` the ray casts per emitter.
    """

    def __init__(self, n_emitters: int, n_rows: int, groups: list, n_bands: int):
        self.E, self.n_rec, self.groups, self.n_bands = n_emitters, n_rows, groups, n_bands
        self.acc = [None] * len(groups)
        self.unit = [None] * len(groups)
        self.book = [None] * len(groups)
        self.book_unit = [None] * len(groups)
        self.rays = None

    def _where(self, band: int):
        for g_i, group in enumerate(self.groups):
            if band in group:
                return g_i, group.index(band)
        raise IndexError(band)

    def add_batch(self, g_i: int, acc, unit, book, rays) -> None:
        """Add one kernel launch's tallies (fixed point with ``unit`` per emitter).

        Parameters
        ----------
        g_i : int
            Band group.
        acc, book : mi.UInt64
            The launch's fixed-point flux and bookkeeping.
        unit : mi.Float64
            Watts per fixed-point unit, one per emitter.
        rays : mi.UInt64
            Ray casts per emitter.
        """
        if self.acc[g_i] is None:
            self.acc[g_i], self.unit[g_i], self.book[g_i] = acc, unit, book
        else:
            # several launches: sum in watts (each launch has its own fixed-point unit)
            self.acc[g_i] = self._watts(self.acc[g_i], self.unit[g_i], self.n_rec * 16) + \
                self._watts(acc, unit, self.n_rec * 16)
            self.book[g_i] = self._watts(self.book[g_i], self.unit[g_i], 4 * _SLOTS) + \
                self._watts(book, unit, 4 * _SLOTS)
            self.unit[g_i] = None
            dr.eval(self.acc[g_i], self.book[g_i])
        if g_i == 0:
            self.rays = rays if self.rays is None else self.rays + rays

    @staticmethod
    def _watts(x, unit, per_emitter: int):
        if unit is None:
            return x
        e = dr.arange(mi.UInt32, dr.width(x)) // per_emitter
        return mi.Float64(x) * dr.gather(mi.Float64, unit, e)

    def flux(self, emitter: int, band: int, rows, comps, sides):
        """Flux [W] of ``rows`` (mi.Float64 expression), summed over ``comps`` and ``sides``.

        Parameters
        ----------
        emitter, band : int
            Emitter and band index.
        rows : mi.UInt32
            Rows.
        comps, sides : tuple of int
            Components (0 direct, 1 indirect) and sides (0 front, 1 back) to add.

        Returns
        -------
        mi.Float64
            Flux per row [W].
        """
        g_i, slot = self._where(band)
        acc = self.acc[g_i]
        base = (rows + emitter * self.n_rec) * 4
        out = None
        for c in comps:
            for sd in sides:
                v = dr.gather(type(acc), acc, (base + (c * 2 + sd)) * _SLOTS + slot)
                v = mi.Float64(v)
                out = v if out is None else out + v
        if self.unit[g_i] is not None:
            # (an opaque index: a literal one would make Dr.Jit copy the value at once)
            out = out * dr.gather(mi.Float64, self.unit[g_i], zero_index() + emitter)
        return out

    def bookkeeping(self):
        """(book [W] as mi.Float64 (emitters x 4 x bands), rays per emitter as mi.UInt64).

        Returns
        -------
        tuple
            The device arrays.
        """
        parts = []
        for g_i, group in enumerate(self.groups):
            w = self._watts(self.book[g_i], self.unit[g_i], 4 * _SLOTS)
            parts.append((w, group))
        return parts, self.rays

    def host_flux(self) -> np.ndarray:
        """All flux read back [W]: (emitters, rows, 2, 2, bands).

        Returns
        -------
        numpy.ndarray
            The flux array.
        """
        out = np.zeros((self.E, self.n_rec, 2, 2, self.n_bands))
        for g_i, group in enumerate(self.groups):
            a = np.asarray(self.acc[g_i]).reshape(self.E, self.n_rec, 2, 2, _SLOTS)
            if self.unit[g_i] is not None:
                u = np.asarray(self.unit[g_i], dtype=np.float64)
                a = a.astype(np.float64) * u[:, None, None, None, None]
            out[..., group] = a[..., :len(group)]
        return out

    def host_bookkeeping(self):
        """(emitted, escaped, absorbed, truncated) [W] (emitters, bands) and the ray casts.

        Returns
        -------
        tuple
            Four NumPy arrays and an int.
        """
        book = np.zeros((4, self.E, self.n_bands))
        for g_i, group in enumerate(self.groups):
            b = np.asarray(self._watts(self.book[g_i], self.unit[g_i], 4 * _SLOTS),
                           dtype=np.float64).reshape(self.E, 4, _SLOTS)
            book[:, :, group] = np.moveaxis(b, 1, 0)[:, :, :len(group)]
        rays = int(np.asarray(self.rays, dtype=np.uint64).sum())
        return book[0], book[1], book[2], book[3], rays


@dataclass
class PhotonPathRecord:
    """The paths of one emitter's photons traced in the "weights" mode (no AD).

    ``elem[k]`` (UInt32, one value per photon) is the element of the photon's k-th hit
    (``0xFFFFFFFF``: none), ``front[k]`` (Bool) whether it hit the element's front side (against
    its geometric normal). ``w0`` is each photon's initial power [W] (the emitter's power in the
    band over the photon count, its 4 band wavelengths averaged; attached to the emitter's
    parameters when traced with ``attach=True``). ``n_elements`` and ``areas`` [m2] are those
    of the scene index. Made by :meth:`PhotonIrradianceIntegrator.trace_paths`; replayed by
    :mod:`mitsuba_veg.integrators.photon_replay` (the plugin's :meth:`replay`).
    """

    emitter: str
    photons: int
    max_depth: int
    band: tuple
    w0: object                   # mi.Float (photons) [W]
    elem: list
    front: list
    n_elements: int = 0
    areas: object = None         # numpy (n_elements,) [m2]
    rays: int = 0                # ray casts made
    seconds: float = 0.0

    @property
    def nbytes(self) -> int:
        """Memory of the record on the device [bytes]: w0 (4) and per depth element (4) and
        side (1) per photon.

        Returns
        -------
        int
            Bytes.
        """
        return self.photons * (4 + len(self.elem) * 5)
