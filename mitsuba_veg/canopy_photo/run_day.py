"""A world run's day as a camera and a one-day photon pass see it: the run's trees as they
stood that day (rebuilt from the scenario with the same seeds, with the trees that grew at a
year's end from ``trees/<year>.npz``, as :func:`mitsuba_veg.render.world.world_trees` rebuilds
them for the render) and their leaves in the state of the run's snapshot of that day (or the
latest before it: ``leaf_tau``, ``leaf_grown``, ``leaf_on``)."""
from __future__ import annotations

import datetime as _dt

import numpy as np

from ..errors import ParameterError
from ..render.history import load_run
from ..render.world import grown_trees, initial_trees
from ..world.trees import age_tree, ages, tree_from_state, with_alive
from ..world.visible_canopy import LeafState, VisibleCanopy

__all__ = ["RunWorld"]


class RunWorld:
    """The days of a world run (module docstring).

    Parameters
    ----------
    run_dir : str or pathlib.Path or Run
        The run folder (or a loaded run).
    scenario : str, optional
        The run's scenario file, instead of the one its summary names.
    """

    def __init__(self, run_dir, scenario=None):
        self.run = run_dir if hasattr(run_dir, "leaf_state") else load_run(run_dir, scenario)
        scn = self.run.scenario
        self.scenario = scn
        self.base_scene = scn.load_scene(daylight=False)
        self.base_shapes = list(self.base_scene.shapes())
        self.ground_id = scn.get("terrain.ground", "ground")
        self.latitude = float(scn.get("site.latitude"))
        self.longitude = float(scn.get("site.longitude"))
        ph = dict(scn.get("phenology") or {})
        self.bins = int(ph.get("stage_bins", 4))
        self.has_trees = bool(scn.get("trees") or scn.get("stand"))
        self._built = None
        self._canopies: dict = {}

    @property
    def last_day(self) -> int:
        """The run's last simulated day (1-based)."""
        return int(self.run.final_day)

    def date(self, day: int) -> _dt.date:
        """The date of a day of the run.

        Parameters
        ----------
        day : int
            Day (1-based).

        Returns
        -------
        datetime.date
            Its date.
        """
        return self.run.date(int(day))

    def day_of(self, date: _dt.date) -> int:
        """The run's day of a date.

        Parameters
        ----------
        date : datetime.date
            A date.

        Returns
        -------
        int
            Day (1-based).
        """
        return (date - self.run.start).days + 1

    def check_day(self, day: int, field: str = "--day") -> int:
        """Refuse a day outside the run.

        Parameters
        ----------
        day : int
            Day (1-based).
        field : str
            The option named by the error.

        Returns
        -------
        int
            The day.
        """
        if not 1 <= int(day) <= self.last_day:
            raise ParameterError(field, day, f"a day of the run, 1..{self.last_day}",
                                 "pick a simulated day (or run the scenario longer)")
        return int(day)

    def canopy(self, day: int) -> VisibleCanopy:
        """The trees standing on ``day`` (cached per year-end growth step).

        Parameters
        ----------
        day : int
            Day (1-based).

        Returns
        -------
        VisibleCanopy
            Their leaves and wood.
        """
        versions = [p for first, p in grown_trees(self.run) if first <= int(day)]
        key = len(versions)
        if key not in self._canopies:
            if self._built is None:
                self._built = initial_trees(self.run, self.base_scene) \
                    if self.has_trees else []
            built = list(self._built)
            if versions:
                with np.load(versions[-1]) as z:
                    d = dict(z)
                for i in np.asarray(d["indices"], np.int64):
                    built[int(i)] = tree_from_state(d, str(int(i)))
                for i in np.asarray(d.get("adapted", np.zeros(0)), np.int64):
                    built[int(i)] = with_alive(built[int(i)], d[f"alive/{int(i)}"])
                for i, wt in enumerate(built):
                    if ages(wt):
                        built[i] = age_tree(wt, len(versions))
            self._canopies = {key: VisibleCanopy(built, self.bins)}   # one year's trees held
        return self._canopies[key]

    def leaf_state(self, day: int, canopy: VisibleCanopy) -> tuple[LeafState, int]:
        """The leaves of ``day``: the latest snapshot on or before it.

        Parameters
        ----------
        day : int
            Day (1-based).
        canopy : VisibleCanopy
            The trees of that day.

        Returns
        -------
        state : LeafState
            One entry per leaf.
        snapshot_day : int
            The snapshot's day (0 for a run without trees).
        """
        if canopy.n_leaves == 0:
            return LeafState.green(0), 0
        best = None
        for d, _ in self.run.snapshots:
            if d <= int(day):
                best = d
        st = self.run.leaf_state(int(day))
        if st is None or len(st["leaf_tau"]) != canopy.n_leaves:
            first = [d for d, _ in self.run.snapshots if d >= int(day)]
            raise ParameterError("--day", day, "a day with a leaf snapshot of its trees on or "
                                 "before it (the run's snapshots: every simulation.frame_every "
                                 "days; after a year's end, the first snapshot of the new "
                                 "trees)", f"pick day {first[0]} or later" if first else
                                 "pick a later day")
        return LeafState.from_arrays(st), int(best)
