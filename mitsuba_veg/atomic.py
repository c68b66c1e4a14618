"""Atomic file writes: the one way the package writes a file that someone may be reading.

Every file written this way is announced, just before it is moved into place, to the watchers
registered with :func:`watch`: an output folder claimed by this process
(:class:`mitsuba_veg.outputs.OutputFolder`) records the files written into it in its manifest,
and refuses to overwrite a file it did not write.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path

__all__ = ["watch", "unwatch", "atomic_write"]

#: callables ``watcher(path)`` told of every file about to be moved into place
_WATCHERS: list = []


def watch(watcher) -> None:
    """Register ``watcher(path)``: called with the final path of every atomic write, before the
    file is moved into place (an exception it raises cancels the write).

    Parameters
    ----------
    watcher : callable
        Takes the written file's path (:class:`pathlib.Path`).
    """
    if watcher not in _WATCHERS:
        _WATCHERS.append(watcher)


def unwatch(watcher) -> None:
    """Remove a watcher registered with :func:`watch` (no error when it is not registered).

    Parameters
    ----------
    watcher : callable
        The watcher to remove.
    """
    if watcher in _WATCHERS:
        _WATCHERS.remove(watcher)


@contextlib.contextmanager
def atomic_write(path, tmp=None):
    """Write a file atomically: yield a temporary path beside ``path``, then move it onto
    ``path`` in one step (``os.replace``), so that a reader never sees a half-written file.

    Parameters
    ----------
    path : path-like
        The file to write.
    tmp : path-like, optional
        The temporary file (default ``.<stem>.tmp<suffix>`` beside ``path``); a run removes
        the temporary files its writers leave when killed, by these names.

    Yields
    ------
    pathlib.Path
        Where to write. If the block raises, or a watcher refuses the file (:func:`watch`), the
        temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    tmp = Path(tmp) if tmp is not None else path.with_name(f".{path.stem}.tmp{path.suffix}")
    try:
        yield tmp
        for w in list(_WATCHERS):
            w(path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)
