"""The tidy table of a sweep: one row per run and day, written as Parquet and CSV.

Columns, in order::

    run                         run folder name (runs/<run>)
    index                       position of the run in the sweep (axes product, then seeds)
    status                      done (run now), skipped (finished before), failed
    error                       the error of a failed run (one line), else empty
    one column per swept field  its dotted name (climate.temperature, light.seed); lists
                                and tables as their TOML text
    day, date                   simulated day (1-based) and its date (a failed run: one row, empty)
    moss_alive                  live moss at the end of the day
    alive.<Species>             live moss per species
    propagules                  waiting gemmae and spores
    covered_area_m2             covered area [m2], and regions.<name>.covered_area_m2 per region
    mean_S_W_m2, mean_Ts_K, mean_rhs, mean_theta
                                area-weighted daily means over the living surfaces (insolation
                                [W m-2], soil surface temperature [K], relative humidity at the
                                surface [-], soil water content [-])
    events.<name>               the day's life-cycle events (germinations, deaths, propagules ...)
    seconds.<part>              wall time of the day's light, soil, moss (and leaves) stages and
                                of its record [s], their kernels included on the CPU (on a GPU the
                                light's only: DayPipeline.run_day); not reproducible: leave them
                                out when comparing runs
"""
from __future__ import annotations

from pathlib import Path

from ..atomic import atomic_write
from .spec import Sweep, toml_value

__all__ = ["RUN_COLUMNS", "flatten_record", "tidy", "write_table", "comparable"]

#: leading columns (before the swept fields)
RUN_COLUMNS = ("run", "index", "status", "error")


def _cell(v):
    """A swept value as a table cell: scalars as they are, lists/tables as TOML text."""
    if isinstance(v, (list, tuple, dict)):
        return toml_value(v)
    return v


def flatten_record(rec: dict) -> dict:
    """A day record of ``summary.json`` as flat columns (module docstring).

    Nested tables become dotted columns (``events.<name>``, ``alive.<Species>``); ``regions``
    becomes ``regions.<name>.covered_area_m2`` [m2].

    Parameters
    ----------
    rec : dict
        One entry of the summary's ``days_record``.

    Returns
    -------
    dict
        Column name -> value.
    """
    row = {}
    for k, v in rec.items():
        if k == "regions":
            for name, area in v.items():
                row[f"regions.{name}.covered_area_m2"] = area
        elif isinstance(v, dict):
            for kk, vv in v.items():
                row[f"{k}.{kk}"] = vv
        else:
            row[k] = v
    return row


def tidy(sw: Sweep, results: list):
    """The sweep's table from the run results (:func:`mitsuba_veg.sweeps.runner.run_task`).

    Parameters
    ----------
    sw : Sweep
        The sweep (its swept fields name the columns).
    results : list of dict
        One result per run, in the sweep's order.

    Returns
    -------
    pandas.DataFrame
    """
    import pandas as pd

    fields = sw.fields
    values = {r.run_id: r.values for r in sw.runs}
    rows = []
    for res in results:
        base = {"run": res["run_id"], "index": res["index"], "status": res["status"],
                "error": res["error"] or ""}
        base.update({f: _cell(values[res["run_id"]].get(f)) for f in fields})
        recs = res["records"] if res["status"] != "failed" else []
        if not recs:
            rows.append(dict(base))
        for rec in recs:
            rows.append({**base, **flatten_record(rec)})
    df = pd.DataFrame(rows)
    lead = list(RUN_COLUMNS) + fields + ["day", "date"]
    for c in lead:
        if c not in df.columns:
            df[c] = pd.NA
    rest = [c for c in df.columns if c not in lead]
    alive = sorted(c for c in rest if c.startswith("alive."))
    rest = alive + [c for c in rest if c not in alive]
    df = df[lead + rest]
    for c in df.columns:
        if c in fields or c in ("error", "status", "run", "date"):
            continue
        col = df[c]
        if col.dtype == float and col.notna().any() and \
                (col.dropna() == col.dropna().round()).all() and not c.startswith(
                    ("mean_", "seconds.", "covered_", "regions.")):
            df[c] = col.astype("Int64")     # counts of failed runs' rows stay empty
    if "day" in df.columns and df["day"].dtype == object:
        df["day"] = pd.to_numeric(df["day"]).astype("Int64")
    return df.reset_index(drop=True)


def write_table(df, out) -> dict:
    """Write ``sweep.parquet`` and ``sweep.csv`` into ``out`` (atomically); returns their paths.

    Parameters
    ----------
    df : pandas.DataFrame
        The tidy table (:func:`tidy`).
    out : str or pathlib.Path
        Output folder (created if missing).

    Returns
    -------
    dict
        ``{"parquet": path, "csv": path}`` (str).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = {}
    for ext, write in (("parquet", lambda p: df.to_parquet(p, index=False)),
                       ("csv", lambda p: df.to_csv(p, index=False))):
        p = out / f"sweep.{ext}"
        with atomic_write(p) as tmp:
            write(tmp)
        files[ext] = str(p)
    return files


def comparable(df):
    """The table without what differs between identical runs: for comparing sweeps.

    Drops the ``seconds.*`` timing columns and ``status``, and sorts by ``index`` and ``day``
    (the order of completion differs).

    Parameters
    ----------
    df : pandas.DataFrame
        A tidy table (:func:`tidy`).

    Returns
    -------
    pandas.DataFrame
        The comparable table, with a fresh index.
    """
    drop = [c for c in df.columns if c.startswith("seconds.") or c == "status"]
    return df.drop(columns=drop).sort_values(["index", "day"]).reset_index(drop=True)
