"""The trees of a world run as the render draws them: rebuilt from the run's scenario (same
seeds) and put, frame by frame, in the leaf state the daily loop saved that day."""
from __future__ import annotations

import logging

import numpy as np

from ..world.tree_record import read_initial_trees
from ..world.trees import age_tree, ages, tree_from_state, with_alive
from ..world.trees import scenario_trees as world_scenario_trees
from .leaves import leaf_shape_of
from .litter import LIFE_DAYS, LitterLeaves
from .seasons import TreeSeasons
from .trees import scenario_trees

__all__ = ["WorldLeaves", "grown_trees", "initial_trees", "world_trees", "tree_version",
           "trees_for_run"]


class WorldLeaves:
    """The leaf state of a world run's trees on a frame's date (from the run's snapshots):
    ``apply(date)`` writes ``autumn_tau``, ``leaf_scale``, ``fallen`` and ``litter_age`` into the
    trees' leaves, as the daily loop had them that day, and the litter of the trees' earlier
    version (``attrs["litter_extra"]``).

    Parameters
    ----------
    run : Run
        The run.
    trees : list of Tree
        Its trees (as :func:`world_trees` built them for the frames' days).
    offsets : list of (int, int)
        Each tree's leaves in the run's leaf arrays.
    first_day : int, optional
        The first day (1-based) of this version of the trees (:func:`grown_trees`); 1 (the
        default): the trees the run started with.
    """

    def __init__(self, run, trees, offsets, first_day: int = 1):
        self.run, self.trees, self.offsets = run, trees, offsets
        self.first_day = int(first_day)
        self._previous = None

    def apply(self, date) -> None:
        """Write the leaf state of the run's snapshot for ``date`` into the trees' leaves.

        Sets ``autumn_tau`` [-], ``leaf_scale`` [-], ``fallen`` (bool) and ``litter_age`` (days
        from the leaf's last fall to ``date`` [days], NaN without one) in ``leaves.attrs`` from
        the latest snapshot on or before that day; without one (or with too few leaves in it) the
        leaves are green, full-size and on the tree, with no litter. When this version of the
        trees began (a year's end regrew them) less than a litter lifetime before ``date``,
        each tree also gets the litter of its earlier version (:meth:`previous_litter`).

        Parameters
        ----------
        date : datetime.date
            The frame's date (day ``(date - run.start).days + 1`` of the run).
        """
        day = (date - self.run.start).days + 1
        st = self.run.leaf_state(day)
        today = date.toordinal()
        for t, (a, b) in zip(self.trees, self.offsets):
            lv = t.leaves
            if st is None or len(st["leaf_tau"]) < b:
                lv.attrs["autumn_tau"] = np.zeros(len(lv))
                lv.attrs["leaf_scale"] = np.ones(len(lv))
                lv.attrs["fallen"] = np.zeros(len(lv), bool)
                lv.attrs["litter_age"] = np.full(len(lv), np.nan)
                continue
            lv.attrs["autumn_tau"] = st["leaf_tau"][a:b].astype(float)
            lv.attrs["leaf_scale"] = st["leaf_grown"][a:b].astype(float)
            lv.attrs["fallen"] = ~st["leaf_on"][a:b].astype(bool)
            fd = st["leaf_fall_day"][a:b]
            lv.attrs["litter_age"] = np.where(fd >= 0, today - fd, np.nan).astype(float)
        extra = self.previous_litter(date)
        for i, t in enumerate(self.trees):
            t.attrs["litter_extra"] = extra.get(i)

    def previous_litter(self, date) -> dict:
        """The litter of the trees' earlier version on ``date``.

        The trees as they stood on the day before this version began (:func:`world_trees`)
        and their leaf state of that day's snapshot (a world writes one every 31 December,
        before its trees regrow): a leaf that fell keeps its day, a leaf still on the tree
        then fell when the trees regrew (this version's first day). Runs whose snapshots have
        no fall days give none.

        Parameters
        ----------
        date : datetime.date
            The frame's date.

        Returns
        -------
        dict
            ``{tree index: LitterLeaves}`` (empty without an earlier version, when it began more
            than a litter lifetime before ``date``, or without its leaf state).
        """
        if self.first_day <= 1:
            return {}
        start = self.run.date(self.first_day)
        if (date - start).days >= LIFE_DAYS[1]:
            return {}
        if self._previous is None:
            prev_day = self.first_day - 1
            st = self.run.leaf_state(prev_day)
            if st is None or not st.get("fall_day_known", False):
                self._previous = {}
            else:
                trees, offsets = world_trees(self.run, prev_day)
                self._previous = {"trees": trees, "offsets": offsets, "state": st}
        if not self._previous:
            return {}
        st, out = self._previous["state"], {}
        today, regrew = date.toordinal(), start.toordinal()
        for i, (t, (a, b)) in enumerate(zip(self._previous["trees"], self._previous["offsets"])):
            if i >= len(self.trees) or len(st["leaf_tau"]) < b or not len(t.leaves):
                continue
            fd = np.where(st["leaf_on"][a:b].astype(bool), regrew,
                          st["leaf_fall_day"][a:b]).astype(float)
            lv = t.leaves
            age = np.where(fd >= 0, today - fd, np.nan)
            out[i] = LitterLeaves(lv.position, lv.normal, lv.up, lv.size, age,
                                  float(t.start[0][1]) if len(t) else 0.0, leaf_shape_of(t),
                                  ("previous", self.first_day, i))
        return out


