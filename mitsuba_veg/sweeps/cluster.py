"""Dask clusters for sweeps and frames: a ``LocalCluster`` of worker processes sized to the
machine, or an existing scheduler; Dr.Jit's thread pool per worker sized so that the workers do
not oversubscribe the cores.

Dask is imported here, lazily: the rest of the package works without the ``distributed`` extra.
"""
from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass

import drjit as dr

from ..errors import DependencyError, ParameterError

__all__ = ["WORKER_MEMORY", "require_distributed", "require_pandas", "machine_cores",
           "machine_memory", "local_workers", "ClusterInfo", "open_client", "worker_drjit_threads",
           "set_drjit_threads"]

#: memory one worker process should have for a moss-garden run at the default scale [bytes]
WORKER_MEMORY = 2 * 1024**3


def require_distributed():
    """``dask.distributed``, or :class:`~mitsuba_veg.errors.DependencyError` naming the fix.

    Returns
    -------
    module
        The ``distributed`` module.
    """
    try:
        import distributed
    except ModuleNotFoundError as e:
        raise DependencyError(
            f"sweeps and Dask frame rendering need dask.distributed, pandas and pyarrow "
            f"({e.name} is missing). Fix: pip install 'mitsuba-veg[distributed]' "
            f"(in a source checkout: pip install -e '.[distributed]')") from None
    return distributed


def require_pandas():
    """``pandas`` (and a Parquet engine), or :class:`DependencyError` naming the fix.

    Returns
    -------
    module
        The imported ``pandas`` module (``pyarrow`` is imported too).

    Raises
    ------
    DependencyError
        If pandas or pyarrow is missing (fix: ``pip install 'mitsuba-veg[distributed]'``).
    """
    try:
        import pandas
        import pyarrow  # noqa: F401  (Parquet)
    except ModuleNotFoundError as e:
        raise DependencyError(
            f"the sweep table needs pandas and pyarrow ({e.name} is missing). Fix: pip install "
            f"'mitsuba-veg[distributed]'") from None
    return pandas


def machine_cores() -> int:
    """CPU cores this process may use (affinity mask, else the CPU count).

    Returns
    -------
    int
        Core count, at least 1.
    """
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # pragma: no cover - not Linux
        return max(os.cpu_count() or 1, 1)


def machine_memory() -> int | None:
    """Physical memory [bytes], or None when unknown.

    Returns
    -------
    int or None
        Page size x physical pages [bytes]; None where ``os.sysconf`` cannot tell.
    """
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover
        return None


def local_workers(workers: int | None = None) -> tuple[int, int]:
    """Worker processes and Dr.Jit threads per worker for a local cluster.

    Parameters
    ----------
    workers : int, optional
        Worker processes; default: one per core, at most one per ``WORKER_MEMORY`` (2 GiB) of
        memory.

    Returns
    -------
    (int, int)
        Worker processes, Dr.Jit threads per worker (cores // workers, at least 1).
    """
    cores = machine_cores()
    if workers is None:
        mem = machine_memory()
        workers = cores if mem is None else max(1, min(cores, mem // WORKER_MEMORY))
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= 1024:
        raise ParameterError("--workers", workers, "an integer in [1, 1024]",
                             f"e.g. --workers {cores} (this machine has {cores} cores)")
    return workers, max(1, cores // workers)


@dataclass
class ClusterInfo:
    """Where the tasks run.

    Attributes
    ----------
    local : bool
        A LocalCluster started here (else an existing scheduler or client).
    address : str
        The scheduler's address.
    dashboard : str or None
        The Dask dashboard link.
    workers : int
        Worker processes when the tasks were submitted.
    drjit_threads : int or None
        Dr.Jit threads per worker (None: each worker takes its host's cores divided by the
        worker processes on that host).
    """

    local: bool
    address: str
    dashboard: str | None
    workers: int
    drjit_threads: int | None
    host_workers: dict


def _host_workers(client) -> dict:
    """Worker processes per host (IP) of the cluster."""
    from distributed.comm import get_address_host
    out = {}
    for addr in client.scheduler_info(n_workers=-1)["workers"]:
        h = get_address_host(addr)
        out[h] = out.get(h, 0) + 1
    return out


@contextlib.contextmanager
def open_client(scheduler=None, workers: int | None = None, client=None,
                drjit_threads: int | None = None, dashboard_address: str = ":8787"):
    """A Dask client for the tasks; closes what it started.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``); default: start a
        ``LocalCluster`` of ``workers`` processes (one task at a time each).
    workers : int, optional
        Worker processes of the local cluster (see :func:`local_workers`). With ``scheduler``
        or ``client``: wait until at least this many workers have joined.
    client : distributed.Client, optional
        An existing client to use (neither started nor closed here).
    drjit_threads : int, optional
        Dr.Jit threads per worker; default: cores // workers locally, and the host's cores
        divided by its worker processes on a remote cluster.
    dashboard_address : str
        Dashboard of a local cluster (``":0"``: any free port).

    Yields
    ------
    (distributed.Client, ClusterInfo)
    """
    distributed = require_distributed()
    if drjit_threads is not None and (isinstance(drjit_threads, bool) or
                                      not isinstance(drjit_threads, int) or drjit_threads < 1):
        raise ParameterError("--threads", drjit_threads, "an integer >= 1", None)
    if client is not None or scheduler is not None:
        own = client is None
        if own:
            try:
                client = distributed.Client(scheduler, timeout="30s")
            except OSError as e:
                raise ParameterError("--scheduler", scheduler, "the address of a running Dask "
                                     "scheduler, e.g. tcp://10.0.0.5:8786",
                                     f"start one with `dask scheduler` ({e})") from None
        try:
            if workers:
                client.wait_for_workers(int(workers), timeout=600)
            hw = _host_workers(client)
            yield client, ClusterInfo(False, client.scheduler.address, client.dashboard_link,
                                      sum(hw.values()), drjit_threads, hw)
        finally:
            if own:
                client.close()
        return
    n, threads = local_workers(workers)
    cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                       dashboard_address=dashboard_address)
    try:
        client = distributed.Client(cluster)
        try:
            yield client, ClusterInfo(True, cluster.scheduler_address, client.dashboard_link, n,
                                      drjit_threads or threads, {})
        finally:
            client.close()
    finally:
        cluster.close()


def worker_drjit_threads(drjit_threads: int | None, host_workers: dict) -> int:
    """Dr.Jit threads for the worker this runs on.

    ``drjit_threads`` if given, else the host's cores divided by the worker processes on the
    host (at least 1); outside a Dask worker, all the machine's cores.

    Parameters
    ----------
    drjit_threads : int or None
        Threads asked for (None or 0: derive them).
    host_workers : dict
        Worker processes per host IP (``ClusterInfo.host_workers``).

    Returns
    -------
    int
        Dr.Jit threads to use, >= 1.
    """
    if drjit_threads:
        return int(drjit_threads)
    n = 1
    try:
        from distributed import get_worker
        from distributed.comm import get_address_host
        n = host_workers.get(get_address_host(get_worker().address), 1)
    except ValueError:  # not running in a worker
        pass
    return max(1, machine_cores() // max(n, 1))


def set_drjit_threads(n: int) -> int:
    """Size Dr.Jit's (process-wide) thread pool.

    Parameters
    ----------
    n : int
        Threads wanted.

    Returns
    -------
    int
        The thread count now in use.
    """
    if dr.thread_count() != n:
        dr.set_thread_count(int(n))
    return dr.thread_count()
