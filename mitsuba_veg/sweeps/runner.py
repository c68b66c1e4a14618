"""Run a sweep on Dask: one task per run, each writing its own run folder.

Layout of ``OUT``::

    runs/run-<id>/      one moss run (mitsuba_veg.run): summary.json, checkpoint.npz, maps/,
                        days.gif, run.json (its swept values), error.json (when it failed)
    sweep.parquet       the tidy table (one row per run and day), also sweep.csv
    sweep.json          the sweep: axes, runs (id, values, status, error), cluster, timings
    plots/              standard plots of the sweep

Every combination is checked before the cluster starts (:func:`~.spec.load_sweep`). A run
whose ``summary.json`` already has all its days is not run again; any other run is submitted
and resumes from its ``checkpoint.npz`` (:func:`mitsuba_veg.run` does so when the checkpoint is
of the same scenario and input files). A task first claims its run folder, waiting for a
process that still holds it (a worker of a killed sweep going away); a folder that stays
locked makes the sweep submit the run again (:data:`BUSY_RETRIES` times) before it reports it
as failed. A run that raises, or ends with fewer day records than its days, is recorded as
failed with its error and the sweep goes on; a worker lost mid-run makes Dask run the task
again elsewhere, and it resumes from the run's last checkpoint.
"""
from __future__ import annotations

import json
import os
import socket
import time
import traceback
import uuid
from pathlib import Path

from ..daily import SIM_DEFAULTS
from ..daily.run import run
from ..errors import FolderBusy, MitsubaVegError
from ..outputs import OutputFolder, write_json
from ..scenario import load_scenario
from .cluster import open_client, require_pandas, set_drjit_threads, worker_drjit_threads
from .plots import sweep_plots
from .spec import RunSpec, Sweep, load_sweep
from .table import tidy, write_table

__all__ = ["TASK_PREFIX", "expected_days", "finished", "RUN_LOCK_WAIT_S", "BUSY_RETRIES",
           "run_task", "sweep"]

#: task key prefix (groups the runs on the Dask dashboard)
TASK_PREFIX = "mitsuba-veg-run"


def expected_days(scenario, overrides, days) -> int | None:
    """Days a run will simulate.

    ``days``, else the scenario's ``simulation.days`` (300 by default); None when the scenario
    with these overrides does not load (the run will say why).

    Parameters
    ----------
    scenario : str or pathlib.Path
        The scenario file.
    overrides : sequence of str
        The run's ``--set`` overrides (``field=value``).
    days : int or None
        Days forced by the sweep (None: the scenario's).

    Returns
    -------
    int or None
        Simulated days [days], or None when the scenario does not load.
    """
    if days is not None:
        return int(days)
    try:
        scn = load_scenario(scenario, overrides)
    except MitsubaVegError:
        return None
    return int(scn.get("simulation.days", SIM_DEFAULTS["days"]))


def finished(run_dir, days: int | None) -> dict | None:
    """The summary of a finished run in ``run_dir`` (all ``days`` days recorded), else None.

    Parameters
    ----------
    run_dir : str or pathlib.Path
        The run folder (holding ``summary.json``).
    days : int or None
        Days the run must have recorded [days]; None: never counts as finished.

    Returns
    -------
    dict or None
        The parsed ``summary.json``, or None when missing, unreadable or incomplete.
    """
    p = Path(run_dir) / "summary.json"
    if days is None or not p.is_file():
        return None
    try:
        s = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    recs = s.get("days_record") or []
    if s.get("days") == days and len(recs) == days and recs[-1].get("day") == days:
        return s
    return None


def _result(spec: dict, status: str, summary: dict | None = None, error: str | None = None,
            tb: str | None = None, seconds: float = 0.0, threads: int | None = None) -> dict:
    return {"run_id": spec["run_id"], "index": spec["index"], "status": status,
            "error": error, "traceback": tb, "records": (summary or {}).get("days_record", []),
            "resumed": bool((summary or {}).get("resumed", False)), "seconds": seconds,
            "worker": f"{socket.gethostname()}:{os.getpid()}", "drjit_threads": threads}


#: how long a run task waits for its run folder when another process holds it [s]: a task of
#: a killed sweep still going away, or the same run in a concurrent sweep (then this one finds
#: it finished)
RUN_LOCK_WAIT_S = 120.0
#: how often the sweep submits a run again whose folder stayed busy
BUSY_RETRIES = 3


