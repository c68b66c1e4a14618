"""The trees in the world's light scene: wood, and leaves binned by autumn stage.

Wood: one two-sided diffuse mesh (``trees_bark``) for all trees. Leaves: ``bins`` meshes
(``leaves_00`` .. ``leaves_KK``), one per Ishikura stage bin, each with the ``veg_leaf`` BSDF
of its stage (PROSPECT-D reflectance **and** transmittance, so far-red passes through the
canopy and red does not). Every bin mesh holds a triangle slot for every leaf triangle; a leaf
shows its blade in the mesh of its stage and is collapsed to a point (a zero-area triangle that
no ray hits) in the others, and in all of them once it has fallen or before it has grown.

So the scene keeps its structure all year: a day moves vertices (``mi.traverse`` + ``update``,
which rebuilds the acceleration structure of the changed meshes only) and the photon kernel is
not recompiled. Leaf blades grow from their centre during leaf-out.

Light per leaf comes from the same photon pass as the terrain's: the flux recorded on a leaf's
triangles (both sides, direct + indirect) in whichever bin mesh it is, divided by its area.
"""
from __future__ import annotations

import numpy as np

from ..foliage.pigments import stage_from_tau

#: bark reflectance: 0.08 at 400 nm rising to 0.30 at 830 nm (a grey-brown bark)
_BARK = {"type": "regular", "wavelength_min": 360.0, "wavelength_max": 830.0,
         "values": "0.07, 0.08, 0.11, 0.15, 0.20, 0.26, 0.30"}


