"""One run of a scenario into a folder: the moss loop, or the world's loop when the scenario
has ``[[trees]]``, with the day maps, moss snapshots and ``summary.json``."""
from __future__ import annotations

from pathlib import Path

from ..outputs import RUN_OUTPUTS, DayFrames, OutputFolder, SnapshotWriter, write_summary
from ..scenario import Scenario, load_scenario
from ..world import WorldSimulation
from .day import MossSimulation


def run(scenario, out="out/run", days: int | None = None, overrides=(), resume: bool = True,
        progress: bool = True, frames: bool = True, snapshot_every: int | None = None) -> dict:
    """Run a moss scenario (TOML path or Scenario) into ``out``; returns the summary dict
    (also written to ``out/summary.json``).

    The folder is claimed for the run (:class:`~mitsuba_veg.outputs.OutputFolder`: a second
    process writing into it is refused; a folder holding another kind of result is refused).
    ``resume=False`` (``--fresh``) discards the checkpoint and every output of an earlier run
    in the folder (maps, snapshots, GIF, renders); so does a run that finds no checkpoint.
    ``snapshot_every``: days between moss snapshots for exact animations (default: the
    scenario's ``simulation.frame_every``)."""
    scn = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    if scn.get("trees"):
        sim = WorldSimulation(scn, out, days=days, progress=progress)
    else:
        sim = MossSimulation(scn, out, days=days, progress=progress)
    with OutputFolder(out, "run", info={"scenario": str(scn.path)}) as folder:
        if not resume:
            folder.clear(RUN_OUTPUTS)
        frames_writer = DayFrames(sim) if frames else None
        # living moss on frame days (exact animations)
        snapshots = SnapshotWriter(snapshot_every) if frames else None

        def on_day(s, rec):
            if frames_writer is not None:
                frames_writer(s, rec)
            if snapshots is not None:
                snapshots(s, rec)

        summary = sim.run(resume=resume, on_day=on_day)
        if frames_writer is not None:
            summary["files"] = frames_writer.finish()
            summary["files"]["snapshots"] = str(Path(out) / "snapshots")
        write_summary(Path(out) / "summary.json", summary)
    return summary
