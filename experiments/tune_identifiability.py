"""How well a discrete coverage map identifies S1, T1, alpha_g (Bryum, moss garden).

Linearises the relaxed model (``--closure``, t = ``--temperature``) at the true parameters:
J[i, k] = d sqrt(cover_i) / d p_k by central differences, p_k in units of the parameter's
scale (``tune.fit.parameter_scale``: S1 - S0, T1 - T0, 0.1 for alpha_g). The noise of the target
(the mean of the ensemble's seeds) per triangle is sigma_i = sd over seeds of sqrt(cover_i) /
sqrt(seeds), floored at ``--floor``. The Fisher matrix F = J^T diag(1/sigma^2) J gives the
standard error of each parameter fitted alone (1 / sqrt(F_kk)) and jointly
(sqrt((F^-1)_kk)), their correlations and F's condition number.

    python experiments/tune_identifiability.py --ensemble out/ens_bryum_1M --day 30
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import drjit as dr  # noqa: E402

from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.tune.fitting import parameter_scale  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ensemble", default="out/ens_bryum_1M")
    ap.add_argument("--day", type=int, default=30)
    ap.add_argument("--closure", default="near-field")
    ap.add_argument("--temperature", type=float, default=0.01)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--params", default="S1,T1,alpha_g")
    ap.add_argument("--floor", type=float, default=0.01)
    a = ap.parse_args()
    data = tune.prepare(SCEN, days=a.day, species=["bryum_argenteum"], photons=a.photons,
                        light_every=15)
    model = tune.SmoothMossModel(data, temperature=a.temperature, closure=a.closure,
                                 precision="float64")
    names = a.params.split(",")
    true = {p: model.default_value(p) for p in names}
    scale = {p: parameter_scale(model, p) for p in names}
    maps = []
    for f in sorted(Path(a.ensemble).glob("seed_*.npz")):
        c = np.load(f)["counts"][a.day - 1].astype(float)
        maps.append(np.sqrt(np.minimum(c * data.cell ** 2, data.areas) / data.areas))
    maps = np.array(maps)
    sigma = np.maximum(maps.std(0, ddof=1) / np.sqrt(len(maps)), a.floor)

    def sq(p):
        with dr.suspend_grad():
            return np.sqrt(np.maximum(np.asarray(model.run(p).cover, float), 0.0))

    J = []
    for k in names:
        h = 0.02
        up, dn = dict(true), dict(true)
        up[k] += h * scale[k]
        dn[k] -= h * scale[k]
        J.append((sq(up) - sq(dn)) / (2 * h))
    J = np.array(J).T / sigma[:, None]
    F = J.T @ J
    alone = 1 / np.sqrt(np.diag(F))
    Finv = np.linalg.inv(F)
    joint = np.sqrt(np.diag(Finv))
    corr = Finv / np.outer(joint, joint)
    print(f"{len(maps)} seeds, day {a.day}, {a.closure}, t = {a.temperature:g}; "
          f"cond(F) = {np.linalg.cond(F):.3g}")
    for i, k in enumerate(names):
        print(f"  {k}: standard error alone {alone[i] * scale[k]:.3g} "
              f"({alone[i] * scale[k] / true[k]:.2%} of the value), jointly "
              f"{joint[i] * scale[k]:.3g} ({joint[i] * scale[k] / true[k]:.2%})")
    print("  correlations (joint):")
    for i, k in enumerate(names):
        print("   " + f"{k:8s}" + " ".join(f"{corr[i, j]:+.3f}" for j in range(len(names))))
    w, v = np.linalg.eigh(F)
    print("  softest direction (scaled units): "
          + ", ".join(f"{k} {v[i, 0]:+.3f}" for i, k in enumerate(names)))


if __name__ == "__main__":
    main()
