"""A finished (or running) moss run as the renderer sees it: scenario, days, moss per day.

A run directory (``mitsuba-veg run ... --out DIR``) holds ``summary.json`` (settings, species,
one record per day), ``checkpoint.npz`` (the whole population at the last checkpoint) and, when
the run was made with snapshots (:class:`~mitsuba_veg.outputs.SnapshotWriter`),
``snapshots/day_NNNN.npz``: the living moss (positions, normals, species, growth) on the frame
days. :func:`load_run` reads them;
:meth:`Run.frame_days` picks the frame days and :meth:`Run.frame` gives the moss of one day
for the animation:

- from the snapshots when they exist (exact);
- otherwise reconstructed from the last checkpoint and the per-day counts of ``summary.json``
  (approximate, flagged ``exact=False``): on day d each species shows its ``alive(d)`` most grown
  moss of the final population, their growth scaled by d / last day. Moss that died before the
  end is missing from such frames. Runs made with snapshots do not have this limitation.
"""
from __future__ import annotations

import datetime as _dt
import json
import logging
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..daily import MOSS_DEFAULTS, SIM_DEFAULTS
from ..daily.run import run
from ..errors import ParameterError
from ..inputs import same_run_scenario
from ..outputs import SNAPSHOT_DIR
from ..scenario import Scenario, load_scenario
from .moss import MossSet, live_moss

__all__ = ["Frame", "Run", "load_run", "run_with_snapshots"]


# ---- reading a run ------------------------------------------------------------------------------
def _read_snapshot(path) -> dict:
    """The arrays of a moss snapshot; a file that cannot be read is one line naming it."""
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
        for k in ("pos", "nrm", "species", "growth"):
            d[k]
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
        raise ParameterError("RUN_DIR snapshot", str(path), "a complete moss snapshot written "
                             "by mitsuba-veg run", f"it cannot be read ({type(e).__name__}); "
                             "render another --day, or run the scenario again with --fresh "
                             "to write the snapshots again") from None
    return d


@dataclass
class Frame:
    """One day of a run as the render draws it: the day (1-based), its date, the living moss,
    and whether the moss is exact (from a snapshot) or approximated (from the last checkpoint)."""

    day: int                 # 1-based simulated day (end of that day)
    date: _dt.date
    moss: MossSet
    exact: bool = True


