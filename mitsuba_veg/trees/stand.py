"""Stand layout: where the trees of a stand stand, which species, how tall, which geometry.

A :class:`StandSpec` describes a stand: a plot (rectangle or polygon in the x-z plane), a
density [trees/ha], a species mix (weights over the Weber-Penn presets of paper 004 and the
growth model of paper 001), the placement (Poisson-disc with a minimum spacing, or clumped), the
spread of tree heights and a seed. :func:`layout` turns it into a :class:`Stand`: one row per
tree with its base position [m] (the base height from the terrain), species, height [m], yaw
[deg], its own seed and a geometry variant, so that trees of one preset can share a few meshes
as Mitsuba instances (:meth:`Stand.transforms`).

Frame: +y up, +x east, +z south (the project's convention); the plot and the density are
horizontal (map) areas, also on a slope.

Placement
---------
``poisson_disc``: Bridson's algorithm (Bridson 2007, "Fast Poisson disk sampling in arbitrary
dimensions") fills the plot with points no closer than ``min_spacing`` s (``k`` = 30 candidates
in the annulus [s, 2s] around an active point; when the front dies, random darts look for gaps
left in a polygon). The fill holds about 0.62/s² points per m² on large plots
(:data:`POISSON_DISC_FILL`, measured). ``N = round(density x area)`` of them are kept, chosen at
random: a thinning that keeps the spacing and spreads the trees evenly. A density above 0.6/s² is
refused, and so is one that the fill of a small plot falls short of.

``clumped``: a Neyman-Scott cluster process. Parents fall at random (Poisson, ``parent_density``
[1/ha]) on the plot widened by the cluster reach; each tree picks a parent at random and lies at a
Gaussian offset of standard deviation ``cluster_radius`` from it (Thomas process) or uniformly
in a disc of radius ``cluster_radius`` (Matérn cluster process); trees off the plot are redrawn,
so a stand has exactly N trees (the process conditioned on its count). With ``min_spacing`` > 0
a tree closer than that to an earlier one is redrawn too (a hard core).

Clark-Evans aggregation index (Clark & Evans 1954), :func:`clark_evans`:
``R = mean nearest-neighbour distance / (0.5 / sqrt(n / A))``: 1 for complete spatial
randomness, < 1 clumped, > 1 regular (no edge correction: edges raise R a little).

Sizes: heights are normal with mean ``height_mean`` and standard deviation ``height_cv x
height_mean``, clipped to ``height_range`` (default 0.5-1.5 x the mean). A Weber-Penn tree is its
variant's mesh scaled uniformly to its height; a growth-model tree (species ``"growth"``) is
grown on its own (variant -1).
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field, fields

import numpy as np

from ..errors import ParameterError, unknown_field
from .weber_penn import PRESETS

#: species name of the growth model (paper 001) in a stand's mix
GROWTH = "growth"
#: names a mix may use: the Weber-Penn presets and the growth model
SPECIES = tuple(PRESETS) + (GROWTH,)
#: how a stand places its trees
PLACEMENTS = ("poisson_disc", "clumped")
#: cluster processes of the clumped placement
CLUSTERS = ("thomas", "matern")
#: points per s² [-] that Bridson's fill reaches: 0.621-0.626 on a 100 s x 100 s square (k = 30,
#: 5 seeds), less on small or narrow plots (edges). Densities above 0.6/s² are refused before
#: placing; a plot whose fill falls short of the density is refused after.
POISSON_DISC_FILL = 0.6
#: densest packing of discs of diameter s (hexagonal) [-]: 2 / sqrt(3) points per s²
HEX_PACKING = 2.0 / math.sqrt(3.0)
#: candidates per active point in Bridson's algorithm
BRIDSON_K = 30


# --------------------------------------------------------------------------------------------
# The plot
# --------------------------------------------------------------------------------------------

def polygon_area(polygon) -> float:
    """Area of a simple polygon in the x-z plane (shoelace formula).

    Parameters
    ----------
    polygon : array_like
        (k, 2) vertices (x, z) [m], in order (either orientation), not repeated at the end.

    Returns
    -------
    float
        The area [m2] (positive).
    """
    p = np.asarray(polygon, float)
    x, z = p[:, 0], p[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1))))


def inside_polygon(points, polygon) -> np.ndarray:
    """Which points lie inside a polygon (even-odd rule, vectorised over points and edges).

    Parameters
    ----------
    points : array_like
        (n, 2) points (x, z) [m].
    polygon : array_like
        (k, 2) vertices (x, z) [m], in order.

    Returns
    -------
    numpy.ndarray
        (n,) bool, True inside (points exactly on an edge may fall either way).
    """
    pts = np.asarray(points, float).reshape(-1, 2)
    poly = np.asarray(polygon, float)
    x, z = pts[:, :1], pts[:, 1:]
    x0, z0 = poly[:, 0][None], poly[:, 1][None]
    x1, z1 = np.roll(poly[:, 0], -1)[None], np.roll(poly[:, 1], -1)[None]
    crosses = (z0 > z) != (z1 > z)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x0 + (z - z0) * (x1 - x0) / (z1 - z0)
    return np.logical_xor.reduce(crosses & (x < xc), axis=1)


class _Region:
    """A rectangle or polygon of the x-z plane: bounds, area, membership."""

    def __init__(self, plot):
        p = np.asarray(plot, float)
        if p.ndim == 1:
            self.polygon = None
            self.bounds = p.copy()
            self.area = float((p[2] - p[0]) * (p[3] - p[1]))
        else:
            self.polygon = p
            self.bounds = np.array([p[:, 0].min(), p[:, 1].min(), p[:, 0].max(), p[:, 1].max()])
            self.area = polygon_area(p)

    def contains(self, pts) -> np.ndarray:
        pts = np.asarray(pts, float).reshape(-1, 2)
        b = self.bounds
        m = (pts[:, 0] >= b[0]) & (pts[:, 0] <= b[2]) & (pts[:, 1] >= b[1]) & (pts[:, 1] <= b[3])
        if self.polygon is not None and m.any():
            m[m] = inside_polygon(pts[m], self.polygon)
        return m

    def uniform(self, rng, n) -> np.ndarray:
        """n uniform points inside (rejection from the bounds)."""
        b = self.bounds
        out = np.zeros((0, 2))
        while len(out) < n:
            m = 2 * n + 8
            c = np.column_stack([rng.uniform(b[0], b[2], m), rng.uniform(b[1], b[3], m)])
            out = np.concatenate([out, c[self.contains(c)]])
        return out[:n]


class _SpacingGrid:
    """Accepted points on a background grid of cell s/sqrt(2) (one point per cell at most),
    padded by two cells so that the 5 x 5 neighbourhood of any cell inside is in range."""

    def __init__(self, bounds, spacing):
        self.s = float(spacing)
        self.cell = self.s / math.sqrt(2.0)
        self.lo = np.asarray(bounds[:2], float)
        nx = int(math.ceil((bounds[2] - bounds[0]) / self.cell)) + 1
        nz = int(math.ceil((bounds[3] - bounds[1]) / self.cell)) + 1
        self.grid = np.full((nz + 4, nx + 4), -1, np.int64)
        self._pts = np.zeros((64, 2))
        self.n = 0
        off = np.arange(-2, 3)
        self.dz, self.dx = [a.ravel() for a in np.meshgrid(off, off, indexing="ij")]

    def _cells(self, p):
        c = np.floor((np.asarray(p, float).reshape(-1, 2) - self.lo) / self.cell).astype(np.int64)
        return c[:, 0] + 2, c[:, 1] + 2

    def fits(self, cand) -> np.ndarray:
        """(n,) bool: each candidate is at least s from every accepted point."""
        cand = np.asarray(cand, float).reshape(-1, 2)
        if not self.n:
            return np.ones(len(cand), bool)
        cx, cz = self._cells(cand)
        nb = self.grid[cz[:, None] + self.dz[None], cx[:, None] + self.dx[None]]   # (n, 25)
        q = self._pts[np.maximum(nb, 0)]
        d2 = ((q - cand[:, None, :]) ** 2).sum(-1)
        d2[nb < 0] = np.inf
        return d2.min(axis=1) >= self.s * self.s

    def add(self, p) -> None:
        if self.n == len(self._pts):
            self._pts = np.concatenate([self._pts, np.zeros_like(self._pts)])
        cx, cz = self._cells(p)
        self.grid[cz[0], cx[0]] = self.n
        self._pts[self.n] = np.asarray(p, float).reshape(2)
        self.n += 1

    @property
    def pts(self) -> np.ndarray:
        return self._pts[: self.n]


def poisson_disc(plot, min_spacing: float, seed=0, k: int = BRIDSON_K) -> np.ndarray:
    """Fill a plot with points no closer than ``min_spacing`` (Bridson's algorithm).

    The fill starts at a random point and grows: each step takes a random active point and
    tries ``k`` random candidates in the annulus [s, 2s] around it; the first that keeps the
    spacing is accepted (and becomes active), else the point retires. When no point is active,
    ``20 k`` random darts over the plot look for a gap (a polygon's parts that the front could
    not reach); a dart that fits starts a new front.

    Parameters
    ----------
    plot : array_like
        ``[x0, z0, x1, z1]`` (a rectangle) or (k, 2) polygon vertices (x, z) [m].
    min_spacing : float
        Smallest distance s between two points [m], > 0.
    seed : int or numpy.random.Generator, optional
        Seed (or generator) of the random numbers; default 0.
    k : int, optional
        Candidates per active point; default :data:`BRIDSON_K` = 30.

    Returns
    -------
    numpy.ndarray
        (m, 2) points (x, z) [m], about :data:`POISSON_DISC_FILL` / s² per m² of a large plot.

    Raises
    ------
    ParameterError
        If ``min_spacing`` is not > 0 or ``k`` < 1.
    """
    if not (float(min_spacing) > 0):
        raise ParameterError("min_spacing", min_spacing, "> 0 m")
    if int(k) < 1:
        raise ParameterError("k", k, "an integer >= 1")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    region = _Region(plot)
    s = float(min_spacing)
    grid = _SpacingGrid(region.bounds, s)
    active: list[int] = []
    darts_left = True
    while True:
        if not active:
            if not darts_left:
                break
            darts = region.uniform(rng, 20 * k)
            ok = np.flatnonzero(grid.fits(darts))
            # a dart that fits starts a new front; accept them one at a time (they may clash)
            started = False
            for i in ok:
                if grid.fits(darts[i])[0]:
                    grid.add(darts[i])
                    active.append(grid.n - 1)
                    started = True
                    break
            darts_left = started
            continue
        j = int(rng.integers(len(active)))
        p = grid.pts[active[j]]
        rho = np.sqrt(rng.uniform(s * s, 4 * s * s, k))
        phi = rng.uniform(0, 2 * np.pi, k)
        cand = p + np.column_stack([rho * np.cos(phi), rho * np.sin(phi)])
        ok = region.contains(cand)
        if ok.any():
            ok[ok] = grid.fits(cand[ok])
        if ok.any():
            grid.add(cand[np.argmax(ok)])
            active.append(grid.n - 1)
        else:
            active[j] = active[-1]
            active.pop()
    return grid.pts.copy()


def cluster_points(plot, n: int, parent_density: float, cluster_radius: float,
                   kind: str = "thomas", min_spacing: float = 0.0, seed=0,
                   max_tries: int | None = None) -> np.ndarray:
    """Exactly ``n`` clumped points on a plot (Thomas or Matérn cluster process).

    Parents: Poisson with ``parent_density`` on the plot's bounds widened by the cluster reach
    (3 x radius for Thomas, the radius for Matérn; at least one parent). Each point picks a
    parent at random and an offset: Gaussian with standard deviation ``cluster_radius`` per axis
    (Thomas) or uniform in the disc of that radius (Matérn). Points off the plot, or closer than
    ``min_spacing`` to an accepted point, are redrawn.

    Parameters
    ----------
    plot : array_like
        ``[x0, z0, x1, z1]`` or (k, 2) polygon vertices (x, z) [m].
    n : int
        Number of points, >= 0.
    parent_density : float
        Cluster centres per hectare [1/ha], > 0.
    cluster_radius : float
        Thomas: standard deviation of the offset per axis [m]; Matérn: disc radius [m]; > 0.
    kind : str, optional
        ``"thomas"`` (default) or ``"matern"``.
    min_spacing : float, optional
        Hard core: smallest distance between two points [m]; default 0 (none).
    seed : int or numpy.random.Generator, optional
        Seed (or generator); default 0.
    max_tries : int, optional
        Candidates drawn at most before giving up; default ``max(10000, 200 n)``.

    Returns
    -------
    numpy.ndarray
        (n, 2) points (x, z) [m].

    Raises
    ------
    ParameterError
        For a bad kind or value, or when ``max_tries`` candidates did not give ``n`` points
        (clusters too tight for the spacing).
    """
    if kind not in CLUSTERS:
        raise ParameterError("cluster", kind, ", ".join(CLUSTERS))
    if not (float(parent_density) > 0 and float(cluster_radius) > 0):
        raise ParameterError("parent_density, cluster_radius", (parent_density, cluster_radius),
                             "both > 0 (1/ha, m)")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    region = _Region(plot)
    reach = float(cluster_radius) * (3.0 if kind == "thomas" else 1.0)
    b = region.bounds + np.array([-reach, -reach, reach, reach])
    area_ext = (b[2] - b[0]) * (b[3] - b[1])
    n_par = max(1, int(rng.poisson(float(parent_density) * area_ext / 1e4)))
    parents = np.column_stack([rng.uniform(b[0], b[2], n_par), rng.uniform(b[1], b[3], n_par)])
    n = int(n)
    max_tries = max(10000, 200 * n) if max_tries is None else int(max_tries)
    grid = _SpacingGrid(region.bounds, min_spacing) if min_spacing > 0 else None
    out: list = []
    tries = 0
    while len(out) < n:
        if tries >= max_tries:
            raise ParameterError(
                "cluster_radius", cluster_radius,
                f"clusters wide enough for {n} trees at min_spacing {min_spacing} m around "
                f"{n_par} parents", "widen cluster_radius, raise parent_density or lower "
                "min_spacing or the density")
        m = min(max(2 * (n - len(out)), 64), 100000)
        tries += m
        par = parents[rng.integers(n_par, size=m)]
        if kind == "thomas":
            off = rng.normal(0.0, float(cluster_radius), (m, 2))
        else:
            rho = float(cluster_radius) * np.sqrt(rng.uniform(0, 1, m))
            phi = rng.uniform(0, 2 * np.pi, m)
            off = np.column_stack([rho * np.cos(phi), rho * np.sin(phi)])
        cand = (par + off)[region.contains(par + off)]
        if grid is None:
            out.extend(cand[: n - len(out)])
            continue
        for c in cand:
            if grid.fits(c)[0]:
                grid.add(c)
                out.append(c)
                if len(out) == n:
                    break
    return np.asarray(out, float).reshape(-1, 2)


def clark_evans(points, area: float) -> float:
    """Clark-Evans aggregation index R of a point pattern (no edge correction).

    ``R = r_obs / r_exp`` with ``r_obs`` the mean distance of each point to its nearest
    neighbour and ``r_exp = 0.5 / sqrt(n / area)`` its expectation under complete spatial
    randomness (Clark & Evans 1954).

    Parameters
    ----------
    points : array_like
        (n, 2) points (x, z) [m], n >= 2.
    area : float
        Area of the window [m2].

    Returns
    -------
    float
        R [-]: 1 random, < 1 clumped, > 1 regular.

    Raises
    ------
    ParameterError
        With fewer than two points or a non-positive area.
    """
    p = np.asarray(points, float).reshape(-1, 2)
    if len(p) < 2 or not float(area) > 0:
        raise ParameterError("points, area", (len(p), area), "at least 2 points and area > 0")
    from scipy.spatial import cKDTree      # here: the package imports faster without it

    d, _ = cKDTree(p).query(p, k=2)
    return float(d[:, 1].mean() / (0.5 / math.sqrt(len(p) / float(area))))


# --------------------------------------------------------------------------------------------
# The specification
# --------------------------------------------------------------------------------------------

@dataclass
class StandSpec:
    """A stand to lay out (module docstring). Lengths [m], densities [1/ha], heights [m].

    Parameters
    ----------
    plot : list
        ``[x0, z0, x1, z1]`` [m] (a rectangle) or ``[[x, z], ...]`` (a polygon, >= 3 vertices).
    density : float
        Trees per hectare of map area [1/ha].
    mix : dict
        ``{species: weight}``: Weber-Penn presets or ``"growth"`` (:data:`SPECIES`), weights >= 0
        [-] (normalised).
    placement : str
        ``"poisson_disc"`` or ``"clumped"`` (:data:`PLACEMENTS`).
    min_spacing : float
        Smallest distance between two trees [m] (> 0 for Poisson-disc; 0 allowed when clumped).
    cluster : str
        ``"thomas"`` or ``"matern"`` (clumped placement).
    cluster_radius : float
        Thomas: offset standard deviation [m]; Matérn: disc radius [m].
    parent_density : float
        Cluster centres per hectare [1/ha].
    height_mean : float
        Mean tree height [m].
    height_cv : float
        Coefficient of variation of the heights [-] (0 = all the same).
    height_range : list or None
        ``[lo, hi]`` [m] the heights are clipped to; None: 0.5 and 1.5 x ``height_mean``.
    variants : int
        Geometry variants per Weber-Penn preset (instanced meshes), >= 1.
    seed : int
        Seed of every random choice, >= 0.
    """

    plot: list = field(default_factory=lambda: [0.0, 0.0, 100.0, 100.0])
    density: float = 400.0
    mix: dict = field(default_factory=lambda: {"quaking_aspen": 1.0})
    placement: str = "poisson_disc"
    min_spacing: float = 2.0
    cluster: str = "thomas"
    cluster_radius: float = 5.0
    parent_density: float = 40.0
    height_mean: float = 15.0
    height_cv: float = 0.15
    height_range: list | None = None
    variants: int = 3
    seed: int = 0

    def __post_init__(self):
        self.validate()

    @classmethod
    def from_dict(cls, d: dict, source: str | None = None, prefix: str = "stand.") -> "StandSpec":
        """A spec from a dict (a scenario table), every field checked; unknown fields refused.

        Parameters
        ----------
        d : dict
            Field values by name (the dataclass fields; missing ones take their defaults).
        source : str, optional
            File named in error messages; default None.
        prefix : str, optional
            Dotted prefix of the field names in messages; default ``"stand."``.

        Returns
        -------
        StandSpec
            The checked spec.

        Raises
        ------
        ParameterError
            For an unknown field (with the closest known names) or a bad value.
        """
        names = [f.name for f in fields(cls)]
        for k, v in d.items():
            if k not in names:
                raise unknown_field(prefix + k, v, [prefix + n for n in names], source)
        try:
            return cls(**d)
        except ParameterError as e:
            raise ParameterError(prefix + e.field, e.value, e.allowed, e.fix, source) from None

    # ---- checks --------------------------------------------------------------------------
    def _number(self, name, lo=None, hi=None, lo_open=False):
        v = getattr(self, name)
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise ParameterError(name, v, "a number") from None
        bad = not math.isfinite(x) or (lo is not None and (x <= lo if lo_open else x < lo)) \
            or (hi is not None and x > hi)
        if bad:
            lo_s = "-inf" if lo is None else f"{lo:g}"
            hi_s = "inf" if hi is None else f"{hi:g}"
            raise ParameterError(name, v, f"{'(' if lo_open else '['}{lo_s}, {hi_s}]")
        return x

    def validate(self) -> None:
        """Check every field and that the density fits the spacing.

        Parameters
        ----------
        self : StandSpec
            The spec (checked in place).

        Raises
        ------
        ParameterError
            Naming the field, its value, the allowed range and the fix.
        """
        try:
            pf = np.asarray(self.plot, float)
        except (TypeError, ValueError):
            raise ParameterError("plot", self.plot, "[x0, z0, x1, z1] or [[x, z], ...] in "
                                 "metres") from None
        if pf.shape == (4,):
            if not (np.all(np.isfinite(pf)) and pf[2] > pf[0] and pf[3] > pf[1]):
                raise ParameterError("plot", self.plot, "[x0, z0, x1, z1] with x1 > x0, z1 > z0 "
                                     "[m]")
        elif pf.ndim == 2 and pf.shape[1] == 2 and len(pf) >= 3 and np.all(np.isfinite(pf)):
            if polygon_area(pf) <= 0:
                raise ParameterError("plot", self.plot, "a polygon of positive area")
        else:
            raise ParameterError("plot", self.plot, "[x0, z0, x1, z1] or [[x, z], ...] "
                                 f"(>= 3 vertices) in metres; got shape {pf.shape}")
        self._number("density", 0.0, 1e6, lo_open=True)
        if not isinstance(self.mix, dict) or not self.mix:
            raise ParameterError("mix", self.mix, "a table {species = weight} of "
                                 + ", ".join(SPECIES))
        for k, w in self.mix.items():
            if k not in SPECIES:
                raise ParameterError(f"mix.{k}", w, "a species of " + ", ".join(SPECIES),
                                     "use a Weber-Penn preset name or 'growth'")
            try:
                ok = float(w) >= 0 and math.isfinite(float(w))
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ParameterError(f"mix.{k}", w, "a weight >= 0")
        if sum(float(w) for w in self.mix.values()) <= 0:
            raise ParameterError("mix", self.mix, "weights with a positive sum")
        if self.placement not in PLACEMENTS:
            raise ParameterError("placement", self.placement, ", ".join(PLACEMENTS))
        if self.cluster not in CLUSTERS:
            raise ParameterError("cluster", self.cluster, ", ".join(CLUSTERS))
        if self.placement == "poisson_disc":
            s = self._number("min_spacing", 0.0, 1e4, lo_open=True)
        else:
            s = self._number("min_spacing", 0.0, 1e4)
            self._number("cluster_radius", 0.0, 1e4, lo_open=True)
            self._number("parent_density", 0.0, 1e6, lo_open=True)
        self._number("height_mean", 0.0, 200.0, lo_open=True)
        self._number("height_cv", 0.0, 1.0)
        lo, hi = self.heights_clip
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise ParameterError("height_range", self.height_range, "[lo, hi] with 0 < lo <= hi "
                                 "[m]")
        if not (isinstance(self.variants, (int, np.integer)) and 1 <= self.variants <= 1000):
            raise ParameterError("variants", self.variants, "an integer in [1, 1000]")
        if not (isinstance(self.seed, (int, np.integer)) and self.seed >= 0):
            raise ParameterError("seed", self.seed, "an integer >= 0")
        lam = float(self.density) / 1e4                       # trees per m2
        if s > 0 and lam * s * s > HEX_PACKING:
            raise ParameterError(
                "density", self.density,
                f"<= {HEX_PACKING / s ** 2 * 1e4:.0f} trees/ha at min_spacing {s:g} m (the "
                f"densest packing, hexagonal: 2/sqrt(3)/s^2)", "lower the density or min_spacing")
        if self.placement == "poisson_disc" and lam * s * s > POISSON_DISC_FILL:
            raise ParameterError(
                "density", self.density,
                f"<= {POISSON_DISC_FILL / s ** 2 * 1e4:.0f} trees/ha at min_spacing {s:g} m (a "
                f"Poisson-disc fill holds about {POISSON_DISC_FILL}/s^2)",
                f"lower the density or set min_spacing <= "
                f"{math.sqrt(POISSON_DISC_FILL / lam):.2f} m")
        if self.placement == "clumped" and s > 0:
            mu = float(self.density) / float(self.parent_density)          # trees per cluster
            # trees of one cluster lie within its reach (Matérn: the radius; Thomas: 3 sigma
            # holds 98.9 %); discs of diameter s fit at most pi / (2 sqrt 3) of the disc of
            # radius reach + s/2 (hexagonal packing)
            reach = float(self.cluster_radius) * (3.0 if self.cluster == "thomas" else 1.0)
            cap = HEX_PACKING * (math.pi / 4) * (2 * reach / s + 1) ** 2
            if mu > cap:
                raise ParameterError(
                    "cluster_radius", self.cluster_radius,
                    f"wide enough to hold density/parent_density = {mu:.1f} trees at "
                    f"min_spacing {s:g} m (at most {cap:.1f} in one cluster)",
                    "widen cluster_radius, raise parent_density or lower min_spacing")

    @property
    def heights_clip(self) -> tuple[float, float]:
        """(lo, hi) the heights are clipped to [m]."""
        if self.height_range is None:
            return 0.5 * float(self.height_mean), 1.5 * float(self.height_mean)
        try:
            lo, hi = (float(x) for x in self.height_range)
        except (TypeError, ValueError):
            raise ParameterError("height_range", self.height_range, "[lo, hi] in metres") \
                from None
        return lo, hi

    @property
    def area(self) -> float:
        """Map area of the plot [m2]."""
        return _Region(self.plot).area

    @property
    def n_trees(self) -> int:
        """Number of trees: ``round(density x area)``."""
        return int(round(float(self.density) * self.area / 1e4))


# --------------------------------------------------------------------------------------------
# The stand
# --------------------------------------------------------------------------------------------

def variant_seed(stand_seed: int, species: str, variant: int) -> int:
    """Seed of one geometry variant of a species (the same for every tree that shares it).

    Parameters
    ----------
    stand_seed : int
        The stand's seed.
    species : str
        Preset name.
    variant : int
        Variant index, >= 0.

    Returns
    -------
    int
        A seed in [0, 2**31), fixed by the three inputs.
    """
    ss = np.random.SeedSequence([int(stand_seed), zlib.crc32(species.encode()), int(variant)])
    return int(ss.generate_state(1)[0] & 0x7FFFFFFF)


@dataclass
class Stand:
    """The trees of a stand, one row each (arrays of length n).

    Attributes: ``positions`` (n, 3) tree bases [m] (y on the terrain); ``species`` (n,) str;
    ``heights`` (n,) [m]; ``yaw`` (n,) rotation about +y [deg]; ``seeds`` (n,) int per-tree
    seeds; ``variants`` (n,) int geometry variant (-1: grown alone); ``spec``; ``area`` [m2].
    """

    spec: StandSpec
    positions: np.ndarray
    species: np.ndarray
    heights: np.ndarray
    yaw: np.ndarray
    seeds: np.ndarray
    variants: np.ndarray
    area: float

    def __len__(self) -> int:
        return len(self.heights)

    @property
    def density(self) -> float:
        """Trees per hectare of map area [1/ha]."""
        return len(self) / self.area * 1e4

    def clark_evans(self) -> float:
        """Clark-Evans R of the tree bases (:func:`clark_evans`).

        Returns
        -------
        float
            R [-].
        """
        return clark_evans(self.positions[:, [0, 2]], self.area)

    def variant_keys(self) -> list[tuple[str, int]]:
        """The distinct (species, variant) geometries the stand uses (growth trees excluded).

        Returns
        -------
        list of (str, int)
            Sorted by species, then variant.
        """
        keys = {(str(s), int(v)) for s, v in zip(self.species, self.variants) if v >= 0}
        return sorted(keys)

    def variant_seed(self, species: str, variant: int) -> int:
        """Seed of a geometry variant (:func:`variant_seed` with the stand's seed).

        Parameters
        ----------
        species : str
            Preset name.
        variant : int
            Variant index.

        Returns
        -------
        int
            The seed to grow that variant with.
        """
        return variant_seed(self.spec.seed, species, variant)

    def transforms(self, variant_heights: dict | None = None) -> np.ndarray:
        """4 x 4 matrices placing each tree's variant mesh (base at the origin) in the stand.

        ``M = T(position) R_y(yaw) S(height / variant height)``: uniform scale about the base,
        rotation about +y (right-handed), then the move to the tree's base.

        Parameters
        ----------
        variant_heights : dict, optional
            ``{(species, variant): height of that mesh [m]}``; default None: no scaling.

        Returns
        -------
        numpy.ndarray
            (n, 4, 4) float64 matrices (column vectors: p' = M p).
        """
        n = len(self)
        s = np.ones(n)
        if variant_heights:
            for i, (sp, v) in enumerate(zip(self.species, self.variants)):
                h0 = variant_heights.get((str(sp), int(v)))
                if h0:
                    s[i] = self.heights[i] / h0
        a = np.radians(self.yaw)
        c, sn = np.cos(a), np.sin(a)
        M = np.zeros((n, 4, 4))
        M[:, 0, 0], M[:, 0, 2] = c * s, sn * s
        M[:, 1, 1] = s
        M[:, 2, 0], M[:, 2, 2] = -sn * s, c * s
        M[:, :3, 3] = self.positions
        M[:, 3, 3] = 1.0
        return M

    def rows(self) -> list[dict]:
        """The stand as a table: one dict per tree.

        Returns
        -------
        list of dict
            ``tree`` (index), ``species``, ``variant``, ``seed``, ``x``, ``y``, ``z`` [m],
            ``height`` [m], ``yaw`` [deg].
        """
        return [{"tree": i, "species": str(self.species[i]), "variant": int(self.variants[i]),
                 "seed": int(self.seeds[i]), "x": float(self.positions[i, 0]),
                 "y": float(self.positions[i, 1]), "z": float(self.positions[i, 2]),
                 "height": float(self.heights[i]), "yaw": float(self.yaw[i])}
                for i in range(len(self))]


def _ground_height(ground, x, z) -> np.ndarray:
    if ground is None:
        return np.zeros(len(x))
    if isinstance(ground, (int, float)):
        return np.full(len(x), float(ground))
    f = getattr(ground, "height", ground)
    if not callable(f):
        raise ParameterError("ground", type(ground).__name__, "None, a height [m], a callable "
                             "height(x, z) or an object with a height(x, z) method")
    return np.asarray(f(x, z), float).reshape(len(x))


def layout(spec: StandSpec | dict, ground=None) -> Stand:
    """Lay out a stand: positions, species, heights, yaw, seeds and variants of its trees.

    Every random choice comes from its own stream of the spec's seed (placement, species,
    heights, variants, yaw, tree seeds), so the same spec gives the same stand and changing,
    say, the height spread leaves the positions where they were.

    Parameters
    ----------
    spec : StandSpec or dict
        The stand (a dict is checked by :meth:`StandSpec.from_dict`).
    ground : None, float, callable or object with ``height(x, z)``, optional
        The terrain: base height y [m] of a tree at (x, z) [m] (e.g. a
        :class:`mitsuba_veg.forest_floor.Heightfield`); None: y = 0.

    Returns
    -------
    Stand
        One row per tree, ``round(density x area)`` trees.

    Raises
    ------
    ParameterError
        For an impossible spec (bad field, unknown species, a density the spacing cannot hold).
    """
    if isinstance(spec, dict):
        spec = StandSpec.from_dict(spec)
    spec.validate()
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(int(spec.seed)).spawn(6)]
    r_place, r_species, r_height, r_variant, r_yaw, r_seed = streams
    n = spec.n_trees
    region = _Region(spec.plot)
    if spec.placement == "poisson_disc":
        fill = poisson_disc(spec.plot, spec.min_spacing, r_place)
        if len(fill) < n:
            s = float(spec.min_spacing)
            raise ParameterError(
                "density", spec.density,
                f"<= {len(fill) / region.area * 1e4:.0f} trees/ha on this plot at min_spacing "
                f"{s:g} m (its Poisson-disc fill holds {len(fill)} trees)",
                "lower the density or min_spacing, or enlarge the plot")
        xz = fill[np.sort(r_place.choice(len(fill), n, replace=False))]
    else:
        xz = cluster_points(spec.plot, n, spec.parent_density, spec.cluster_radius,
                            spec.cluster, spec.min_spacing, r_place)
    names = list(spec.mix)
    w = np.array([float(spec.mix[k]) for k in names])
    species = np.array(names, dtype=object)[r_species.choice(len(names), n, p=w / w.sum())]
    lo, hi = spec.heights_clip
    heights = np.clip(r_height.normal(float(spec.height_mean),
                                      float(spec.height_cv) * float(spec.height_mean), n), lo, hi)
    variants = r_variant.integers(0, int(spec.variants), n)
    variants[species == GROWTH] = -1
    yaw = r_yaw.uniform(0.0, 360.0, n)
    seeds = r_seed.integers(0, 2 ** 31 - 1, n)
    y = _ground_height(ground, xz[:, 0], xz[:, 1])
    pos = np.column_stack([xz[:, 0], y, xz[:, 1]])
    return Stand(spec, pos, species.astype(str), heights, yaw, seeds.astype(np.int64),
                 variants.astype(np.int64), region.area)


__all__ = ["GROWTH", "SPECIES", "PLACEMENTS", "CLUSTERS", "POISSON_DISC_FILL", "HEX_PACKING",
           "BRIDSON_K", "polygon_area", "inside_polygon", "poisson_disc", "cluster_points",
           "clark_evans", "StandSpec", "Stand", "variant_seed", "layout"]
