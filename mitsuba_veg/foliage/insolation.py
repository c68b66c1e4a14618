"""Sun path and insolation per leaf with ray-traced shadows (paper 003 §3.2).

Paper 003 computes the sun's path from almanac formulas and the insolation of a leaf as
I (L·S) for leaf normal L, unit sun vector S and beam intensity I, summed over time:
cumulative insolation Σ_i I (L·S_i); leaves shaded by other leaves or branches receive less.

Here:

- :func:`~mitsuba_veg.light.sunpath.sun_path` samples the sun every ``step_hours``
  (mid-interval times, local standard time) over ``days`` days with the NREL SPA
  (:func:`mitsuba_veg.light.sun_position`, more accurate than the paper's almanac formulas;
  same horizontal frame), and gives the clear-sky broadband
  (300-4000 nm) direct-normal irradiance I(t) and diffuse horizontal irradiance from SPCTRAL2
  with the package's default atmosphere (:mod:`mitsuba_veg.light.clear_sky`), or a constant I.
- :func:`leaf_insolation` traces one shadow ray from every leaf centre towards the sun at every
  daytime step: all leaves × all steps in one Dr.Jit kernel per ≤ 8M rays
  (``scene.ray_test`` against the tree's leaf quads, bark tubes and any obstacles), and sums
  I ``|L·S|`` per leaf per day. A leaf is a thin blade lit on either face, hence ``|L·S|`` (the paper's
  L·S with the blade's sunlit face; ``two_sided=False`` keeps max(L·S, 0)).
  Occluding leaves are opaque (as in the paper) unless ``leaf_transmittance`` > 0: then each
  leaf crossed passes that fraction (up to ``max_layers`` leaves; bark and obstacles block).
- ``sky=True`` adds diffuse skylight: DHI(t) × the leaf's sky view factor V (an isotropic sky,
  both faces: V = (1/π) ∫_upper vis(ω) ``|ω·L|`` dω, 1 for an unobstructed leaf of any tilt),
  estimated once per leaf with ``sky_rays`` stratified shadow rays.

Units: irradiance W m-2, insolation MJ m-2 (per unit one-sided leaf area).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, check_range
from ..light import photon_irradiance
from ..light.sunpath import SunPath, clear_sky_broadband, sun_path  # noqa: F401 (re-exported)
from ..trees.structure import Leaves, Tree
from .canopy import bark_mesh_arrays, leaves_mesh_arrays, mesh
from .light_study import leaf_values, tree_scene


__all__ = ["shadow_scene", "InsolationResult", "instantaneous_insolation", "leaf_insolation",
           "sky_view_factor", "sky_view_factor_photons"]

# --------------------------------------------------------------------------------------------
# Shadow scene
# --------------------------------------------------------------------------------------------
def shadow_scene(tree_or_leaves, obstacles=(), bark: bool = True, bark_sides: int = 6):
    """A Mitsuba scene of a tree's leaves, bark and obstacles, for shadow rays.

    Shape ids: ``leaves`` (the leaf quads, leaf i owning triangles 2i, 2i + 1), ``bark`` (the
    live branches as tubes) and ``obstacle0``, ``obstacle1``, ...

    Parameters
    ----------
    tree_or_leaves : Tree or Leaves
        A :class:`~mitsuba_veg.trees.Tree` (leaves and bark) or
        :class:`~mitsuba_veg.trees.Leaves` (leaves only).
    obstacles : sequence
        Further occluders: each a ``(vertices [m], faces)`` pair or an ``mi.Mesh``.
    bark : bool
        Include the tree's live branches (default True).
    bark_sides : int
        Sides of each bark tube (default 6).

    Returns
    -------
    scene : mi.Scene
        The scene (no emitters).
    leaves : Leaves
        The leaves, in the order of the ``leaves`` mesh.

    Raises
    ------
    ParameterError
        When ``tree_or_leaves`` is neither a Tree nor Leaves.
    """
    if isinstance(tree_or_leaves, Tree):
        tree, leaves = tree_or_leaves, tree_or_leaves.leaves
    elif isinstance(tree_or_leaves, Leaves):
        tree, leaves = None, tree_or_leaves
    else:
        raise ParameterError("tree_or_leaves", type(tree_or_leaves).__name__,
                             "a mitsuba_veg.trees.Tree or Leaves")
    d = {"type": "scene"}
    v, f = leaves_mesh_arrays(leaves)
    if len(f):
        d["leaves"] = mesh("leaves", v, f)
    if bark and tree is not None and tree.alive.any():
        bv, bf = bark_mesh_arrays(tree, bark_sides)
        d["bark"] = mesh("bark", bv, bf)
    for i, ob in enumerate(obstacles or ()):
        if isinstance(ob, mi.Mesh):
            d[f"obstacle{i}"] = ob
        else:
            ov, of = ob
            d[f"obstacle{i}"] = mesh(f"obstacle{i}", ov, of)
    return mi.load_dict(d, optimize=False), leaves


def _leaf_shape_id(scene):
    for sh in scene.shapes():
        if sh.id() == "leaves":
            return int(np.asarray(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(sh)))[0])
    return None


# --------------------------------------------------------------------------------------------
# Insolation
# --------------------------------------------------------------------------------------------
@dataclass
class InsolationResult:
    """Per-leaf insolation over a sun path."""

    daily: np.ndarray          # (n_leaves, days) insolation per day [MJ m-2]
    beam_daily: np.ndarray     # (n_leaves, days) direct-beam part [MJ m-2]
    sunlit_fraction: np.ndarray  # (n_leaves,) fraction of daytime steps with the sun visible
    sky_view: np.ndarray | None  # (n_leaves,) sky view factor (None without sky)
    open_daily: np.ndarray     # (days,) beam + sky on an unshaded horizontal leaf [MJ m-2]
    rays: int
    seconds: float
    settings: dict = field(default_factory=dict)

    @property
    def cumulative(self) -> np.ndarray:
        """Cumulative insolation per leaf over the whole path [MJ m-2]."""
        return self.daily.sum(axis=1)

    def cumulative_by_day(self) -> np.ndarray:
        """(n_leaves, days) running sum of the daily insolation [MJ m-2].

        Returns
        -------
        numpy.ndarray
            Insolation of each leaf from the first day through each day [MJ m-2].
        """
        return np.cumsum(self.daily, axis=1)


def instantaneous_insolation(scene_or_tree, sun_vector, intensity: float = 1.0,
                             two_sided: bool = True, obstacles=()) -> np.ndarray:
    """I ``|L·S|`` [W m-2] per leaf for one sun direction (towards the sun), 0 where shaded.

    Parameters
    ----------
    scene_or_tree : Tree, Leaves or tuple
        A tree or leaves (a shadow scene is built with ``obstacles``), or a ``(scene, leaves)``
        pair from :func:`shadow_scene`.
    sun_vector : array_like
        (3,) direction towards the sun (+x east, +y up, +z south; normalised here).
    intensity : float
        Beam (direct-normal) irradiance I [W m-2] (default 1).
    two_sided : bool
        ``|L·S|`` (a blade lit on either face, default) or max(L·S, 0).
    obstacles : sequence
        Further occluders (``(vertices, faces)`` pairs or ``mi.Mesh``) when a scene is built.

    Returns
    -------
    numpy.ndarray
        (n_leaves,) irradiance on each leaf [W m-2].
    """
    scene, leaves = (scene_or_tree if isinstance(scene_or_tree, tuple)
                     else shadow_scene(scene_or_tree, obstacles))
    s = np.asarray(sun_vector, float).reshape(1, 3)
    s = s / np.linalg.norm(s)
    path = SunPath(np.array([np.datetime64("2000-01-01T12:00:00")]), np.zeros(1, int),
                   np.zeros(1), np.array([45.0]), s, np.array([float(intensity)]), np.zeros(1),
                   1.0, 1)
    res = leaf_insolation((scene, leaves), path, two_sided=two_sided)
    return res.beam_daily[:, 0] * 1e6 / 3600.0


def leaf_insolation(tree_or_scene, path: SunPath, *, obstacles=(), two_sided: bool = True,
                    shadows: bool = True, leaf_transmittance: float = 0.0, max_layers: int = 8,
                    sky: bool = False, sky_rays: int = 64, sky_method: str = "rays",
                    sky_photons: int = 1_000_000, bark: bool = True,
                    batch: int = 1 << 23, seed: int = 0) -> InsolationResult:
    """Daily insolation per leaf over ``path`` with ray-traced shadows (module docstring).

    One shadow ray from every leaf centre towards the sun at every daytime step, all leaves × all
    steps in one Dr.Jit kernel per ``batch`` rays; I ``|L·S|`` × step [MJ m-2] summed per leaf per
    day. With ``sky`` the diffuse horizontal irradiance times the leaf's sky view factor is added.

    Parameters
    ----------
    tree_or_scene : Tree, Leaves or tuple
        A :class:`~mitsuba_veg.trees.Tree` (its leaves and live branches are the occluders, plus
        ``obstacles``), :class:`~mitsuba_veg.trees.Leaves`, or a ``(scene, leaves)`` pair from
        :func:`shadow_scene`.
    path : SunPath
        Sun directions, direct-normal and diffuse horizontal irradiance [W m-2] at regular steps
        (:func:`~mitsuba_veg.light.sunpath.sun_path`).
    obstacles : sequence
        Further occluders (``(vertices [m], faces)`` pairs or ``mi.Mesh``), used when a scene is
        built.
    two_sided : bool
        ``|L·S|`` (a thin blade lit on either face, default) or max(L·S, 0).
    shadows : bool
        Trace shadow rays (default True); False: every leaf sees the sun.
    leaf_transmittance : float
        Fraction [-] in [0, 1) of the beam each occluding leaf passes (default 0: opaque leaves,
        as in the paper); bark and obstacles block.
    max_layers : int
        Most leaves a transmitted shadow ray crosses (default 8).
    sky : bool
        Add diffuse skylight: DHI × the leaf's sky view factor (default False).
    sky_rays : int
        Stratified shadow rays per leaf for the view factor (``sky_method="rays"``, default 64).
    sky_method : str
        ``"rays"`` (view factor of the sky by shadow rays: direct skylight only) or ``"photons"``
        (a photon pass from a uniform sky through the tree with green ``veg_leaf`` leaves:
        skylight including its scattering by leaves and bark, :func:`sky_view_factor_photons`;
        needs a Tree or Leaves, refused with ``obstacles`` or ``bark=False``).
    sky_photons : int
        Photons of the ``"photons"`` sky pass (default 1 000 000).
    bark : bool
        Include the tree's live branches as occluders when a scene is built (default True).
    batch : int
        Rays per kernel (default 2**23, about 8M).
    seed : int
        Seed of the sky rays or sky photons (default 0).

    Returns
    -------
    InsolationResult
        ``daily`` and ``beam_daily`` (n_leaves, days) [MJ m-2], ``sunlit_fraction`` [-],
        ``sky_view`` [-] (None without sky), ``open_daily`` (days,) [MJ m-2] on an unshaded
        horizontal leaf, rays traced, seconds [s] and the settings.

    Raises
    ------
    ParameterError
        When there is no leaf, ``sky_method`` is unknown (or ``"photons"`` with a prebuilt
        scene), or a setting is out of range.
    """
    check_range("leaf_transmittance", leaf_transmittance, 0.0, 1.0, hi_open=True)
    check_range("max_layers", max_layers, 1, 1000)
    check_range("sky_rays", sky_rays, 1, 100000)
    t0 = _time.perf_counter()
    if isinstance(tree_or_scene, tuple):
        scene, leaves = tree_or_scene
    else:
        scene, leaves = shadow_scene(tree_or_scene, obstacles, bark=bark)
    n, h, nd = len(leaves), len(path), int(path.days)
    if n == 0:
        raise ParameterError("leaves", 0, "at least one leaf")
    P = np.asarray(leaves.position, np.float64)
    N = np.asarray(leaves.normal, np.float64)
    N = N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-30)
    eps = 1e-3 * float(np.median(leaves.size)) + 1e-6
    P_dr = [mi.Float(P[:, k].astype(np.float32)) for k in range(3)]
    N_dr = [mi.Float(N[:, k].astype(np.float32)) for k in range(3)]
    S_dr = [mi.Float(path.direction[:, k].astype(np.float32)) for k in range(3)]
    # energy per step [MJ m-2] = W m-2 * step seconds / 1e6
    E_dr = mi.Float((path.dni * path.step_hours * 3600.0 / 1e6).astype(np.float32))
    D_dr = mi.UInt32(path.day.astype(np.uint32))
    leaf_sid = _leaf_shape_id(scene)

    daily = np.zeros((n, nd))
    visible_steps = np.zeros(n)
    rays = 0
    leaves_per_batch = max(1, batch // max(h, 1))
    for l0 in range(0, n, leaves_per_batch):
        l1 = min(n, l0 + leaves_per_batch)
        m = (l1 - l0) * h
        idx = dr.arange(mi.UInt32, m)
        hh = dr.opaque(mi.UInt32, h)
        li = idx // hh
        ti = idx - li * hh
        p = mi.Point3f(*[dr.gather(mi.Float, P_dr[k], li + l0) for k in range(3)])
        nr = mi.Vector3f(*[dr.gather(mi.Float, N_dr[k], li + l0) for k in range(3)])
        s = mi.Vector3f(*[dr.gather(mi.Float, S_dr[k], ti) for k in range(3)])
        e = dr.gather(mi.Float, E_dr, ti)
        c = dr.dot(nr, s)
        sign = dr.select(c >= 0, 1.0, -1.0)
        o = p + nr * (sign * dr.opaque(mi.Float, eps))
        cosw = dr.abs(c) if two_sided else dr.maximum(c, 0.0)
        lit = cosw > 0
        vis = mi.Float(1.0)
        if shadows:
            ray = mi.Ray3f(o, s)
            if leaf_transmittance <= 0.0:
                blocked = scene.ray_test(ray, lit)
                vis = dr.select(blocked, 0.0, 1.0)
            else:
                vis = _transmitted(scene, ray, lit, leaf_sid, leaf_transmittance, max_layers)
        val = e * cosw * vis
        acc = dr.zeros(mi.Float, (l1 - l0) * nd)
        dr.scatter_add(acc, val, li * dr.opaque(mi.UInt32, nd) + dr.gather(mi.UInt32, D_dr, ti))
        vcount = dr.zeros(mi.Float, l1 - l0)
        dr.scatter_add(vcount, dr.select(lit & (vis > 0), 1.0, 0.0), li)
        dr.eval(acc, vcount)
        daily[l0:l1] = np.asarray(acc, np.float64).reshape(l1 - l0, nd)
        visible_steps[l0:l1] = np.asarray(vcount, np.float64)
        rays += m
    beam_daily = daily.copy()
    sky_view = None
    if sky:
        if sky_method == "rays":
            sky_view = sky_view_factor((scene, leaves), rays=sky_rays, seed=seed)
            rays += n * sky_rays
        elif sky_method == "photons":
            if isinstance(tree_or_scene, tuple):
                raise ParameterError("sky_method", sky_method, "'rays' for a prebuilt scene",
                                     "pass the Tree or Leaves for sky_method='photons'")
            if obstacles or not bark:
                # the photon pass's scene is the tree with its bark: it would not see them
                raise ParameterError("sky_method", sky_method,
                                     "'rays' with obstacles or bark=False",
                                     "use sky_method='rays' (its shadow rays see the obstacles "
                                     "and honour bark=False)")
            sky_view = sky_view_factor_photons(tree_or_scene, photons=sky_photons, seed=seed)
        else:
            raise ParameterError("sky_method", sky_method, "'rays' or 'photons'")
        dhi_day = np.bincount(path.day, path.dhi * path.step_hours * 3600.0 / 1e6, minlength=nd)
        daily = daily + sky_view[:, None] * dhi_day[None, :]
    up = path.direction[:, 1]
    open_daily = np.bincount(path.day, (path.dni * np.maximum(up, 0) + (path.dhi if sky else 0))
                             * path.step_hours * 3600.0 / 1e6, minlength=nd)
    return InsolationResult(daily, beam_daily, visible_steps / max(h, 1), sky_view, open_daily,
                            int(rays), _time.perf_counter() - t0,
                            dict(path.settings, two_sided=two_sided, shadows=shadows,
                                 leaf_transmittance=leaf_transmittance, sky=sky,
                                 steps=h, leaves=n, days=nd))


def _transmitted(scene, ray, active, leaf_sid, t_leaf, max_layers):
    """Fraction of a shadow ray passing leaves (each passes t_leaf); bark/obstacles block."""
    sid_leaf = mi.UInt32(leaf_sid if leaf_sid is not None else 0xFFFFFFFF)
    return _transmit_loop(scene, mi.Ray3f(ray), mi.Bool(active), sid_leaf,
                          dr.opaque(mi.Float, t_leaf), dr.opaque(mi.UInt32, max_layers))


@dr.syntax
def _transmit_loop(scene, ray, active, sid_leaf, t_leaf, max_layers):
    vis = mi.Float(1.0)
    k = mi.UInt32(0)
    while active:
        pi = scene.ray_intersect_preliminary(ray, active=active)
        hit = active & pi.is_valid()
        sid = dr.reinterpret_array(mi.UInt32, pi.shape)
        is_leaf = sid == sid_leaf
        vis = dr.select(hit, dr.select(is_leaf, vis * t_leaf, 0.0), vis)
        k += 1
        ray.o = ray.o + ray.d * (pi.t * 1.0001 + 1e-6)
        active = hit & is_leaf & (k < max_layers) & (vis > 0)
    return vis


def sky_view_factor(tree_or_scene, rays: int = 64, seed: int = 0) -> np.ndarray:
    """Per-leaf view factor of an isotropic sky, both faces.

    V = (1/π) ∫_upper vis ``|ω·L|`` dω (1 for an unobstructed leaf of any tilt), by ``rays``
    stratified uniform-hemisphere shadow rays per leaf.

    Parameters
    ----------
    tree_or_scene : Tree, Leaves or tuple
        A tree or leaves (a shadow scene is built), or a ``(scene, leaves)`` pair from
        :func:`shadow_scene`.
    rays : int
        Shadow rays per leaf (rounded up to a square number for the stratification; default 64).
    seed : int
        Seed of the jitter (default 0).

    Returns
    -------
    numpy.ndarray
        (n_leaves,) sky view factor V [-] in [0, 1].
    """
    if isinstance(tree_or_scene, tuple):
        scene, leaves = tree_or_scene
    else:
        scene, leaves = shadow_scene(tree_or_scene)
    n = len(leaves)
    P = np.asarray(leaves.position, np.float32)
    N = np.asarray(leaves.normal, np.float64)
    N = (N / np.linalg.norm(N, axis=1, keepdims=True)).astype(np.float32)
    eps = 1e-3 * float(np.median(leaves.size)) + 1e-6
    m = int(np.ceil(np.sqrt(rays)))
    k = m * m
    idx = dr.arange(mi.UInt32, n * k)
    li = idx // k
    j = idx - li * k
    rng = np.random.default_rng(seed)
    jit = mi.Float(rng.random(n * k).astype(np.float32))
    jit2 = mi.Float(rng.random(n * k).astype(np.float32))
    u = (mi.Float(j % m) + jit) / m
    v = (mi.Float(j // m) + jit2) / m
    # uniform upper hemisphere around +y: pdf 1/(2π)
    cos_t = u
    sin_t = dr.safe_sqrt(1 - cos_t * cos_t)
    phi = 2 * dr.pi * v
    w = mi.Vector3f(sin_t * dr.cos(phi), cos_t, sin_t * dr.sin(phi))
    p = mi.Point3f(*[dr.gather(mi.Float, mi.Float(P[:, q]), li) for q in range(3)])
    nr = mi.Vector3f(*[dr.gather(mi.Float, mi.Float(N[:, q]), li) for q in range(3)])
    c = dr.dot(nr, w)
    o = p + nr * (dr.select(c >= 0, 1.0, -1.0) * eps)
    blocked = scene.ray_test(mi.Ray3f(o, w))
    val = dr.select(blocked, 0.0, dr.abs(c)) * (2.0 / k)
    acc = dr.zeros(mi.Float, n)
    dr.scatter_add(acc, val, li)
    return np.asarray(acc, np.float64)


def sky_view_factor_photons(tree_or_leaves, photons: int = 1_000_000, seed: int = 0,
                            tau=None) -> np.ndarray:
    """Per-leaf skylight factor from the photon pass.

    A uniform sky of unit horizontal irradiance over a tree with ``veg_leaf`` leaves
    (PROSPECT-D, ``tau`` per leaf, default green) and grey bark, no ground; V = PAR power on both
    faces / (leaf area x open PAR). Includes light scattered by leaves (so V can exceed the
    ray-cast view factor).

    Parameters
    ----------
    tree_or_leaves : Tree or Leaves
        The tree (leaves and bark) or its leaves.
    photons : int
        Photons of the pass (default 1 000 000).
    seed : int
        Seed of the pass (default 0).
    tau : array_like, optional
        (n_leaves,) autumn logical time [-] of the leaves' spectra (default: green, τ = 0).

    Returns
    -------
    numpy.ndarray
        (n_leaves,) skylight factor V [-] (can exceed 1).
    """
    em = {"sky": {"type": "veg_sky", "radiance": {"type": "uniform", "value": 1.0 / np.pi},
                  "distribution": "uniform", "sun_direction": [0.0, 1.0, 0.0]}}
    leaves = tree_or_leaves.leaves if hasattr(tree_or_leaves, "leaves") else tree_or_leaves
    scene, leaf_map = tree_scene(tree_or_leaves, emitters=em, tau=tau, ground=False)

    res = photon_irradiance(scene, photons=int(photons), seed=int(seed), bands=("par",))
    lv = leaf_values(res, leaf_map, n_leaves=len(leaves))
    return lv["par_W_m2"] / 300.0      # open: 1 W m-2 nm-1 x 300 nm
