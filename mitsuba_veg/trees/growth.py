"""Tree growth in its light environment (paper 001: Yoshizawa 2007, after Kanamaru & Chiba).

Model (every step vectorised over all growing tips of all trees):

- **Branching** (§2.1): one vertical branch to start; every live tip branch splits into two
  children each generation: one continues the parent axis (length L_t), one is a lateral at the
  branch angle θ, rotated about the parent axis by the phyllotaxis divergence (5/8 of a turn by
  default) from the previous lateral of that axis. The main-axis child keeps the parent's
  ``level``; a lateral is one level higher.
- **Pipe model** (§2.2): cross-section areas add up, so a segment's radius is
  ``tip_radius x sqrt(live tips it carries)``.
- **Leaf spheres** (§2.3.1): the leaves of a tip branch are a sphere of radius R at its tip.
  Received light and light vector per sphere (eqs 2.3, 2.4) from an H x V sky with C1 above and
  C2 below the horizon, attenuated by α per other leaf sphere passed, obstacles reflecting
  C2 x env (see :mod:`mitsuba_veg.trees.leaflight`, :mod:`mitsuba_veg.trees.environment`).
- **Each generation**: light at all tip spheres → tips with received light < T_D die and fall
  (eq 2.6), parents whose children all died fall too (§2.3.5) → surviving tips branch: if
  red/far-red < T_r/fr (eq 2.5, received light with α_r and α_fr) the main-axis child is
  L_t + L_ts long and the lateral L_l − L_ls (shade avoidance, §2.3.4); both children are
  turned towards the tip's light vector by the fraction H of the angle between them
  (phototropism, §2.3.3). After the last generation one more light pass culls the new tips.

Lengths are in model units (the paper's table 3.1 values); ``unit`` [m] converts them to the
scene: positions, scene meshes and the returned trees are in metres (+y up).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, fields
from fractions import Fraction

import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

from .environment import Environment
from .leaflight import LeafLight, Sky, leaf_sphere_light
from .structure import Leaves, Tree

__all__ = ["PAPER_SYMBOLS", "GrowthParams", "grow_forest", "base_positions", "grow", "TipLight",
           "grow_step", "branching"]

#: paper symbols of the parameters (table 3.1)
PAPER_SYMBOLS = {
    "branch_angle": "θ", "main_length": "L_t", "lateral_length": "L_l", "phototropism": "H",
    "light_ratio": "C", "leaf_radius": "R", "alpha": "α_l", "alpha_red": "α_r",
    "alpha_far_red": "α_fr", "death_threshold": "T_D", "shade_main_extension": "L_ts",
    "shade_lateral_reduction": "L_ls", "shade_threshold": "T_r/fr", "phyllotaxis": "Div",
    "sky_h": "H (sky)", "sky_v": "V (sky)",
}


def _fraction(v, field_name="phyllotaxis") -> float:
    if isinstance(v, str):
        try:
            v = float(Fraction(v.strip()))
        except (ValueError, ZeroDivisionError):
            raise ParameterError(field_name, v, "a fraction of a turn like '5/8' or 0.625",
                                 "use p/q with 0 < p/q < 1") from None
    check_range(field_name, v, 0.0, 1.0, lo_open=True, hi_open=True,
                fix="a fraction of a turn such as 1/2, 1/3, 2/5, 3/8, 5/8, 5/13")
    return float(v)


@dataclass
class GrowthParams:
    """Parameters of the growth model. Defaults = paper 001 table 3.1.

    Lengths (``main_length``, ``lateral_length``, ``leaf_radius``, ``shade_*``, ``tip_radius``,
    ``leaf_size``) are in model units; ``unit`` is the size of one unit in metres.
    """

    branch_angle: float = 60.0            # θ [deg]
    main_length: float = 4.0              # L_t [unit]
    lateral_length: float = 8.0           # L_l [unit]
    phototropism: float = 0.4             # H [-] 0 = none, 1 = along the light vector
    light_ratio: float = 1.5              # C = C1/C2 [-] (3/2)
    leaf_radius: float = 4.0              # R [unit]
    alpha: float = 0.3                    # α_l: light transmitted per leaf sphere passed [-]
    alpha_red: float = 0.3                # α_r [-]
    alpha_far_red: float = 0.7            # α_fr [-]
    death_threshold: float = 0.2          # T_D [-] (received light, eq 2.3)
    shade_main_extension: float = 4.0     # L_ts [unit]
    shade_lateral_reduction: float = 4.0  # L_ls [unit]
    shade_threshold: float = 0.5          # T_r/fr [-]
    phyllotaxis: float | str = 0.625      # Div [turn] (5/8)
    sky_h: int = 10                       # sky cells in longitude
    sky_v: int = 10                       # sky cells in latitude (even)
    unit: float = 0.25                    # [m] per model unit
    tip_radius: float = 0.06              # [unit] radius of a tip branch (pipe model base)
    leaves_per_sphere: int = 12           # leaf blades drawn in each leaf sphere (mesh only)
    leaf_size: float = 0.5                # [unit] blade length
    random_phase: bool = True             # random initial phyllotaxis azimuth per tree (seeded)
    ray_cutoff: float = 1e-3              # stop a ray when every band is attenuated below this
    engine: str = "auto"                  # sphere counting: "grid" | "mitsuba" | "analytic" | "auto"
    obstacle_collision: bool = True       # a child that would grow into an obstacle is not made

    def __post_init__(self):
        self.validate()

    def validate(self, source: str | None = None) -> "GrowthParams":
        """Check every field's range and normalise the integer and fraction fields, in place.

        ``phyllotaxis`` given as a string ('5/8') becomes a float [turn]; ``sky_h``, ``sky_v`` and
        ``leaves_per_sphere`` become int.

        Parameters
        ----------
        source : str, optional
            Where the values came from (e.g. a TREE.toml path), named in errors; default None.

        Returns
        -------
        GrowthParams
            ``self``, for chaining.

        Raises
        ------
        ParameterError
            If a field is out of range (e.g. ``branch_angle`` not in (0, 180) [deg], ``sky_v`` odd,
            ``engine`` unknown).
        """
        def c(name, lo=None, hi=None, **kw):
            check_range(name, getattr(self, name), lo, hi, source=source, **kw)
        c("branch_angle", 0.0, 180.0, lo_open=True, hi_open=True)
        c("main_length", 0.0, None, lo_open=True)
        c("lateral_length", 0.0, None)
        c("phototropism", 0.0, 1.0)
        c("light_ratio", 0.0, None, lo_open=True)
        c("leaf_radius", 0.0, None, lo_open=True)
        for a in ("alpha", "alpha_red", "alpha_far_red"):
            c(a, 0.0, 1.0)
        c("death_threshold", 0.0, 1.0)
        c("shade_main_extension", 0.0, None)
        c("shade_lateral_reduction", 0.0, None)
        c("shade_threshold", 0.0, None)
        self.phyllotaxis = _fraction(self.phyllotaxis)
        for name in ("sky_h", "sky_v"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v < 2:
                raise ParameterError(name, v, "an integer >= 2", "e.g. 10", source)
            setattr(self, name, int(v))
        if self.sky_v % 2:
            raise ParameterError("sky_v", self.sky_v, "an even integer (half of the cells above "
                                 "the horizon)", "e.g. 10", source)
        c("unit", 0.0, None, lo_open=True)
        c("tip_radius", 0.0, None, lo_open=True)
        if int(self.leaves_per_sphere) != self.leaves_per_sphere or self.leaves_per_sphere < 0:
            raise ParameterError("leaves_per_sphere", self.leaves_per_sphere, "an integer >= 0",
                                 source=source)
        self.leaves_per_sphere = int(self.leaves_per_sphere)
        c("leaf_size", 0.0, None, lo_open=True)
        c("ray_cutoff", 0.0, 1.0, lo_open=True, hi_open=True)
        if self.engine not in ("auto", "grid", "mitsuba", "analytic"):
            raise ParameterError("engine", self.engine, "'auto', 'grid', 'mitsuba' or "
                                 "'analytic'", source=source)
        return self

    @classmethod
    def from_dict(cls, d: dict, source: str | None = None, prefix: str = "growth.") \
            -> "GrowthParams":
        """Growth parameters from a dict (e.g. the [growth] table of a TREE.toml).

        Unknown keys are an error naming the allowed ones; errors name the field as
        ``prefix + name``.

        Parameters
        ----------
        d : dict
            Field name -> value (units as the class fields: lengths in model units, angles [deg]).
        source : str, optional
            Where ``d`` came from, named in errors (default None).
        prefix : str, optional
            Prefix of the field names in errors (default ``"growth."``).

        Returns
        -------
        GrowthParams
            The validated parameters (defaults for missing keys, paper 001 table 3.1).

        Raises
        ------
        ParameterError
            For an unknown key or a value out of range.
        """
        names = {f.name for f in fields(cls)}
        bad = [k for k in d if k not in names]
        if bad:
            raise ParameterError(prefix + bad[0], d[bad[0]], f"one of {sorted(names)}",
                                 "check the spelling", source)
        try:
            return cls(**d)
        except ParameterError as e:
            raise ParameterError(prefix + e.field, e.value, e.allowed, e.fix, source) from None

    def foliage_transmission(self) -> float:
        """Share of the light that crosses a leaf sphere's blades unhit, on average [-].

        The mesh's blades (``leaves_per_sphere`` quads of ``leaf_size`` x 0.6 ``leaf_size``)
        spread through the sphere of radius R: leaf area density u = n 0.6 s² / (4/3 π R³),
        random orientation (projection G = 1/2), mean chord 4R/3 (Beer-Lambert):
        T = exp(-G u 4R/3). Where the light comes from the world's photon passes (trees that
        grow year after year) this should be near the model's α (``alpha``), the share paper
        001's sphere lets through, so that a crown shades its inner spheres as the model's
        light does (docs/deviations.md).

        Returns
        -------
        float
            T [-].
        """
        R = float(self.leaf_radius)
        u = self.leaves_per_sphere * 0.6 * float(self.leaf_size) ** 2 / (4.0 / 3.0 * math.pi
                                                                          * R ** 3)
        return math.exp(-0.5 * u * 4.0 * R / 3.0)

    def replace(self, **kw) -> "GrowthParams":
        """A validated copy with some fields changed.

        Parameters
        ----------
        **kw : dict
            Field name -> new value.

        Returns
        -------
        GrowthParams
            The new parameters.
        """
        d = asdict(self)
        d.update(kw)
        return GrowthParams(**d)

    def to_dict(self) -> dict:
        """All fields as a plain dict (field name -> value).

        Returns
        -------
        dict
            The parameters (lengths in model units, ``unit`` [m], angles [deg]).
        """
        return asdict(self)


# --------------------------------------------------------------------------------------------
# small vector helpers (row-wise)
# --------------------------------------------------------------------------------------------
def _norm(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def _rotate(v, axis, angle):
    """Rodrigues: rotate rows of v about unit rows of axis by angle (rad, per row)."""
    c = np.cos(angle)[:, None]
    s = np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * (axis * v).sum(1, keepdims=True) * (1 - c)


def _turn_towards(d, u, target, frac):
    """Rotate unit rows d (and their frame vectors u) towards unit rows target by frac of the
    angle between them."""
    ax = np.cross(d, target)
    s = np.linalg.norm(ax, axis=1)
    ang = np.arctan2(s, (d * target).sum(1)) * frac
    ok = s > 1e-9
    if not ok.any():
        return d, u
    ax = ax[ok] / s[ok, None]
    d2, u2 = d.copy(), u.copy()
    d2[ok] = _norm(_rotate(d[ok], ax, ang[ok]))
    u2[ok] = _rotate(u[ok], ax, ang[ok])
    u2 = _norm(u2 - (u2 * d2).sum(1, keepdims=True) * d2)
    return d2, u2


# --------------------------------------------------------------------------------------------
# the grower
# --------------------------------------------------------------------------------------------
class _Forest:
    """Segments of all trees in one structure of arrays (append-only, parents first)."""

    def __init__(self, p: GrowthParams, positions, seed, env=None):
        self.p = p
        self.env = env
        self.blocked = 0
        n = len(positions)
        self.n_trees = n
        L = p.main_length * p.unit
        base = np.asarray(positions, float)
        up = np.tile([0.0, 1.0, 0.0], (n, 1))
        self.start = [base]
        self.end = [base + L * up]
        self.parent = [np.full(n, -1)]
        self.level = [np.zeros(n, np.int64)]
        self.tree = [np.arange(n)]
        self.gen = [np.zeros(n, np.int64)]
        self.alive = np.ones(n, bool)
        self.kind = [np.zeros(n, np.int64)]        # 0 trunk/main-axis child, 1 lateral
        phase = np.zeros(n)
        if p.random_phase:
            phase = np.array([np.random.default_rng([seed, i]).uniform(0, 2 * math.pi)
                              for i in range(n)])
        self.tip = np.arange(n)                    # segment index of each growing tip
        self.tip_dir = up.copy()
        self.tip_u = np.stack([np.cos(phase), np.zeros(n), np.sin(phase)], 1)
        self.nseg = n
        self.children_alive = np.zeros(n, np.int64)

    @classmethod
    def from_tree(cls, tree: Tree, p: GrowthParams, env=None) -> "_Forest":
        """The forest state of one tree grown by this model (its ``attrs`` hold the tips: the
        leaf spheres' segments, their phyllotaxis frames ``tip_u``), to grow it further."""
        f = cls.__new__(cls)
        f.p, f.env, f.blocked, f.n_trees = p, env, 0, 1
        n = len(tree)
        f.start, f.end = [tree.start.copy()], [tree.end.copy()]
        f.parent = [tree.parent.copy()]
        f.level = [tree.level.copy()]
        f.tree = [np.zeros(n, np.int64)]
        f.gen = [np.asarray(tree.attrs["generation"], np.int64).copy()]
        f.kind = [np.asarray(tree.attrs["lateral"], bool).astype(np.int64)]
        f.alive = tree.alive.copy()
        f.tip = np.asarray(tree.attrs["leaf_sphere_segment"], np.int64).copy()
        f.tip_dir = _norm(tree.end[f.tip] - tree.start[f.tip])
        f.tip_u = np.asarray(tree.attrs["tip_u"], float).reshape(-1, 3).copy()
        f.nseg = n
        par = tree.parent[(tree.parent >= 0) & f.alive]
        f.children_alive = np.bincount(par, minlength=n).astype(np.int64)
        return f

    def arrays(self):
        return (np.concatenate(self.start), np.concatenate(self.end),
                np.concatenate(self.parent), np.concatenate(self.level),
                np.concatenate(self.tree), np.concatenate(self.gen), np.concatenate(self.kind))

    def tip_positions(self):
        return np.concatenate(self.end)[self.tip] if len(self.tip) else np.zeros((0, 3))

    def kill(self, segs):
        """Tips ``segs`` die; parents whose children all died fall too."""
        parent = np.concatenate(self.parent)
        dead = np.asarray(segs, np.int64)
        while len(dead):
            self.alive[dead] = False
            par = parent[dead]
            par = par[par >= 0]
            if not len(par):
                break
            np.subtract.at(self.children_alive, par, 1)
            par = np.unique(par)
            dead = par[(self.children_alive[par] <= 0) & self.alive[par]]

    def branch(self, light, gen):
        """Children of the surviving tips (light: LeafLight of the tips, in tip order)."""
        p = self.p
        n = len(self.tip)
        if n == 0:
            return
        ends = np.concatenate(self.end)[self.tip]
        lev = np.concatenate(self.level)[self.tip]
        tree = np.concatenate(self.tree)[self.tip]
        d, u = self.tip_dir, self.tip_u
        shade = light.ratio("red", "far_red") < p.shade_threshold
        lm = np.where(shade, p.main_length + p.shade_main_extension, p.main_length)
        ll = np.where(shade, p.lateral_length - p.shade_lateral_reduction, p.lateral_length)
        ll = np.maximum(ll, 0.0)
        th = math.radians(p.branch_angle)
        div = 2 * math.pi * p.phyllotaxis
        # lateral in the plane (d, u); the main child's frame turns by the divergence
        dl = math.cos(th) * d + math.sin(th) * u
        ul = -math.sin(th) * d + math.cos(th) * u
        ul = _rotate(ul, dl, np.full(n, div))
        um = _rotate(u, d, np.full(n, div))
        dm = d.copy()
        if p.phototropism > 0:
            v = light.vector
            dm, um = _turn_towards(dm, um, v, p.phototropism)
            dl, ul = _turn_towards(dl, ul, v, p.phototropism)
        L = p.unit
        # candidate children: all main-axis children, then all laterals
        c_start = np.concatenate([ends, ends])
        c_dir = np.concatenate([dm, dl])
        c_len = np.concatenate([lm, ll]) * L
        c_u = np.concatenate([um, ul])
        c_par = np.concatenate([self.tip, self.tip])
        c_lev = np.concatenate([lev, lev + 1])
        c_tree = np.concatenate([tree, tree])
        c_kind = np.concatenate([np.zeros(n, np.int64), np.ones(n, np.int64)])
        ok = c_len > 1e-9
        if self.env is not None and self.p.obstacle_collision:
            ok &= ~self.env.blocked(c_start, c_dir, c_len)
        # a tip none of whose children can grow keeps its leaf sphere and tries again
        grown = ok[:n] | ok[n:]
        k = int(ok.sum())
        self.start.append(c_start[ok])
        self.end.append(c_start[ok] + c_dir[ok] * c_len[ok, None])
        self.parent.append(c_par[ok])
        self.level.append(c_lev[ok])
        self.tree.append(c_tree[ok])
        self.gen.append(np.full(k, gen))
        self.kind.append(c_kind[ok])
        self.alive = np.concatenate([self.alive, np.ones(k, bool)])
        self.children_alive = np.concatenate([self.children_alive, np.zeros(k, np.int64)])
        np.add.at(self.children_alive, c_par[ok], 1)
        new = self.nseg + np.arange(k)
        self.nseg += k
        self.tip = np.concatenate([new, self.tip[~grown]])
        self.tip_dir = np.concatenate([c_dir[ok], d[~grown]])
        self.tip_u = np.concatenate([c_u[ok], u[~grown]])
        self.blocked += int((~ok & (c_len > 1e-9)).sum())


def _auto_engine(engine: str) -> str:
    if engine != "auto":
        return engine
    # measured (benchmarks/trees_growth.py): the Dr.Jit grid walk counts the same spheres as
    # the all-pairs test (bit-identical counts) 2-3x faster than re-casting through Mitsuba's
    # ellipsoid BVH, and the all-pairs test only wins below ~300 spheres, where both take ms
    return "grid"


def _light(forest, p, sky, env, alphas, engine):
    pos = forest.tip_positions()
    return leaf_sphere_light(pos, p.leaf_radius * p.unit, sky, alphas, env,
                             _auto_engine(engine), p.ray_cutoff)


def grow_forest(positions, params: GrowthParams | None = None, generations: int = 10,
                scene=None, seed: int = 0, progress: bool = False, engine: str | None = None,
                history: list | None = None) -> list[Tree]:
    """Grow trees at ``positions`` together, so that they shade each other (paper 001 §3.3).

    Each of the ``generations`` generations: light at all tip spheres, death of tips below
    ``death_threshold`` (and of parents whose children all died), branching of the survivors;
    after the last generation one more light pass culls the new tips (see the module docstring).

    Parameters
    ----------
    positions : array_like
        (n, 3) [m] tree bases, or (n, 2) (x, z) pairs placed on the scene's terrain (``y`` from
        the obstacles below, else the ground at y = 0); see :func:`base_positions`.
    params : GrowthParams or dict, optional
        Model parameters (a dict is read with :meth:`GrowthParams.from_dict`); default None:
        paper 001 table 3.1.
    generations : int, optional
        Number of branching generations G (default 10); >= 0.
    scene : None, Environment, mi.Scene, trimesh.Trimesh or list, optional
        None (open sky all round, the paper's ideal environment), an
        :class:`~mitsuba_veg.trees.environment.Environment`, a Mitsuba scene (its meshes are
        obstacles), a trimesh or (vertices, faces) pairs.
    seed : int, optional
        Random seed (initial phyllotaxis phase, leaf blades); default 0.
    progress : bool, optional
        Show a tqdm progress bar over generations (default False).
    engine : str, optional
        Sphere-counting engine, "grid" | "mitsuba" | "analytic" | "auto"; default None:
        ``params.engine``.
    history : list, optional
        If given, one dict per generation is appended to it (``generation``, ``tips``,
        ``died``, ``blocked``, ``rays``, ``casts``, ``engine``, ``light_s`` [s], ``seconds`` [s]);
        the same list is stored in every tree's ``attrs["history"]``.

    Returns
    -------
    list of Tree
        One :class:`~mitsuba_veg.trees.structure.Tree` per position (in metres, +y up; dead
        branches kept with ``alive = False``), with the per-leaf-sphere light in ``tree.attrs``
        (``leaf_sphere_center`` [m], ``leaf_sphere_radius`` [m], ``light`` [-],
        ``red_far_red`` [-], ``light_vector``, ``generation``, ``lateral``, ``params``,
        ``history``, ``seed``).

    Raises
    ------
    ParameterError
        If ``generations`` is not an integer >= 0, a parameter is out of range or the positions
        are not valid points.
    """
    p = GrowthParams() if params is None else params
    if not isinstance(p, GrowthParams):
        p = GrowthParams.from_dict(dict(p), prefix="params.")
    p.validate()
    if isinstance(generations, bool) or int(generations) != generations or generations < 0:
        raise ParameterError("generations", generations, "an integer >= 0", "e.g. 10 (G)")
    generations = int(generations)
    engine = engine or p.engine
    env = Environment.coerce(scene)
    pos = base_positions(positions, env)
    sky = Sky(p.sky_h, p.sky_v, p.light_ratio)
    alphas = {"light": p.alpha, "red": p.alpha_red, "far_red": p.alpha_far_red}
    if env is not None:
        env.reflected_light(sky)           # once, before growth (the paper's generation 0)
    forest = _Forest(p, pos, seed, env)
    hist = [] if history is None else history
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=generations + 1, desc=f"growing {len(pos)} tree(s)", unit="gen")
    light = None
    for g in range(generations + 1):
        t0 = time.perf_counter()
        light = _light(forest, p, sky, env, alphas, engine)
        dead = light.received["light"] < p.death_threshold
        n_tips = len(forest.tip)
        forest.kill(forest.tip[dead])
        keep = ~dead
        forest.tip = forest.tip[keep]
        forest.tip_dir = forest.tip_dir[keep]
        forest.tip_u = forest.tip_u[keep]
        light = _subset_light(light, keep)
        if g < generations:
            forest.branch(light, g + 1)
        hist.append({"generation": g, "tips": int(n_tips), "died": int(dead.sum()),
                     "blocked": forest.blocked,
                     "rays": light.rays, "casts": light.casts, "engine": light.stats.get("engine"),
                     "light_s": light.seconds, "seconds": time.perf_counter() - t0})
        if bar is not None:
            bar.update(1)
            bar.set_postfix(tips=n_tips)
    if bar is not None:
        bar.close()
    return _to_trees(forest, light, p, seed, hist)


