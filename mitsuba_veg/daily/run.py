"""One run of a scenario into a folder: the daily pipeline (with the world's trees when the
scenario has ``[[trees]]``), the day maps, moss snapshots, the ``[[hemiphotos]]`` series and
``summary.json``."""
from __future__ import annotations

from pathlib import Path

from ..outputs import RUN_OUTPUTS, DayFrames, OutputFolder, SnapshotWriter, write_summary
from ..scenario import Scenario, load_scenario
from .hemiphotos import FOLDER as PHOTO_FOLDER
from .hemiphotos import PhotoSeries
from .pipeline import Simulation


__all__ = ["run"]

def run(scenario, out="out/run", days: int | None = None, overrides=(), resume: bool = True,
        progress: bool = True, frames: bool = True, snapshot_every: int | None = None) -> dict:
    """Run a scenario into a folder through the daily pipeline.

    The folder is claimed for the run (:class:`~mitsuba_veg.outputs.OutputFolder`: a second
    process writing into it is refused; a folder holding another kind of result is refused).

    Parameters
    ----------
    scenario : path-like or Scenario
        A scenario TOML or a loaded scenario.
    out : path-like
        The run folder.
    days : int, optional
        Simulated days [d] (default: the scenario's ``simulation.days``).
    overrides : sequence of str
        ``KEY=VALUE`` fields (as ``--set``), for a TOML path.
    resume : bool
        Resume from the checkpoint; ``False`` (``--fresh``) discards it and every output of an
        earlier run in the folder (maps, snapshots, GIF, renders), as does a run that finds no
        checkpoint.
    progress : bool
        Show a progress bar.
    frames : bool
        Write the day maps, the GIF and the moss snapshots.
    snapshot_every : int, optional
        Days between moss snapshots for exact animations [d] (default: the scenario's
        ``simulation.frame_every``).

    Returns
    -------
    dict
        The summary, also written to ``out/summary.json``.
    """
    scn = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    sim = Simulation(scn, out, days=days, progress=progress)
    with OutputFolder(out, "run", info={"scenario": str(scn.path)}) as folder:
        if not resume or not sim.checkpoint_path.exists():
            # a run that starts at day 0 owns the folder's run outputs: maps, snapshots,
            # renders and the GIF of an earlier run would otherwise be shown as this run's
            folder.clear(RUN_OUTPUTS + (PHOTO_FOLDER,))
        frames_writer = DayFrames(sim) if frames else None
        # living moss on frame days (exact animations)
        snapshots = SnapshotWriter(snapshot_every) if frames else None
        # the scenario's [[hemiphotos]] on their days (docs/hemiphoto.md)
        photos = PhotoSeries(sim) if scn.get("hemiphotos") else None

        def on_day(s, rec):
            if frames_writer is not None:
                frames_writer(s, rec)
            if snapshots is not None:
                snapshots(s, rec)
            if photos is not None:
                photos(s, rec)

        summary = sim.run(resume=resume, on_day=on_day)
        if frames_writer is not None:
            summary["files"] = frames_writer.finish()
            summary["files"]["snapshots"] = str(Path(out) / "snapshots")
        write_summary(Path(out) / "summary.json", summary)
    return summary
