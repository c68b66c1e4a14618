"""The trees of a world scenario (``[[trees]]``): part of the simulated world, not decoration.

Each entry is one tree at ``position`` [m] (trunk base):

- ``model = "growth"``: grown by paper 001's model **in the scene's light**: the scene's meshes
  (terrain, buildings) and the trees built before it are obstacles of its sky light, so a tree
  beside a wall grows away from it. ``generations``, ``[trees.growth]`` (GrowthParams fields;
  ``unit`` [m] sets the size), ``seed``.
- ``model = "weber_penn"``: a Weber-Penn preset (paper 004, with knots and smooth junctions),
  ``preset``, ``seed``, ``overrides`` (Weber-Penn parameters), ``height`` [m] to scale it;
  ``adapt = true`` deforms it by paper 002's non-growth rules (branch death, heliotropism) in
  the voxel light of the scene's meshes and the other trees.
- ``model = "mesh"``: a user's own tree: ``file`` (PLY/OBJ/GLB, read by trimesh) is the wood,
  ``leaves_file`` the foliage (each triangle one leaf element); ``scale`` multiplies both.

Trees are built in the order of the entries; every tree is an obstacle for the ones after it.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..integrators.scene_index import emitter_name
from ..meshes import triangle_geometry
from ..trees import weber_penn as wp
from ..trees.environment import Environment
from ..trees.growth import GrowthParams, TipLight, base_positions, grow, grow_forest, grow_step
from ..trees.stand import GROWTH, StandSpec, layout
from ..trees.junction import tree_mesh
from ..trees.nongrowth import death_by_leaf_light, deform
from ..trees.structure import Leaves, Tree, leaf_quads, placed_tree, scaled_tree, tube_mesh
from .canopy import Canopy

__all__ = ["MODELS", "TUBE_SIDES", "TWIG_SIDES", "WorldTree", "build_trees", "AGE_SHAPE",
           "AGE_RATE", "age_curve", "ages", "age_tree", "adapts", "adapt_tree", "with_alive",
           "obstacles", "regrow", "tree_state", "tree_from_state", "world_tree",
           "STAND_WORLD_FIELDS", "build_stand", "scenario_trees", "scene_with_trees"]

#: the kinds of a ``[[trees]]`` entry
MODELS = ("growth", "weber_penn", "mesh")
#: sides of the wood tubes of growth trees and of a stand's Weber-Penn trees
TUBE_SIDES = 6
#: sides of the twigs (deepest level) of a stand's Weber-Penn trees
TWIG_SIDES = 3


@dataclass
class WorldTree:
    """One tree of the world: its name, model, wood mesh and leaf blades.

    ``leaf_vertices`` (m, k, 3): the k corners of each leaf element's blade (quads from a Tree's
    leaves, triangles from a user's mesh); ``leaf_centre`` (m, 3) [m]; ``leaf_area`` (m,) [m2].
    """

    name: str
    model: str
    position: np.ndarray
    bark: tuple                      # (vertices (n, 3), faces (f, 3))
    leaf_vertices: np.ndarray
    leaf_area: np.ndarray
    tree: Tree | None = None         # the branch structure (growth / Weber-Penn)
    info: dict = field(default_factory=dict)

    #: the crown's measures, computed once (a tree's arrays are not changed in place: ageing,
    #: growth and death make a new WorldTree); the year's end asks for them per tree several
    #: times (rows, the floor's crowns, the figure), at 22,000 leaves a tree
    _measures: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def leaf_centre(self) -> np.ndarray:
        """(m, 3) centre of each leaf element's blade [m] (mean of its corners)."""
        if "centre" not in self._measures:
            c = self.leaf_vertices.mean(axis=1)
            c.flags.writeable = False    # cached: a caller's in-place change would stick
            self._measures["centre"] = c
        return self._measures["centre"]

    def crown_centre(self) -> np.ndarray:
        """Horizontal centre (x, z) of the crown [m].

        The mean of the leaves (the trunk's base when there are none); a tree beside a wall has it
        off its trunk.

        Returns
        -------
        numpy.ndarray
            (2,) x and z [m].
        """
        if "crown_centre" not in self._measures:
            c = self.leaf_centre
            self._measures["crown_centre"] = (self.position[[0, 2]].astype(float) if len(c) == 0
                                              else c[:, [0, 2]].mean(axis=0))
        return self._measures["crown_centre"].copy()

    def crown_radius(self) -> float:
        """Horizontal radius of the crown around its centre [m].

        90th percentile of the leaves' horizontal distances from :meth:`crown_centre`.

        Returns
        -------
        float
            Radius [m] (0 without leaves).
        """
        if "crown_radius" not in self._measures:
            c = self.leaf_centre
            m = self.crown_centre()
            self._measures["crown_radius"] = 0.0 if len(c) == 0 else \
                float(np.percentile(np.hypot(c[:, 0] - m[0], c[:, 2] - m[1]), 90))
        return self._measures["crown_radius"]