@dataclass
class Run:
    """A run folder as the render reads it (:func:`load_run`): its summary, scenario, species,
    moss size [m], start date, days, last checkpoint and snapshot days."""

    dir: Path
    summary: dict
    scenario: object                      # mitsuba_veg.scenario.Scenario
    species: list                         # species keys, index = population species id
    moss_size: float
    start: _dt.date
    days: int                             # days simulated so far
    checkpoint: dict | None = None
    snapshots: list = field(default_factory=list)

    def date(self, day: int) -> _dt.date:
        """Calendar date of simulated day ``day`` (1-based).

        Parameters
        ----------
        day : int
            Simulated day [days] (1 = the start date).

        Returns
        -------
        datetime.date
            ``start + (day - 1)`` days.
        """
        return self.start + _dt.timedelta(days=int(day) - 1)

    def final_moss(self) -> MossSet:
        """The living moss at the end of the run.

        From the last snapshot when it is at least as recent as the checkpoint, else from the
        checkpoint.

        Returns
        -------
        MossSet
            The living moss (positions [m], normals, species, growth G_moss [-]).

        Raises
        ------
        ParameterError
            If the run has neither a checkpoint nor snapshots.
        """
        if self.snapshots and (self.checkpoint is None or
                               int(self.checkpoint.get("day", 0)) <= self.snapshots[-1][0]):
            return self._snapshot(self.snapshots[-1][1])
        if self.checkpoint is None:
            raise ParameterError("run", str(self.dir), "a run with checkpoint.npz or snapshots/",
                                 "run `mitsuba-veg run SCENARIO --out DIR` first")
        return live_moss(self.checkpoint, self.species)

    @property
    def final_day(self) -> int:
        """The last day with moss: the checkpoint's, else the last snapshot's, else ``days``."""
        if self.checkpoint is not None:
            return int(self.checkpoint["day"])
        return self.snapshots[-1][0] if self.snapshots else self.days

    def _snapshot(self, path) -> MossSet:
        z = _read_snapshot(path)
        return MossSet(z["pos"], z["nrm"].astype(np.float64), z["species"],
                       z["growth"].astype(np.float64), list(self.species))

    def leaf_state(self, day: int) -> dict | None:
        """A world run's leaf state at the latest snapshot on or before ``day``.

        Parameters
        ----------
        day : int
            Simulated day [days] (1-based).

        Returns
        -------
        dict or None
            ``leaf_tau`` (autumn logical time [-]), ``leaf_grown`` (leaf-out size factor [-]),
            ``leaf_on`` (bool) and ``leaf_fall_day`` (date ordinal of the leaf's last fall, −1:
            none; all −1 in a snapshot written before runs kept it), one entry per leaf of its
            trees, ``fall_day_known`` (whether the snapshot has the fall days) and ``day``, the
            snapshot's day; None without such a snapshot (or when the
            snapshot has no leaf state).
        """
        best = None
        for d, p in self.snapshots:
            if d <= day:
                best = (d, p)
        if best is None:
            return None
        z = _read_snapshot(best[1])
        if "leaf_tau" not in z:
            return None
        out = {k: np.asarray(z[k]) for k in ("leaf_tau", "leaf_grown", "leaf_on")}
        out["fall_day_known"] = "leaf_fall_day" in z
        out["leaf_fall_day"] = np.asarray(z["leaf_fall_day"], np.int64) \
            if "leaf_fall_day" in z else np.full(len(out["leaf_tau"]), -1, np.int64)
        out["day"] = int(best[0])
        return out

    def frame_days(self, count: int | None = None, every: int | None = None) -> list[int]:
        """Days to animate.

        The snapshot days (or every ``every`` days), thinned to at most ``count`` frames, always
        including the last day.

        Parameters
        ----------
        count : int, optional
            Most frames (evenly spaced over the days); None: no limit.
        every : int, optional
            Keep days that are multiples of ``every`` [days] (and day 1 and the last); without
            snapshots the step of the days (default 10).

        Returns
        -------
        list of int
            The simulated days [days], ascending.
        """
        last = self.final_day
        if self.snapshots:
            days = [d for d, _ in self.snapshots]
        else:
            step = max(int(every or 10), 1)
            days = sorted(set([1] + list(range(step, last + 1, step)) + [last]))
        if every and self.snapshots:
            days = sorted(set([d for d in days if d % every == 0 or d == 1] + [days[-1]]))
        if count and len(days) > count:
            idx = np.unique(np.round(np.linspace(0, len(days) - 1, int(count))).astype(int))
            days = [days[i] for i in idx]
        return days

    def frame(self, day: int) -> Frame:
        """The moss at the end of simulated ``day``.

        Exact from a snapshot of that day or on/after the final day; otherwise reconstructed from
        the final moss (module docstring, ``exact=False``).

        Parameters
        ----------
        day : int
            Simulated day [days] (1-based).

        Returns
        -------
        Frame
            Day, date, moss and whether it is exact.
        """
        snap = dict(self.snapshots)
        if day in snap:
            return Frame(day, self.date(day), self._snapshot(snap[day]), True)
        final = self.final_moss()
        last = self.final_day
        if day >= last:
            return Frame(day, self.date(day), final, True)
        rec = {r["day"]: r for r in self.summary.get("days_record", [])}.get(int(day))
        names = list(self.summary.get("species", []))
        keep = np.zeros(len(final), bool)
        for si in range(len(self.species)):
            idx = np.nonzero(final.species == si)[0]
            if rec is not None and si < len(names):
                n = int(rec.get("alive", {}).get(names[si], 0))
            else:
                n = int(round(len(idx) * day / max(last, 1)))
            order = idx[np.argsort(-final.growth[idx], kind="stable")]
            keep[order[:min(n, len(order))]] = True
        m = final.subset(keep)
        m.growth = m.growth * (day / max(last, 1))
        return Frame(day, self.date(day), m, False)


def _resolve_scenario(summary: dict, checkpoint, run_dir: Path):
    raw = summary.get("scenario")
    cands, shipped = [], []
    if raw:
        p = Path(raw)
        cands += [p] if p.is_absolute() else [Path.cwd() / p, run_dir / p, run_dir.parent / p]
        here = Path(__file__).resolve().parents[1]
        for base in (here.parent / "scenes", here / "scenes"):
            shipped.append(base / p.parent.name / p.name)
    path = next((c for c in cands if c.exists()), None)
    if path is None:
        path = next((c for c in shipped if c.exists()), None)
        if path is not None:
            logging.getLogger("mitsuba_veg").warning(
                "the run's scenario %s is gone; using the shipped %s instead (pass --scenario "
                "to choose)", raw, path)
    if path is None:
        raise ParameterError("summary.json scenario", raw, "an existing scenario file",
                             "run the command from the folder the run was started in, or pass "
                             "the scenario explicitly (--scenario TOML, or scenario=...)")
    if checkpoint is not None and "fingerprint" in checkpoint:
        try:
            fp = json.loads(str(checkpoint["fingerprint"]))
            data = dict(fp["scenario"])
            data["simulation"] = load_scenario(path).data.get("simulation", {})
            return Scenario(path.resolve(), data)
        except (ValueError, KeyError, TypeError):
            pass
    return load_scenario(path)


