"""Inverse problems on the moss garden with ``mitsuba_veg.tune.fit`` (docs/tuning.md).

Part A - synthetic (issue 8): the coverage map after ``--days`` days of a relaxed run with the
table 4.2 values of Bryum argenteum (S1 = 60 W m-2, T1 = 299.15 K) is the target; fits start
from the four corners of the +-30 % box (30 % of the range S1 - S0 = 60 W m-2 and T1 - T0 = 25 K).

Part B - a discrete run as the target: the coverage of ``mitsuba_veg.run`` (same species,
days and climate, several seeds) is fitted with the relaxed model, per triangle and on a coarse
plan-view grid (cells of ``--cell`` metres on the ground: the discrete map is a sparse pattern
of 1 cm moss, the relaxed one an expectation). The relaxed model is a mean-field model (docs:
it grows faster than the discrete one), so this part measures that model error, not the
optimiser.

    python experiments/tune_inverse.py [--days 30] [--steps 80] [--seeds 2] [--out out/tune_inverse]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import drjit as dr  # noqa: E402

import mitsuba_veg as mv  # noqa: E402
from mitsuba_veg import tune  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
TRUE = {"S1": 60.0, "T1": 299.15}
WIDTH = {"S1": 60.0, "T1": 25.0}


def coarse_loss(data, cell: float):
    """A loss on plan-view cells of the ground: area-weighted mean cover per cell, squared
    difference of square roots (the target given per element is aggregated the same way)."""
    g = data.shape_slices[data.scenario.get("terrain.ground", "ground")]
    c = data.index.centroids
    ij = np.floor((c[:, [0, 2]] + 1.0) / cell).astype(int)
    nc = int(np.ceil(2.0 / cell))
    cid = np.clip(ij[:, 0], 0, nc - 1) + nc * np.clip(ij[:, 1], 0, nc - 1)
    on = np.zeros(data.n, bool)
    on[g] = True

    def loss(cover, target, weights, model):
        T = model.T
        U = dr.uint32_array_t(T)
        idx, a = U(cid.astype(np.uint32)), T(np.where(on, data.areas, 0.0))
        area = dr.zeros(T, nc * nc)
        dr.scatter_add(area, a, idx)
        cm, tm = dr.zeros(T, nc * nc), dr.zeros(T, nc * nc)
        dr.scatter_add(cm, cover * a, idx)
        dr.scatter_add(tm, target * a, idx)
        safe = dr.maximum(area, 1e-12)
        d = dr.sqrt(cm / safe + 1e-6) - dr.sqrt(tm / safe + 1e-6)
        return dr.sum(d * d * area) / dr.sum(area)
    return loss


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--steps", type=int, default=80)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--cell", type=float, default=0.2)
    ap.add_argument("--out", default="out/tune_inverse")
    ap.add_argument("--skip-discrete", action="store_true")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    data = tune.prepare(SCEN, days=a.days, species=["bryum_argenteum"], photons=250_000,
                        light_every=15)
    model = tune.SmoothMossModel(data, temperature=0.05)
    with dr.suspend_grad():
        target = np.asarray(model.run(TRUE).cover, float)
    res = {"synthetic": [], "discrete": []}
    print(f"Part A: synthetic target ({a.days} days, {a.steps} Adam steps)")
    for ds in (-0.3, 0.3):
        for dt in (-0.3, 0.3):
            init = {"S1": TRUE["S1"] + ds * WIDTH["S1"], "T1": TRUE["T1"] + dt * WIDTH["T1"]}
            r = tune.fit(model, target, params=["S1", "T1"], init=init, steps=a.steps,
                         out=out / f"synthetic_{ds:+.1f}_{dt:+.1f}", progress=False)
            err = {k: abs(r.values[k] - TRUE[k]) / WIDTH[k] for k in TRUE}
            res["synthetic"].append({"init": init, "fitted": r.values, "err_of_range": err,
                                     "loss0": r.history[0]["loss"], "loss": r.loss,
                                     "seconds": r.seconds})
            print(f"  start S1 {init['S1']:5.1f} T1 {init['T1']:6.2f} -> S1 {r.values['S1']:6.2f} "
                  f"T1 {r.values['T1']:7.2f}  errors {err['S1']:.2%} / {err['T1']:.2%} of the "
                  f"range  loss {r.history[0]['loss']:.1e} -> {r.loss:.1e}  {r.seconds:.0f} s",
                  flush=True)
    if not a.skip_discrete:
        print(f"Part B: discrete runs as the target ({a.seeds} seeds)")
        maps = []
        for s in range(a.seeds):
            d = out / f"discrete_{s}"
            mv.run(SCEN, out=d, days=a.days, progress=False, frames=False, resume=False,
                   overrides=["light.photons=250000", f"light.seed={s}",
                              "moss.species=['bryum_argenteum']", "simulation.checkpoint_every=0"])
            maps.append(tune.coverage_from_checkpoint(d / "checkpoint.npz", data))
        disc = np.mean(maps, axis=0)
        print(f"  discrete covered area {np.sum(disc * data.areas):.3f} m2, relaxed with the true "
              f"parameters {np.sum(target * data.areas):.3f} m2")
        for name, loss in (("per triangle", "sqrt"),
                           (f"{a.cell:g} m cells", coarse_loss(data, a.cell))):
            init = {"S1": TRUE["S1"] * 0.7, "T1": TRUE["T1"] + 0.3 * WIDTH["T1"]}
            r = tune.fit(model, disc, params=["S1", "T1"], init=init, steps=a.steps, loss=loss,
                         out=out / f"discrete_fit_{name.split()[0]}", progress=False)
            with dr.suspend_grad():
                cov = np.asarray(model.run(r.values).cover)
            res["discrete"].append({"loss": name, "fitted": r.values,
                                    "covered_fit_m2": float(np.sum(cov * data.areas)),
                                    "covered_discrete_m2": float(np.sum(disc * data.areas))})
            print(f"  {name:14s}: S1 {r.values['S1']:6.2f} T1 {r.values['T1']:7.2f} "
                  f"(table: 60, 299.15); covered {np.sum(cov * data.areas):.3f} m2", flush=True)
    (out / "inverse.json").write_text(json.dumps(res, indent=1))
    print(f"wrote {out / 'inverse.json'}")


if __name__ == "__main__":
    main()