def _tree_to_world(name, model, tree: Tree, position, info) -> WorldTree:
    a = tree.alive if tree.alive is not None else np.ones(len(tree), bool)
    if getattr(tree, "weber_penn", None) is not None and info.get("bark") != "tubes":
        b, _ = tree_mesh(tree, smooth=True, leaves=False, arrays=True)
        bark = (np.asarray(b.vertices, float), np.asarray(b.faces, np.int64))
    elif info.get("bark") == "tubes" and len(tree):
        # a stand's Weber-Penn tree: the twigs (its deepest level, where the leaves hang, a
        # few mm thick) as triangular prisms, the rest as tubes
        twig = tree.level == tree.level.max()
        parts = [tube_mesh(tree.start[m], tree.end[m], tree.radius_start[m], tree.radius_end[m],
                           k) for m, k in ((a & ~twig, TUBE_SIDES), (a & twig, TWIG_SIDES))]
        bark = (np.concatenate([parts[0][0], parts[1][0]]),
                np.concatenate([parts[0][1], parts[1][1] + len(parts[0][0])]))
    else:
        bark = tube_mesh(tree.start[a], tree.end[a], tree.radius_start[a], tree.radius_end[a],
                         TUBE_SIDES)
    if len(tree.leaves):
        v, _f = leaf_quads(tree.leaves)
        quads = np.asarray(v, float).reshape(-1, 4, 3)
        area = 0.6 * tree.leaves.size ** 2          # quad: length x 0.6 length
    else:
        quads, area = np.zeros((0, 4, 3)), np.zeros(0)
    return WorldTree(name, model, np.asarray(position, float), bark, quads, area, tree, info)


def _obstacles(base_scene, built: list[WorldTree]):
    """Environment of the scene's meshes plus the trees built so far (wood and leaves)."""
    env = Environment.from_mitsuba(base_scene)
    for wt in built:
        env.add(wt.bark, name=f"{wt.name}.bark")
        if len(wt.leaf_vertices):
            k = wt.leaf_vertices.shape[1]
            v = wt.leaf_vertices.reshape(-1, 3)
            base = k * np.arange(len(wt.leaf_vertices))[:, None, None]
            tri = np.array([[0, 1, 2]] if k == 3 else [[0, 1, 2], [0, 2, 3]])[None]
            f = (base + tri).reshape(-1, 3)
            env.add((v, f), name=f"{wt.name}.leaves", light_factor=0.5)
    return env