def run_task(spec: dict) -> dict:
    """One run of a sweep (a Dask task; also callable in-process).

    The task claims the run folder first (:class:`~mitsuba_veg.outputs.OutputFolder`), waiting
    up to :data:`RUN_LOCK_WAIT_S` for another process that holds it, then looks again whether
    the run is finished (the holder may have finished it), writes ``run.json`` and runs or
    resumes. A run that ends with fewer day records than its days is a failed run, never a
    done one.

    Parameters
    ----------
    spec : dict
        ``run_id``, ``index``, ``scenario`` (absolute path), ``overrides`` (list of
        ``KEY=VALUE``), ``out`` (the run folder), ``days`` (or None), ``frames`` (bool),
        ``values`` (swept values), ``drjit_threads`` (int or None), ``host_workers``
        (host -> worker processes).

    Returns
    -------
    dict
        ``run_id``, ``index``, ``status`` (``"done"``, ``"skipped"``: already finished,
        ``"failed"``, ``"busy"``: the folder stayed locked by another process, to be
        submitted again), ``error`` (one line) and ``traceback``, ``records`` (the run's
        ``days_record``), ``resumed``, ``seconds`` [s], ``worker``, ``drjit_threads``.
    """
    t0 = time.perf_counter()
    out = Path(spec["out"])
    threads = set_drjit_threads(worker_drjit_threads(spec.get("drjit_threads"),
                                                     spec.get("host_workers") or {}))
    days = expected_days(spec["scenario"], spec["overrides"], spec["days"])
    done = finished(out, days)
    if done is not None:
        return _result(spec, "skipped", done, seconds=time.perf_counter() - t0, threads=threads)
    try:
        folder = OutputFolder(out, "run", info={"scenario": spec["scenario"]},
                              wait=float(spec.get("lock_wait", RUN_LOCK_WAIT_S)))
    except FolderBusy as e:
        return _result(spec, "busy", error=" ".join(f"{type(e).__name__}: {e}".split()),
                       seconds=time.perf_counter() - t0, threads=threads)
    with folder:
        done = finished(out, days)        # the holder waited for may have finished it
        if done is not None:
            return _result(spec, "skipped", done, seconds=time.perf_counter() - t0,
                           threads=threads)
        write_json(out / "run.json", {"run_id": spec["run_id"], "values": spec["values"],
                                      "overrides": spec["overrides"],
                                      "scenario": spec["scenario"], "days": spec["days"]})
        try:
            summary = run(spec["scenario"], out=out, days=spec["days"],
                          overrides=spec["overrides"], resume=True, progress=False,
                          frames=bool(spec["frames"]))
        except Exception as e:  # noqa: BLE001 - a failing run is a result of the sweep
            msg = " ".join(f"{type(e).__name__}: {e}".split())
            tb = traceback.format_exc()
            write_json(out / "error.json", {"error": msg, "traceback": tb})
            return _result(spec, "failed", error=msg, tb=tb, seconds=time.perf_counter() - t0,
                           threads=threads)
        n = len(summary.get("days_record") or [])
        if days is not None and n != days:
            msg = (f"RuntimeError: the run recorded {n} of its {days} days (run it again: "
                   "it resumes from its checkpoint)")
            write_json(out / "error.json", {"error": msg, "traceback": ""})
            return _result(spec, "failed", error=msg, seconds=time.perf_counter() - t0,
                           threads=threads)
        folder.clear(["error.json"])
    return _result(spec, "done", summary, seconds=time.perf_counter() - t0, threads=threads)


def _task_error(fut) -> str:
    """One line for a task that Dask could not finish (KilledWorker, cancelled ...)."""
    if fut.status == "cancelled":
        return "CancelledError: the task was cancelled"
    exc = fut.exception()
    return " ".join(f"{type(exc).__name__}: {exc}".split())


def _task_spec(sw: Sweep, r: RunSpec, runs_dir: Path) -> dict:
    return {"run_id": r.run_id, "index": r.index, "scenario": str(sw.scenario),
            "overrides": list(r.overrides), "out": str(runs_dir / r.run_id), "days": sw.days,
            "frames": sw.frames, "values": r.values, "drjit_threads": None, "host_workers": {}}


