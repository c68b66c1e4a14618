"""Expected propagule dispersal between triangles: the kernels of eqs 3.22-3.23, precomputed.

In the discrete model (``daily/moss.py``, ``moss/propagules.py``) a gemma leaves its parent M
towards B = M + k I (eq 3.22, I uniform on the sphere), a spore towards Q = M + l I_N (eq 3.23,
I_N in the 45° cones about the normal), both stop at a surface in the way, else fall along -y;
nothing hit or a back face: lost; a landing on a surface where moss may not live: lost.

The relaxed model needs the *expectation* of that: the probability ``K[j -> i]`` that a
propagule released by a moss lying uniformly on triangle j lands on triangle i. It does not
depend on the model's parameters, so it is estimated once by Monte Carlo with the very same
functions (``land``, ``uniform_sphere``, ``spore_direction``, the same lift off the surface) and
stored as a sparse matrix (COO: src, dst, weight). Applying it is a gather and a scatter-add,
differentiable w.r.t. the number of propagules produced on each triangle:

    arrivals_i = sum_j K[j -> i] * produced_j.

The Monte-Carlo error of K is fixed (same for every evaluation); with ``samples`` per source
triangle a weight is a multiple of 1/samples.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..moss.propagules import land, spore_direction, uniform_sphere

__all__ = ["Kernel", "dispersal_kernel", "random_points", "sibling_overlap", "pooled_share"]


@dataclass
class Kernel:
    """Sparse dispersal matrix: ``weight[k]`` = P(land on ``dst[k]`` | released on ``src[k]``)."""

    kind: str
    distance: float
    samples: int
    src: np.ndarray
    dst: np.ndarray
    weight: np.ndarray
    n_elements: int
    #: per source element: the effective number of cells around the parent's cell where its
    #: propagules land, 1 / sum_k p_k^2 over the landing cells' offsets k (the near-field
    #: closure's z; NaN where fewer than two landings were sampled); None if not estimated
    near_cells: np.ndarray | None = None
    #: per source element: the share of a landing cell's other z - 1 neighbour cells that are
    #: also neighbours of the parent's cell (weighted by the landing probabilities; the
    #: near-field closure's triplet term); NaN where not estimable; None if not estimated
    near_overlap: np.ndarray | None = None
    #: per source element: the share of its landings (other than the parent's own spot) that
    #: fall outside the gemmae's reach of its parent's cell, more than ``near_radius`` cells
    #: away along an axis (the far field, where a landing cell is occupied with the
    #: triangle's mean occupancy); None if not estimated
    far_share: np.ndarray | None = None
    #: per source element: the probability that this propagule and a gemma released from the
    #: same point land in the same cell, given both landed (:func:`sibling_overlap`, pooled
    #: over the element's gemma neighbourhood: :func:`pooled_share`); for the gemma kernel its
    #: inverse is the number of cells a parent at a fixed point reaches; None if not estimated
    sibling_share: np.ndarray | None = None

    def __post_init__(self):
        self._dr = None

    @property
    def nnz(self) -> int:
        """Number of stored (source, destination) pairs.

        Returns
        -------
        int
            The non-zeros of the sparse matrix.
        """
        return len(self.weight)

    def kept(self) -> np.ndarray:
        """Per source triangle: the fraction of its propagules that land on a living surface.

        Returns
        -------
        numpy.ndarray
            (triangles,) fraction [-] (the parent's own spot left out).
        """
        return np.bincount(self.src, self.weight, minlength=self.n_elements)

    def apply(self, produced):
        """Expected arrivals per element for ``produced`` propagules per element.

        Parameters
        ----------
        produced : Dr.Jit float array
            (triangles,) propagules released on each triangle [-] (AD-tracked or not).

        Returns
        -------
        Dr.Jit float array
            (triangles,) expected arrivals ``sum_j K[j -> i] produced_j`` [-], differentiable
            in ``produced``.
        """
        t = type(produced)
        if self._dr is None or self._dr[0] is not t:
            u = dr.uint32_array_t(t)
            self._dr = (t, u(self.src.astype(np.uint32)), u(self.dst.astype(np.uint32)),
                        t(self.weight))
        _, src, dst, w = self._dr
        out = dr.zeros(t, self.n_elements)
        dr.scatter_add(out, dr.gather(t, produced, src) * w, dst)
        return out


def random_points(index, elems: np.ndarray, rng: np.random.Generator):
    """Uniform random points on the given elements (triangles of ``index.geometry``) and their
    unit normals.

    Parameters
    ----------
    index : SceneIndex
        The photon pass's scene index (its ``geometry``, ``normals`` and shape slices).
    elems : numpy.ndarray
        (n,) global element (triangle) indices, one point each.
    rng : numpy.random.Generator
        Source of the random numbers.

    Returns
    -------
    pts : numpy.ndarray
        (n, 3) points [m].
    nrm : numpy.ndarray
        (n, 3) unit normals of their triangles [-].
    """
    elems = np.asarray(elems, np.int64)
    u = rng.random((len(elems), 2))
    flip = u.sum(1) > 1
    u[flip] = 1 - u[flip]
    pts = np.zeros((len(elems), 3))
    for sid, (v, f) in index.geometry.items():
        sl = index.shape_slice(sid)
        sel = (elems >= sl.start) & (elems < sl.stop)
        if sel.any():
            fc = f[elems[sel] - sl.start]
            p0, p1, p2 = v[fc[:, 0]], v[fc[:, 1]], v[fc[:, 2]]
            pts[sel] = p0 + u[sel, :1] * (p1 - p0) + u[sel, 1:] * (p2 - p0)
    return pts, index.normals[elems]


def dispersal_kernel(scene, index, living: np.ndarray, kind: str, distance: float,
                     samples: int = 64, seed: int = 0, grid=None, batch: int = 1 << 21,
                     near_radius: int | None = None) -> Kernel:
    """Monte-Carlo dispersal kernel of ``kind`` ``"gemma"`` (eq 3.22) or ``"spore"`` (eq 3.23)
    over the living elements of ``scene`` (``samples`` releases per living source triangle).

    ``grid``: the run's spot grid (:class:`~mitsuba_veg.moss.spatial.CellGrid`); a propagule
    that lands in its parent's own spot is lost in the discrete model (the parent holds it and
    wins the priority rule), so such landings are left out of K. On the moss garden that is 25 %
    of the gemmae and 42 % of the spores (half of them leave into the cone below the surface and
    stop right at the parent).

    Parameters
    ----------
    scene : mitsuba.Scene
        The light scene (propagules are traced against it).
    index : SceneIndex
        Its element index (shape lookup, geometry, normals).
    living : numpy.ndarray
        (triangles,) bool: where moss may live (sources; landings elsewhere are lost).
    kind : str
        ``"gemma"`` or ``"spore"``.
    distance : float
        Flight distance k (gemma) or l (spore) of eqs 3.22-3.23 [m].
    samples : int
        Releases per living source triangle.
    seed : int
        Seed of the NumPy generator.
    grid : SpotGrid, optional
        The run's spot grid (own-spot landings left out, ``near_cells``, ``near_overlap`` and,
        with ``near_radius``, ``far_share`` estimated).
    batch : int
        Releases traced at a time.
    near_radius : int, optional
        The gemmae's reach [cells]: landings more than this many cells from the parent's cell
        along an axis count as far (``far_share``).

    Returns
    -------
    Kernel
        The sparse kernel (weights: multiples of 1 / samples).

    Raises
    ------
    ValueError
        For an unknown ``kind``.
    """
    if kind not in ("gemma", "spore"):
        raise ValueError(f"kind must be 'gemma' or 'spore', not {kind!r}")
    n = index.n_elements
    living = np.asarray(living, bool)
    sources = np.flatnonzero(living)
    rng = np.random.default_rng([seed, 0 if kind == "gemma" else 1])
    src_all = np.repeat(sources, samples)
    srcs, dsts, offs = [], [], []
    for start in range(0, len(src_all), batch):
        src = src_all[start:start + batch]
        m = len(src)
        pts, nrm = random_points(index, src, rng)
        ok, el, p, P = _fly(scene, index, living, grid, pts, nrm, kind, distance, rng)
        srcs.append(src[ok])
        dsts.append(el[ok])
        if grid is not None:  # landing cell relative to the parent's cell (17^3 offsets)
            off = np.zeros(m, np.int64)
            for k, (a, b) in enumerate(zip(grid.coords(p), grid.coords(P))):
                dk = np.asarray(a).astype(np.int64) - np.asarray(b).astype(np.int64)
                off += (np.clip(dk, -8, 8) + 8) * 17 ** k
            offs.append(off[ok])
    src = np.concatenate(srcs)
    dst = np.concatenate(dsts)
    key = src * n + dst
    uniq, counts = np.unique(key, return_counts=True)
    near = overlap = far = None
    if grid is not None:
        off = np.concatenate(offs)
        near = near_cells(src, off, n)
        overlap = near_overlap(src, off, n)
        if near_radius is not None:
            out = np.abs(_decode_offset(off)).max(-1) > int(near_radius)
            with np.errstate(divide="ignore", invalid="ignore"):
                far = np.bincount(src, out, n) / np.bincount(src, minlength=n)
    return Kernel(kind, float(distance), int(samples), (uniq // n).astype(np.int64),
                  (uniq % n).astype(np.int64), counts / float(samples), n, near, overlap, far)


def _decode_offset(code: np.ndarray) -> np.ndarray:
    """(..., 3) cell offsets [cells] from the 17^3 codes of ``dispersal_kernel``."""
    return np.stack([(code // 17 ** k) % 17 - 8 for k in range(3)], -1)


def _fly(scene, index, living, grid, pts, nrm, kind, distance, rng):
    """One propagule of ``kind`` released from each point ``pts`` (on normals ``nrm``; lifted
    0.1 mm, as individuals sit in daily/moss.py): whether it counts (landed on a living surface
    and, with a ``grid``, not in the parent's own spot), its element, landing point and the
    release point (both Dr.Jit points)."""
    m = len(pts)
    pts = pts + nrm * 1e-4
    P = mi.Point3f(*[mi.Float(pts[:, k].astype(np.float32)) for k in range(3)])
    N = mi.Vector3f(*[mi.Float(nrm[:, k].astype(np.float32)) for k in range(3)])
    r = rng.random((m, 3)).astype(np.float32)
    u = mi.Point2f(mi.Float(r[:, 0]), mi.Float(r[:, 1]))
    d = spore_direction(N, u, mi.Float(r[:, 2])) if kind == "spore" else uniform_sphere(u)
    landed, elem, p, _ = land(scene, index.lookup, P + N * 2e-3, d, float(distance),
                              mi.Bool(True))
    if grid is not None:
        landed &= grid.index(p) != grid.index(P)
    ok = np.asarray(landed)
    el = np.asarray(elem).astype(np.int64)
    ok &= (el >= 0) & (el < index.n_elements)
    ok[ok] &= living[el[ok]]
    return ok, el, p, P


def sibling_overlap(scene, index, living: np.ndarray, grid, kind: str, distance: float,
                    gemma_distance: float, samples: int = 128, seed: int = 0,
                    batch: int = 1 << 20) -> tuple[np.ndarray, np.ndarray]:
    """Per source element: how often a propagule of ``kind`` and a gemma released from the
    *same* point land in the same cell (both landed, neither in the parent's own spot).

    The kernel's ``near_cells`` pools the parent's position over the whole triangle; a parent
    stays at one point, and where the landings are short next to the cell's size (on a wall a
    gemma hops a few mm into the surface) it reaches only the few cells beside that point, the
    same ones every day: its offspring crowd there. For two gemmae this share is
    ``sum_k p_k(x)^2`` averaged over the parent's point x, the inverse of the cells a parent
    reaches; for a spore and a gemma it says how often a spore lands where the parent's gemmae
    land (near field) rather than anywhere.

    Parameters
    ----------
    scene, index : mitsuba.Scene, SceneIndex
        The light scene and its element index.
    living : numpy.ndarray
        (triangles,) bool: where moss may live.
    grid : SpotGrid
        The run's spot grid.
    kind : str
        ``"gemma"`` or ``"spore"``: the first propagule's kind.
    distance : float
        Its flight distance [m].
    gemma_distance : float
        The gemma's flight distance k of eq 3.22 [m].
    samples : int
        Release points per living source triangle (two propagules each).
    seed : int
        Seed of the NumPy generator.
    batch : int
        Release points traced at a time.

    Returns
    -------
    same : numpy.ndarray
        (triangles,) pairs in the same cell [-] (counts).
    both : numpy.ndarray
        (triangles,) pairs where both landed [-] (counts).
    """
    if kind not in ("gemma", "spore"):
        raise ValueError(f"kind must be 'gemma' or 'spore', not {kind!r}")
    n = index.n_elements
    living = np.asarray(living, bool)
    rng = np.random.default_rng([seed, 0 if kind == "gemma" else 1, 2])
    src_all = np.repeat(np.flatnonzero(living), samples)
    same = np.zeros(n)
    both = np.zeros(n)
    for start in range(0, len(src_all), batch):
        src = src_all[start:start + batch]
        pts, nrm = random_points(index, src, rng)
        oka, _, pa, _ = _fly(scene, index, living, grid, pts, nrm, kind, distance, rng)
        okb, _, pb, _ = _fly(scene, index, living, grid, pts, nrm, "gemma", gemma_distance, rng)
        b = oka & okb
        same_cell = np.asarray(grid.index(pa) == grid.index(pb))
        both += np.bincount(src, b, n)
        same += np.bincount(src, b & same_cell, n)
    return same, both


def pooled_share(kernel: Kernel, same: np.ndarray, both: np.ndarray,
                 min_pairs: float = 20.0) -> np.ndarray:
    """``same / both`` per element, pooled over the element and the elements its propagules
    reach by ``kernel`` (the same surface within a flight: a few samples per triangle are too
    few on their own); NaN where fewer than ``min_pairs`` pairs landed.

    Parameters
    ----------
    kernel : Kernel
        The neighbourhood (the gemma kernel).
    same, both : numpy.ndarray
        (triangles,) counts of :func:`sibling_overlap`.
    min_pairs : float
        Least pooled pairs for an estimate.

    Returns
    -------
    numpy.ndarray
        (triangles,) share in [0, 1] [-] (NaN where not estimable).
    """
    n = kernel.n_elements
    nb = kernel.src != kernel.dst
    s = same + np.bincount(kernel.src[nb], same[kernel.dst[nb]], n)
    b = both + np.bincount(kernel.src[nb], both[kernel.dst[nb]], n)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(b >= min_pairs, s / b, np.nan)


def _offset_counts(src: np.ndarray, offset: np.ndarray, n: int):
    """Per source element the landed count in each cell offset: ``(owner, code, count, N)``
    (sorted by owner and code) and the landings per element."""
    key = src.astype(np.int64) * (17 ** 3) + offset
    uniq, cnt = np.unique(key, return_counts=True)
    return uniq // (17 ** 3), uniq % (17 ** 3), cnt.astype(float), \
        np.bincount(src, minlength=n).astype(float), uniq


def near_overlap(src: np.ndarray, offset: np.ndarray, n: int) -> np.ndarray:
    """Per source element, the share theta of a landing cell's other neighbour cells that are
    also neighbours of the parent's cell, weighted by the kernel's landing probabilities p_k
    (k: offset from the parent's cell):

        theta = z / (z - 1) * sum_(k, m) p_k p_m p_(k + m) / sum_k p_k^2,   z = 1 / sum_k p_k^2

    (a cell c = parent + k; its neighbour c + m is the parent's neighbour with weight
    p_(k + m); for a uniform kernel over z cells this is |N and (N - k)| / (z - 1) averaged over
    k). The triple sum is estimated without bias from the sampled landings: ordered triples of
    distinct landings with o_i + o_j = o_l, (sum_(a, b) n_a n_b n_(a + b) - sum_a n_a n_(2a)) /
    (N (N - 1) (N - 2)) (the parent's own cell is never a landing cell, so only i = j
    coincides); sum p_k^2 as in :func:`near_cells`. NaN where fewer than three landings or no
    repeated cell.

    Parameters
    ----------
    src : numpy.ndarray
        (landings,) source element of each landed propagule.
    offset : numpy.ndarray
        (landings,) code of the landing cell's offset from the parent's cell (17^3 codes).
    n : int
        Number of elements.

    Returns
    -------
    numpy.ndarray
        (n,) overlap theta in [0, 1] [-] (NaN where not estimable).
    """
    owner, code, cnt, N, key = _offset_counts(src, offset, n)
    # pairs (a, b) of offsets of the same owner
    start = np.searchsorted(owner, np.arange(n))
    size = np.bincount(owner, minlength=n)
    reps = size[owner]                                   # each entry pairs with its group
    ia = np.repeat(np.arange(len(owner)), reps)
    grp_start = start[owner][ia]
    within = np.arange(len(ia)) - np.repeat(np.cumsum(reps) - reps, reps)
    ib = grp_start + within

    def lookup(o, vec):
        """Count of owner o's landings at offset vec (0 outside the coded range)."""
        ok = np.all(np.abs(vec) <= 8, -1)
        c = ((np.clip(vec, -8, 8) + 8) * np.array([1, 17, 17 ** 2])).sum(-1)
        k = o * 17 ** 3 + c
        pos = np.clip(np.searchsorted(key, k), 0, len(key) - 1)
        return np.where(ok & (key[pos] == k), cnt[pos], 0.0)

    va, vb = _decode_offset(code[ia]), _decode_offset(code[ib])
    triple = np.bincount(owner[ia], cnt[ia] * cnt[ib] * lookup(owner[ia], va + vb),
                         minlength=n)
    va = _decode_offset(code)
    triple -= np.bincount(owner, cnt * lookup(owner, 2 * va), minlength=n)
    s2 = np.bincount(owner, cnt ** 2, minlength=n) - N
    with np.errstate(divide="ignore", invalid="ignore"):
        sum_p2 = s2 / (N * (N - 1))
        t = (triple / (N * (N - 1) * (N - 2))) / sum_p2
        z = 1.0 / sum_p2
        theta = np.where((N >= 3) & (s2 > 0) & (z > 1), t * z / (z - 1), np.nan)
    return np.clip(theta, 0.0, 1.0)


def near_cells(src: np.ndarray, offset: np.ndarray, n: int) -> np.ndarray:
    """Per source element, the effective number of landing cells 1 / sum_k p_k^2 (p_k: the
    share of its landed propagules in the cell at offset k from the parent's), from the sampled
    landings; sum_k p_k^2 is estimated without bias as (sum n_k^2 - N) / (N (N - 1)). NaN where
    fewer than two landings (or no repeated cell: then z is large) were sampled.

    Parameters
    ----------
    src : numpy.ndarray
        (landings,) source element of each landed propagule.
    offset : numpy.ndarray
        (landings,) code of the landing cell's offset from the parent's cell (17^3 codes).
    n : int
        Number of elements.

    Returns
    -------
    numpy.ndarray
        (n,) effective number of landing cells z [cells] (NaN where not estimable).
    """
    owner, _, cnt, N, _ = _offset_counts(src, offset, n)
    s2 = np.bincount(owner, cnt ** 2, minlength=n)
    num = s2 - N
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where((N >= 2) & (num > 0), N * (N - 1) / num, np.nan)
    return z