def base_positions(positions, env) -> np.ndarray:
    """Tree bases from (x, y, z) and/or (x, z) items (these stand on the terrain).

    Parameters
    ----------
    positions : sequence
        One position or a list of them [m].
    env : Environment
        The obstacles; (x, z) items are dropped onto them.

    Returns
    -------
    numpy.ndarray
        (n, 3) bases [m].
    """
    items = positions
    if isinstance(items, np.ndarray):
        items = items.tolist()
    if len(items) and isinstance(items[0], (int, float, np.floating)) or \
            (len(items) and items[0] is None):
        items = [items]
    rows, need = [], []
    try:
        for i, it in enumerate(items):
            it = list(it)
            if len(it) == 2:
                it = [it[0], None, it[1]]
            if len(it) != 3:
                raise ValueError
            if it[1] is None:
                need.append(i)
                it[1] = 0.0
            rows.append([float(v) for v in it])
    except (TypeError, ValueError):
        raise ParameterError("positions", positions, "a list of (x, y, z) or (x, z) points "
                             "[m]", "e.g. [[0, 0, 0], [5, 0]]") from None
    pos = np.array(rows, float).reshape(-1, 3)
    if len(pos) == 0 or not np.all(np.isfinite(pos)):
        raise ParameterError("positions", positions, "one or more finite points [m]")
    if need and env is not None:
        pos[need, 1] = env.height_at(pos[need, 0], pos[need, 2])
    return pos


