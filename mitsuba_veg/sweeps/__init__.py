"""Sweeps on Dask: many moss runs (axes of scenario fields x seeds), one Dask task per run,
gathered into one tidy table (Parquet + CSV) with standard plots.

    mitsuba-veg sweep scenes/moss_garden/sweep.toml --workers 2 --out out/sweep

or from Python (``mv.sweep`` is :func:`sweep`)::

    table = mv.sweep("scenes/moss_garden/sweep.toml", out="out/sweep")   # pandas.DataFrame

Dask, pandas and pyarrow are the optional extra ``distributed`` and are imported only when a
sweep runs (``pip install 'mitsuba-veg[distributed]'``). Modules: :mod:`.spec` (the sweep file),
:mod:`.cluster` (LocalCluster or an existing scheduler, Dr.Jit threads per worker),
:mod:`.runner` (the tasks), :mod:`.table` (the tidy table), :mod:`.plots`, :mod:`.frames`
(animation frames as Dask tasks), :mod:`.cli`.
"""
from __future__ import annotations

from .runner import run_task, sweep
from .spec import RunSpec, Sweep, load_sweep

__all__ = ["sweep", "load_sweep", "run_task", "Sweep", "RunSpec"]