def build_trees(entries, base_scene, root: Path, source: str | None = None,
                progress: bool = False) -> list[WorldTree]:
    """Build the ``[[trees]]`` entries in order, each in the light of the scene and earlier trees.

    The entries are already checked against the scenario schema (models in the module
    docstring).

    Parameters
    ----------
    entries : list of dict
        The scenario's ``[[trees]]`` tables (None or empty: no trees).
    base_scene : mi.Scene
        The scenario's light scene (terrain, buildings): obstacles of the growth and
        non-growth models.
    root : pathlib.Path
        Folder of the scenario (``file`` / ``leaves_file`` of mesh trees are relative to it).
    source : str, optional
        Scenario file named in error messages.
    progress : bool
        Progress bar of the growth model (default False).

    Returns
    -------
    list of WorldTree
        One tree per entry, in order.

    Raises
    ------
    ParameterError
        When an entry's model, parameters or mesh file are invalid.
    """
    out: list[WorldTree] = []
    for i, cfg in enumerate(entries or []):
        name = str(cfg.get("name", f"tree{i}"))
        field_ = f"trees[{i}]"
        model = cfg.get("model", "weber_penn")
        pos = np.asarray(cfg.get("position", [0.0, 0.0, 0.0]), float)
        seed = int(cfg.get("seed", i))
        if model == "growth":
            params = GrowthParams.from_dict(dict(cfg.get("growth", {}) or {}), source,
                                            prefix=f"{field_}.growth.")
            env = _obstacles(base_scene, out)
            tree = grow(params, int(cfg.get("generations", 8)), pos, scene=env, seed=seed,
                        progress=progress)
            tree.drop_dead_leaves()
            wt = _tree_to_world(name, model, tree, pos, {"generations": int(cfg.get(
                "generations", 8)), "unit_m": params.unit})
        elif model == "weber_penn":
            try:
                tree = wp.generate(cfg.get("preset", "quaking_aspen"), seed=seed,
                                   overrides=cfg.get("overrides"))
            except ParameterError as e:
                raise ParameterError(f"{field_}.{e.field}", e.value, e.allowed, e.fix,
                                     source) from None
            h = tree.metrics()["height"]
            f = float(cfg["height"]) / h if cfg.get("height") and h > 0 else 1.0
            base = tree.start[0] if len(tree) else np.zeros(3)
            tree = scaled_tree(tree, f, pos - base)
            info = {"preset": cfg.get("preset", "quaking_aspen"), "scale": f}
            if cfg.get("age") is not None:       # it ages every 31 December (age_tree)
                info.update({"age": float(cfg["age"]),
                             "age_rate": float(cfg.get("age_rate", AGE_RATE)),
                             "height_m": float(h * f)})
            if cfg.get("adapt_yearly", False):   # paper 002's death rule every 31 December
                info["death_threshold"] = float(cfg.get("death_threshold", 0.5))
            if cfg.get("adapt", False):
                res = deform([tree], _obstacles(base_scene, out), shade_from="leaves",
                             voxel_size=float(cfg.get("voxel_size", 0.25)),
                             death_threshold=float(cfg.get("death_threshold", 0.5)))
                tree = res.trees[0]
                info["nongrowth"] = [{k: s[k] for k in ("rule", "seconds") if k in s}
                                     for s in res.stats]
            wt = _tree_to_world(name, model, tree, pos, info)
        elif model == "mesh":
            wt = _mesh_tree(name, cfg, pos, root, field_, source)
        else:  # the schema refuses other names; a direct caller gets the same message
            raise ParameterError(f"{field_}.model", model, ", ".join(MODELS), None, source)
        out.append(wt)
    return out


#: shape exponent p of the Chapman-Richards height curve H(a) = H_max (1 - exp(-k a))^p
AGE_SHAPE = 1.5
#: default rate k of the height curve [1/year]
AGE_RATE = 0.05


def age_curve(age, rate: float = AGE_RATE, shape: float = AGE_SHAPE):
    """Relative height of a tree of ``age`` years on the Chapman-Richards curve,
    (1 - exp(-k a))^p [-] (H / H_max).

    Parameters
    ----------
    age : float or array_like
        Age [years], > 0.
    rate : float
        k [1/year].
    shape : float
        p [-].

    Returns
    -------
    float or numpy.ndarray
        H(a) / H_max.
    """
    return (1.0 - np.exp(-float(rate) * np.asarray(age, float))) ** float(shape)


def ages(wt: WorldTree) -> bool:
    """Whether a tree ages every 31 December (:func:`age_tree`): a Weber-Penn tree whose
    scenario entry gives its ``age``.

    Parameters
    ----------
    wt : WorldTree
        A world tree.

    Returns
    -------
    bool
        True for an ageing Weber-Penn tree.
    """
    return wt.model == "weber_penn" and wt.info.get("age") is not None


