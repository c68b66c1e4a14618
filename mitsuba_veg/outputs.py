"""Run outputs: per-day maps (PNG), the animation of the days (GIF), summary.json.

Maps show the ground (the scenario's ``terrain.ground``) from above, one colour per triangle;
the coverage map also draws the other living surfaces' moss as points.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import threading
import time
from pathlib import Path

import numpy as np

from .atomic import atomic_write
from .atomic import unwatch as atomic_unwatch
from .atomic import watch as atomic_watch
from .errors import FolderBusy, ParameterError
from .plots import _mpl, plan_map


__all__ = ["write_json", "MARKER", "LOCK", "READERS", "RUN_OUTPUTS", "folder_kind",
           "EXITING_GRACE_S", "lock_holders", "OutputFolder", "RunReader", "clear_outputs",
           "SNAPSHOT_DIR", "SnapshotWriter", "write_snapshot", "write_summary", "jsonable",
           "DayFrames"]

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
# Output folders: one kind of result per folder, one writer at a time, and a manifest of the
# files the package wrote (it deletes or overwrites nothing else)
# --------------------------------------------------------------------------------------------
#: the marker file of an output folder (kind of result, manifest of the files written)
MARKER = ".mitsuba-veg.json"
#: the lock file of an output folder (held while a process writes there)
LOCK = ".mitsuba-veg.lock"
#: a shared lock held by the commands that read a run folder (render, animate): a run that
#: would clear the folder (``--fresh``) is refused while one is held
READERS = ".mitsuba-veg.readers.lock"
#: the package's own bookkeeping files of a folder (never foreign, never in the manifest)
_OWN = (MARKER, LOCK, READERS, MARKER + ".tmp")
#: what each command leaves in its folder (used to recognise folders written before markers)
_KIND_FILES = {"run": ("checkpoint.npz",), "irradiance": ("irradiance.npz",),
               "render": ("render.json",), "animate": ("animate.json",),
               "light-study": ("light_study.npz",), "grow": ("metrics.json",),
               "tune": ("fitted.json",), "sweep": ("sweep.json",)}
#: files and folders of a moss run that belong to one run (cleared when a run starts afresh)
RUN_OUTPUTS = ("checkpoint.npz", "checkpoint.tmp.npz", "summary.json", "summary.json.tmp",
               "days.gif", "days.tmp.gif", "maps", "snapshots", "render", "animation",
               "sensors_daily.csv", "sensors_daily.csv.tmp", "trees", "trees_yearly.csv", "years",
               "floor_years.png")
#: output folders nested in a run folder that are cleared with the run (their own manifests)
_RUN_CHILD_KINDS = ("render", "animate")
#: a run folder written before manifests existed: the files adopted as the package's, by name
_ADOPT_RUN = ("checkpoint.npz", "summary.json", "days.gif", "run.json", "error.json",
              "sensors_daily.csv", "maps/day_*.png", "snapshots/day_*.npz")


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


def _read_marker(path: Path) -> dict | None:
    """The folder's marker as a dict (None when there is none); a marker that cannot be read
    raises :class:`ValueError`."""
    m = path / MARKER
    if not m.exists():
        return None
    meta = json.loads(m.read_text())
    if not isinstance(meta, dict):
        raise ValueError("not a JSON object")
    return meta


def _write_marker(path: Path, meta: dict) -> None:
    """Write the marker atomically (directly: a marker is not an output of the folder)."""
    tmp = path / (MARKER + ".tmp")
    tmp.write_text(json.dumps(meta, indent=1, default=jsonable))
    os.replace(tmp, path / MARKER)


def _adopted(path: Path, kind: str) -> set:
    """The files of a folder written before manifests existed that are taken as the package's:
    a run folder's outputs by name; every file of a folder of another kind."""
    if kind == "run":
        return {p.relative_to(path).as_posix() for pat in _ADOPT_RUN for p in path.glob(pat)
                if p.is_file()}
    out = set()
    for p in path.rglob("*"):
        rel = p.relative_to(path)
        nested = any((path / Path(*rel.parts[:i]) / MARKER).exists()
                     for i in range(1, len(rel.parts)))
        if p.is_file() and p.name not in _OWN and not nested:
            out.add(rel.as_posix())
    return out


