"""Sweep throughput on Dask: runs per hour on 1 vs 2 local worker processes, and the overhead
of a task.

(a) the same sweep (4 air temperatures x 2 seeds = 8 moss-garden runs of ``--days`` days at
    ``--photons`` photons/day, maps on) on a LocalCluster of 1 worker process (Dr.Jit: all
    cores) and of 2 worker processes (Dr.Jit: cores / 2 each); each cluster is warmed up first
    (imports, kernels) and its start-up is timed apart; runs/hour = runs / sweep wall time;
(b) overhead per task: the round trip of a trivial task (median of 50), and one run (5 days)
    as a task vs the same run in this process with the same Dr.Jit threads (median of 3 each).

    python benchmarks/sweep_throughput.py [--days 20] [--photons 300000] [--reps 3]
"""
import argparse
import statistics
import tempfile
import time
from pathlib import Path

import mitsuba_veg as mv
from mitsuba_veg.sweeps import load_sweep
from mitsuba_veg.sweeps.cluster import machine_cores, open_client, set_drjit_threads
from mitsuba_veg.sweeps.runner import _task_spec, run_task

SCEN = Path(__file__).resolve().parent.parent / "scenes" / "moss_garden" / "scenario.toml"


def write_sweep(path: Path, days: int, photons: int) -> Path:
    path.write_text(f"""[sweep]
scenario = "{SCEN}"
days = {days}
seeds = [0, 1]
set = ["light.photons={photons}"]
frames = true
[axes]
"climate.temperature" = [283.15, 288.15, 293.15, 298.15]
""")
    return path


def _warm(tmp: str) -> float:
    """Import the package and compile the kernels in a worker (a 2-day run)."""
    import mitsuba_veg as mv_
    t = time.perf_counter()
    mv_.run(SCEN, out=Path(tmp) / f"warm-{time.time_ns()}", days=2, progress=False,
            frames=False, overrides=["light.photons=30000"])
    return time.perf_counter() - t


def _noop(x):
    return x


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--days", type=int, default=20)
    ap.add_argument("--photons", type=int, default=300_000)
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    cores = machine_cores()
    tmp = Path(tempfile.mkdtemp(prefix="sweep-bench-"))
    f = write_sweep(tmp / "sweep.toml", a.days, a.photons)
    n_runs = len(load_sweep(f).runs)
    print(f"machine: {cores} cores; sweep: {n_runs} runs x {a.days} days, "
          f"{a.photons:,d} photons/day, maps on")
    rates = {}
    from _record import Recorder
    rec = Recorder("sweep_throughput", notes=f"{n_runs} runs x {a.days} days, {a.photons:,d} "
                   "photons a day, maps on, on a local Dask cluster")
    for workers in (1, 2):
        t0 = time.perf_counter()
        with open_client(workers=workers, dashboard_address=":0") as (cl, info):
            cl.wait_for_workers(workers)
            t_start = time.perf_counter() - t0
            cl.run(set_drjit_threads, info.drjit_threads)
            cl.run(_warm, str(tmp))
            t_warm = time.perf_counter() - t0 - t_start
            t1 = time.perf_counter()
            df = mv.sweep(f, tmp / f"out-{workers}", client=cl, threads=info.drjit_threads,
                          progress=False, plots=False)
            wall = time.perf_counter() - t1
            assert set(df["status"]) == {"done"}, df[["run", "status", "error"]]
            rates[workers] = n_runs / wall * 3600
            print(f"(a) {workers} worker process{'es' if workers > 1 else ''} x "
                  f"{info.drjit_threads} Dr.Jit thread{'s' if info.drjit_threads > 1 else ''}: "
                  f"{n_runs} runs in {wall:.1f} s = {rates[workers]:.0f} runs/hour "
                  f"({wall / n_runs:.2f} s/run; cluster start {t_start:.1f} s, warm-up "
                  f"{t_warm:.1f} s)")
            rec.add(f"runs_per_hour_{workers}w", rates[workers], "runs/h",
                    f"runs per hour, {workers} worker process{'es' if workers > 1 else ''}")
            if workers == 1:
                # (b) overhead per task, on the 1-worker cluster (same Dr.Jit threads here)
                rt = []
                for i in range(50):
                    t = time.perf_counter()
                    cl.submit(_noop, i, pure=False).result()
                    rt.append(time.perf_counter() - t)
                sw = load_sweep(f, ["simulation.checkpoint_every=10"])
                spec0 = _task_spec(sw, sw.runs[0], tmp / "overhead")
                set_drjit_threads(info.drjit_threads)
                _warm(str(tmp))
                local, remote, inside = [], [], []
                for k in range(a.reps):
                    for where in ("local", "task"):
                        spec = dict(spec0, days=5, out=str(tmp / "overhead" / f"{where}{k}"))
                        t = time.perf_counter()
                        if where == "local":
                            run_task(spec)
                            local.append(time.perf_counter() - t)
                        else:
                            res = cl.submit(run_task, spec, pure=False).result()
                            remote.append(time.perf_counter() - t)
                            inside.append(res["seconds"])
                ml, mr, mi_ = (statistics.median(x) for x in (local, remote, inside))
                print(f"(b) trivial task round trip: median {statistics.median(rt) * 1e3:.1f} ms "
                      f"(min {min(rt) * 1e3:.1f}, max {max(rt) * 1e3:.1f}) over 50")
                print(f"    a 5-day run: in this process {ml:.2f} s, as a Dask task {mr:.2f} s "
                      f"round trip ({mi_:.2f} s inside the worker): overhead {mr - ml:+.2f} s "
                      f"per run ({(mr - ml) / ml:+.1%}); medians of {a.reps}")
                rec.add("task_round_trip_ms", statistics.median(rt) * 1e3, "ms",
                        "trivial Dask task round trip (median of 50)")
                rec.add("task_overhead", (mr - ml) / ml, "fraction",
                        "a 5-day run as a Dask task vs in this process (overhead)")
    print(f"(a) speed-up 2 workers vs 1: {rates[2] / rates[1]:.2f}x")
    rec.add("speedup_2w", rates[2] / rates[1], "ratio", "2 workers vs 1")
    rec.write()
    print(f"files under {tmp}")


if __name__ == "__main__":
    main()
