"""Run outputs: per-day maps (PNG), the animation of the days (GIF), summary.json.

Maps show the ground (the scenario's ``terrain.ground``) from above, one colour per triangle;
the coverage map also draws the other living surfaces' moss as points.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import numpy as np

from .atomic import atomic_write
from .errors import ParameterError
from .plots import _mpl, plan_map


def write_json(path, data, indent: int = 2) -> None:
    """Write ``data`` as JSON atomically (NumPy values converted).

    Parameters
    ----------
    path : path-like
        The JSON file (its temporary file is ``<name>.tmp``).
    data : object
        JSON-able data; NumPy scalars and arrays are converted (:func:`jsonable`).
    indent : int
        Indentation [spaces].
    """
    path = Path(path)
    with atomic_write(path, path.with_suffix(path.suffix + ".tmp")) as tmp:
        tmp.write_text(json.dumps(data, indent=indent, default=jsonable))


# --------------------------------------------------------------------------------------------
# Output folders: one kind of result per folder, one writer at a time
# --------------------------------------------------------------------------------------------
MARKER = ".mitsuba-veg.json"
LOCK = ".mitsuba-veg.lock"
#: what each command leaves in its folder (used to recognise folders written before markers)
_KIND_FILES = {"run": ("checkpoint.npz",), "irradiance": ("irradiance.npz",),
               "render": ("render.json",), "animate": ("animate.json",),
               "light-study": ("light_study.npz",), "grow": ("metrics.json",),
               "tune": ("fitted.json",), "sweep": ("sweep.json",)}
#: files and folders of a moss run that belong to one run (cleared when a run starts afresh)
RUN_OUTPUTS = ("checkpoint.npz", "checkpoint.tmp.npz", "summary.json", "summary.json.tmp",
               "days.gif", "days.tmp.gif", "maps", "snapshots", "render", "animation",
               "sensors_daily.csv", "sensors_daily.csv.tmp")


def folder_kind(path) -> str | None:
    """The kind of result a folder holds (its marker, else recognised by its files).

    Parameters
    ----------
    path : str or pathlib.Path
        The output folder.

    Returns
    -------
    str or None
        The kind (``"run"``, ``"irradiance"``, ``"render"``, ``"animate"``, ``"light-study"``,
        ``"grow"``, ``"tune"``, ``"sweep"``, the ``command`` of an older ``summary.json``, or
        ``"unknown"`` for an unreadable one); None for an empty or unrecognised folder or an
        unreadable marker.
    """
    path = Path(path)
    m = path / MARKER
    if m.exists():
        try:
            return str(json.loads(m.read_text()).get("kind"))
        except (ValueError, OSError, AttributeError):
            return None
    for kind, files in _KIND_FILES.items():
        if any((path / f).exists() for f in files):
            return kind
    if (path / "summary.json").exists():
        try:
            return str(json.loads((path / "summary.json").read_text()).get("command", "")) or None
        except (ValueError, OSError, AttributeError):
            return "unknown"
    return None


#: how long a folder whose lock holder is exiting is waited for [s]
EXITING_GRACE_S = 30.0


def _process_exiting(pid: str) -> bool:
    """Whether local process ``pid`` is exiting: its main thread has ended (state Z or X in
    ``/proc/PID/stat``) while other threads still close down. A process killed with SIGKILL
    keeps its files, and so the folder's lock, until its last thread has gone (Dr.Jit's thread
    pool takes a moment), so a run started at once after a kill would find the folder busy."""
    try:
        stat = Path(f"/proc/{int(pid)}/stat").read_text()
    except (OSError, ValueError):
        return False           # not a local process (or no /proc): a real holder
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def _flock_unless_held(fcntl, fh) -> bool:
    """Take an exclusive ``flock`` on ``fh``; wait up to :data:`EXITING_GRACE_S` while its holder
    (the pid written in the file) is exiting. Returns False if another process holds it."""
    t0 = time.monotonic()
    while True:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            fh.seek(0)
            if not _process_exiting(fh.read().strip()) or \
                    time.monotonic() - t0 > EXITING_GRACE_S:
                return False
            time.sleep(0.02)


class OutputFolder:
    """An output folder claimed by one command.

    The folder is created if needed, checked to be writable, marked with its kind
    (``.mitsuba-veg.json``) and locked (``.mitsuba-veg.lock``, an advisory ``flock`` the kernel
    drops when the process ends, also on SIGKILL) so that a second process writing into it is
    refused instead of interleaving. A holder that is exiting (killed, its threads still closing
    down) is waited for, up to :data:`EXITING_GRACE_S`. Use as a context manager or call
    :meth:`release`.

    Parameters
    ----------
    path : str or pathlib.Path
        The folder.
    kind : str
        The kind of result it will hold (``"run"``, ``"render"``, ...); a folder holding another
        kind is refused.
    option : str, optional
        The command-line option that named the folder, for messages; default ``"--out"``.
    info : dict, optional
        More fields for the marker file (e.g. the scenario); default None.

    Raises
    ------
    ParameterError
        If the path is a file, cannot be created or written, holds another kind of result, or
        another process holds the lock.
    """

    def __init__(self, path, kind: str, option: str = "--out", info: dict | None = None):
        self.path = Path(path)
        self.kind = kind
        self._fh = None
        p = self.path
        if p.exists() and not p.is_dir():
            raise ParameterError(option, str(p), "a folder (this is a file)",
                                 "choose another output folder")
        try:
            p.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise ParameterError(option, str(p), "a folder that can be created and written",
                                 f"{e.strerror}: choose a writable location") from None
        held = folder_kind(p)
        if held is not None and held != kind:
            raise ParameterError(option, str(p), f"an empty folder or one holding a `{kind}` "
                                 f"result (it holds a `{held}` result)",
                                 f"choose another {option} folder; this one is not changed")
        try:
            import fcntl
            self._fh = open(p / LOCK, "a+")
            if not _flock_unless_held(fcntl, self._fh):
                self._fh.seek(0)
                other = self._fh.read().strip() or "?"
                self._fh.close()
                self._fh = None
                raise ParameterError(option, str(p), "a folder no other mitsuba-veg process "
                                     f"is writing (process {other} holds it)",
                                     "wait for that process to finish, or choose another "
                                     f"{option} folder") from None
            self._fh.seek(0)
            self._fh.truncate()
            self._fh.write(str(os.getpid()))
            self._fh.flush()
            if not (p / MARKER).exists():
                write_json(p / MARKER, {"kind": kind, **(info or {})})
        except PermissionError as e:
            if self._fh is not None:
                self._fh.close()
                self._fh = None
            raise ParameterError(option, str(p), "a writable folder",
                                 f"{e.strerror}: choose a writable location") from None

    def clear(self, names) -> None:
        """Remove stale outputs (files or folders named in ``names``) of an earlier result.

        Parameters
        ----------
        names : iterable of str
            File or folder names inside the output folder (e.g. :data:`RUN_OUTPUTS`); missing ones
            are skipped.
        """
        clear_outputs(self.path, names)

    def release(self) -> None:
        """Release the folder's lock (closing the lock file drops the ``flock``); idempotent."""
        if self._fh is not None:
            self._fh.close()  # closing drops the flock
            self._fh = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    def __del__(self):
        self.release()


