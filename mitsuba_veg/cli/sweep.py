"""``mitsuba-veg sweep SWEEP.toml [--scheduler ADDRESS] [--workers N] [--out DIR]``.

Runs every run of a sweep file as a Dask task (a local cluster of worker processes, or the
cluster behind ``--scheduler``), prints the dashboard link and a progress bar, and writes
``OUT/sweep.parquet``, ``OUT/sweep.csv``, ``OUT/sweep.json`` and ``OUT/plots/``. Exit code 0
when every run finished, 1 when some failed (the table has their errors), 2 for a bad sweep
file or a missing extra (one line on stderr).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from ..sweeps.runner import sweep
from .args import add_out, add_quiet, add_set, ranged

__all__ = ["add_parser"]


def add_parser(subparsers) -> None:
    """Add ``sweep`` to the ``mitsuba-veg`` sub-command parsers.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command registry of the ``mitsuba-veg`` parser (``add_subparsers()``).
    """
    s = subparsers.add_parser("sweep", help="many moss runs on Dask (axes x seeds) -> one table")
    s.add_argument("sweep_file", help="sweep TOML, e.g. scenes/moss_garden/sweep.toml")
    s.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local "
                        "cluster of worker processes)")
    s.add_argument("--workers", type=ranged(int, 1, 4096, "processes"), metavar="N",
                   help="worker processes of the local cluster (default: one per core); with "
                        "--scheduler: wait for N workers")
    s.add_argument("--threads", type=ranged(int, 1, 1024, "threads"), metavar="N",
                   help="Dr.Jit threads per worker (default: cores // worker processes)")
    add_out(s, "out/sweep", "the table, the runs and the plots")
    add_set(s, "base scenario")
    s.add_argument("--no-plots", action="store_true", help="skip the standard plots")
    add_quiet(s, "no progress bar and no per-run lines")
    s.set_defaults(func=_cmd_sweep)


def _cmd_sweep(a) -> int:
    out = Path(a.out)
    df = sweep(a.sweep_file, out, scheduler=a.scheduler, workers=a.workers,
               overrides=a.set or (), threads=a.threads, progress=not a.quiet,
               plots=not a.no_plots)
    m = json.loads((out / "sweep.json").read_text())
    c = m["counts"]
    print(f"{len(m['runs'])} runs: {c['done']} run now, {c['skipped']} finished before, "
          f"{c['failed']} failed; {len(df)} rows in {m['seconds']:.1f} s")
    for r in m["runs"]:
        if r["status"] == "failed":
            print(f"  failed {r['run']} {r['values']}: {r['error']}")
    print("wrote:")
    for k in ("parquet", "csv"):
        print(f"  {m['files'][k]}")
    print(f"  {out.resolve() / 'sweep.json'}")
    for p in m["files"].get("plots", []):
        print(f"  {p}")
    print(f"  {out.resolve() / 'runs'}/run-*/ (summary.json, checkpoint.npz, maps)")
    if c["failed"]:   # also with --quiet: on stderr, one line
        first = next(r for r in m["runs"] if r["status"] == "failed")
        print(f"mitsuba-veg: error: {c['failed']} of {len(m['runs'])} runs failed (the first: "
              f"{first['run']}: {first['error']}); see {out / 'sweep.json'}", file=sys.stderr)
    return 1 if c["failed"] else 0