def grown_trees(run) -> list:
    """The run's year-end growth steps: ``[(first day, path)]`` of its ``trees/<year>.npz``
    (written by the daily loop), by day.

    Parameters
    ----------
    run : Run
        A loaded run.

    Returns
    -------
    list of (int, pathlib.Path)
        The 1-based day from which each file's trees stand, and the file.
    """
    out = []
    for p in sorted((run.dir / "trees").glob("[0-9]*.npz")) if (run.dir / "trees").is_dir() \
            else []:
        with np.load(p) as z:
            out.append((int(z["day"]) + 1, p))
    return sorted(out)


def initial_trees(run, base_scene=None) -> list:
    """The trees a world run started with: its record (``trees/initial.npz``,
    :mod:`mitsuba_veg.world.tree_record`), else re-grown from its scenario as the run built them
    (same seeds; run folders without the record).

    Parameters
    ----------
    run : Run
        A loaded run.
    base_scene : mi.Scene, optional
        The run's light scene without daylight, to re-grow the trees in (default: loaded).

    Returns
    -------
    list of WorldTree
        The trees, before any year-end growth.
    """
    built = read_initial_trees(run.dir)
    if built is None:
        if base_scene is None:
            base_scene = run.scenario.load_scene(daylight=False)
        built = world_scenario_trees(run.scenario, base_scene)
    return built


def world_trees(run, day: int | None = None):
    """The trees of a world run (``[[trees]]`` and ``[stand]``) on a day: the trees it started
    with (:func:`initial_trees`: its record, else re-grown with the same seeds), with the trees
    that grew at a year's end as they stood that day (``trees/<year>.npz``). Trees given as
    meshes are drawn by the light scene only (not by the render).

    Parameters
    ----------
    run : Run
        A loaded run (:func:`mitsuba_veg.render.history.load_run`).
    day : int, optional
        The run's day (1-based); default: the last.

    Returns
    -------
    trees : list of Tree
        The trees the render draws.
    offsets : list of (int, int)
        Each tree's leaves in the run's leaf arrays (start, stop).
    """
    if not (run.scenario.get("trees") or run.scenario.get("stand")):
        return [], []
    # the trees the run started with, built once per loaded run (the litter of a tree's
    # earlier version asks for them again); the list is copied, its trees are replaced, not
    # changed
    built = getattr(run, "_initial_trees", None)
    if built is None:
        built = initial_trees(run)
        run._initial_trees = built
    built = list(built)
    day = run.final_day if day is None else int(day)
    versions = [p for first, p in grown_trees(run) if first <= day]
    if versions:
        with np.load(versions[-1]) as z:
            d = dict(z)
        for i in np.asarray(d["indices"], np.int64):
            built[int(i)] = tree_from_state(d, str(int(i)))
        for i in np.asarray(d.get("adapted", np.zeros(0)), np.int64):   # paper 002's deaths
            built[int(i)] = with_alive(built[int(i)], d[f"alive/{int(i)}"])
        for i, wt in enumerate(built):   # Weber-Penn trees a year older at every year's end
            if ages(wt):
                built[i] = age_tree(wt, len(versions))
    trees, offsets, n = [], [], 0
    for wt in built:
        m = len(wt.leaf_area)
        if wt.tree is not None:
            wt.tree.name = wt.name          # the world's name (summaries, glTF meshes)
            trees.append(wt.tree)
            offsets.append((n, n + m))
        else:
            logging.getLogger("mitsuba_veg").warning(
                "tree '%s' (a mesh) is in the run's light but not drawn by the render", wt.name)
        n += m
    return trees, offsets


def tree_version(run, day: int) -> int:
    """How many year-end growth steps of the run lie before ``day`` (1-based): frames with
    the same number draw the same trees.

    Parameters
    ----------
    run : Run
        A loaded run.
    day : int
        The day.

    Returns
    -------
    int
        0 before the first step.
    """
    return sum(1 for first, _ in grown_trees(run) if first <= int(day))


def trees_for_run(run, trees, day: int | None = None):
    """The trees of a render and the seasons that set their leaves frame by frame.

    Parameters
    ----------
    run : Run
        A loaded run.
    trees : list of Tree or None
        Trees to draw instead of the run's (``[]`` for none); ``None``: a world run's
        ``[[trees]]`` (in each frame's leaf state) and the scenario's ``[[render.trees]]``
        (decoration, with their calendar phenology).
    day : int, optional
        The day (1-based) whose trees a world run draws (its trees grow at each year's end;
        :func:`tree_version`); default the last.

    Returns
    -------
    trees : list of Tree
    seasons : list
        Objects with ``apply(date)`` that set the trees' leaves for a frame's date.
    """
    world, seasons = [], []
    if trees is None:
        world, offsets = world_trees(run, day)
        if world:
            d = run.final_day if day is None else int(day)
            first = max([f for f, _ in grown_trees(run) if f <= d], default=1)
            seasons.append(WorldLeaves(run, world, offsets, first))
    tl = scenario_trees(run.scenario) if trees is None else list(trees)
    if tl:
        lat = float(run.scenario.get("site.latitude"))
        cfgs = run.scenario.get("render.trees", []) or []
        if isinstance(cfgs, dict):
            cfgs = [cfgs]
        for i, t in enumerate(tl):
            auto = cfgs[i].get("autumn", True) if i < len(cfgs) else True
            if auto and trees is None and len(t.leaves):
                seasons.append(TreeSeasons(t, lat, run.start, max(run.final_day, 1) + 1, seed=i))
    return world + tl, seasons
