"""Atomic file writes: the one way the package writes a file that someone may be reading."""
from __future__ import annotations

import contextlib
import os
from pathlib import Path


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
        Where to write. If the block raises, the temporary file is removed and ``path`` is
        left as it was.
    """
    path = Path(path)
    tmp = Path(tmp) if tmp is not None else path.with_name(f".{path.stem}.tmp{path.suffix}")
    try:
        yield tmp
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)