class Canopy:
    """Leaves and wood of all world trees as Mitsuba meshes (see the module docstring)."""

    def __init__(self, trees, bins: int = 4):
        self.trees = list(trees)
        self.bins = int(bins)
        tris, owner, area, tree_of = [], [], [], []
        n = 0
        for t_i, wt in enumerate(self.trees):
            m = len(wt.leaf_vertices)
            if m:
                k = wt.leaf_vertices.shape[1]
                if k == 4:   # quad -> two triangles
                    q = wt.leaf_vertices
                    tr = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]], axis=1).reshape(-1, 3, 3)
                    own = np.repeat(np.arange(m), 2) + n
                else:
                    tr = wt.leaf_vertices
                    own = np.arange(m) + n
                tris.append(tr)
                owner.append(own)
            area.append(wt.leaf_area)
            tree_of.append(np.full(m, t_i))
            n += m
        self.n_leaves = n
        self.tri = np.concatenate(tris) if tris else np.zeros((0, 3, 3))     # (F, 3, 3)
        self.face_leaf = np.concatenate(owner) if owner else np.zeros(0, np.int64)
        self.area = np.concatenate(area) if area else np.zeros(0)
        self.tree_of = np.concatenate(tree_of) if tree_of else np.zeros(0, np.int64)
        self.centre = np.zeros((n, 3))
        if n:
            np.add.at(self.centre, self.face_leaf, self.tri.mean(1))
            self.centre /= np.bincount(self.face_leaf, minlength=n)[:, None]
        self._bin = np.full(n, -1)        # bin each leaf is shown in (-1: none)
        self._scale = np.zeros(n)
        self.bin_names = [f"leaves_{b:02d}" for b in range(self.bins)]

    # ---- the scene's shapes -------------------------------------------------------------
    def bin_stage(self, b: int) -> float:
        """Ishikura stage at the centre of bin ``b`` (1 .. 7)."""
        return 1.0 + 6.0 * (b + 0.5) / self.bins if self.bins > 1 else 1.0

    def shapes(self, full_leaf: bool = False) -> dict:
        """Mitsuba meshes: ``trees_bark`` and the leaf bin meshes (all leaves collapsed, or with
        ``full_leaf`` every leaf shown green in the first bin: a summer light study)."""
        from ..foliage import leaf_bsdf_dict, leaf_spectra
        out = {}
        bv, bf, nb = [], [], 0
        for wt in self.trees:
            v, f = wt.bark
            if len(f):
                bv.append(np.asarray(v, float))
                bf.append(np.asarray(f, np.int64) + nb)
                nb += len(v)
        if bv:
            out["trees_bark"] = _mesh("trees_bark", np.concatenate(bv), np.concatenate(bf),
                                      {"type": "twosided", "bsdf": {"type": "diffuse",
                                                                    "reflectance": _BARK}})
        F = len(self.tri)
        faces = np.arange(3 * max(F, 1)).reshape(-1, 3)
        collapsed = self._collapsed()
        for b, name in enumerate(self.bin_names):
            bsdf = leaf_bsdf_dict(leaf_spectra(stage=self.bin_stage(b)))
            v = self.tri.reshape(-1, 3) if full_leaf and b == 0 and F else collapsed
            out[name] = _mesh(name, v, faces, bsdf)
        if full_leaf:
            self._bin = np.zeros(self.n_leaves, np.int64)
            self._scale = np.ones(self.n_leaves)
        return out

    def _collapsed(self) -> np.ndarray:
        F = len(self.tri)
        if F == 0:
            return np.zeros((3, 3))
        c = self.centre[self.face_leaf]
        return np.repeat(c[:, None, :], 3, axis=1).reshape(-1, 3)

    # ---- daily update -------------------------------------------------------------------
    def leaf_bins(self, tau: np.ndarray) -> np.ndarray:
        """Bin of each leaf from its autumn logical time τ (stage 1 + 6 τ)."""
        s = stage_from_tau(np.clip(tau, 0.0, 1.0))
        return np.minimum(((s - 1.0) / 6.0 * self.bins).astype(np.int64), self.bins - 1)

    #: the light scene follows the leaves when this share of them shows a new state (bin, fallen
    #: or grown, blade size in steps of 0.1) or after ``max_lag_days`` with any change: every
    #: update rebuilds the acceleration structure of the leaf meshes (the leaves' own state is
    #: kept exactly, day by day, by the phenology)
    min_change = 0.02
    max_lag_days = 7

    def update(self, params, tau: np.ndarray, scale: np.ndarray, on_tree: np.ndarray) -> int:
        """Show each leaf on the tree in the bin of its stage, at blade size ``scale`` (0..1),
        collapse the others; move only the meshes whose content changed (see
        :attr:`min_change`). Returns the number of meshes updated."""
        import mitsuba as mi
        if self.n_leaves == 0:
            return 0
        b = np.where(on_tree & (scale > 1e-3), self.leaf_bins(tau), -1)
        sc = np.where(b >= 0, np.round(scale, 1), 0.0)
        changed_leaf = (b != self._bin) | (sc != self._scale)
        if not changed_leaf.any():
            self._lag = 0
            return 0
        self._lag = getattr(self, "_lag", 0) + 1
        if changed_leaf.mean() < self.min_change and \
                self._lag < self.max_lag_days:
            return 0
        self._lag = 0
        touched = set(np.unique(self._bin[changed_leaf]).tolist()) | \
            set(np.unique(b[changed_leaf]).tolist())
        touched.discard(-1)
        fb = b[self.face_leaf]
        c = self.centre[self.face_leaf][:, None, :]
        grown = c + sc[self.face_leaf][:, None, None] * (self.tri - c)
        for k in sorted(touched):
            show = (fb == k)[:, None, None]
            v = np.where(show, grown, np.broadcast_to(c, self.tri.shape)).reshape(-1)
            params[f"{self.bin_names[k]}.vertex_positions"] = mi.Float(v.astype(np.float32))
        params.update()
        self._bin, self._scale = b, sc
        return len(touched)

    def displayed_area(self) -> np.ndarray:
        """Blade area of each leaf as the light scene shows it now [m2] (0 when hidden)."""
        return np.where(self._bin >= 0, self.area * self._scale ** 2, 0.0)

    # ---- light per leaf -----------------------------------------------------------------
    def leaf_elements(self, index) -> np.ndarray:
        """Element numbers (in the photon pass's index) of every leaf triangle slot, bin by
        bin; :attr:`slot_leaf` gives the leaf of each."""
        return np.concatenate([np.arange(index.shape_slice(n).start, index.shape_slice(n).stop)
                               for n in self.bin_names])

    @property
    def slot_leaf(self) -> np.ndarray:
        return np.tile(self.face_leaf, self.bins)

    def leaf_flux(self, slot_flux: np.ndarray) -> np.ndarray:
        """Flux incident on each leaf [W] from the fluxes of its triangle slots (rows in the
        order of :meth:`leaf_elements`, any trailing axes); returns (n_leaves, ...)."""
        f = np.asarray(slot_flux)
        tail = f.shape[1:]
        f = f.reshape(len(f), -1)
        leaf = self.slot_leaf
        out = np.stack([np.bincount(leaf, weights=f[:, j], minlength=self.n_leaves)
                        for j in range(f.shape[1])], axis=1)
        return out.reshape((self.n_leaves,) + tail)


def _mesh(name, vertices, faces, bsdf):
    from ..meshes import make_mesh
    return make_mesh(name, vertices, faces, bsdf)
