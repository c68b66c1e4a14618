"""The trees of a world run as the render draws them: rebuilt from the run's scenario (same
seeds) and put, frame by frame, in the leaf state the daily loop saved that day."""
from __future__ import annotations

import logging

import numpy as np

from ..world import build_trees
from .seasons import TreeSeasons
from .trees import scenario_trees


class WorldLeaves:
    """The leaf state of a world run's trees on a frame's date (from the run's snapshots):
    ``apply(date)`` writes ``autumn_tau``, ``leaf_scale`` and ``fallen`` into the trees'
    leaves, as the daily loop had them that day."""

    def __init__(self, run, trees, offsets):
        self.run, self.trees, self.offsets = run, trees, offsets

    def apply(self, date) -> None:
        """Write the leaf state of the run's snapshot for ``date`` into the trees' leaves.

        Sets ``autumn_tau`` [-], ``leaf_scale`` [-] and ``fallen`` (bool) in ``leaves.attrs`` from
        the latest snapshot on or before that day; without one (or with too few leaves in it) the
        leaves are green, full-size and on the tree.

        Parameters
        ----------
        date : datetime.date
            The frame's date (day ``(date - run.start).days + 1`` of the run).
        """
        day = (date - self.run.start).days + 1
        st = self.run.leaf_state(day)
        for t, (a, b) in zip(self.trees, self.offsets):
            lv = t.leaves
            if st is None or len(st["leaf_tau"]) < b:
                lv.attrs["autumn_tau"] = np.zeros(len(lv))
                lv.attrs["leaf_scale"] = np.ones(len(lv))
                lv.attrs["fallen"] = np.zeros(len(lv), bool)
                continue
            lv.attrs["autumn_tau"] = st["leaf_tau"][a:b].astype(float)
            lv.attrs["leaf_scale"] = st["leaf_grown"][a:b].astype(float)
            lv.attrs["fallen"] = ~st["leaf_on"][a:b].astype(bool)


def world_trees(run):
    """The trees of a world run (``[[trees]]``), rebuilt from its scenario as the run built them
    (same seeds). Trees given as meshes are drawn by the light scene only (not by the render).

    Parameters
    ----------
    run : Run
        A loaded run (:func:`mitsuba_veg.render.history.load_run`).

    Returns
    -------
    trees : list of Tree
        The trees the render draws.
    offsets : list of (int, int)
        Each tree's leaves in the run's leaf arrays (start, stop).
    """
    entries = run.scenario.get("trees") or []
    if not entries:
        return [], []
    base = run.scenario.load_scene(daylight=False)
    built = build_trees(entries, base, run.scenario.root, str(run.scenario.path))
    trees, offsets, n = [], [], 0
    for wt in built:
        m = len(wt.leaf_area)
        if wt.tree is not None:
            trees.append(wt.tree)
            offsets.append((n, n + m))
        else:
            logging.getLogger("mitsuba_veg").warning(
                "tree '%s' (a mesh) is in the run's light but not drawn by the render", wt.name)
        n += m
    return trees, offsets


def trees_for_run(run, trees):
    """The trees of a render and the seasons that set their leaves frame by frame.

    Parameters
    ----------
    run : Run
        A loaded run.
    trees : list of Tree or None
        Trees to draw instead of the run's (``[]`` for none); ``None``: a world run's
        ``[[trees]]`` (in each frame's leaf state) and the scenario's ``[[render.trees]]``
        (decoration, with their calendar phenology).

    Returns
    -------
    trees : list of Tree
    seasons : list
        Objects with ``apply(date)`` that set the trees' leaves for a frame's date.
    """
    world, seasons = [], []
    if trees is None:
        world, offsets = world_trees(run)
        if world:
            seasons.append(WorldLeaves(run, world, offsets))
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