def _foreign_entries(path: Path) -> list[str]:
    """Entries of a folder other than the package's bookkeeping files."""
    try:
        return sorted(q.name for q in path.iterdir() if q.name not in _OWN)
    except OSError:
        return []


#: how long a folder whose lock holder is exiting is waited for [s]
EXITING_GRACE_S = 30.0
#: SIGKILL's bit in the pending-signal masks of /proc/PID/status
_SIGKILL_BIT = 1 << 8


def _process_exiting(pid) -> bool:
    """Whether local process ``pid`` is going away: its main thread has ended (state Z or X in
    ``/proc/PID/stat``) while other threads still close down, or a SIGKILL is pending for it
    (a killed process on a busy machine waits for a core before it ends). A process killed with
    SIGKILL keeps its files, and so the folder's lock, until its last thread has gone (Dr.Jit's
    thread pool takes a moment), so a run started at once after a kill would find the folder
    busy."""
    try:
        stat = Path(f"/proc/{int(pid)}/stat").read_text()
    except (OSError, ValueError):
        return False           # not a local process (or no /proc): a real holder
    if stat.rsplit(")", 1)[1].split()[0] in ("Z", "X"):
        return True
    try:
        status = Path(f"/proc/{int(pid)}/status").read_text()
    except OSError:
        return False
    for line in status.splitlines():
        if line.startswith(("SigPnd:", "ShdPnd:")) and int(line.split()[1], 16) & _SIGKILL_BIT:
            return True
    return False


def lock_holders(lock_file) -> list[int]:
    """The processes holding a ``flock`` on a file, from ``/proc/locks`` (Linux).

    Parameters
    ----------
    lock_file : str or pathlib.Path
        The locked file.

    Returns
    -------
    list of int
        Their process ids (empty when none, or when ``/proc/locks`` cannot be read).
    """
    try:
        st = os.stat(lock_file)
        text = Path("/proc/locks").read_text()
    except OSError:
        return []
    dev = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    pids = []
    for line in text.splitlines():
        parts = line.split()
        if len(parts) >= 6 and parts[1] == "FLOCK" and parts[5] == dev:
            try:
                pids.append(int(parts[4]))
            except ValueError:
                continue
    return sorted(set(pids))


def _describe(pid) -> str:
    """``process PID (its command line)`` for messages."""
    try:
        cmd = Path(f"/proc/{int(pid)}/cmdline").read_bytes().split(b"\0")
        text = " ".join(c.decode(errors="replace") for c in cmd if c)
    except (OSError, ValueError):
        text = ""
    if len(text) > 80:
        text = text[:77] + "..."
    return f"process {pid}" + (f" ({text})" if text else "")


def _holders_text(lock_file: Path, written: str) -> str:
    """Who holds a lock: the processes ``/proc/locks`` names, else the pid the last
    mitsuba-veg writer wrote into the file."""
    pids = lock_holders(lock_file)
    if pids:
        return ", ".join(_describe(p) for p in pids)
    return f"process {written or '?'}"