def _subset_light(light, keep):
    return LeafLight({b: v[keep] for b, v in light.received.items()}, light.vector[keep],
                     light.rays, light.casts, light.seconds, light.spheres_passed, light.stats)


def grow(params: GrowthParams | None = None, generations: int = 10, position=(0.0, 0.0, 0.0),
         scene=None, seed: int = 0, progress: bool = False, engine: str | None = None) -> Tree:
    """Grow one tree at ``position`` [m] (see :func:`grow_forest`).

    Parameters
    ----------
    params : GrowthParams or dict, optional
        Model parameters; default None: paper 001 table 3.1.
    generations : int, optional
        Number of branching generations G (default 10).
    position : array_like, optional
        Tree base (x, y, z) [m], or (x, z) placed on the terrain; default the origin.
    scene : None, Environment, mi.Scene, trimesh.Trimesh or list, optional
        Obstacles around the tree (default None: open sky, the paper's ideal environment).
    seed : int, optional
        Random seed (default 0).
    progress : bool, optional
        Show a progress bar (default False).
    engine : str, optional
        Sphere-counting engine (default None: ``params.engine``).

    Returns
    -------
    Tree
        The grown tree, in metres (see :func:`grow_forest`).
    """
    return grow_forest([position], params, generations, scene, seed, progress, engine)[0]


