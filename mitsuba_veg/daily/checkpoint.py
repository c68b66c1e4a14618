"""Checkpoints of the daily loop: the whole state in one ``checkpoint.npz`` (written
atomically), resumed only by a run of the same scenario. A killed run resumes from the last
checkpoint and reproduces the uninterrupted run exactly."""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..inputs import check_resume, input_hashes
from ..outputs import atomic_write


class Checkpoints:
    """Saving and resuming the state of a :class:`~mitsuba_veg.daily.day.MossSimulation`.

    Subclass hooks: :meth:`_checkpoint_extra` (arrays beyond soil and moss) and
    :meth:`_load_extra` (restore them).
    """

    @property
    def checkpoint_path(self) -> Path:
        """The run's checkpoint file, ``<out>/checkpoint.npz``."""
        return self.out / "checkpoint.npz"

    def save_checkpoint(self):
        """Write the whole state (population, :meth:`_checkpoint_extra`, day, soil water,
        history, timings, the scenario's fingerprint) atomically to :attr:`checkpoint_path`.
        """
        d = self.pop.to_numpy()
        d.update(self._checkpoint_extra())
        d.update({"day": np.array(self.day), "O": self.O,
                  "history": np.array(json.dumps(self.history)),
                  "timings": np.array(json.dumps(self.timings)),
                  "fingerprint": np.array(self._fingerprint())})
        with atomic_write(self.checkpoint_path, self.out / "checkpoint.tmp.npz") as tmp:
            np.savez_compressed(tmp, **d)

    def _checkpoint_extra(self) -> dict:
        """Arrays of the state beyond soil and moss (a world: its leaves)."""
        return {}

    def _load_extra(self, d: dict) -> None:
        """Restore what :meth:`_checkpoint_extra` saved."""

    def _fingerprint(self) -> str:
        """What must match for a checkpoint to be resumed: the settings of the run and the
        content of every file it reads (:func:`mitsuba_veg.inputs.input_hashes`)."""
        keep = {k: v for k, v in self.scn.data.items() if k != "simulation"}
        return json.dumps({"scenario": keep, "start": self.start.isoformat(),
                           "inputs": input_hashes(self.scn)}, sort_keys=True, default=str)

    def load_checkpoint(self) -> bool:
        """Resume from :attr:`checkpoint_path` if there is one.

        Returns
        -------
        bool
            Whether a checkpoint was loaded.

        Raises
        ------
        ParameterError
            The checkpoint cannot be read, belongs to another scenario, or holds more days than
            this run has.
        """
        p = self.checkpoint_path
        if not p.exists():
            return False
        try:
            d = dict(np.load(p, allow_pickle=False))
            fingerprint, day = str(d["fingerprint"]), int(d["day"])
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
            raise ParameterError("checkpoint", str(p), "a complete checkpoint written by "
                                 "mitsuba-veg run", f"it cannot be read ({type(e).__name__}); "
                                 "run again with --fresh to start over") from None
        check_resume(fingerprint, self._fingerprint(), p)  # names the field or file that changed
        if day > self.days:
            raise ParameterError("--days", self.days, f">= {day}: the checkpoint in "
                                 f"{self.out} already holds day {day}",
                                 f"pass --days {day} or more to resume, or --fresh to start "
                                 "over with fewer days")
        self.pop.load_numpy(d)
        self._load_extra(d)
        self.grid.rebuild(self.pop.pos, self.pop.state)
        self._moss_version += 1
        self.day = int(d["day"])
        self.O = np.asarray(d["O"], np.float64)
        self.history = json.loads(str(d["history"]))
        self.timings.update(json.loads(str(d["timings"])))
        return True
