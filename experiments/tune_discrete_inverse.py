"""Inverse problems on *discrete* targets: recover S1, T1, alpha_g of Bryum argenteum (or a
light parameter: ``--params strength.sky``, ``albedo.ground``) from the mean coverage map of an
ensemble of discrete runs with the table values.

Target: the covered fraction per triangle on day ``--day``, averaged over the seeds of an
ensemble made by ``experiments/tune_discrete_ensemble.py`` (Bryum, the scenario's parameters:
S1 = 60 W m-2, T1 = 299.15 K, alpha_g = Bryum's table value). Fitted with
:func:`mitsuba_veg.tune.fit` on the relaxed model with the chosen spatial closure, one parameter
at a time from -30 % and +30 % starts, then all three jointly from two corners of the box.
For T1 the +-30 % is of its range T1 - T0 = 25 K (of the value it would be +-90 K). Errors are
printed relative to the true value and to the parameter's scale (``tune.fit.parameter_scale``).

    python experiments/tune_discrete_inverse.py --ensemble out/ens_bryum_1M --day 30 \
        --closure near-field --temperature 0.01 --steps 80
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.tune.fitting import parameter_scale  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def discrete_target(folder: Path, day: int, data) -> np.ndarray:
    """Mean over the ensemble's seeds of the covered fraction per triangle on ``day``."""
    maps = []
    for f in sorted(folder.glob("seed_*.npz")):
        c = np.load(f)["counts"][day - 1].astype(float)
        maps.append(np.minimum(c * data.cell ** 2, data.areas) / data.areas)
    return np.mean(maps, axis=0), len(maps)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ensemble", default="out/ens_bryum_1M")
    ap.add_argument("--day", type=int, default=30)
    ap.add_argument("--closure", default="near-field")
    ap.add_argument("--temperature", type=float, default=0.01)
    ap.add_argument("--steps", type=int, default=80)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--params", default="S1,T1,alpha_g")
    ap.add_argument("--joint", type=int, default=2, help="joint fits (box corners)")
    ap.add_argument("--out", default="out/tune_discrete_inverse")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    light = any(p.startswith(("albedo.", "strength.")) for p in a.params.split(","))
    data = tune.prepare(SCEN, days=a.day, species=["bryum_argenteum"], photons=a.photons,
                        light_every=15, differentiable_light=light)
    target, n = discrete_target(Path(a.ensemble), a.day, data)
    model = tune.SmoothMossModel(data, temperature=a.temperature, closure=a.closure)
    names = a.params.split(",")
    true = {p: model.default_value(p) for p in names}
    scale = {p: parameter_scale(model, p) for p in names}
    box = {p: 0.3 * (scale[p] if p in ("T1", "T0") else true[p]) for p in names}
    if any(p.startswith("albedo.") for p in names):
        box.update({p: 0.3 * true[p] for p in names if p.startswith("albedo.")})
    with np.errstate(all="ignore"):
        import drjit as dr
        with dr.suspend_grad():
            cov = np.asarray(model.run(true).cover, float)
    print(f"target: mean of {n} discrete runs, day {a.day}: covered {np.sum(target * data.areas):.4f}"
          f" m2; relaxed ({a.closure}, t = {a.temperature:g}) with the true values "
          f"{np.sum(cov * data.areas):.4f} m2", flush=True)
    rows = []

    def one(params, init):
        r = tune.fit(model, target, params=params, init=init, steps=a.steps, progress=False,
                     out=out / ("_".join(f"{k}{init[k]:.4g}" for k in params)))
        row = {"params": params, "init": init, "fitted": r.values, "loss0": r.history[0]["loss"],
               "loss": r.loss, "seconds": r.seconds,
               "err_rel": {k: (r.values[k] - true[k]) / true[k] for k in params},
               "err_scale": {k: (r.values[k] - true[k]) / scale[k] for k in params}}
        rows.append(row)
        print("  " + ", ".join(f"{k}: {init[k]:.4g} -> {r.values[k]:.4g} (true {true[k]:.4g}; "
                               f"{row['err_rel'][k]:+.2%} of the value, {row['err_scale'][k]:+.2%}"
                               f" of the scale {scale[k]:g})" for k in params)
              + f"  loss {row['loss0']:.2e} -> {row['loss']:.2e}, {r.seconds:.0f} s", flush=True)

    print("one at a time:")
    for p in names:
        for sgn in (-1, 1):
            one([p], {p: true[p] + sgn * box[p]})
    corners = [(-1, 1, -1), (1, -1, 1), (-1, -1, -1), (1, 1, 1)][:a.joint]
    if len(names) > 1 and corners:
        print("jointly:")
        for c in corners:
            one(names, {p: true[p] + s * box[p] for p, s in zip(names, c)})
    (out / "inverse.json").write_text(json.dumps({"settings": vars(a), "true": true,
                                                  "fits": rows}, indent=1))
    print(f"wrote {out / 'inverse.json'}")


if __name__ == "__main__":
    main()