class TipLight:
    """The light of a tree's leaf spheres from elsewhere (the world's daily photon passes):
    what :meth:`_Forest.branch` reads, as :class:`~mitsuba_veg.trees.leaflight.LeafLight` gives
    it from the model's own sky.

    Parameters
    ----------
    received : array_like
        (N,) received light relative to the open [-] (eq 2.3's quantity).
    red_far_red : array_like
        (N,) red : far-red ratio relative to the open [-] (eq 2.5's quantity).
    vector : array_like
        (N, 3) unit light vectors (eq 2.4's quantity).
    """

    def __init__(self, received, red_far_red, vector):
        self.received = {"light": np.asarray(received, float)}
        self._rfr = np.asarray(red_far_red, float)
        self.vector = _norm(np.asarray(vector, float).reshape(-1, 3))

    def ratio(self, num="red", den="far_red") -> np.ndarray:
        """The red : far-red ratio per sphere (the only ratio this light knows).

        Parameters
        ----------
        num, den : str
            ``"red"`` and ``"far_red"``.

        Returns
        -------
        numpy.ndarray
            (N,) ratio [-].
        """
        if (num, den) != ("red", "far_red"):
            raise ParameterError("ratio", f"{num}/{den}", "red/far_red")
        return self._rfr

    def subset(self, keep) -> "TipLight":
        """The spheres selected by a mask.

        Parameters
        ----------
        keep : array_like
            (N,) boolean mask.

        Returns
        -------
        TipLight
            The selected spheres' light.
        """
        return TipLight(self.received["light"][keep], self._rfr[keep], self.vector[keep])