def clear_outputs(folder, names) -> None:
    """Remove the files or folders ``names`` from ``folder`` (those that exist).

    Parameters
    ----------
    folder : str or pathlib.Path
        The folder.
    names : iterable of str
        File or folder names inside ``folder``; folders are removed with their contents.
    """
    for n in names:
        q = Path(folder) / n
        if q.is_dir():
            shutil.rmtree(q)
        elif q.exists():
            q.unlink()


# --------------------------------------------------------------------------------------------
# Moss snapshots (living moss on frame days, read by the render's animation)
# --------------------------------------------------------------------------------------------
SNAPSHOT_DIR = "snapshots"


# ---- writing snapshots during a run -------------------------------------------------------------
class SnapshotWriter:
    """``on_day`` hook for :meth:`mitsuba_veg.daily.Simulation.run` that writes moss snapshots.

    Writes the living moss to ``OUT/snapshots/day_NNNN.npz`` on day 1, every ``every`` days
    (default: the run's ``frame_every``) and on the last day (a world adds every leaf's state).
    About 0.3 MB per 16,000 moss (compressed).

    Parameters
    ----------
    every : int, optional
        Days between snapshots [d]; default None: the run's ``frame_every`` (10 if unset).
    """

    def __init__(self, every: int | None = None):
        self.every = every

    def __call__(self, sim, rec) -> None:
        every = max(int(self.every or getattr(sim, "frame_every", 10) or 10), 1)
        if sim.day % every == 0 or sim.day == sim.days or sim.day == 1:
            extra = None
            phen = getattr(sim, "phen", None)
            if phen is not None:   # a world: every leaf's state (the render draws it)
                extra = {"leaf_tau": np.asarray(phen.tau).astype(np.float16),
                         "leaf_grown": np.asarray(phen.grown).astype(np.float16),
                         "leaf_on": np.asarray(phen.on_tree)}
            write_snapshot(Path(sim.out) / SNAPSHOT_DIR, sim.day, sim.pop.to_numpy(),
                           date=rec.get("date"), extra=extra)