def age_tree(wt: WorldTree, years: int = 1) -> WorldTree:
    """A Weber-Penn tree ``years`` older: scaled about its base by H(a + 1) / H(a) of
    :func:`age_curve` for each year (a Chapman-Richards curve through its height at its
    scenario age, so the height, the branch lengths and radii and the leaves grow alike: a
    uniform scaling). Year by year, so that a run, its resumed copy and the render get the
    same numbers.

    Parameters
    ----------
    wt : WorldTree
        A tree whose ``info`` holds ``age`` [years] and ``age_rate`` [1/year].
    years : int
        Years to age it.

    Returns
    -------
    WorldTree
        The older tree (``info["age"]`` + years, ``info["height_m"]``).
    """
    a, k = float(wt.info["age"]), float(wt.info["age_rate"])
    tree = wt.tree
    (bv, bf), quads, area = wt.bark, wt.leaf_vertices, wt.leaf_area
    for y in range(int(years)):
        f = float(age_curve(a + y + 1, k) / age_curve(a + y, k))
        # the meshes scale with the tree (tubes, junctions and blades are linear in the
        # positions and sizes): meshing a hectare's 300 trees again cost 10 s a year
        base = tree.start[0].copy() if len(tree) else np.zeros(3)
        tree = scaled_tree(tree, f)
        # (x - base) f + base with one new array each (in place after the subtraction: the
        # same values; three temporaries of a hectare's meshes cost seconds in page faults)
        bv = np.asarray(bv, float) - base
        bv *= f
        bv += base
        quads = quads - base
        quads *= f
        quads += base
        area = area * (f * f)
    info = dict(wt.info)
    info["age"] = a + years
    info["height_m"] = float(tree.metrics()["height"]) if tree.alive.any() else 0.0
    return WorldTree(wt.name, wt.model, np.asarray(wt.position, float), (bv, bf), quads, area,
                     tree, info)


def adapts(wt: WorldTree) -> bool:
    """Whether paper 002's death rule adapts a tree every 31 December from its leaves' light
    (:func:`adapt_tree`): a Weber-Penn tree with ``adapt_yearly`` (its ``death_threshold``).

    Parameters
    ----------
    wt : WorldTree
        A world tree.

    Returns
    -------
    bool
        True when it adapts every year.
    """
    return wt.model == "weber_penn" and wt.info.get("death_threshold") is not None \
        and wt.tree is not None


def adapt_tree(wt: WorldTree, leaf_light) -> tuple[WorldTree, dict]:
    """Paper 002's branch death (§5.1) on a tree from the light its leaves received in the
    year's daily passes (:func:`mitsuba_veg.trees.nongrowth.death_by_leaf_light`: a subtree
    whose leaves' mean light relative to the open is below ``info["death_threshold"]`` dies
    and falls with its leaves; a whole crown below it, the whole tree).

    Parameters
    ----------
    wt : WorldTree
        A tree that adapts (:func:`adapts`).
    leaf_light : array_like
        (leaves,) each leaf's year light relative to the open [-].

    Returns
    -------
    tree : WorldTree
        The tree without its dead subtrees.
    stats : dict
        ``died`` (segments), ``leaf_light_mean``, ``alive`` (whether any segment lives).
    """
    res = death_by_leaf_light(wt.tree, leaf_light, float(wt.info["death_threshold"]))
    st = res.stats[0]
    out = _tree_to_world(wt.name, wt.model, res.trees, wt.position, wt.info)
    return out, {"died": int(st["died"]), "leaf_light_mean": float(st["leaf_light_mean"]),
                 "alive": bool(res.trees.alive.any())}


def with_alive(wt: WorldTree, alive) -> WorldTree:
    """The tree with only the segments ``alive`` marks (and the leaves on them): a tree that
    lost subtrees over the years (:func:`adapt_tree`) rebuilt from its scenario and its mask.

    Parameters
    ----------
    wt : WorldTree
        The tree as the scenario builds it.
    alive : array_like
        (segments,) bool.

    Returns
    -------
    WorldTree
        The tree with those segments.

    Raises
    ------
    ValueError
        When the mask does not have one value per segment.
    """
    alive = np.asarray(alive, bool)
    if alive.shape != (len(wt.tree),):
        raise ValueError(f"alive: {alive.shape} != ({len(wt.tree)},)")
    t = wt.tree.copy()
    t.alive = t.alive & alive
    t.drop_dead_leaves()
    return _tree_to_world(wt.name, wt.model, t, wt.position, wt.info)


def obstacles(base_scene, trees=()):
    """The obstacles of growing branches: the scene's meshes and the given trees' wood and
    leaves (an :class:`~mitsuba_veg.trees.environment.Environment`).

    Parameters
    ----------
    base_scene : mi.Scene
        The scenario's light scene (terrain, buildings, floor objects).
    trees : sequence of WorldTree
        Trees to add.

    Returns
    -------
    Environment
        The obstacles.
    """
    return _obstacles(base_scene, list(trees))