def grow_step(tree: Tree, light: TipLight, params: GrowthParams | None = None, seed: int = 0,
              scene=None) -> Tree:
    """One more generation of a tree grown by this model, with its tips' light given.

    The step of :func:`grow_forest` (§2.3) with the light of every leaf sphere from elsewhere
    (a world's daily photon passes over a year) instead of the model's own sky: tips whose
    received light is below ``death_threshold`` die (eq 2.6) and parents whose children all
    died fall (§2.3.5); the survivors branch, shade-avoiding where red : far-red is below
    ``shade_threshold`` (eq 2.5, §2.3.4) and turned towards their light vector by
    ``phototropism`` (§2.3.3). The new tips get leaf spheres; their light comes with the next
    step (``attrs["light"]`` NaN). The pipe model gives every segment its new radius.

    Parameters
    ----------
    tree : Tree
        A tree from :func:`grow` / :func:`grow_forest` or this function (its ``attrs`` hold
        the tips and their phyllotaxis frames).
    light : TipLight
        Light of each of the tree's leaf spheres (``attrs["leaf_sphere_segment"]`` order).
    params : GrowthParams, optional
        The tree's parameters (default: ``attrs["params"]``).
    seed : int
        Seed of the new leaf blades.
    scene : optional
        Obstacles for the new segments (as for :func:`grow_forest`).

    Returns
    -------
    Tree
        The tree one generation older (dead branches dropped from the leaves, kept in the
        structure with ``alive = False``).

    Raises
    ------
    ParameterError
        When ``tree`` was not grown by this model or ``light`` does not hold one value per
        leaf sphere.
    """
    if "tip_u" not in tree.attrs or "leaf_sphere_segment" not in tree.attrs:
        raise ParameterError("tree", tree.name, "a tree grown by paper 001's model (grow)",
                             "grow it with mitsuba_veg.trees.grow")
    p = GrowthParams.from_dict(tree.attrs["params"]) if params is None else params
    n_tips = len(tree.attrs["leaf_sphere_segment"])
    if len(light.received["light"]) != n_tips:
        raise ParameterError("light", f"{len(light.received['light'])} spheres",
                             f"one per leaf sphere of the tree ({n_tips})")
    env = Environment.coerce(scene)
    forest = _Forest.from_tree(tree, p, env)
    t0 = time.perf_counter()
    dead = light.received["light"] < p.death_threshold
    forest.kill(forest.tip[dead])
    keep = ~dead
    forest.tip = forest.tip[keep]
    forest.tip_dir = forest.tip_dir[keep]
    forest.tip_u = forest.tip_u[keep]
    gen = int(np.concatenate(forest.gen).max()) + 1
    forest.branch(light.subset(keep), gen)
    hist = list(tree.attrs.get("history", [])) + [{
        "generation": gen, "tips": int(n_tips), "died": int(dead.sum()),
        "blocked": forest.blocked, "light": "given", "seconds": time.perf_counter() - t0}]
    out = _to_trees(forest, None, p, int(seed), hist)[0]
    out.name = tree.name
    return out.drop_dead_leaves()