def _flock_wait(fcntl, fh, mode, lock_file: Path, wait: float = 0.0) -> bool:
    """Take a ``flock`` (``mode``: ``LOCK_EX`` or ``LOCK_SH``) on ``fh``. Waits up to ``wait``
    seconds for any holder, and up to :data:`EXITING_GRACE_S` while every holder is going away
    (:func:`_process_exiting`). Returns False if another process holds it."""
    t0 = time.monotonic()
    while True:
        try:
            fcntl.flock(fh.fileno(), mode | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            waited = time.monotonic() - t0
            if waited < wait:
                time.sleep(0.05)
                continue
            pids = lock_holders(lock_file)
            if not pids:
                fh.seek(0)
                pids = [fh.read().strip()]
            if not all(_process_exiting(p) for p in pids) or waited > EXITING_GRACE_S:
                return False
            time.sleep(0.02)


def _flock_unless_held(fcntl, fh) -> bool:
    """Take an exclusive ``flock`` on ``fh``; wait up to :data:`EXITING_GRACE_S` while its holder
    is exiting. Returns False if another process holds it."""
    return _flock_wait(fcntl, fh, fcntl.LOCK_EX, Path(fh.name))


class _Claim:
    """The state of a folder claimed by this process, shared by every :class:`OutputFolder` of
    it (a folder claimed again in the same process, e.g. a sweep's run folder claimed by the
    sweep's task and then by the run, shares one lock and one manifest)."""

    def __init__(self, path: Path, kind: str, option: str, fh, meta: dict, files: set):
        self.path, self.kind, self.option, self.fh = path, kind, option, fh
        self.root = path.resolve()
        self.meta, self.files, self.refs = meta, files, 1
        self.owner = threading.get_ident()
        self.lock = threading.RLock()

    def save(self) -> None:
        with self.lock:
            self.meta["files"] = sorted(self.files)
            _write_marker(self.path, self.meta)

    def record(self, path: Path) -> None:
        rel = Path(os.path.abspath(path)).relative_to(self.root).as_posix()
        if Path(rel).name in _OWN:
            return
        with self.lock:
            if rel in self.files:
                return
            if Path(path).is_file():
                raise ParameterError(self.option, str(self.path), "output names free or "
                                     f"taken by mitsuba-veg's own files ({rel} exists and was "
                                     "not written by mitsuba-veg)", f"move {rel} out of the "
                                     "folder, or "
                                     f"choose another {self.option} folder; nothing was "
                                     "overwritten")
            self.files.add(rel)
            self.save()


#: folders claimed by this process: resolved path -> claim
_HELD: dict = {}
_HELD_LOCK = threading.RLock()


def _innermost_claim(path) -> "_Claim | None":
    """The claimed folder of this process that holds ``path`` most closely."""
    p = Path(os.path.abspath(path))
    best = None
    with _HELD_LOCK:
        for c in _HELD.values():
            if p == c.root or c.root in p.parents:
                if best is None or len(c.root.parts) > len(best.root.parts):
                    best = c
    return best


def _on_write(path) -> None:
    """Watcher of :func:`mitsuba_veg.atomic.atomic_write`: a file written into a claimed folder
    goes into that folder's manifest (a foreign file in its place is refused)."""
    c = _innermost_claim(path)
    if c is not None:
        c.record(Path(path))


def _probe_writable(path: Path) -> str | None:
    """None if a file can be created in ``path``, else the reason (as the OS says it)."""
    probe = path / f".mitsuba-veg.probe.{os.getpid()}.{threading.get_ident()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        return e.strerror or str(e)
    return None


class _Released:
    """A context manager whose exit (and garbage collection) calls ``release()``."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    def __del__(self):
        self.release()


class OutputFolder(_Released):
    """An output folder claimed by one command.

    The folder is created if needed, checked to be writable (for the files to come, not only
    the marker), marked with its kind (``.mitsuba-veg.json``) and locked
    (``.mitsuba-veg.lock``, an advisory ``flock`` the kernel drops when the process ends, also
    on SIGKILL) so that a second process writing into it is refused instead of interleaving.
    A holder that is going away (killed, its threads still closing down) is waited for, up to
    :data:`EXITING_GRACE_S`. The marker keeps a manifest of the files the package wrote into
    the folder (every :func:`~mitsuba_veg.atomic.atomic_write` into it, and
    :meth:`record`): :meth:`clear` deletes only those, and a file the package did not write is
    never overwritten. A folder that holds anything mitsuba-veg did not write and no marker is
    refused (it is not an output folder), as is an empty path. Use as a context manager or
    call :meth:`release`.

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
    wait : float, optional
        Seconds to wait for another process's lock before refusing [s]; default 0 (a holder
        that is going away is always waited for).
    reads : str or pathlib.Path, optional
        A run folder the command reads (``render``, ``animate``): it is held with a
        :class:`RunReader` until :meth:`release`, so that no run clears it meanwhile; default
        None.

    Raises
    ------
    ParameterError
        If the path is empty or a file, cannot be created or written, holds another kind of
        result or files mitsuba-veg did not write, or another process holds the lock.
    """

    def __init__(self, path, kind: str, option: str = "--out", info: dict | None = None,
                 wait: float = 0.0, reads=None):
        self._claim = self._fh = self._reader = None
        if reads is not None:
            self._reader = RunReader(reads)
        if not str(path).strip():
            raise ParameterError(option, str(path), "a folder path (an empty one would be the "
                                 "current folder)", f"give {option} DIR (is a variable such "
                                 "as $OUTDIR unset?)")
        self.path = Path(path)
        self.kind = kind
        key = str(Path(os.path.abspath(self.path)))
        t0 = time.monotonic()
        while True:
            with _HELD_LOCK:
                held = _HELD.get(key)
                if held is not None and held.owner == threading.get_ident():
                    if held.kind != kind:
                        raise ParameterError(option, str(self.path), f"a folder for a `{kind}`"
                                             f" result (this process is writing a "
                                             f"`{held.kind}` result into it)",
                                             f"choose another {option} folder")
                    held.refs += 1        # claimed again by the same task: one lock
                    self._claim, self._fh = held, held.fh
                    return
            if held is None:
                break
            if time.monotonic() - t0 >= wait:   # another thread of this process writes it
                raise FolderBusy(option, str(self.path), "a folder no other task is writing "
                                 f"(another thread of this process, {os.getpid()}, holds it)",
                                 f"wait for it to finish, or choose another {option} folder")
            time.sleep(0.05)
        self._claim = self._take(option, info, wait)
        self._fh = self._claim.fh
        with _HELD_LOCK:
            _HELD[key] = self._claim
        atomic_watch(_on_write)

    def _take(self, option, info, wait) -> _Claim:
        p = self.path
        if p.exists() and not p.is_dir():
            raise ParameterError(option, str(p), "a folder (this is a file)",
                                 "choose another output folder")
        try:
            p.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise ParameterError(option, str(p), "a folder that can be created and written",
                                 f"{e.strerror}: choose a writable location") from None
        try:
            meta = _read_marker(p)
        except (ValueError, OSError) as e:
            raise ParameterError(option, str(p), f"a folder with a readable {MARKER}",
                                 f"its marker cannot be read ({type(e).__name__}); choose "
                                 f"another {option} folder") from None
        held = folder_kind(p)
        if held is not None and held != self.kind:
            raise ParameterError(option, str(p), f"an empty folder or one holding a "
                                 f"`{self.kind}` result (it holds a `{held}` result)",
                                 f"choose another {option} folder; this one is not changed")
        if meta is None and held is None:
            foreign = _foreign_entries(p)
            if foreign:
                more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
                raise ParameterError(option, str(p), "an empty folder or one written by "
                                     "mitsuba-veg (this one holds "
                                     f"{', '.join(foreign[:3])}{more}, not written by it)",
                                     f"choose a new or empty {option} folder; nothing in this "
                                     "one was changed")
        import fcntl
        try:
            fh = open(p / LOCK, "a+")
        except OSError as e:
            raise ParameterError(option, str(p), "a writable folder",
                                 f"{e.strerror}: choose a writable location") from None
        if not _flock_wait(fcntl, fh, fcntl.LOCK_EX, p / LOCK, wait):
            fh.seek(0)
            who = _holders_text(p / LOCK, fh.read().strip())
            fh.close()
            raise FolderBusy(option, str(p), f"a folder no other process is writing ({who} "
                             "holds it)", "wait for that process to finish, or choose another "
                             f"{option} folder")
        try:
            why = _probe_writable(p)
            if why is None:
                for sub in ("maps", "snapshots"):
                    if self.kind == "run" and (p / sub).is_dir():
                        why = _probe_writable(p / sub)
                        if why is not None:
                            why = f"{sub}/: {why}"
                            break
            if why is not None:
                raise ParameterError(option, str(p), "a writable folder", f"{why}: make it "
                                     f"writable or choose another {option} folder (checked "
                                     "before any work)")
            fh.seek(0)
            fh.truncate()
            fh.write(str(os.getpid()))
            fh.flush()
            if meta is None:
                meta = {"kind": self.kind, **(info or {})}
            files = meta.get("files")
            files = set(files) if isinstance(files, list) else _adopted(p, self.kind)
            claim = _Claim(p, self.kind, option, fh, meta, files)
            claim.save()
        except BaseException:
            fh.close()
            raise
        return claim

    @property
    def files(self) -> list[str]:
        """The files the package wrote into the folder (its manifest), relative paths."""
        return sorted(self._claim.files) if self._claim is not None else []

    def record(self, path) -> None:
        """Add a file written into the folder by other means than
        :func:`~mitsuba_veg.atomic.atomic_write` (e.g. by a Dask worker) to the manifest.

        Parameters
        ----------
        path : str or pathlib.Path
            The file (inside the folder).
        """
        c = self._claim
        if c is None:
            return
        rel = Path(os.path.abspath(path)).relative_to(c.root).as_posix()
        with c.lock:
            if rel not in c.files:
                c.files.add(rel)
                c.save()

    def clear(self, names) -> None:
        """Remove the earlier result's outputs named in ``names``: the files of the manifest
        among them (a folder name: the manifest's files under it, and the output folders of a
        render or an animation nested there); anything else stays.

        Parameters
        ----------
        names : iterable of str
            File or folder names inside the output folder (e.g. :data:`RUN_OUTPUTS`); missing ones
            are skipped.
        """
        clear_outputs(self.path, names)

    def release(self) -> None:
        """Release the folder's lock (closing the lock file drops the ``flock``); idempotent."""
        reader, self._reader = getattr(self, "_reader", None), None
        if reader is not None:
            reader.release()
        c, self._claim = getattr(self, "_claim", None), None
        self._fh = None
        if c is None:
            return
        with _HELD_LOCK:
            c.refs -= 1
            if c.refs > 0:
                return
            _HELD.pop(str(Path(os.path.abspath(c.path))), None)
            if not _HELD:
                atomic_unwatch(_on_write)
        c.fh.close()  # closing drops the flock


