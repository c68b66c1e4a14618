"""Inverse problems on *discrete* targets solved on the discrete model (``tune.fit_discrete``:
defect correction with the relaxed model's gradient, docs/tuning.md).

Target: the mean covered fraction per triangle of ``--target-seeds`` discrete runs with the
scenario's (true) values, or with ``--truth NAME=VALUE`` changed; the fit runs the discrete
model on other seeds (``--seeds``, common random numbers) and the relaxed model (near field) for
the gradient. One parameter at a time from -30 % and +30 % starts, then jointly from box corners.
For T1 the +-30 % is of its range T1 - T0 (25 K). ``--tree X,Z`` adds a 3 m Weber-Penn aspen
to the scenario and makes the target (and the fit's discrete runs) with the scenario's trees in the daily pipeline: the
tree shades the ground; the relaxed surrogate has no tree. ``--report 10,20,30``: the target
is the maps of those days (a time series). ``--eval NAME=V,...`` (repeatable) prints the
discrete loss of the fit's seeds at those values and stops, or with ``--eval-then-fit`` goes on
to the fits.

    python experiments/tune_discrete_fit.py --params S1,T1,alpha_g --days 30 --photons 250000
    python experiments/tune_discrete_fit.py --params strength.sky --joint 0
    python experiments/tune_discrete_fit.py --tree 0.3,1.4 --start-date 2026-05-01 \
        --params S1 --starts -0.3 --joint 0 --days 25 --target-seeds 100-103 --seeds 0-3
    python experiments/tune_discrete_fit.py --params S1,T1,alpha_g --starts "" --joint 1 \
        --iterations 6 --steps 20 --report 10,20,30

``--window NAME:START_DATE:T_AIR`` (repeatable) makes the target of several experiments: the
garden from START_DATE with the daily air temperature T_AIR [K], each with its own target maps,
discrete model and relaxed surrogate; the fit (``fit_discrete_experiments``) adds their losses.

    python experiments/tune_discrete_fit.py --params S1,T1,alpha_g --starts "" --corners 0 \
        --window spring:2026-04-01:283.15 --window summer:2026-07-01:295.15 --report 10,20,30
"""
from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.tune.discrete import (DiscreteExperiment, DiscreteMossModel,  # noqa: E402
                                       fit_discrete_experiments, patch_cover, patch_labels,
                                       patch_loss_value)
from mitsuba_veg.tune.fitting import parameter_scale  # noqa: E402
from mitsuba_veg.scenario import Scenario, load_scenario  # noqa: E402


def seeds_arg(s: str) -> list[int]:
    """Seeds from ``"A-B"`` (inclusive) or ``"a,b,c"``.

    Parameters
    ----------
    s : str
        The seeds.

    Returns
    -------
    list of int
        The seed numbers.
    """
    if "-" in s:
        a, b = s.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in s.split(",")]