def branching(params: GrowthParams | None = None, generations: int = 10,
              position=(0.0, 0.0, 0.0), seed: int = 0) -> Tree:
    """The pure branching model (no light: no death, no phototropism, no shade avoidance).

    The paper's H = 0 shape, used as the sample tree of paper 002: ``phototropism`` is forced to
    0 and every tip branches every generation.

    Parameters
    ----------
    params : GrowthParams or dict, optional
        Model parameters (only the branching ones matter; a dict is read with
        :meth:`GrowthParams.from_dict`, as :func:`grow_forest` does); default None: paper 001
        table 3.1.
    generations : int, optional
        Number of branching generations (default 10).
    position : array_like, optional
        (3,) tree base (x, y, z) [m]; default the origin.
    seed : int, optional
        Random seed (phyllotaxis phase, leaf blades); default 0.

    Returns
    -------
    Tree
        The tree, in metres, with uniform received light (1) in ``attrs``.
    """
    p = GrowthParams() if params is None else params
    if not isinstance(p, GrowthParams):
        p = GrowthParams.from_dict(dict(p), prefix="params.")
    p.validate()
    p = p.replace(phototropism=0.0)
    forest = _Forest(p, np.asarray(position, float)[None], seed)
    for g in range(int(generations)):
        n = len(forest.tip)
        fake = LeafLight({"light": np.ones(n), "red": np.ones(n), "far_red": np.ones(n)},
                         np.tile([0.0, 1.0, 0.0], (n, 1)))
        forest.branch(fake, g + 1)
    n = len(forest.tip)
    fake = LeafLight({"light": np.ones(n), "red": np.ones(n), "far_red": np.ones(n)},
                     np.tile([0.0, 1.0, 0.0], (n, 1)))
    return _to_trees(forest, fake, p, seed, [])[0]