def load_run(run_dir, scenario=None) -> Run:
    """Read a run directory (see module docstring).

    Parameters
    ----------
    run_dir : str or pathlib.Path
        The run folder (``summary.json``, ``checkpoint.npz``, optional ``snapshots/``).
    scenario : str, pathlib.Path or Scenario, optional
        A scenario path or :class:`~mitsuba_veg.scenario.Scenario` to use instead of the one the
        run names.

    Returns
    -------
    Run
        The run: scenario, species keys, moss size [m], start date, days simulated, checkpoint
        arrays and snapshot files.

    Raises
    ------
    ParameterError
        If the folder is not a run, its checkpoint or summary cannot be read, its scenario
        cannot be found, or ``scenario`` is not the run's (its settings or input files differ
        from the run's checkpoint).
    """
    d = Path(run_dir)
    sp = d / "summary.json"
    cp = d / "checkpoint.npz"
    if not d.is_dir() or not (sp.exists() or cp.exists()):
        raise ParameterError("RUN_DIR", str(d), "a moss run folder with summary.json and "
                             "checkpoint.npz", "run `mitsuba-veg run SCENARIO --out DIR` first")
    try:
        ck = dict(np.load(cp, allow_pickle=False)) if cp.exists() else None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise ParameterError("RUN_DIR checkpoint.npz", str(cp), "a complete checkpoint",
                             f"it cannot be read ({type(e).__name__}); resume the run with "
                             "`mitsuba-veg run SCENARIO --out RUN_DIR --fresh`") from None
    try:
        summary = json.loads(sp.read_text()) if sp.exists() else {}
    except (ValueError, OSError) as e:
        raise ParameterError("RUN_DIR summary.json", str(sp), "a complete JSON file",
                             f"it cannot be read ({type(e).__name__}); run `mitsuba-veg run "
                             "SCENARIO --out RUN_DIR` again to rewrite it (it resumes from the "
                             "checkpoint)") from None
    if not isinstance(summary, dict):
        raise ParameterError("RUN_DIR summary.json", str(sp), "a run summary (a JSON object)",
                             "point RUN_DIR at a folder written by `mitsuba-veg run`")
    if not summary and ck is not None and "history" in ck:
        summary = {"days_record": json.loads(str(ck["history"]))}
    if scenario is None:
        if not summary.get("scenario"):
            raise ParameterError("RUN_DIR", str(d), "a run with summary.json",
                                 "wait for the run to write summary.json or pass --scenario")
        scn = _resolve_scenario(summary, ck, d)
    else:
        scn = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        diff = same_run_scenario(str(ck["fingerprint"]), scn) \
            if ck is not None and "fingerprint" in ck else None
        if diff is not None:   # another scenario would draw another scene over this run
            raise ParameterError("--scenario", str(scn.path), f"the scenario of the run in {d} "
                                 f"(this one differs: {diff})", "pass the run's own scenario "
                                 "(or a copy of it), or leave --scenario out", None)
    moss_cfg = {**MOSS_DEFAULTS, **(scn.get("moss", {}) or {}),
                **(summary.get("settings", {}).get("moss", {}) or {})}
    sim = {**SIM_DEFAULTS, **(scn.get("simulation", {}) or {})}
    start = summary.get("settings", {}).get("simulation", {}).get("start_date") or \
        sim["start_date"]
    start = _dt.date.fromisoformat(str(start))
    recs = summary.get("days_record", [])
    days = int(recs[-1]["day"]) if recs else int(ck["day"]) if ck is not None else 0
    snaps = []
    sd = d / SNAPSHOT_DIR
    if sd.is_dir():
        for p in sorted(sd.glob("day_*.npz")):
            try:
                snaps.append((int(p.stem.split("_")[1]), p))
            except ValueError:
                continue
    return Run(d, summary, scn, list(moss_cfg["species"]), float(moss_cfg["size"]), start, days,
               ck, snaps)


def run_with_snapshots(scenario, out, days: int | None = None, overrides=(),
                       resume: bool = True, progress: bool = True, every: int | None = None):
    """:func:`mitsuba_veg.daily.run.run` with moss snapshots every ``every`` days.

    Snapshots give exact animations.

    Parameters
    ----------
    scenario : str, pathlib.Path or Scenario
        The scenario to run.
    out : str or pathlib.Path
        The run folder.
    days : int, optional
        Simulated days [days] (default: the scenario's ``simulation.days``).
    overrides : sequence of str, optional
        ``KEY=VALUE`` fields (as ``--set``), for a TOML path.
    resume : bool, optional
        Resume from the folder's checkpoint (default True); False discards it and the earlier
        outputs in the folder.
    progress : bool, optional
        Show a progress bar (default True).
    every : int, optional
        Days between snapshots [days] (default: the scenario's ``simulation.frame_every``).

    Returns
    -------
    dict
        The run's summary dict.
    """
    return run(scenario, out, days=days, overrides=overrides, resume=resume,
               progress=progress, snapshot_every=every)