class RunReader(_Released):
    """A shared lock on a folder that a command reads (``render`` and ``animate`` read a run
    folder): while one is held, a run that would clear the folder (``--fresh``, or a new run
    in it) is refused instead of deleting files under the reader. A folder that cannot be
    written (so nothing can clear it) is read without the lock. Use as a context manager or
    call :meth:`release`.

    Parameters
    ----------
    path : str or pathlib.Path
        The folder that is read.
    option : str, optional
        The argument that named the folder, for messages; default ``"RUN_DIR"``.

    Raises
    ------
    ParameterError
        If a run has been clearing the folder for more than 5 s.
    """

    def __init__(self, path, option: str = "RUN_DIR"):
        import fcntl
        self._fh = None
        lock = Path(path) / READERS
        try:
            fh = open(lock, "a+")
        except OSError:
            return
        if not _flock_wait(fcntl, fh, fcntl.LOCK_SH, lock, wait=5.0):
            fh.close()
            raise FolderBusy(option, str(path), "a run folder that is not being cleared "
                             f"({_holders_text(lock, '')} is starting a new run in it)",
                             "wait for that run to write its first day, then try again")
        self._fh = fh

    def release(self) -> None:
        """Drop the shared lock; idempotent."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None


class _Exclusive:
    """An exclusive ``flock`` on a folder's lock file for the time of a clear; refused with one
    line when another command holds it (a reader of the folder, or a nested folder's writer).
    Without a lock file that can be created (a read-only folder) it is a no-op."""

    def __init__(self, lock: Path, folder: Path, what: str):
        import fcntl
        self._fh = None
        try:
            fh = open(lock, "a+")
        except OSError:
            return
        if not _flock_wait(fcntl, fh, fcntl.LOCK_EX, lock):
            fh.seek(0)
            who = _holders_text(lock, fh.read().strip() if lock.name == LOCK else "")
            fh.close()
            raise FolderBusy("--out", str(folder), "a folder no other mitsuba-veg command is "
                             f"using when its earlier outputs are cleared ({who} {what} it)",
                             "wait for that command to finish, or choose another --out "
                             "folder; nothing was deleted")
        self._fh = fh

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def _manifest_of(folder: Path):
    """(claim or None, the manifest's set of files or None when nothing is known to be the
    package's)."""
    c = _innermost_claim(folder)
    if c is not None and c.root == Path(os.path.abspath(folder)):
        return c, c.files
    try:
        meta = _read_marker(folder)
    except (ValueError, OSError):
        return None, None
    if meta is not None and isinstance(meta.get("files"), list):
        return None, set(meta["files"])
    kind = folder_kind(folder)
    if kind == "run":
        return None, _adopted(folder, "run")
    return None, None


def _prune(directory: Path) -> None:
    """Remove the empty folders under ``directory`` and ``directory`` itself if empty."""
    if not directory.is_dir():
        return
    for root, _, _ in sorted(os.walk(directory), key=lambda t: -len(t[0])):
        try:
            os.rmdir(root)
        except OSError:
            pass


def _clear_nested(sub: Path) -> None:
    """Clear a render's or an animation's output folder nested in a run folder: the files of
    its manifest; the folder itself goes when nothing else is left in it."""
    with _Exclusive(sub / LOCK, sub, "writes"):
        _, files = _manifest_of(sub)
        for rel in sorted(files or ()):
            (sub / rel).unlink(missing_ok=True)
        for rel in sorted(files or (), key=len, reverse=True):
            if "/" in rel:
                _prune(sub / rel.split("/", 1)[0])
        if _foreign_entries(sub):
            meta = _read_marker(sub) or {"kind": folder_kind(sub)}
            meta["files"] = []
            _write_marker(sub, meta)
            return
        for n in _OWN:
            (sub / n).unlink(missing_ok=True)
    _prune(sub)


def clear_outputs(folder, names) -> None:
    """Remove an earlier result's outputs among ``names`` from ``folder``: only files the package
    wrote and recorded in the folder's manifest (a run folder from before manifests: its
    outputs by name), and the output folders of a render or an animation nested under those
    names; files the package did not write stay, and so do the folders holding them.

    Parameters
    ----------
    folder : str or pathlib.Path
        The folder.
    names : iterable of str
        File or folder names inside ``folder``; for a folder name, the recorded files under it.

    Raises
    ------
    ParameterError
        If another command uses the folder (``render``/``animate`` reading it, or writing a
        nested output folder): nothing is deleted then.
    """
    folder = Path(folder)
    claim, files = _manifest_of(folder)
    if files is None:
        return
    names = [str(n).strip("/") for n in names if str(n).strip("/")]
    targets = sorted(f for f in files for n in names if f == n or f.startswith(n + "/"))
    nested = []
    for n in names:
        q = folder / n
        if q.is_dir():
            for m in sorted(q.rglob(MARKER)):
                if folder_kind(m.parent) in _RUN_CHILD_KINDS:
                    nested.append(m.parent)
    if not nested and not any((folder / t).exists() for t in targets):
        return
    with _Exclusive(folder / READERS, folder, "reads"):
        for sub in nested:
            _clear_nested(sub)
        for t in targets:
            (folder / t).unlink(missing_ok=True)
            files.discard(t)
        for n in names:
            _prune(folder / n)
    if claim is not None:
        claim.save()
    else:
        try:
            meta = _read_marker(folder)
        except (ValueError, OSError):
            meta = None
        if meta is not None:
            meta["files"] = sorted(files)
            _write_marker(folder, meta)


# --------------------------------------------------------------------------------------------
# Moss snapshots (living moss on frame days, read by the render's animation)
# --------------------------------------------------------------------------------------------
#: the folder of a run's snapshots
SNAPSHOT_DIR = "snapshots"


# ---- writing snapshots during a run -------------------------------------------------------------
class SnapshotWriter:
    """``on_day`` hook for :meth:`mitsuba_veg.daily.Simulation.run` that writes moss snapshots.

    Writes the living moss to ``OUT/snapshots/day_NNNN.npz`` on day 1, every ``every`` days
    (default: the run's ``frame_every``) and on the last day. A world adds every leaf's state
    (``leaf_tau``, ``leaf_grown``, ``leaf_on`` and ``leaf_fall_day``, the date ordinal of each
    leaf's last fall, −1 for none) and writes a snapshot on every 31 December too: the year's
    end may regrow its trees and start their leaves anew, and the render's litter reads the
    year's falls from that day's snapshot (:mod:`mitsuba_veg.render.litter`).
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
        phen = getattr(sim, "phen", None)
        year_end = phen is not None and _is_31_december(rec.get("date"))
        if sim.day % every == 0 or sim.day == sim.days or sim.day == 1 or year_end:
            # live moss per terrain element (the glTF export's moss cover)
            extra = {"moss_counts": np.asarray(sim.counts()[:sim.site.n_terrain])
                     .astype(np.uint32)}
            if phen is not None:   # a world: every leaf's state (the render draws it)
                extra.update({"leaf_tau": np.asarray(phen.tau).astype(np.float16),
                              "leaf_grown": np.asarray(phen.grown).astype(np.float16),
                              "leaf_on": np.asarray(phen.on_tree),
                              "leaf_fall_day": np.asarray(phen.fall_day).astype(np.int32)})
            write_snapshot(Path(sim.out) / SNAPSHOT_DIR, sim.day, sim.pop.to_numpy(),
                           date=rec.get("date"), extra=extra)


def _is_31_december(date) -> bool:
    """Whether an ISO date (a day record's ``date``) is 31 December (False without one)."""
    try:
        d = _dt.date.fromisoformat(str(date)[:10])
    except ValueError:
        return False
    return d.month == 12 and d.day == 31


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
        More arrays to store (a world's ``leaf_tau``, ``leaf_grown``, ``leaf_on``,
        ``leaf_fall_day``); default None.

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
            ``{"maps": [PNG paths of every map of the run], "animation": GIF path}``
            (``animation`` only when the GIF was written); paths as str. A resumed run lists
            the maps written before the resume as well.
        """
        frames = sorted(p for p in set(self.dir.glob("day_*.png"))
                        if p.stem[4:].isdigit() and int(p.stem[4:]) <= self.sim.days)
        files = {"maps": [str(p) for p in sorted(set(frames) | set(self.frames))]}
        if len(frames) >= 2:
            from PIL import Image
            imgs = [Image.open(p).convert("P", palette=Image.ADAPTIVE) for p in frames]
            gif = Path(self.sim.out) / "days.gif"
            with atomic_write(gif, gif.with_suffix(".tmp.gif")) as tmp:
                imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=400, loop=0)
            files["animation"] = str(gif)
        return files