def _to_trees(forest, light, p, seed, hist) -> list[Tree]:
    start, end, parent, level, tree_of, gen, kind = forest.arrays()
    alive = forest.alive
    n = len(start)
    # pipe model: live tips per segment (one reverse pass: parents come first)
    tips = np.zeros(n)
    tips[forest.tip] = 1.0
    acc = tips.copy()
    for g in range(int(gen.max()), 0, -1):          # children are one generation younger
        idx = np.nonzero(gen == g)[0]
        np.add.at(acc, parent[idx], acc[idx])
    r = p.tip_radius * p.unit * np.sqrt(np.maximum(acc, 1.0))
    R = p.leaf_radius * p.unit
    trees = []
    tip_tree = tree_of[forest.tip]
    for t in range(forest.n_trees):
        idx = np.nonzero(tree_of == t)[0]
        remap = np.full(n, -1)
        remap[idx] = np.arange(len(idx))
        par = parent[idx]
        par = np.where(par >= 0, remap[np.maximum(par, 0)], -1)
        sel = tip_tree == t
        tip_seg_global = forest.tip[sel]
        centers = end[tip_seg_global]
        rng = np.random.default_rng([seed, t, 7])
        leaves = _leaf_blades(centers, remap[tip_seg_global], R, p, rng)
        tr = Tree(start[idx], end[idx], r[idx], r[idx], par, level[idx], alive[idx].copy(),
                  None, leaves, name=f"tree{t}")
        m = int(sel.sum())
        tr.attrs.update({
            "model": "growth_001",
            "leaf_sphere_center": centers,
            "leaf_sphere_radius": R,
            "leaf_sphere_segment": remap[tip_seg_global],
            # the new tips of a step whose light comes next year have none yet (NaN)
            "light": light.received["light"][sel] if light is not None else np.full(m, np.nan),
            "red_far_red": light.ratio("red", "far_red")[sel] if light is not None
            else np.full(m, np.nan),
            "light_vector": light.vector[sel] if light is not None
            else np.full((m, 3), np.nan),
            "tip_u": forest.tip_u[sel],
            "generation": gen[idx],
            "lateral": kind[idx].astype(bool),
            "params": p.to_dict(),
            "history": hist,
            "seed": seed,
        })
        trees.append(tr)
    return trees


def _leaf_blades(centers, segs, R, p, rng) -> Leaves:
    k = p.leaves_per_sphere
    m = len(centers)
    if k == 0 or m == 0:
        return Leaves.empty()
    n = m * k
    d = rng.normal(size=(n, 3))
    d = _norm(d)
    rad = R * rng.random(n) ** (1 / 3)
    pos = np.repeat(centers, k, 0) + d * rad[:, None]
    nrm = rng.normal(size=(n, 3))
    nrm[:, 1] = np.abs(nrm[:, 1]) + 1.0
    nrm = _norm(nrm)
    up = _norm(np.cross(nrm, rng.normal(size=(n, 3))))
    return Leaves(pos, nrm, np.full(n, p.leaf_size * p.unit), np.repeat(segs, k), up,
                  {"sphere": np.repeat(np.arange(m), k)})
