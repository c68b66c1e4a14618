"""The trees in the world's light scene: wood, and one leaf mesh whose optics follow the stages.

Wood: one two-sided diffuse mesh (``trees_bark``) for all trees. Leaves: one mesh
(``trees_leaves``) holding every leaf blade once (a quad leaf is two triangles). Its state is
two per-triangle tables handed to the photon pass each day, not geometry:

- **mode** (``trace(..., modes=...)``): a leaf on the tree is a SURFACE; a fallen leaf, or one
  not yet out, is HIDDEN: photons cross it unrecorded, as if it were not there;
- **optics** (``trace(..., bsdf_override=...)``): the ``veg_leaf`` BSDF of the leaf's Ishikura
  stage bin (PROSPECT-D reflectance **and** transmittance of the bin's centre stage, so far-red
  passes the canopy and red does not). The ``bins`` BSDFs are built once; the kernel calls them
  directly and gathers each triangle's choice from a device table, so a new day's table does
  not recompile the kernel.

Both tables are rebuilt every day from the phenology (a few integer arrays over the leaf
triangles), so stage, fall and leaf-out are exact day by day in the light. Vertices move only
(each time one vertex update, which rebuilds the leaf mesh's acceleration structure):

- during leaf-out: blades grow from their centre in steps of 0.1 of their size, and the mesh
  follows when 2 % of the shown leaves have a new blade size or 7 days after the first change
  (:attr:`Canopy.min_change`, :attr:`Canopy.max_lag_days`);
- when 25 % of the leaves are hidden with their blades still in the mesh
  (:attr:`Canopy.max_hidden_blades`): a photon crossing a hidden blade costs one more ray cast,
  so in autumn, every few days of leaf fall, and for the bare winter the hidden blades are
  taken out of the mesh.

A blade taken out (size 0) has NaN corners: Embree (and, by its documentation, OptiX) leaves
triangles with a NaN vertex out of its acceleration structure, where blades collapsed to a point were kept as
degenerate triangles that no ray can hit (the same hits, but the build paid for them: 4.4 s
for 4 M collapsed blades, 0.04 s for 4 M taken out; a bare hectare's scene 12-13 s instead of
17-20 s at every year's end, of which its wood and ground take 10 s). Mitsuba's mesh and scene
boxes leave NaN corners out too.

Outside leaf-out and leaf fall no vertex moves.

Light per leaf comes from the same photon pass as the terrain's: the flux recorded on a leaf's
triangles (both sides, direct + indirect), divided by the blade area the pass saw.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..arrays import aligned_empty, host_array
from ..foliage import leaf_bsdf_dict, leaf_spectra
from ..foliage.pigments import stage_from_tau
from ..integrators.photon_irradiance import HIDDEN, SURFACE, registry_id
from ..meshes import make_mesh
from ..parallel import map_on_cores

__all__ = ["LEAF_MESH", "Canopy"]

#: bark reflectance: 0.07 at 360 nm rising to 0.30 at 830 nm (7 values 78 nm apart; grey-brown)
_BARK = {"type": "regular", "wavelength_min": 360.0, "wavelength_max": 830.0,
         "values": "0.07, 0.08, 0.11, 0.15, 0.20, 0.26, 0.30"}

#: id of the leaf mesh in the light scene
LEAF_MESH = "trees_leaves"


class Canopy:
    """Leaves and wood of all world trees as Mitsuba meshes (see the module docstring).

    Parameters
    ----------
    trees : sequence of WorldTree
        The world's trees (their wood and leaf blades).
    bins : int
        Number of autumn-stage bins (stage 1..7 split evenly), one ``veg_leaf`` BSDF each.
    """

    #: a vertex update rebuilds the light scene's acceleration structure (about the time of a
    #: photon pass): at most one every ``min_update_days`` days. Stage, fall and leaf-out
    #: themselves are per-triangle tables, exact every day.
    min_update_days = 5
    #: growth: the mesh follows the blades (sizes in steps of 0.1) when this share of the
    #: shown leaves has a new size, or ``max_lag_days`` after the first change
    min_change = 0.02
    max_lag_days = 7
    #: a hidden leaf costs the photons that cross it one more ray cast each: the hidden blades
    #: still in the mesh are taken out (NaN corners) once they are this share of the leaves, or
    #: (more than 1 %) once none has been added for ``max_lag_days`` (the leaf fall is over)
    max_hidden_blades = 0.25

    def __init__(self, trees, bins: int = 4):
        self.trees = list(trees)
        self.bins = int(bins)
        # each tree's leaves fill their own slices of the whole tables, the trees on the
        # machine's cores (NumPy lets go of the GIL: a hectare's 13.4 M blade triangles took
        # 4 s on one thread); a quad is two triangles, (0, 1, 2) and (0, 2, 3)
        counts = [len(wt.leaf_vertices) for wt in self.trees]
        corners = [wt.leaf_vertices.shape[1] if m else 3 for wt, m in zip(self.trees, counts)]
        for wt, k in zip(self.trees, corners):
            if k not in (3, 4):
                raise ValueError(f"tree {wt.name}: a leaf element has {k} corners; 3 (a "
                                 "triangle) or 4 (a quad, two triangles) are drawn")
        per_leaf = [2 if k == 4 else 1 for k in corners]
        leaf0 = np.r_[0, np.cumsum(counts)].astype(np.int64)
        tri0 = np.r_[0, np.cumsum([m * t for m, t in zip(counts, per_leaf)])].astype(np.int64)
        n, F = int(leaf0[-1]), int(tri0[-1])
        dtype = np.result_type(np.float64, *[wt.leaf_vertices.dtype for wt in self.trees])
        self.n_leaves = n
        self.tri = np.empty((F, 3, 3), dtype)
        self.face_leaf = np.empty(F, np.int64)
        self.area = np.concatenate([np.asarray(wt.leaf_area) for wt in self.trees]) \
            if self.trees else np.zeros(0)
        self.tree_of = np.repeat(np.arange(len(self.trees)), counts).astype(np.int64)
        # the leaves of a tree are consecutive: tree t owns leaves [start[t], start[t + 1])
        self._tree_start = leaf0
        # first triangle of each leaf (triangles of a leaf are consecutive) and their count
        ntri = np.repeat(np.asarray(per_leaf, np.int64), counts)
        self._first = np.empty(n, np.int64)
        self.centre = np.zeros((n, 3))
        # (aligned: the device table maps it without a copy, arrays.aligned_empty)
        tri32 = aligned_empty(F * 9, np.float32)

        def fill(t):
            q, m = self.trees[t].leaf_vertices, counts[t]
            if not m:
                return
            a, b, j = tri0[t], tri0[t + 1], leaf0[t]
            tr = self.tri[a:b]
            if per_leaf[t] == 2:
                tq = tr.reshape(m, 2, 3, 3)
                tq[:, 0] = q[:, :3]
                tq[:, 1, 0] = q[:, 0]
                tq[:, 1, 1:] = q[:, 2:]
                self.face_leaf[a:b] = np.repeat(np.arange(m), 2) + j
                self._first[j:j + m] = np.arange(a, b, 2)
            else:
                tr[:] = q
                self.face_leaf[a:b] = np.arange(m) + j
                self._first[j:j + m] = np.arange(a, b)
            # each leaf's centre: the mean of its triangles' centroids, summed from 0 in face
            # order and divided by their number (the values of np.add.at, without its slowness)
            mid = tr.mean(1)
            c = 0.0 + mid[self._first[j:j + m] - a]
            if per_leaf[t] == 2:
                c += mid[self._first[j:j + m] - a + 1]
            self.centre[j:j + m] = c / ntri[j:j + m, None]
            tri32[9 * a:9 * b] = tr.reshape(-1)
        map_on_cores(fill, range(len(self.trees)))
        # device copies: the daily state and tables never leave the device
        # (aligned copies, not NumPy memory mapped: arrays.host_array)
        self.d_face_leaf = host_array(mi.UInt32, self.face_leaf)
        self.d_first = host_array(mi.UInt32, self._first)
        self.d_two = host_array(mi.Bool, ntri == 2)
        self.d_area = host_array(mi.Float64, self.area)
        self.d_tree_of = host_array(mi.UInt32, self.tree_of)
        self.d_tri = mi.Float(tri32)
        self.d_centre = host_array(mi.Float, self.centre)
        self._bin = dr.zeros(mi.UInt32, n)        # stage bin of each leaf
        self._shown = dr.zeros(mi.Bool, n)        # on the tree with a blade in the mesh
        self._scale = dr.full(mi.Float64, 1.0, n)  # blade size in the mesh (0..1, steps of 0.1)
        self._lag = 0
        self._since = 1 << 30                 # days since the last vertex update
        self._stale_prev, self._stale_days = -1, 0
        self.stage_bsdfs: list = []
        self.mesh_updates = 0                 # leaf-mesh vertex updates (BVH rebuilds) so far

    def leaves_of(self, t: int) -> slice:
        """The leaves of tree ``t`` (consecutive in every per-leaf table).

        Parameters
        ----------
        t : int
            Index of the tree in :attr:`trees`.

        Returns
        -------
        slice
            Its leaves.
        """
        return slice(int(self._tree_start[t]), int(self._tree_start[t + 1]))

    # ---- the scene's shapes -------------------------------------------------------------
    def bin_stage(self, b: int) -> float:
        """Ishikura stage at the centre of bin ``b`` (1 .. 7).

        Parameters
        ----------
        b : int
            Stage bin, 0 .. bins − 1.

        Returns
        -------
        float
            Stage [-]: 1 + 6 (b + 0.5) / bins (1 with a single bin).
        """
        return 1.0 + 6.0 * (b + 0.5) / self.bins if self.bins > 1 else 1.0

    def shapes(self, full_leaf: bool = False, bare: bool = False) -> dict:
        """Mitsuba meshes: ``trees_bark`` and ``trees_leaves`` with every blade at full size
        (or none, ``bare``).

        The leaf mesh's own BSDF is the first stage bin's; without the daily tables
        (:meth:`trace_tables`) every leaf is shown with it, green (``full_leaf``: a summer light
        study). In the world loop the tables hide the leaves until they are out. Builds the
        ``bins`` stage BSDFs (:attr:`stage_bsdfs`) and resets the blades to full size.

        Parameters
        ----------
        full_leaf : bool
            Show every leaf in the daily tables from the start (default False: all hidden until the
            first :meth:`update`).
        bare : bool
            Every blade taken out (NaN corners) from the start, as :meth:`update` leaves hidden
            leaves (the same vertices, so a run and its resumed copy agree): a scene rebuilt at
            the year's end, when the leaves start bare, then needs no vertex update (and no
            second BVH build) on its first day, and its BVH holds the wood and the terrain
            only.

        Returns
        -------
        dict
            ``{shape id: mitsuba.Mesh}``: ``trees_bark`` (two-sided diffuse, grey-brown bark
            reflectance) when any tree has wood, ``trees_leaves`` when any has leaves
            (vertices [m]).
        """
        if full_leaf and bare:
            raise ValueError("Canopy.shapes: full_leaf and bare exclude each other")
        out = {}
        bv, bf = self._bark()
        if len(bf):
            out["trees_bark"] = _mesh("trees_bark", bv, bf,
                                      {"type": "twosided", "bsdf": {"type": "diffuse",
                                                                    "reflectance": _BARK}})
        self.stage_bsdfs = [mi.load_dict(leaf_bsdf_dict(leaf_spectra(stage=self.bin_stage(b))))
                            for b in range(self.bins)]
        F = len(self.tri)
        if F:
            # a triangle soup (3 corners of its own per triangle), made on the device
            out[LEAF_MESH] = _mesh(LEAF_MESH, self._leaf_vertices(bare),
                                   dr.arange(mi.UInt32, 3 * F), self.stage_bsdfs[0])
        self._scale = dr.full(mi.Float64, 0.0 if bare else 1.0, self.n_leaves)
        self._bin = dr.zeros(mi.UInt32, self.n_leaves)
        self._shown = dr.full(mi.Bool, bool(full_leaf), self.n_leaves)
        # registry id of each bin's BSDF (the photon pass's per-triangle BSDF table holds them)
        self.d_bin_reg = host_array(mi.UInt32, [registry_id(b) for b in self.stage_bsdfs])
        return out

    def _bark(self) -> tuple:
        """The trees' wood as one mesh: vertices (n, 3) [m], faces (f, 3)."""
        bv, bf, nb = [], [], 0
        for wt in self.trees:
            v, f = wt.bark
            if len(f):
                bv.append(np.asarray(v, float))
                bf.append(np.asarray(f, np.int64) + nb)
                nb += len(v)
        if not bv:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
        return np.concatenate(bv), np.concatenate(bf)

    def _leaf_vertices(self, bare: bool) -> mi.Float:
        """(9F,) corners of the leaf mesh on the device: the full blades, or (``bare``) every
        blade taken out, the NaN corners :meth:`_set_blades` gives at size 0."""
        if bare:
            return dr.full(mi.Float, dr.nan, 9 * len(self.tri))
        return mi.Float(self.d_tri)

    def reference_geometry(self) -> dict:
        """The leaf mesh with every blade at full size, as the scene's index reads it
        (:func:`mitsuba_veg.integrators.scene_index.scene_index`'s ``reference``).

        Returns
        -------
        dict
            ``{LEAF_MESH: (vertices (3F, 3) float32 as in the mesh [m], None)}``: the device
            copy of the blades seen from the host (no copy), a triangle soup (triangle i is
            vertices 3i..3i+2); empty without leaves.
        """
        if not len(self.tri):
            return {}
        return {LEAF_MESH: (np.asarray(self.d_tri).reshape(-1, 3), None)}

    # ---- daily update -------------------------------------------------------------------
    def leaf_bins(self, tau: np.ndarray) -> np.ndarray:
        """Bin of each leaf from its autumn logical time τ (stage 1 + 6 τ).

        Parameters
        ----------
        tau : numpy.ndarray or mi.Float64
            (n_leaves,) autumn logical time τ [-] (clipped to [0, 1]).

        Returns
        -------
        numpy.ndarray or mi.UInt32
            (n_leaves,) stage bin in 0 .. bins − 1 (on the backend of ``tau``).
        """
        if dr.is_array_v(tau):
            s = stage_from_tau(dr.clip(tau, 0.0, 1.0))
            return dr.minimum(mi.UInt32((s - 1.0) / 6.0 * self.bins), self.bins - 1)
        s = stage_from_tau(np.clip(tau, 0.0, 1.0))
        return np.minimum(((s - 1.0) / 6.0 * self.bins).astype(np.int64), self.bins - 1)

    def update(self, params, tau, scale, on_tree, also=()) -> int:
        """Set the day's stage bin and shown/hidden state of every leaf (exact, tables only)
        and, during leaf-out, grow the blades in the mesh (see :attr:`min_change`).

        Everything stays on the device but three counts (leaves with a new blade size, leaves
        on the tree, hidden blades still in the mesh), read back in one go to decide whether
        the mesh's vertices move today.

        Parameters
        ----------
        params : mi.SceneParameters
            ``mi.traverse`` of the light scene (vertex updates go through it).
        tau : mi.Float64
            Autumn logical time τ of each leaf (0..1).
        scale : mi.Float64
            Blade size of each leaf (0..1, leaf-out).
        on_tree : mi.Bool
            Leaves out and not fallen.
        also : sequence of Dr.Jit arrays
            Arrays of the same width evaluated in the same kernel (the phenology's state).

        Returns
        -------
        int
            1 when the leaf mesh's vertices were updated (its BVH rebuilt) today, else 0.
        """
        if self.n_leaves == 0:
            if also:
                dr.eval(*also)
            return 0
        self._bin = self.leaf_bins(tau)
        live = on_tree & (scale > 1e-3)
        size = dr.round(scale * 10.0) / 10.0
        # only leaves on the tree matter: hidden ones keep whatever blade the mesh holds
        changed = live & (size != self._scale)
        # hidden leaves whose blades are still in the mesh (photons cross them, one cast each)
        stale_m = (self._scale > 0) & ~live
        counts = dr.zeros(mi.UInt32, 3)
        for k, m in enumerate((changed, live, stale_m)):
            dr.scatter_add(counts, mi.UInt32(1), mi.UInt32(k), m, mode=dr.ReduceMode.Local)
        dr.eval(self._bin, live, size, counts, *also)
        n_changed, n_live, stale = (int(v) for v in np.asarray(counts))
        moved = 0
        self._since += 1
        self._stale_days = self._stale_days + 1 if stale == self._stale_prev else 0
        self._stale_prev = stale
        collapse = stale > self.max_hidden_blades * self.n_leaves or \
            (stale > 0.01 * self.n_leaves and self._stale_days >= self.max_lag_days)
        self._lag = self._lag + 1 if n_changed else 0
        grow = n_changed >= self.min_change * max(n_live, 1) or \
            (n_changed > 0 and self._lag >= self.max_lag_days)
        if (collapse or grow) and self._since >= self.min_update_days:
            # hidden leaves leave the mesh (NaN corners): a leaf that comes out later shows no
            # blade until the next update gives it its size
            self._set_blades(params, dr.select(live, size, 0.0))
            self._lag = 0
            self._since = 0
            self.mesh_updates += 1
            moved = 1
        # a blade of size 0 in the mesh (round(scale, 1) == 0) is not shown
        self._shown = live & (self._scale > 0)
        dr.eval(self._shown)
        return moved

    def _set_blades(self, params, scale) -> None:
        """Blades at ``scale`` (per leaf, 0..1) around their centres in the light scene; a
        blade at 0 is taken out of the mesh (NaN corners: no triangle for the ray tracer)."""
        # (a copy: a NumPy array, e.g. a checkpoint's, would otherwise be mapped, arrays.host_array)
        scale = scale if dr.is_array_v(scale) else host_array(mi.Float64, scale)
        dr.eval(scale)
        F = len(self.face_leaf)
        k = dr.arange(mi.UInt32, 9 * F)          # triangle, corner, axis
        tri = k // 9
        axis = k % 3
        leaf = dr.gather(mi.UInt32, self.d_face_leaf, tri)
        s = mi.Float(dr.gather(mi.Float64, scale, leaf))
        c = dr.gather(mi.Float, self.d_centre, leaf * 3 + axis)
        v = dr.select(s > 0, c + s * (dr.gather(mi.Float, self.d_tri, k) - c), dr.nan)
        params[f"{LEAF_MESH}.vertex_positions"] = v
        params.update()
        self._scale = scale

    # ---- checkpoints --------------------------------------------------------------------
    def state(self, prefix: str = "canopy_") -> dict:
        """The mesh's state (blade sizes, update clocks) for a checkpoint.

        A resumed run must show the same blades and update on the same days as an uninterrupted one.

        Parameters
        ----------
        prefix : str
            Prefix of the keys (default ``"canopy_"``).

        Returns
        -------
        dict
            ``prefix + "scale"``: (n_leaves,) blade size in the mesh [-] (0..1); ``prefix +
            "clocks"``: (5,) int64 update clocks: days of pending growth, days since the last vertex
            update, hidden blades still in the mesh at the last count, days that count has not
            changed, leaf-mesh updates so far.
        """
        clocks = np.array([self._lag, self._since, self._stale_prev, self._stale_days,
                           self.mesh_updates], np.int64)
        return {prefix + "scale": np.array(self._scale, dtype=np.float64),
                prefix + "clocks": clocks}

    def load_state(self, d: dict, params, prefix: str = "canopy_") -> None:
        """Restore :meth:`state` (and the blades in the light scene).

        Parameters
        ----------
        d : dict
            A checkpoint holding the keys of :meth:`state`.
        params : mi.SceneParameters
            ``mi.traverse`` of the light scene (the blades are written through it when they differ).
        prefix : str
            Prefix of the keys (default ``"canopy_"``).

        Raises
        ------
        ValueError
            When the saved blade sizes do not have one value per leaf.
        """
        scale = np.asarray(d[prefix + "scale"], float)
        if scale.shape != (self.n_leaves,):
            raise ValueError(f"{prefix}scale: {scale.shape} != ({self.n_leaves},)")
        if self.n_leaves and not np.array_equal(scale, np.asarray(self._scale)):
            self._set_blades(params, scale)
        (self._lag, self._since, self._stale_prev, self._stale_days,
         self.mesh_updates) = (int(x) for x in np.asarray(d[prefix + "clocks"]))

    def trace_tables(self, tri=None, active=True) -> tuple:
        """The day's per-triangle leaf tables for the photon pass, on the device.

        Per leaf triangle: HIDDEN unless the leaf is shown, else SURFACE; the registry id of
        its stage bin's BSDF (what ``PassTables.bsdf_table`` holds).

        Parameters
        ----------
        tri : mi.UInt32, optional
            The leaf triangles wanted (default: all, in order): the tables at them, lazy, for
            the kernel that reads them.
        active : mi.Bool or bool
            With ``tri``: which of them are read.

        Returns
        -------
        modes : mi.UInt32 or None
            (triangles,) SURFACE / HIDDEN (None without leaves or before :meth:`shapes`).
        bsdf_ids : mi.UInt32 or None
            (triangles,) BSDF registry id of each triangle's stage bin.
        """
        if self.n_leaves == 0 or not self.stage_bsdfs:
            return None, None
        leaf = self.d_face_leaf if tri is None else \
            dr.gather(mi.UInt32, self.d_face_leaf, tri, active)
        mode = dr.select(dr.gather(mi.Bool, self._shown, leaf, active), mi.UInt32(SURFACE),
                         mi.UInt32(HIDDEN))
        reg = dr.gather(mi.UInt32, self.d_bin_reg, dr.gather(mi.UInt32, self._bin, leaf, active),
                        active)
        return mode, reg

    def trace_tables_numpy(self) -> tuple[dict, dict]:
        """The day's ``modes`` and ``bsdf_override`` for :meth:`PhotonIrradianceIntegrator.trace`
        (read back: a light study of one day).

        Returns
        -------
        modes : dict
            ``{"trees_leaves": (triangles,) uint32 mode}`` (empty without leaves).
        bsdf_override : dict
            ``{"trees_leaves": (stage BSDFs, (triangles,) bin index)}`` (empty likewise).
        """
        if self.n_leaves == 0 or not self.stage_bsdfs:
            return {}, {}
        shown = np.asarray(self._shown)
        bins = np.asarray(self._bin).astype(np.int64)
        mode = np.where(shown, SURFACE, HIDDEN).astype(np.uint32)[self.face_leaf]
        return ({LEAF_MESH: mode}, {LEAF_MESH: (self.stage_bsdfs, bins[self.face_leaf])})

    def displayed_area(self):
        """Blade area of each leaf as the light scene shows it now [m2] (0 when hidden).

        Returns
        -------
        mi.Float64
            (n_leaves,) one-sided blade area [m2]: full area × (blade size in the mesh)².
        """
        return dr.select(self._shown, self.d_area * self._scale * self._scale, 0.0)

    # ---- light per leaf -----------------------------------------------------------------
    def leaf_flux(self, tri_flux):
        """Flux incident on each leaf [W] from the fluxes of its triangles.

        A leaf's triangles are consecutive in the leaf mesh (one, or two for a quad).

        Parameters
        ----------
        tri_flux : mi.Float64 or numpy.ndarray
            (triangles,) flux per leaf triangle [W], in the leaf mesh's triangle order.

        Returns
        -------
        mi.Float64 or numpy.ndarray
            (n_leaves,) flux per leaf [W] (on the backend of ``tri_flux``).
        """
        if not dr.is_array_v(tri_flux):
            f = np.asarray(tri_flux)
            if self.n_leaves == 0:
                return np.zeros((0,) + f.shape[1:])
            return np.add.reduceat(f, self._first, axis=0)
        t = type(tri_flux)
        a = dr.gather(t, tri_flux, self.d_first)
        b = dr.gather(t, tri_flux, self.d_first + 1, self.d_two)
        return a + dr.select(self.d_two, b, 0.0)


def _mesh(name, vertices, faces, bsdf):
    return make_mesh(name, vertices, faces, bsdf)