def regrow(wt: WorldTree, light: TipLight, env, seed: int) -> WorldTree:
    """A growth tree one generation older, grown from the light given per leaf sphere.

    Paper 001's step (:func:`mitsuba_veg.trees.growth.grow_step`: death below the threshold,
    shade avoidance, phototropism) with ``env`` as the obstacles of the new segments; the wood
    and the leaf blades are rebuilt.

    Parameters
    ----------
    wt : WorldTree
        A tree of ``model = "growth"``.
    light : TipLight
        The light of each of its leaf spheres (the world's daily passes over a year).
    env : Environment
        Obstacles of its new segments (:func:`obstacles`).
    seed : int
        Seed of the new leaf blades.

    Returns
    -------
    WorldTree
        The new tree (``info["generations"]`` one more).

    Raises
    ------
    ParameterError
        When ``wt`` is not a growth tree.
    """
    if wt.model != "growth" or wt.tree is None:
        raise ParameterError("tree", wt.name, "a tree of model 'growth'")
    tree = grow_step(wt.tree, light, seed=seed, scene=env)
    info = dict(wt.info)
    info["generations"] = int(info.get("generations", 0)) + 1
    return _tree_to_world(wt.name, wt.model, tree, wt.position, info)


_TREE_FIELDS = ("start", "end", "radius_start", "radius_end", "parent", "level", "alive", "kind")
_LEAF_FIELDS = ("position", "normal", "size", "segment", "up")
_ATTR_ARRAYS = ("leaf_sphere_center", "leaf_sphere_segment", "light", "red_far_red",
                "light_vector", "tip_u", "generation", "lateral")
_ATTR_JSON = ("params", "history", "seed", "model", "leaf_sphere_radius")


def tree_state(wt: WorldTree, prefix: str) -> dict:
    """A growth tree as plain arrays (a checkpoint's), keys ``<prefix>/...``.

    Parameters
    ----------
    wt : WorldTree
        A tree with a branch structure.
    prefix : str
        Key prefix.

    Returns
    -------
    dict
        Arrays of the structure, its leaves and its leaf spheres; JSON strings of the rest.
    """
    t = wt.tree
    d = {f"{prefix}/{f}": np.asarray(getattr(t, f)) for f in _TREE_FIELDS}
    for f in _LEAF_FIELDS:
        v = getattr(t.leaves, f)
        if v is not None:
            d[f"{prefix}/leaves/{f}"] = np.asarray(v)
    d[f"{prefix}/leaves/sphere"] = np.asarray(t.leaves.attrs.get("sphere", np.zeros(0)))
    for f in _ATTR_ARRAYS:
        d[f"{prefix}/attrs/{f}"] = np.asarray(t.attrs[f])
    meta = {f: t.attrs.get(f) for f in _ATTR_JSON}
    meta.update({"name": wt.name, "model": wt.model, "info": wt.info,
                 "position": [float(x) for x in wt.position]})
    d[f"{prefix}/meta"] = np.array(json.dumps(meta, default=float))
    return d


def tree_from_state(d: dict, prefix: str) -> WorldTree:
    """The tree written by :func:`tree_state`.

    Parameters
    ----------
    d : dict
        The arrays.
    prefix : str
        Their key prefix.

    Returns
    -------
    WorldTree
        The tree (wood and leaf blades rebuilt from the structure, as when it grew).
    """
    meta = json.loads(str(d[f"{prefix}/meta"]))
    up = d.get(f"{prefix}/leaves/up")
    leaves = Leaves(*(np.asarray(d[f"{prefix}/leaves/{f}"]) for f in _LEAF_FIELDS[:4]),
                    None if up is None else np.asarray(up),
                    {"sphere": np.asarray(d[f"{prefix}/leaves/sphere"], np.int64)})
    tree = Tree(*(np.asarray(d[f"{prefix}/{f}"]) for f in _TREE_FIELDS[:6]),
                alive=np.asarray(d[f"{prefix}/alive"]), kind=np.asarray(d[f"{prefix}/kind"]),
                leaves=leaves, name=meta["name"])
    tree.attrs.update({f: np.asarray(d[f"{prefix}/attrs/{f}"]) for f in _ATTR_ARRAYS})
    tree.attrs.update({f: meta[f] for f in _ATTR_JSON})
    return _tree_to_world(meta["name"], meta["model"], tree, np.asarray(meta["position"]),
                          meta["info"])