def write_snapshot(directory, day: int, population: dict, date: str | None = None,
                   extra: dict | None = None) -> Path:
    """Write the living moss of a population and a world's leaf state to ``day_NNNN.npz``.

    The file (written atomically, compressed) holds ``day``, ``date``, ``pos`` [m] (n, 3) float32,
    ``nrm`` [-] (n, 3) float16, ``species`` uint8, ``growth`` G_moss [-] float16 of the n living
    moss (state 2), and the arrays of ``extra``.

    Parameters
    ----------
    directory : str or pathlib.Path
        Snapshot folder (created if needed), usually ``OUT/snapshots``.
    day : int
        Simulated day number (file name ``day_NNNN.npz``).
    population : dict
        ``MossPopulation.to_numpy()``: ``state``, ``pos`` [m] (capacity, 3), ``nrm`` (capacity,
        3), ``species``, ``growth`` [-].
    date : str, optional
        Calendar date of the day (ISO); default None (stored as ``""``).
    extra : dict of str to numpy.ndarray, optional
        More arrays to store (a world's ``leaf_tau``, ``leaf_grown``, ``leaf_on``); default None.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    m = np.asarray(population["state"]) == 2
    path = d / f"day_{int(day):04d}.npz"
    with atomic_write(path, d / f".day_{int(day):04d}.tmp.npz") as tmp:
        np.savez_compressed(tmp, day=np.array(int(day)), date=np.array(str(date or "")),
                            pos=np.asarray(population["pos"])[m].astype(np.float32),
                            nrm=np.asarray(population["nrm"])[m].astype(np.float16),
                            species=np.asarray(population["species"])[m].astype(np.uint8),
                            growth=np.asarray(population["growth"])[m].astype(np.float16),
                            **(extra or {}))
    return path



def write_summary(path, summary: dict) -> None:
    """Write a run's ``summary.json`` atomically (indent 1, NumPy values converted).

    Parameters
    ----------
    path : str or pathlib.Path
        The JSON file.
    summary : dict
        The summary (JSON-able, NumPy values allowed).
    """
    write_json(path, summary, indent=1)


def jsonable(x):
    """JSON fallback for NumPy arrays and scalars (anything else becomes its str).

    Parameters
    ----------
    x : object
        A value ``json`` cannot serialise.

    Returns
    -------
    list, float, int, bool or str
        ``x.tolist()`` for arrays, ``x.item()`` for NumPy scalars, else ``str(x)``.
    """
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    return str(x)


class DayFrames:
    """``on_day`` hook that writes the day maps and assembles them into ``days.gif``.

    Called after every simulated day; writes maps every ``frame_every`` days, on day 1 and on the
    last day; :meth:`finish` assembles them into ``days.gif`` at the end.

    Parameters
    ----------
    sim : Simulation
        The simulation (its ``out`` folder holds ``maps/``).
    """

    def __init__(self, sim):
        self.sim = sim
        self.dir = Path(sim.out) / "maps"
        self.frames: list[Path] = []

    def __call__(self, sim, rec) -> None:
        every = max(int(sim.frame_every), 1)
        if sim.day % every == 0 or sim.day == sim.days or sim.day == 1:
            self.frames.append(self.write_day(sim, rec))

    def write_day(self, sim, rec) -> Path:
        """Write the map of one day, ``maps/day_NNNN.png``: four panels, ground seen from above.

        Panels: moss cover [-] (fraction of each triangle, with the living moss as points),
        daily-mean insolation S [W m-2], soil surface temperature Ts [K] and soil water content
        theta [-]; a world's tree crowns (dashed) and trunks are drawn on every panel.

        Parameters
        ----------
        sim : Simulation
            The running simulation (its index, population, ``last`` day's fields and trees).
        rec : dict
            The day's record (``day``, ``date``, ``moss_alive``, ``propagules``,
            ``covered_area_m2`` [m2], optional ``trees``).

        Returns
        -------
        pathlib.Path
            The written PNG.
        """
        plt = _mpl()

        self.dir.mkdir(parents=True, exist_ok=True)
        idx = sim.index
        ground = sim.scn.get("terrain.ground", "ground")
        sl = idx.shape_slice(ground)
        v, f = idx.geometry[ground]
        counts = sim.counts()
        cover = np.minimum(counts * sim.grid_cell() ** 2 / np.maximum(idx.areas, 1e-30), 1.0)
        last = sim.last
        fig, axs = plt.subplots(1, 4, figsize=(17, 4.1), constrained_layout=True)
        plan_map(axs[0], v, f, cover[sl], title="moss cover (fraction of each triangle)",
                 label="cover [-]", cmap="Greens", vmin=0.0, vmax=1.0)
        pos = sim.pop.to_numpy()
        live = pos["state"] == 2
        if live.any():
            p = pos["pos"][live]
            axs[0].scatter(p[:, 0], -p[:, 2], s=0.4, c="k", alpha=0.35, linewidths=0)
        plan_map(axs[1], v, f, last["S"][sl], title="insolation S (daily mean)",
                 label="W m$^{-2}$", cmap="inferno", vmin=0.0)
        plan_map(axs[2], v, f, last["Ts"][sl], title="soil surface temperature Ts",
                 label="K", cmap="coolwarm")
        plan_map(axs[3], v, f, last["theta"][sl], title="soil water content θ",
                 label="θ [-]", cmap="Blues", vmin=0.0)
        for ax in axs:
            ax.autoscale(False)
        for wt in getattr(sim, "trees", []):   # a world: the crowns (dashed) and trunks
            r, (cx, cz) = wt.crown_radius(), wt.crown_centre()
            for ax in axs:
                ax.add_patch(plt.Circle((cx, -cz), r, fill=False, ls="--", lw=0.9,
                                        color="tab:green"))
                ax.plot(wt.position[0], -wt.position[2], "^", color="saddlebrown", ms=5)
        rec_trees = rec.get("trees")
        if rec_trees:
            on = sum(t["leaves_on_tree"] for t in rec_trees.values())
            axs[1].set_title(f"insolation S (daily mean), {on:,d} leaves on", fontsize=10)
        fig.suptitle(f"day {rec['day']} ({rec['date']}): {rec['moss_alive']} moss, "
                     f"{rec['propagules']} propagules, covered {rec['covered_area_m2']:.4f} m²",
                     fontsize=11)
        path = self.dir / f"day_{rec['day']:04d}.png"
        with atomic_write(path, self.dir / f".day_{rec['day']:04d}.tmp.png") as tmp:
            fig.savefig(tmp, dpi=80)
        plt.close(fig)
        return path

    def finish(self) -> dict:
        """Assemble the day maps into ``days.gif`` (400 ms per frame) when there are at least two.

        Returns
        -------
        dict
            ``{"maps": [PNG paths written by this run], "animation": GIF path}`` (``animation`` only
            when the GIF was written); paths as str.
        """
        files = {"maps": [str(p) for p in sorted(set(self.frames))]}
        frames = sorted(p for p in set(self.dir.glob("day_*.png"))
                        if p.stem[4:].isdigit() and int(p.stem[4:]) <= self.sim.days)
        if len(frames) >= 2:
            from PIL import Image
            imgs = [Image.open(p).convert("P", palette=Image.ADAPTIVE) for p in frames]
            gif = Path(self.sim.out) / "days.gif"
            with atomic_write(gif, gif.with_suffix(".tmp.gif")) as tmp:
                imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=400, loop=0)
            files["animation"] = str(gif)
        return files
