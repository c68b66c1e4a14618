"""A stand's trees as Mitsuba instances of a few meshes per preset, and what that saves.

A stand (:mod:`mitsuba_veg.trees.stand`) gives each Weber-Penn tree one of a few geometry
variants of its preset and a transform (position, yaw, uniform scale to its height).
:func:`build_variants` grows each variant once (paper 004, at its own seed, base at the origin)
and meshes it as the world loop does: smooth-junction bark and one quad (two triangles) per
leaf. :func:`scene_dict` puts them in a Mitsuba scene either as ``shapegroup`` + ``instance``
(one mesh per variant, one transform per tree) or as plain meshes (every tree's copy merged
into one bark and one leaf mesh).

Memory (:func:`memory_estimate`, :class:`MemoryModel`): a triangle mesh costs Mitsuba 12 bytes
per vertex (float32 positions) and 12 per face (uint32 indices), plus the acceleration
structure, measured per face; an instance costs its transform and a leaf of the top-level
structure. The photon pass (integrators/photon_irradiance.py) keeps per-element tables for
every triangle of every instance, instanced or not (its elements are per instance so that each
tree has its own light and leaf state), and an accumulator row for every recorded triangle.
So instancing removes the geometry and its acceleration structure from the memory per leaf, but
not the per-element state of the light pass. The constants are measured by
``benchmarks/stand_instancing.py`` (Mitsuba 3.9.1, llvm_ad_spectral; docs/forest.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..meshes import make_mesh
from . import weber_penn as wp
from .junction import tree_mesh
from .stand import GROWTH, Stand
from .structure import leaf_quads


@dataclass
class VariantMesh:
    """One geometry variant of a preset: its meshes with the base at the origin.

    Parameters
    ----------
    species : str
        Preset name.
    variant : int
        Variant index.
    seed : int
        Seed it was grown with.
    height : float
        Height of the mesh above its base [m].
    bark : tuple
        (vertices (n, 3) [m], faces (m, 3)) of the wood.
    leaves : tuple
        (vertices (4 k, 3) [m], faces (2 k, 3)) of the leaf quads, two triangles per leaf.
    n_leaves : int
        Number of leaves k.
    """

    species: str
    variant: int
    seed: int
    height: float
    bark: tuple
    leaves: tuple
    n_leaves: int

    @property
    def n_faces(self) -> int:
        """Triangles of bark and leaves together."""
        return len(self.bark[1]) + len(self.leaves[1])

    @property
    def n_vertices(self) -> int:
        """Vertices of bark and leaves together."""
        return len(self.bark[0]) + len(self.leaves[0])


def variant_mesh(species: str, variant: int, seed: int, smooth: bool = True) -> VariantMesh:
    """Grow one Weber-Penn variant and mesh it (bark by junction.tree_mesh, leaf quads).

    Parameters
    ----------
    species : str
        A Weber-Penn preset (:data:`mitsuba_veg.trees.weber_penn.PRESETS`).
    variant : int
        Variant index (recorded).
    seed : int
        Seed of the tree.
    smooth : bool, optional
        Smooth junctions (paper 004 §4) on the bark; default True.

    Returns
    -------
    VariantMesh
        The meshes, base at the origin.

    Raises
    ------
    ParameterError
        For a species that is not a Weber-Penn preset.
    """
    if species not in wp.PRESETS:
        raise ParameterError("species", species, ", ".join(wp.PRESETS),
                             "growth-model trees are grown one by one, not instanced")
    tree = wp.generate(species, seed=seed)
    base = tree.start[0].copy()
    b, _ = tree_mesh(tree, smooth=smooth, leaves=False)
    bark = (np.asarray(b.vertices, float) - base, np.asarray(b.faces, np.int64))
    if len(tree.leaves):
        lv, lf = leaf_quads(tree.leaves)
        leaves = (np.asarray(lv, float) - base, np.asarray(lf, np.int64))
    else:
        leaves = (np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    top = max(float(bark[0][:, 1].max()) if len(bark[0]) else 0.0,
              float(leaves[0][:, 1].max()) if len(leaves[0]) else 0.0)
    return VariantMesh(species, int(variant), int(seed), top, bark, leaves, len(tree.leaves))


def build_variants(stand: Stand, smooth: bool = True) -> dict:
    """Every geometry variant a stand uses, grown once (:func:`variant_mesh`).

    Parameters
    ----------
    stand : Stand
        The stand (its variant keys and seed).
    smooth : bool, optional
        Smooth junctions on the bark; default True.

    Returns
    -------
    dict
        ``{(species, variant): VariantMesh}``.
    """
    return {k: variant_mesh(k[0], k[1], stand.variant_seed(*k), smooth)
            for k in stand.variant_keys()}


def tree_transforms(stand: Stand, variants: dict) -> np.ndarray:
    """Each tree's 4 x 4 transform, scaling its variant to the tree's height.

    Parameters
    ----------
    stand : Stand
        The stand.
    variants : dict
        ``{(species, variant): VariantMesh}`` (their heights [m]).

    Returns
    -------
    numpy.ndarray
        (n, 4, 4) matrices (:meth:`Stand.transforms`).
    """
    return stand.transforms({k: v.height for k, v in variants.items()})


def _transform(v, M):
    return v @ M[:3, :3].T + M[:3, 3]


def merged_meshes(stand: Stand, variants: dict, trees=None) -> dict:
    """Every instanced tree's copy of its variant, transformed and merged (plain meshes).

    Parameters
    ----------
    stand : Stand
        The stand.
    variants : dict
        ``{(species, variant): VariantMesh}``.
    trees : array_like, optional
        Indices of the trees to take; default every tree with a variant (growth trees are not
        instanced and are left out).

    Returns
    -------
    dict
        ``{"bark": (V, F), "leaves": (V, F)}``: float32 vertices [m] (what Mitsuba stores;
        half the memory of float64 for a stand's millions of vertices) and uint32 faces, trees
        in order, each tree's leaves as consecutive quads.
    """
    M = tree_transforms(stand, variants)
    idx = np.flatnonzero(stand.variants >= 0) if trees is None else np.asarray(trees)
    out = {}
    for part in ("bark", "leaves"):
        meshes = [getattr(variants[(str(stand.species[i]), int(stand.variants[i]))], part)
                  for i in idx]
        nv = sum(len(v) for v, _ in meshes)
        nf = sum(len(f) for _, f in meshes)
        V = np.empty((nv, 3), np.float32)
        F = np.empty((nf, 3), np.uint32)
        a = b = 0
        for i, (v, f) in zip(idx, meshes):
            V[a:a + len(v)] = _transform(v, M[i])
            F[b:b + len(f)] = f + a
            a += len(v)
            b += len(f)
        out[part] = (V, F)
    return out


#: bark reflectance of the light scenes (the world's canopy uses the same values)
BARK_BSDF = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {
    "type": "regular", "wavelength_min": 360.0, "wavelength_max": 830.0,
    "values": "0.07, 0.08, 0.11, 0.15, 0.20, 0.26, 0.30"}}}
#: a plain green leaf for scenes built without the stage optics
LEAF_BSDF = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {
    "type": "uniform", "value": 0.1}}}


def variant_group_id(key) -> str:
    """Shape id of a variant's ``shapegroup``: ``variant_<species>_<k>``.

    Parameters
    ----------
    key : tuple
        (species, variant).

    Returns
    -------
    str
        The id.
    """
    return f"variant_{key[0]}_{int(key[1])}"


def scene_dict(stand: Stand, variants: dict, instanced: bool = True, bark_bsdf=None,
               leaf_bsdf=None, trees=None) -> dict:
    """Mitsuba scene-dict entries for a stand's trees (no emitters, integrator or sensor).

    Instanced: one ``shapegroup`` per variant (``variant_<species>_<k>`` holding ``bark`` and
    ``leaves``) and one ``instance`` per tree (``tree_<i>``, ``to_world`` = its transform).
    Plain: the meshes ``trees_bark`` and ``trees_leaves`` of :func:`merged_meshes`.

    Parameters
    ----------
    stand : Stand
        The stand.
    variants : dict
        ``{(species, variant): VariantMesh}``.
    instanced : bool, optional
        Instances (default) or merged plain meshes.
    bark_bsdf, leaf_bsdf : dict or mitsuba.BSDF, optional
        BSDFs (dicts or loaded); default :data:`BARK_BSDF`, :data:`LEAF_BSDF`.
    trees : array_like, optional
        Indices of the trees to take; default every tree with a variant.

    Returns
    -------
    dict
        ``{id: shape or dict}`` to merge into a ``{"type": "scene", ...}`` dict (load it with
        ``optimize=False`` to keep the ids).
    """
    bark_bsdf, leaf_bsdf = (b if isinstance(b, mi.BSDF) else mi.load_dict(b or default)
                            for b, default in ((bark_bsdf, BARK_BSDF), (leaf_bsdf, LEAF_BSDF)))
    idx = np.flatnonzero(stand.variants >= 0) if trees is None else np.asarray(trees)
    if not instanced:
        m = merged_meshes(stand, variants, idx)
        return {"trees_bark": make_mesh("trees_bark", *m["bark"], bsdf=bark_bsdf),
                "trees_leaves": make_mesh("trees_leaves", *m["leaves"], bsdf=leaf_bsdf)}
    d = {}
    used = {(str(stand.species[i]), int(stand.variants[i])) for i in idx}
    for key in sorted(used):
        v = variants[key]
        g = {"type": "shapegroup"}
        if len(v.bark[1]):
            g["bark"] = make_mesh("bark", *v.bark, bsdf=bark_bsdf)
        if len(v.leaves[1]):
            g["leaves"] = make_mesh("leaves", *v.leaves, bsdf=leaf_bsdf)
        d[variant_group_id(key)] = g
    M = tree_transforms(stand, variants)
    for i in idx:
        key = (str(stand.species[i]), int(stand.variants[i]))
        d[f"tree_{i}"] = {"type": "instance", "shape": {"type": "ref",
                                                         "id": variant_group_id(key)},
                          "to_world": mi.ScalarTransform4f(M[i].tolist())}
    return d


# --------------------------------------------------------------------------------------------
# Memory
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class MemoryModel:
    """Bytes per item of a light scene (module docstring; measured values in docs/forest.md).

    Parameters
    ----------
    vertex : float
        Per mesh vertex [B]: float32 positions.
    face : float
        Per mesh triangle [B]: uint32 indices.
    accel_face : float
        Acceleration structure per triangle [B] (Embree on the LLVM variants): 80, fitted to
        the resident memory of 50 plain aspens (7.5 M triangles) and of their 3 variants.
    instance : float
        Per instance [B]: transform, instance record, top-level structure.
    element : float
        Photon-pass tables per element, i.e. per triangle of every instance [B]: area,
        normal and centroid (float64) on the host, normal, mode, BSDF and record row on the
        device.
    recorded : float
        Accumulator and read-back per recorded triangle [B]: 2 components x 2 sides x 4
        wavelength slots of uint64 tallies.
    plain_vertex, plain_face : float
        The photon pass's own float64 / int64 copy of every plain (not instanced) mesh, per
        vertex and per triangle [B].
    """

    vertex: float = 12.0
    face: float = 12.0
    accel_face: float = 80.0
    instance: float = 1024.0
    element: float = 80.0
    recorded: float = 128.0
    plain_vertex: float = 24.0
    plain_face: float = 24.0


@dataclass
class MemoryEstimate:
    """Bytes of a stand's light geometry, plain vs instanced (:func:`memory_estimate`).

    Parameters
    ----------
    trees : int
        Instanced trees counted.
    leaves : int
        Leaves over all those trees.
    faces : int
        Triangles over all those trees (the photon pass's elements).
    geometry_plain : float
        Meshes and acceleration structure with every tree a plain copy [B].
    geometry_instanced : float
        The same with one mesh per variant plus the instances [B].
    photon_plain : float
        Photon-pass tables, accumulator rows and mesh copies with plain meshes [B].
    photon_instanced : float
        Photon-pass tables and accumulator rows with instances [B].
    """

    trees: int
    leaves: int
    faces: int
    geometry_plain: float
    geometry_instanced: float
    photon_plain: float
    photon_instanced: float

    @property
    def plain(self) -> float:
        """Total bytes with plain meshes [B]."""
        return self.geometry_plain + self.photon_plain

    @property
    def instanced(self) -> float:
        """Total bytes with instances [B]."""
        return self.geometry_instanced + self.photon_instanced

    def per_leaf(self) -> dict:
        """Bytes per leaf [B] of the totals and of their parts.

        Returns
        -------
        dict
            ``plain``, ``instanced``, ``geometry_plain``, ``geometry_instanced``,
            ``photon_plain``, ``photon_instanced``, each divided by :attr:`leaves` (NaN
            without leaves).
        """
        n = self.leaves if self.leaves else float("nan")
        return {"plain": self.plain / n, "instanced": self.instanced / n,
                "geometry_plain": self.geometry_plain / n,
                "geometry_instanced": self.geometry_instanced / n,
                "photon_plain": self.photon_plain / n,
                "photon_instanced": self.photon_instanced / n}


def memory_estimate(sizes: dict, counts: dict, model: MemoryModel = MemoryModel(),
                    recorded: str = "leaves") -> MemoryEstimate:
    """Bytes of a stand's tree geometry as plain meshes and as instances.

    For variants k with V_k vertices, F_k triangles (of which R_k recorded) and n_k trees::

        geometry_plain     = sum_k n_k (V_k vertex + F_k (face + accel_face))
        geometry_instanced = sum_k (V_k vertex + F_k (face + accel_face)) + sum_k n_k instance
        photon_instanced   = sum_k n_k (F_k element + R_k recorded)
        photon_plain       = photon_instanced + sum_k n_k (V_k plain_vertex + F_k plain_face)

    Parameters
    ----------
    sizes : dict
        ``{key: (vertices, faces, leaves)}`` per variant, two triangles per leaf (or
        ``{key: VariantMesh}``).
    counts : dict
        ``{key: number of trees}`` per variant.
    model : MemoryModel, optional
        Bytes per item; default the measured :class:`MemoryModel`.
    recorded : str, optional
        Triangles with accumulator rows: ``"leaves"`` (the world loop records its leaves, not
        its bark; default), ``"all"`` or ``"none"``.

    Returns
    -------
    MemoryEstimate
        The totals and their parts [B].

    Raises
    ------
    ParameterError
        When a key of ``counts`` has no size, or for an unknown ``recorded``.
    """
    if recorded not in ("leaves", "all", "none"):
        raise ParameterError("recorded", recorded, "'leaves', 'all' or 'none'")
    geo_plain = geo_inst = ph_inst = ph_copy = 0.0
    trees = leaves = faces = 0
    for key, n in counts.items():
        if key not in sizes:
            raise ParameterError("counts", key, "a key of sizes (" + ", ".join(map(str, sizes))
                                 + ")")
        s = sizes[key]
        V, F, L = (s.n_vertices, s.n_faces, s.n_leaves) if isinstance(s, VariantMesh) else s
        n = int(n)
        if n <= 0:
            continue
        R = {"leaves": 2 * L, "all": F, "none": 0}[recorded]
        geo = V * model.vertex + F * (model.face + model.accel_face)
        geo_plain += n * geo
        geo_inst += geo + n * model.instance
        ph_inst += n * (F * model.element + R * model.recorded)
        ph_copy += n * (V * model.plain_vertex + F * model.plain_face)
        trees += n
        leaves += n * L
        faces += n * F
    return MemoryEstimate(trees, leaves, faces, geo_plain, geo_inst, ph_inst + ph_copy, ph_inst)


def stand_memory(stand: Stand, variants: dict, model: MemoryModel = MemoryModel(),
                 recorded: str = "leaves") -> MemoryEstimate:
    """:func:`memory_estimate` for a stand's instanced trees (growth trees left out).

    Parameters
    ----------
    stand : Stand
        The stand.
    variants : dict
        ``{(species, variant): VariantMesh}``.
    model : MemoryModel, optional
        Bytes per item.
    recorded : str, optional
        Triangles with accumulator rows: ``"leaves"`` (default), ``"all"`` or ``"none"``.

    Returns
    -------
    MemoryEstimate
        The totals [B].
    """
    counts: dict = {}
    for sp, v in zip(stand.species, stand.variants):
        if sp != GROWTH and v >= 0:
            counts[(str(sp), int(v))] = counts.get((str(sp), int(v)), 0) + 1
    return memory_estimate(variants, counts, model, recorded)


__all__ = ["VariantMesh", "variant_mesh", "build_variants", "tree_transforms", "merged_meshes",
           "BARK_BSDF", "LEAF_BSDF", "variant_group_id", "scene_dict", "MemoryModel",
           "MemoryEstimate", "memory_estimate", "stand_memory"]