def world_tree(name: str, model: str, tree: Tree, position, info: dict) -> WorldTree:
    """A world tree from a branch structure (wood as tubes, one quad per leaf).

    Parameters
    ----------
    name, model : str
        The tree's name and model (``"growth"``, ``"weber_penn"``).
    tree : Tree
        Its structure (metres).
    position : array_like
        Its base [m].
    info : dict
        What the run's summary reports about it.

    Returns
    -------
    WorldTree
        The tree.
    """
    return _tree_to_world(name, model, tree, position, info)


#: stand fields that are not :class:`~mitsuba_veg.trees.stand.StandSpec` fields
STAND_WORLD_FIELDS = ("generations", "growth", "age", "age_rate", "adapt_yearly",
                      "death_threshold")


def build_stand(cfg: dict, base_scene, built: list, source: str | None = None,
                progress: bool = False) -> list[WorldTree]:
    """The scenario's ``[stand]``: trees laid out over the terrain
    (:func:`mitsuba_veg.trees.stand.layout`: density, species mix, Poisson-disc or clumped
    placement, size spread, seed), each based on the terrain below it.

    - Weber-Penn members (a preset in the mix): ``variants`` trees per preset are generated
      (paper 004; seeds from the stand's seed) and every member is its variant turned by its
      yaw and scaled to its height (:func:`~mitsuba_veg.trees.structure.placed_tree`). Their
      wood is drawn as tubes of :data:`TUBE_SIDES` sides along the segments (not the
      smooth junction mesh of a ``[[trees]]`` entry: a tenth of the triangles, docs/forest.md).
      With ``age`` [years] they age every 31 December along :func:`age_curve` (``age_rate``).
    - Growth members (``"growth"``): grown **together** by paper 001's model
      (:func:`mitsuba_veg.trees.growth.grow_forest`, §3.3: they shade each other as they grow)
      in the light of the scene, the trees built before and the stand's Weber-Penn members.

    Parameters
    ----------
    cfg : dict
        The ``[stand]`` table (StandSpec fields, ``generations``, ``growth``, ``age``,
        ``age_rate``).
    base_scene : mi.Scene
        The scenario's light scene (terrain, buildings, floor objects).
    built : list of WorldTree
        The ``[[trees]]`` built before (obstacles).
    source : str, optional
        Scenario file named in error messages.
    progress : bool
        Progress bar of the growth model.

    Returns
    -------
    list of WorldTree
        ``stand_000``, ``stand_001``, ... in the layout's order (growth members grow every
        year in a run; Weber-Penn members with an ``age`` age).

    Raises
    ------
    ParameterError
        For a bad stand field.
    """
    spec_d = {k: v for k, v in cfg.items() if k not in STAND_WORLD_FIELDS}
    spec = StandSpec.from_dict(spec_d, source)
    stand = layout(spec)
    env = _obstacles(base_scene, built)
    species = np.asarray(stand.species, str)
    out: dict[int, WorldTree] = {}
    wp_idx = np.flatnonzero(species != GROWTH)
    if len(wp_idx):
        base = base_positions(stand.positions[wp_idx][:, [0, 2]], env)
        variants = {}
        for sp, v in stand.variant_keys():
            t = wp.generate(sp, seed=stand.variant_seed(sp, v))
            variants[sp, v] = (t, float(t.metrics()["height"]))
        age = cfg.get("age")
        for j, i in enumerate(wp_idx):
            sp, v = str(species[i]), int(stand.variants[i])
            t, h0 = variants[sp, v]
            f = float(stand.heights[i]) / h0 if h0 > 0 else 1.0
            tree = placed_tree(t, f, float(stand.yaw[i]), base[j])
            info = {"preset": sp, "variant": v, "scale": f, "stand": True, "bark": "tubes",
                    "height_m": float(h0 * f)}
            if age is not None:
                info.update({"age": float(age), "age_rate": float(cfg.get("age_rate",
                                                                          AGE_RATE))})
            if cfg.get("adapt_yearly", False):
                info["death_threshold"] = float(cfg.get("death_threshold", 0.5))
            out[int(i)] = _tree_to_world(f"stand_{i:03d}", "weber_penn", tree, base[j], info)
    g_idx = np.flatnonzero(species == GROWTH)
    if len(g_idx):
        params = GrowthParams.from_dict(dict(cfg.get("growth", {}) or {}), source,
                                        prefix="stand.growth.")
        gens = int(cfg.get("generations", 6))
        if out:      # the stand's Weber-Penn members shade the growing ones
            env = _obstacles(base_scene, list(built) + [out[i] for i in sorted(out)])
        grown = grow_forest(stand.positions[g_idx][:, [0, 2]], params, gens, scene=env,
                            seed=spec.seed, progress=progress)
        for i, t in zip(g_idx, grown):
            t.drop_dead_leaves()
            out[int(i)] = _tree_to_world(f"stand_{i:03d}", "growth", t, t.start[0],
                                         {"generations": gens, "unit_m": params.unit,
                                          "stand": True})
    return [out[i] for i in sorted(out)]