def main():
    """Build the targets of the windows, then run ``--eval`` or the fits (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenes" / "moss_garden" / "scenario.toml"))
    ap.add_argument("--species", default="bryum_argenteum")
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--photons", type=int, default=250_000)
    ap.add_argument("--target-seeds", default="100-107")
    ap.add_argument("--seeds", default="0-7")
    ap.add_argument("--params", default="S1,T1,alpha_g")
    ap.add_argument("--truth", action="append", default=[], help="NAME=VALUE of the target")
    ap.add_argument("--starts", default="-0.3,0.3", help="relative starts, one at a time")
    ap.add_argument("--joint", type=int, default=2, help="joint fits (box corners)")
    ap.add_argument("--corners", default=None, help="which corners (indices 0-3 of (-,+,-), "
                    "(+,-,+), (-,-,-), (+,+,+)), e.g. 1; default: the first --joint")
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--steps", type=int, default=25)
    ap.add_argument("--tree", default=None, help="world target: add a Weber-Penn aspen at "
                    "X,Z [m] (3 m tall) to the scenario and run it with the trees in the light")
    ap.add_argument("--start-date", default=None, help="simulation.start_date override")
    ap.add_argument("--patch", type=float, default=0.2)
    ap.add_argument("--report", default=None, help="target days, e.g. 10,20,30 (a time series "
                    "of maps; default: the last day)")
    ap.add_argument("--closure", default="near-field")
    ap.add_argument("--siblings", type=int, default=1, choices=(0, 1),
                    help="near-field surrogate: a parent's fixed point (SmoothMossModel siblings)")
    ap.add_argument("--moss-pairs", type=int, default=1, choices=(0, 1),
                    help="near-field surrogate: the occupancy seen from a moss (moss_pairs); "
                         "--siblings 0 --moss-pairs 0 is the surrogate of b4a1d50")
    ap.add_argument("--temperature", type=float, default=0.02)
    ap.add_argument("--init", default=None, help="a joint start NAME=V,NAME=V (instead of "
                    "box corners; e.g. to continue a fit)")
    ap.add_argument("--eval", action="append", default=[],
                    help="only print the discrete loss (fit seeds) at NAME=V,NAME=V points")
    ap.add_argument("--eval-then-fit", action="store_true", help="after --eval, run the fits "
                    "as without it (same targets and set-up)")
    ap.add_argument("--window", action="append", default=[],
                    help="NAME:START_DATE:T_AIR of one experiment (repeatable; START_DATE or "
                    "T_AIR may be empty: the scenario's); default: one, the scenario")
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--lr", type=float, default=0.08)
    ap.add_argument("--accept", default="always", choices=["always", "decrease"],
                    help="outer step: take every step, or only (halved) steps that lower the "
                    "discrete loss")
    ap.add_argument("--backtrack", type=int, default=2, help="step halvings with --accept "
                    "decrease")
    ap.add_argument("--out", default="out/tune_discrete_fit")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    names = a.params.split(",")
    species = a.species.split(",")
    t0 = time.perf_counter()
    world = a.tree is not None
    windows = a.window or [f"main:{a.start_date or ''}:"]
    light = any(p.startswith(("albedo.", "strength.")) for p in names)
    report = [int(d) for d in a.report.split(",")] if a.report else [a.days]
    exps, truth = [], None
    for spec in windows:
        wname, start, T_air = spec.split(":")
        scn = load_scenario(a.scenario)
        d = copy.deepcopy(scn.data)
        if start:
            d.setdefault("simulation", {})["start_date"] = start
        if T_air:
            d.setdefault("climate", {})["temperature"] = float(T_air)
        if world:
            x, z = (float(v) for v in a.tree.split(","))
            d["trees"] = [{"name": "aspen", "model": "weber_penn", "preset": "quaking_aspen",
                           "position": [x, 0.0, z], "height": 3.0, "seed": 3}]
        scn = Scenario(scn.path, d)
        data = tune.prepare(scn, days=a.days, species=species, photons=a.photons,
                            light_every=15, differentiable_light=light)
        sm = tune.SmoothMossModel(data, temperature=a.temperature, closure=a.closure,
                                  siblings=bool(a.siblings), moss_pairs=bool(a.moss_pairs))
        dm = DiscreteMossModel(scn, a.days, species=species, seeds=seeds_arg(a.seeds),
                               photons=a.photons, world=world)
        if truth is None:
            truth = {p: dm.default_value(p) for p in names}
            for item in a.truth:
                k, v = item.split("=")
                truth[k] = float(v)
        tm = DiscreteMossModel(scn, a.days, species=species, seeds=seeds_arg(a.target_seeds),
                               photons=a.photons, world=world)
        if set(tm.seeds) & set(dm.seeds):
            raise SystemExit("--seeds and --target-seeds must be disjoint")
        tr = tm.run(truth, report=report)
        target = {day: tm.to_layout(tr.mean(day), data.shape_slices) for day in report}
        exps.append(DiscreteExperiment(dm, sm, target, name=wname))
        kind = "world: garden + aspen" if world else "garden"
        print(f"target {spec}: mean of {len(tm.seeds)} discrete runs ({kind}, "
              f"{a.days} days, {a.photons} photons), truth {truth}: covered "
              f"{np.mean(tr.total[:, -1]):.4f} m2 (sd {np.std(tr.total[:, -1]):.4f}); maps of "
              f"days {report}; set-up {time.perf_counter() - t0:.0f} s", flush=True)
    sm = exps[0].surrogate
    if a.eval:
        for point in a.eval:
            th = {k: float(v) for k, v in (x.split("=") for x in point.split(","))}
            tot, parts = 0.0, []
            for e in exps:
                data, dm = e.surrogate.data, e.discrete
                r = dm.run(th, report=report)
                ls = []
                for day in report:
                    lab = patch_labels(data.index.centroids, data.shape_slices,
                                       data.living & np.isfinite(e.target[day]), a.patch)
                    tp = patch_cover(np.nan_to_num(e.target[day]), data.areas, lab)
                    D = dm.to_layout(r.mean(day), data.shape_slices)
                    ls.append(patch_loss_value(D, data.areas, lab, tp))
                tot += float(np.mean(ls))
                parts.append(f"{e.name}: {np.mean(ls):.4e} (per day "
                             + ", ".join(f"{x:.3e}" for x in ls)
                             + f"; covered on day {report[-1]} {np.mean(r.total[:, -1]):.4f} m2)")
            print(f"discrete loss at {th}: {tot:.4e} = " + "; ".join(parts), flush=True)
        if not a.eval_then_fit:
            return
    scale = {p: parameter_scale(sm, p) for p in names}
    box = {p: 0.3 * (scale[p] if p in ("T1", "T0") else truth[p]) for p in names}
    rows = []

    def one(params, init):
        r = fit_discrete_experiments(exps, params, init=init, iterations=a.iterations,
                                     steps=a.steps, patch=a.patch, tol=a.tol,
                                     lr=a.lr, verbose=True, accept=a.accept,
                                     backtrack=a.backtrack)
        err = {k: (r.values[k] - truth[k]) / truth[k] for k in params}
        err_s = {k: (r.values[k] - truth[k]) / scale[k] for k in params}
        rows.append({"params": params, "init": init, "fitted": r.values, "err_rel": err,
                     "discrete_loss": r.discrete_loss,
                     "err_scale": err_s, "iterations": r.iterations, "seconds": r.seconds})
        print("  => " + ", ".join(f"{k}: {init[k]:.4g} -> {r.values[k]:.4g} (true "
                                  f"{truth[k]:.4g}; {err[k]:+.2%} of the value, "
                                  f"{err_s[k]:+.2%} of the scale {scale[k]:g})" for k in params)
              + f"; {len(r.iterations) - 1} iterations, {r.seconds:.0f} s", flush=True)
        (out / "inverse.json").write_text(json.dumps({"settings": vars(a), "truth": truth,
                                                      "fits": rows}, indent=1))

    starts = [float(x) for x in a.starts.split(",")] if a.starts else []
    if starts:
        print("one at a time:")
    for p in names:
        for sgn in starts:
            one([p], {p: truth[p] + sgn / 0.3 * box[p]})
    corners = [(-1, 1, -1), (1, -1, 1), (-1, -1, -1), (1, 1, 1)]
    corners = [corners[int(i)] for i in a.corners.split(",")] if a.corners else corners[:a.joint]
    if a.init:
        print("jointly, from --init:")
        one(names, {k: float(v) for k, v in (x.split("=") for x in a.init.split(","))})
    elif len(names) > 1 and corners:
        print("jointly:")
        for c in corners:
            one(names, {p: truth[p] + s * box[p] for p, s in zip(names, c)})
    (out / "inverse.json").write_text(json.dumps({"settings": vars(a), "truth": truth,
                                                  "fits": rows}, indent=1))
    print(f"wrote {out / 'inverse.json'}")


if __name__ == "__main__":
    main()
