"""Gradients of the relaxed moss model: accuracy against finite differences, time and memory.

Part A - accuracy: the moss garden (Bryum argenteum, float64), the sqrt coverage loss against a
target made with other parameters; Dr.Jit reverse-mode gradient (day-by-day adjoint) against
central finite differences for species, climate and reflectance parameters.

Part B - cost: seconds per gradient (warm kernel cache: the second call) and the peak resident
memory of a process that prepares the garden and computes gradients, for both reverse-mode
schemes (``mode="adjoint"``: day-by-day with checkpoints; ``mode="graph"``: one AD graph), for
several run lengths; each configuration in its own process.

    python experiments/tune_gradients.py [--days 15 30 60 120] [--graph-days 15 30]
        [--species 1] [--cohort-days 1] [--skip-accuracy] [--out out/tune_gradients]
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _status(key: str) -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return float(line.split()[1]) / 1024.0
    return float("nan")


def reset_peak() -> float:
    """Reset the peak resident set size (Linux: /proc/self/clear_refs); returns the current RSS."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass
    return _status("VmRSS")


def accuracy(days=30):
    import drjit as dr

    import mitsuba_veg  # noqa: F401  (variant)
    import numpy as np

    from mitsuba_veg import tune
    from mitsuba_veg.tune.fitting import coverage_loss
    data = tune.prepare(SCEN, days=days, species=["bryum_argenteum"], photons=200_000,
                        light_every=15, differentiable_light=True)
    m = tune.SmoothMossModel(data, temperature=0.05, precision="float64")
    params = {"S1": 60.0, "T1": 299.15, "alpha_g": 0.3, "T": 288.15, "rh": 0.73,
              "albedo.roof": 0.35, "albedo.ground": 0.2, "strength.sky": 1.0}
    steps = {"S1": 0.5, "T1": 0.1, "alpha_g": 0.003, "T": 0.05, "rh": 0.002,
             "albedo.roof": 0.01, "albedo.ground": 0.01, "strength.sky": 0.01}
    with dr.suspend_grad():
        target = np.asarray(m.run({"S1": 50.0, "T1": 296.0, "alpha_g": 0.27, "T": 289.0,
                                   "rh": 0.75, "albedo.roof": 0.3}).cover)
    w, tg, lf = m.T(data.areas / data.areas.sum()), m.T(target), coverage_loss("sqrt")
    loss = lambda r, mm: lf(r.cover, tg, w, mm)  # noqa: E731
    g = tune.value_and_grad(m, params, loss)
    rows = []
    for k, h in steps.items():
        fd = tune.finite_difference(m, params, loss, k, h)
        rows.append({"param": k, "ad": g.grad[k], "fd": fd,
                     "rel_err": abs(g.grad[k] - fd) / abs(fd)})
    return rows


def one(mode: str, days: int, species: int, cohort_days: int = 1):
    import drjit as dr

    from mitsuba_veg import tune
    keys = ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"][:species]
    data = tune.prepare(SCEN, days=days, species=keys, photons=200_000, light_every=15)
    m = tune.SmoothMossModel(data, temperature=0.05, cohort_days=cohort_days)
    w = m.T(data.areas / data.areas.sum())
    loss = lambda r, mm: dr.sum(r.cover * w)  # noqa: E731
    names = ["S1", "T1"] if species == 1 else [f"{keys[0]}.S1", f"{keys[0]}.T1"]
    params = {names[0]: 60.0, names[1]: 299.15, "T": 288.15}
    with dr.suspend_grad():
        t0 = time.perf_counter()
        m.run(params)
        t_fwd = time.perf_counter() - t0
    base = reset_peak()
    out = []
    for i in range(2):
        t0 = time.perf_counter()
        r = tune.value_and_grad(m, params, loss, mode=mode)
        out.append(time.perf_counter() - t0)
    st = m.initial_state()
    return {"mode": mode, "days": days, "species": species, "cohort_days": cohort_days,
            "seconds_first": out[0],
            "seconds": out[1], "forward_s": t_fwd, "rss_before_mb": base,
            "peak_rss_mb": _status("VmHWM"),
            "state_mb": st.nbytes() / 2**20, "stats": {k: v for k, v in r.stats.items()}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--days", type=int, nargs="*", default=[15, 30, 60, 120])
    ap.add_argument("--graph-days", type=int, nargs="*", default=[15, 30])
    ap.add_argument("--species", type=int, default=1)
    ap.add_argument("--cohort-days", type=int, default=1)
    ap.add_argument("--out", default="out/tune_gradients")
    ap.add_argument("--one", nargs=4, metavar=("MODE", "DAYS", "SPECIES", "COHORT_DAYS"),
                    help=argparse.SUPPRESS)
    ap.add_argument("--skip-accuracy", action="store_true")
    a = ap.parse_args()
    if a.one:
        import mitsuba_veg  # noqa: F401
        print(json.dumps(one(a.one[0], int(a.one[1]), int(a.one[2]), int(a.one[3]))))
        return
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    res = {}
    if not a.skip_accuracy:
        rows = accuracy()
        res["accuracy"] = rows
        print("Part A: gradient vs central finite difference (30 days, float64)")
        for r in rows:
            print(f"  {r['param']:14s} AD {r['ad']: .6e}  FD {r['fd']: .6e}  "
                  f"rel err {r['rel_err']:.1e}")
    res["cost"] = []
    print("Part B: seconds per gradient (warm), peak RSS")
    for mode, days_list in (("adjoint", a.days), ("graph", a.graph_days)):
        for d in days_list:
            p = subprocess.run([sys.executable, __file__, "--one", mode, str(d), str(a.species),
                                str(a.cohort_days)], capture_output=True, text=True)
            if p.returncode != 0:
                print(f"  {mode} {d} days: failed\n{p.stderr[-2000:]}")
                continue
            r = json.loads(p.stdout.strip().splitlines()[-1])
            res["cost"].append(r)
            print(f"  {mode:8s} {d:4d} days: {r['seconds']:7.2f} s "
                  f"(first {r['seconds_first']:.1f} s,"
                  f" forward {r['forward_s']:.2f} s), peak RSS {r['peak_rss_mb']:.0f} MB "
                  f"(+{r['peak_rss_mb'] - r['rss_before_mb']:.0f} MB over the set-up), "
                  f"state {r['state_mb']:.1f} MB",
                  flush=True)
    (out / "gradients.json").write_text(json.dumps(res, indent=1))
    print(f"wrote {out / 'gradients.json'}")


if __name__ == "__main__":
    main()
