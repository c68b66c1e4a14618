"""The world's trees as a camera (or a photon pass of one day) sees them: the leaves on the
trees that day, at their blade size, with the optics of their autumn stage, and the wood; and
the true leaf and wood area inside an instrument's view cone.

The daily loop keeps every blade in one leaf mesh and hides the leaves that are not out (or
have fallen) in the photon pass's tables (:mod:`mitsuba_veg.world.canopy`). A camera has no
tables: :meth:`VisibleCanopy.shapes` builds meshes of the shown leaves only, one per stage bin
with that bin's ``veg_leaf`` BSDF (PROSPECT-D reflectance and transmittance), and the wood as
the light scene's ``trees_bark``. A leaf state (:class:`LeafState`) is the run's snapshot of a
day (``leaf_tau``, ``leaf_grown``, ``leaf_on``, :class:`mitsuba_veg.outputs.SnapshotWriter`):
a leaf is shown when it is on the tree and its blade, rounded to a tenth of its size as the
canopy rounds it (:meth:`Canopy.update`), is not zero; the blade is scaled about its centre
by that size.

**True area index in a view cone** (:meth:`VisibleCanopy.cone_area_index`): the shown
leaves whose centre lies above the lens within the zenith angle θ_max of it (the
instrument's view cone: 74° for the LAI-2000's outer ring), each leaf's one-sided area a_i
divided by the area of the cone's horizontal cross-section at the leaf's height above the lens
h_i, π (h_i tan θ_max)², and summed:

    LAI_cone = Σ_i a_i / (π h_i² tan² θ_max)

This is the brief's "per unit of the ground area the cone covers at the mean crown height"
with the mean crown height taken leaf by leaf (equivalently at h̄ = (Σ a_i / Σ a_i h_i⁻²)^½,
the area-weighted quadratic-harmonic mean height, also returned): for a canopy that is
horizontally uniform within the cone it equals the canopy's LAI exactly. Dividing the cone's
leaf area by the cross-section at the area-weighted *arithmetic* mean height of the cone's
leaves instead understates it, because the cone holds more of the higher leaves: by
(∫h²)³ / ((∫h³)² (h2 − h1)) for foliage spread evenly from h1 to h2 above the lens, 0.90 for
1-2 m, 0.76 for 2-8 m (that value is returned too, ``lai_mean_height``). Wood enters the plant area index with half
its bark surface (the convention of the woody area index for round stems, Chen & Black
1992), by bark triangle: PAI = LAI + WAI.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from ..errors import ParameterError, check_range
from ..foliage import leaf_bsdf_dict, leaf_spectra
from ..foliage.pigments import stage_from_tau
from ..meshes import make_mesh, triangle_geometry
from .canopy import _BARK

__all__ = ["LeafState", "VisibleCanopy", "BARK_ID", "LEAF_PREFIX"]

#: shape id of the wood and prefix of the leaf meshes (``trees_leaves_<bin>``)
BARK_ID, LEAF_PREFIX = "trees_bark", "trees_leaves_"


@dataclass
class LeafState:
    """Every leaf's state on a day (one entry per leaf of the trees, in canopy order).

    Attributes
    ----------
    tau : numpy.ndarray
        Autumn logical time τ [-].
    grown : numpy.ndarray
        Blade size from leaf-out [-] (0..1).
    on : numpy.ndarray
        bool: out and not fallen.
    """

    tau: np.ndarray
    grown: np.ndarray
    on: np.ndarray

    @classmethod
    def green(cls, n: int) -> "LeafState":
        """Every leaf out, full-size and green.

        Parameters
        ----------
        n : int
            Leaves.

        Returns
        -------
        LeafState
            τ = 0, size 1, on.
        """
        return cls(np.zeros(n), np.ones(n), np.ones(n, bool))

    @classmethod
    def from_arrays(cls, d: dict) -> "LeafState":
        """From a snapshot's ``leaf_tau``, ``leaf_grown``, ``leaf_on``.

        Parameters
        ----------
        d : dict
            The arrays (float16 in a snapshot).

        Returns
        -------
        LeafState
            As float64 / bool arrays.
        """
        return cls(np.asarray(d["leaf_tau"], np.float64), np.asarray(d["leaf_grown"], np.float64),
                   np.asarray(d["leaf_on"], bool))

    @classmethod
    def from_phenology(cls, phen) -> "LeafState":
        """From the daily loop's :class:`~mitsuba_veg.world.phenology.Phenology`, stored as a
        snapshot stores it (τ and size as float16), so that a photo taken in the run and one
        taken later from its snapshot of that day are the same.

        Parameters
        ----------
        phen : Phenology
            The leaves' state.

        Returns
        -------
        LeafState
            The state.
        """
        return cls.from_arrays({"leaf_tau": np.asarray(phen.tau).astype(np.float16),
                                "leaf_grown": np.asarray(phen.grown).astype(np.float16),
                                "leaf_on": np.asarray(phen.on_tree)})

    def __len__(self) -> int:
        return len(self.tau)


class VisibleCanopy:
    """The trees' leaves and wood for cameras and one-day photon passes (module docstring).

    Parameters
    ----------
    trees : sequence of WorldTree
        The world's trees of the day (their leaves in canopy order).
    bins : int
        Autumn-stage bins (the scenario's ``phenology.stage_bins``, default 4).
    """

    def __init__(self, trees, bins: int = 4):
        check_range("bins", bins, 1, 7)
        self.trees = list(trees)
        self.bins = int(bins)
        self.counts = np.array([len(t.leaf_area) for t in self.trees], np.int64)
        self.n_leaves = int(self.counts.sum())
        self.area = np.concatenate([np.asarray(t.leaf_area, float) for t in self.trees]) \
            if self.trees else np.zeros(0)
        # each leaf's centre as the canopy computes it (mean of its triangles' centroids)
        cs = []
        for t in self.trees:
            q = np.asarray(t.leaf_vertices, float)
            if not len(q):
                continue
            if q.shape[1] == 4:
                cs.append((2 * q[:, 0] + q[:, 1] + 2 * q[:, 2] + q[:, 3]) / 6.0)
            else:
                cs.append(q.mean(axis=1))
        self.centre = np.concatenate(cs) if cs else np.zeros((0, 3))
        bv, bf, nb = [], [], 0
        for t in self.trees:
            v, f = t.bark
            if len(f):
                bv.append(np.asarray(v, float))
                bf.append(np.asarray(f, np.int64) + nb)
                nb += len(v)
        self.bark = (np.concatenate(bv), np.concatenate(bf)) if bv else \
            (np.zeros((0, 3)), np.zeros((0, 3), np.int64))
        self._bark_geo = None

    # ---- the day's leaves --------------------------------------------------------------
    def check(self, state: LeafState) -> LeafState:
        """Refuse a state that is not one entry per leaf.

        Parameters
        ----------
        state : LeafState
            The state.

        Returns
        -------
        LeafState
            ``state``.
        """
        if len(state) != self.n_leaves:
            raise ParameterError("leaf state", f"{len(state)} leaves", f"one entry per leaf of "
                                 f"these trees ({self.n_leaves})", "take the state of a day "
                                 "of these trees (after the year-end growth, the next "
                                 "snapshot)")
        return state

    def blades(self, state: LeafState):
        """Which leaves are shown, their blade size and stage bin.

        Parameters
        ----------
        state : LeafState
            The day's leaves.

        Returns
        -------
        shown : numpy.ndarray
            bool per leaf.
        scale : numpy.ndarray
            Blade size in the mesh [-] (tenths, as the canopy rounds it).
        bin : numpy.ndarray
            Stage bin per leaf (0 .. bins − 1).
        """
        self.check(state)
        scale = np.round(np.clip(state.grown, 0.0, 1.0) * 10.0) / 10.0
        shown = state.on & (state.grown > 1e-3) & (scale > 0)
        s = stage_from_tau(np.clip(state.tau, 0.0, 1.0))
        b = np.minimum(((s - 1.0) / 6.0 * self.bins).astype(np.int64), self.bins - 1)
        return shown, np.where(shown, scale, 0.0), b

    def bin_stage(self, b: int) -> float:
        """Ishikura stage at the centre of bin ``b`` (as :meth:`Canopy.bin_stage`).

        Parameters
        ----------
        b : int
            Stage bin.

        Returns
        -------
        float
            Stage [-].
        """
        return 1.0 + 6.0 * (b + 0.5) / self.bins if self.bins > 1 else 1.0

    def shapes(self, state: LeafState, optics: bool = True) -> dict:
        """Meshes of the wood and of the shown leaves (one per stage bin).

        Parameters
        ----------
        state : LeafState
            The day's leaves.
        optics : bool
            Give the leaves their stage's ``veg_leaf`` BSDF and the wood its bark (False:
            Mitsuba's default BSDF, for ray-cast photographs).

        Returns
        -------
        dict
            ``{shape id: mitsuba.Mesh}``: ``trees_bark`` and ``trees_leaves_<bin>`` for the
            bins with a shown leaf.
        """
        shown, scale, b = self.blades(state)
        out = {}
        v, f = self.bark
        if len(f):
            out[BARK_ID] = make_mesh(BARK_ID, v, f, {"type": "twosided", "bsdf": {
                "type": "diffuse", "reflectance": _BARK}} if optics else None)
        start = 0
        parts = {k: [] for k in range(self.bins)}
        for t, m in zip(self.trees, self.counts):
            if m:
                q = np.asarray(t.leaf_vertices, float)
                sl = slice(start, start + m)
                keep = np.flatnonzero(shown[sl])
                if len(keep):
                    c = self.centre[sl][keep][:, None, :]
                    qq = c + scale[sl][keep][:, None, None] * (q[keep] - c)
                    for k in np.unique(b[sl][keep]):
                        parts[int(k)].append(qq[b[sl][keep] == k])
            start += m
        for k, qs in parts.items():
            if not qs:
                continue
            tris = []
            for q in qs:
                if q.shape[1] == 4:
                    tris.append(np.concatenate([q[:, :3], q[:, [0, 2, 3]]], axis=1)
                                .reshape(-1, 3, 3))
                else:
                    tris.append(q)
            tri = np.concatenate(tris)
            name = f"{LEAF_PREFIX}{k}"
            bsdf = leaf_bsdf_dict(leaf_spectra(stage=self.bin_stage(k))) if optics else None
            out[name] = make_mesh(name, tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3),
                                  bsdf)
        return out

    def scene(self, base_shapes, state: LeafState, optics: bool = True,
              emitters: dict | None = None, extra: dict | None = None):
        """A Mitsuba scene: ``base_shapes`` (terrain, walls), the day's trees and emitters.

        Parameters
        ----------
        base_shapes : sequence of mitsuba.Shape
            The scenario's own shapes (with ids).
        state : LeafState
            The day's leaves.
        optics : bool
            As :meth:`shapes`.
        emitters : dict, optional
            Emitter dicts/objects by id.
        extra : dict, optional
            More shapes or objects by id (a sensor, an integrator).

        Returns
        -------
        mitsuba.Scene
            Loaded with ``optimize=False`` (shape ids kept).
        """
        d = {"type": "scene"}
        for i, sh in enumerate(base_shapes):
            d[sh.id() or f"shape{i}"] = sh
        d.update(self.shapes(state, optics))
        d.update(emitters or {})
        d.update(extra or {})
        return mi.load_dict(d, optimize=False)

    # ---- the truth in a view cone ------------------------------------------------------
    def cone_area_index(self, point, state: LeafState, theta_max_deg: float = 74.0) -> dict:
        """True leaf, wood and plant area index in the view cone above ``point`` (module
        docstring).

        Parameters
        ----------
        point : sequence of 3 float
            The lens [m].
        state : LeafState
            The day's leaves.
        theta_max_deg : float
            Half-angle of the view cone [deg] (74: the LAI-2000's outer ring's edge).

        Returns
        -------
        dict
            ``lai_true``, ``wai_true``, ``pai_true`` [m2 m-2] (each element's one-sided area
            per cone cross-section at its own height, summed); ``lai_mean_height`` (the
            cone's leaf area over the cross-section at the leaves' area-weighted mean height
            [m2 m-2]); ``leaf_area_m2`` and ``wood_area_m2`` (one-sided, in the cone);
            ``leaves`` (count); ``height_mean_m`` and ``height_qh_m`` (the leaves'
            area-weighted arithmetic and quadratic-harmonic mean height above the lens [m]).
        """
        check_range("theta_max", theta_max_deg, 1.0, 89.0, fix="degrees, e.g. 74")
        p = np.asarray(point, float).reshape(3)
        tan2 = math.tan(math.radians(theta_max_deg)) ** 2
        shown, scale, _ = self.blades(state)
        a = self.area * scale * scale

        def cone(c, area):
            h = c[:, 1] - p[1]
            rho = np.hypot(c[:, 0] - p[0], c[:, 2] - p[2])
            inside = (h > 1e-6) & (rho * rho < tan2 * h * h) & (area > 0)
            hh = h[inside]
            return inside, hh, float(np.sum(area[inside] / (math.pi * tan2 * hh * hh)))

        inside, h, lai = cone(self.centre, np.where(shown, a, 0.0))
        la = a[inside]
        if self._bark_geo is None:
            v, f = self.bark
            if len(f):
                ar, _, cen = triangle_geometry(v, f)
                self._bark_geo = (cen, 0.5 * ar)        # one-sided: half the surface
            else:
                self._bark_geo = (np.zeros((0, 3)), np.zeros(0))
        wc, wa = self._bark_geo
        winside, _, wai = cone(wc, wa)
        total = float(la.sum())
        hm = float(np.sum(la * h) / total) if total > 0 else math.nan
        hq = float(math.sqrt(total / np.sum(la / (h * h)))) if total > 0 else math.nan
        return {"lai_true": lai, "wai_true": wai, "pai_true": lai + wai,
                "lai_mean_height": total / (math.pi * tan2 * hm * hm) if total > 0 else 0.0,
                "leaf_area_m2": total, "wood_area_m2": float(wa[winside].sum()),
                "leaves": int(inside.sum()), "height_mean_m": hm, "height_qh_m": hq}
