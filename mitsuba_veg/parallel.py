"""Work on the machine's cores: a map over independent items in threads.

NumPy lets go of the GIL inside its array operations, so independent NumPy work on separate
arrays (a stand's trees aged at the year's end, their leaf tables filled into one mesh, the
triangle geometry of a large mesh block by block) runs on
all the cores from Python threads. Nothing here touches Dr.Jit or Mitsuba: their work stays on
the calling thread.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor


__all__ = ["map_on_cores"]

def map_on_cores(fn, items, max_workers: int | None = None) -> list:
    """``[fn(x) for x in items]`` on the machine's cores, one thread per core.

    The same results in the same order as one thread; an exception raised by ``fn`` reaches
    the caller. ``fn`` must touch nothing that another item's call touches (its own arrays, or
    disjoint slices of a shared one).

    Parameters
    ----------
    fn : callable
        Work on one item.
    items : iterable
        The items (e.g. tree indices).
    max_workers : int, optional
        At most this many threads (default: one per core).

    Returns
    -------
    list
        ``fn`` of each item, in order.
    """
    items = list(items)
    workers = min(len(items), os.cpu_count() or 1, max_workers or len(items) or 1)
    if workers <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(workers) as ex:
        return list(ex.map(fn, items))