def sweep(sweep_file, out="out/sweep", *, scheduler: str | None = None,
          workers: int | None = None, client=None, overrides=(), threads: int | None = None,
          progress: bool = True, plots: bool = True, dashboard_address: str = ":8787"):
    """Run a sweep on Dask and gather its results into one tidy table.

    Parameters
    ----------
    sweep_file : str or Path
        The sweep TOML (:mod:`mitsuba_veg.sweeps.spec`).
    out : str or Path
        Output folder (module docstring); a sweep run again into the same folder skips the
        finished runs and resumes the others from their checkpoints.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); the workers must see ``out``
        and the scenario at the same paths (a shared file system). Default: a ``LocalCluster``.
    workers : int, optional
        Worker processes of the local cluster (default: one per core, at most one per 2 GiB
        of memory); with ``scheduler``: wait for this many workers before submitting.
    client : distributed.Client, optional
        Use this client (its cluster is left running).
    overrides : sequence of str
        ``KEY=VALUE`` overrides of the base scenario for every run.
    threads : int, optional
        Dr.Jit threads per worker (default: cores // worker processes of the host).
    progress : bool
        Print the dashboard link and show a progress bar (runs).
    plots : bool
        Write the standard plots (``OUT/plots``).
    dashboard_address : str
        Dashboard address of a local cluster (``":0"``: any free port).

    Returns
    -------
    pandas.DataFrame
        One row per run and day (a failed run: one row without a day), columns ``run``,
        ``status``, ``error``, every swept field, ``day``, ``date`` and every number of the
        day records (see :func:`mitsuba_veg.sweeps.table.tidy`).

    Raises
    ------
    ParameterError
        A bad sweep file, axis field or base scenario (before any run starts).
    DependencyError
        Dask, pandas or pyarrow missing (``pip install 'mitsuba-veg[distributed]'``).
    """
    sw = load_sweep(sweep_file, overrides)
    require_pandas()
    t_start = time.perf_counter()
    out = Path(out).resolve()
    # one sweep per folder at a time (each run's own folder is locked by its run as well)
    folder = OutputFolder(out, "sweep", info={"sweep": str(sw.path)})
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    specs = [_task_spec(sw, r, runs_dir) for r in sw.runs]
    results = {}
    todo = []
    for s in specs:
        done = finished(s["out"], expected_days(s["scenario"], s["overrides"], s["days"]))
        if done is not None:
            results[s["run_id"]] = _result(s, "skipped", done)
        else:
            todo.append(s)
    info = None
    if todo:
        with open_client(scheduler, workers, client, threads, dashboard_address) as (cl, info):
            from distributed import as_completed
            for s in todo:
                s["drjit_threads"] = info.drjit_threads
                s["host_workers"] = info.host_workers
            if progress:
                print(f"mitsuba-veg sweep: {len(sw.runs)} runs ({len(results)} finished "
                      f"before, {len(todo)} to run) on {info.workers} Dask worker"
                      f"{'s' if info.workers != 1 else ''} ({'local cluster' if info.local else info.address})")
                if info.dashboard:
                    print(f"Dask dashboard: {info.dashboard}")
            def submit(s, attempt=0):
                key = f"{TASK_PREFIX}-{s['run_id']}-{uuid.uuid4().hex[:8]}"
                by_key[key] = (s, attempt)
                return cl.submit(run_task, s, key=key, pure=False)

            by_key = {}
            futures = as_completed([submit(s) for s in todo])
            bar = None
            if progress:
                from tqdm.auto import tqdm
                bar = tqdm(total=len(sw.runs), initial=len(results), unit="run", desc="sweep")
            n_failed = 0
            for fut in futures:
                s, attempt = by_key.pop(fut.key)
                if fut.status == "finished":
                    res = fut.result()
                else:  # the task itself could not finish (e.g. its workers kept dying)
                    res = _result(s, "failed", error=_task_error(fut))
                fut.release()
                if res["status"] == "busy":
                    if attempt + 1 < BUSY_RETRIES:     # its folder stayed locked: again
                        futures.add(submit(s, attempt + 1))
                        continue
                    res["status"] = "failed"
                results[s["run_id"]] = res
                n_failed += res["status"] == "failed"
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix(failed=n_failed, last=f"{res['seconds']:.0f}s")
            if bar is not None:
                bar.close()
    ordered = [results[s["run_id"]] for s in specs]
    table = tidy(sw, ordered)
    files = write_table(table, out)
    if plots:
        files["plots"] = [str(p) for p in sweep_plots(table, sw, out / "plots")]
    manifest = {
        "sweep": str(sw.path), "scenario": str(sw.scenario), "days": sw.days,
        "axes": sw.axes, "set": sw.base_set, "frames": sw.frames,
        "runs": [{"run": r["run_id"], "index": r["index"], "values": s["values"],
                  "status": r["status"], "error": r["error"], "resumed": r["resumed"],
                  "seconds": r["seconds"], "worker": r["worker"],
                  "drjit_threads": r["drjit_threads"], "folder": s["out"]}
                 for r, s in zip(ordered, specs)],
        "counts": {k: sum(r["status"] == k for r in ordered)
                   for k in ("done", "skipped", "failed")},
        "cluster": None if info is None else {
            "local": info.local, "address": info.address, "dashboard": info.dashboard,
            "workers": info.workers, "drjit_threads": info.drjit_threads},
        "seconds": time.perf_counter() - t_start, "files": files}
    write_json(out / "sweep.json", manifest)
    folder.release()
    return table