def scenario_trees(scenario, base_scene, progress: bool = False) -> list[WorldTree]:
    """Every tree of a world scenario as a run builds it: the ``[[trees]]`` entries in order,
    then the ``[stand]``.

    Parameters
    ----------
    scenario : Scenario
        The loaded scenario.
    base_scene : mi.Scene
        Its light scene (obstacles).
    progress : bool
        Progress bars of the growth models.

    Returns
    -------
    list of WorldTree
        The trees (empty without either).
    """
    src = str(scenario.path)
    trees = build_trees(scenario.get("trees"), base_scene, scenario.root, src, progress)
    if scenario.get("stand"):
        trees += build_stand(scenario.get("stand"), base_scene, trees, src, progress)
    return trees


def _load_mesh(path: Path, field_: str, source):
    if not path.is_file():
        raise ParameterError(field_, str(path), "an existing PLY/OBJ/GLB file (relative to the "
                             "scenario)", "check the path", source)
    import trimesh              # here: importing it costs every command most of a second

    try:
        m = trimesh.load(path, force="mesh")
    except Exception as e:  # trimesh raises many types for unreadable files
        raise ParameterError(field_, str(path), "a mesh trimesh can read (PLY, OBJ, GLB)",
                             f"{type(e).__name__}: {e}", source) from None
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def _mesh_tree(name, cfg, pos, root: Path, field_, source) -> WorldTree:
    s = float(cfg.get("scale", 1.0))
    v, f = _load_mesh(root / str(cfg["file"]), f"{field_}.file", source)
    bark = (v * s + pos, f)
    if cfg.get("leaves_file"):
        lv, lf = _load_mesh(root / str(cfg["leaves_file"]), f"{field_}.leaves_file", source)
        tri = lv[lf] * s + pos                                  # (m, 3, 3)
        area = triangle_geometry(tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3))[0]
    else:
        tri, area = np.zeros((0, 3, 3)), np.zeros(0)
    return WorldTree(name, "mesh", pos, bark, tri, area, None, {"file": str(cfg["file"])})


def scene_with_trees(scenario, scene, bins: int = 4):
    """``scene`` plus the scenario's ``[[trees]]`` in full green leaf (light studies of a world).

    Parameters
    ----------
    scenario : Scenario
        The loaded scenario (its ``[[trees]]``, folder and path).
    scene : mi.Scene
        The scenario's scene, with its emitters.
    bins : int
        Autumn-stage bins of the :class:`Canopy` (default 4; all leaves use the first, green).

    Returns
    -------
    scene : mi.Scene
        A new scene with the shapes and emitters of ``scene`` and the trees' meshes.
    tree_ids : list of str
        Shape ids of the trees (``trees_bark``, ``trees_leaves``).
    """

    trees = scenario_trees(scenario, scene)
    shapes = Canopy(trees, bins).shapes(full_leaf=True)
    d = {"type": "scene"}
    for sh in scene.shapes():
        d[sh.id()] = sh
    for i, em in enumerate(scene.emitters()):
        d[emitter_name(em, i)] = em
    d.update(shapes)
    return mi.load_dict(d, optimize=False), list(shapes)
