"""How well a discrete coverage map identifies S1, T1, alpha_g (Bryum, moss garden).

Linearises the relaxed model (``--closure``, t = ``--temperature``) at the true parameters:
J[i, k] = d sqrt(cover_i) / d p_k by central differences, p_k in units of the parameter's
scale (``tune.fit.parameter_scale``: S1 - S0, T1 - T0, 0.1 for alpha_g). The noise of the target
(the mean of the ensemble's seeds) per triangle is sigma_i = sd over seeds of sqrt(cover_i) /
sqrt(seeds), floored at ``--floor``. The Fisher matrix F = J^T diag(1/sigma^2) J gives the
standard error of each parameter fitted alone (1 / sqrt(F_kk)) and jointly
(sqrt((F^-1)_kk)), their correlations and F's condition number.

    python experiments/tune_identifiability.py --ensemble out/ens_bryum_1M --day 30

``--discrete``: the same question for the *discrete* model and the loss of ``fit_discrete``
(sqrt of the patch cover, patches weighted by area, mean over the report days, summed over the
windows), without the relaxed model. Per window (``--window NAME:START_DATE:T_AIR``: the garden
from that date with the daily air temperature T_AIR [K]) the discrete runs on the fit seeds
(common random numbers) at the truth and at truth +- ``--rel`` of each parameter (of its value;
for T0/T1 of the range T1 - T0) give J = d sqrt(patch cover) / d p (central differences, p in
units of ``parameter_scale``) per report day and patch; the runs at the truth on the fit seeds
and the target seeds give the seed-to-seed covariance of the per-seed projections
g_s = J^T W y_s (W the loss's weights). Linearised, the fit's error is
A^-1 J^T W (mean_target - mean_fit) with A = J^T W J, so its covariance is
A^-1 C A^-1 (1/n_target + 1/n_fit), C = cov_s(g_s) (windows on the same seed numbers: the
projections of one seed are summed over the windows, so cross-window correlations count). Printed
for every window alone and every combination, for report-day subsets, and scaled to other
seed counts.

    python experiments/tune_identifiability.py --discrete --window march:2026-03-01:288.15 \
        --window spring:2026-04-01:281.15 --window summer:2026-06-15:295.15
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

import drjit as dr  # noqa: E402

from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.tune.fitting import parameter_scale  # noqa: E402
from mitsuba_veg.tune.discrete import DiscreteMossModel, patch_cover, patch_labels  # noqa: E402
from mitsuba_veg.scenario import Scenario, load_scenario  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def seeds_arg(s: str) -> list[int]:
    """Seeds from ``"A-B"`` (inclusive) or ``"a,b,c"``."""
    if "-" in s:
        a, b = s.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in s.split(",")]


def window_scenario(spec: str):
    """``NAME:START_DATE:T_AIR`` -> (name, scenario of the garden from START_DATE with the daily
    air temperature T_AIR [K])."""
    name, start, T = spec.split(":")
    scn = load_scenario(SCEN)
    d = copy.deepcopy(scn.data)
    d.setdefault("simulation", {})["start_date"] = start
    d.setdefault("climate", {})["temperature"] = float(T)
    return name, Scenario(scn.path, d)


def discrete_study(a):
    """The discrete identifiability study (module docstring, ``--discrete``)."""
    names = a.params.split(",")
    report = [int(x) for x in a.report.split(",")]
    fit_seeds, target_seeds = seeds_arg(a.seeds), seeds_arg(a.target_seeds)
    nf, nt = len(fit_seeds), len(target_seeds)
    win = {}
    t0 = time.perf_counter()
    for spec in a.window:
        name, scn = window_scenario(spec)
        dm = DiscreteMossModel(scn, a.days, species=["bryum_argenteum"],
                               seeds=fit_seeds + target_seeds, photons=a.photons)
        truth = {p: dm.default_value(p) for p in names}
        scale, step = {}, {}
        sp = dm.species[0]
        for p in names:
            rng = (sp.T1 - sp.T0) if p in ("T0", "T1") else None
            scale[p] = rng if rng is not None else (sp.S1 - sp.S0 if p in ("S0", "S1")
                                                    else 0.1)
            step[p] = a.rel * (rng if rng is not None else abs(truth[p]))
        labels = patch_labels(dm.centroids, dm.shape_slices, dm.living, a.patch)
        n_p = int(labels.max()) + 1
        ok = labels >= 0
        pa = np.bincount(labels[ok], weights=dm.areas[ok], minlength=n_p)
        w = pa / pa.sum()

        def y(res):
            out = np.empty(res.cover.shape[:2] + (n_p,))
            for i in range(res.cover.shape[0]):
                for j in range(res.cover.shape[1]):
                    out[i, j] = np.sqrt(patch_cover(res.cover[i, j], dm.areas, labels) + 1e-6)
            return out
        base = dm.run(truth, report=report)
        Yb = y(base)                                     # (nf + nt, days, patches)
        J, Jse = [], []
        for p in names:
            up, dn = dict(truth), dict(truth)
            up[p] += step[p]
            dn[p] -= step[p]
            d = (y(dm.run(up, report=report, seeds=fit_seeds))
                 - y(dm.run(dn, report=report, seeds=fit_seeds))) / (2 * step[p] / scale[p])
            J.append(d)
        Js = np.array(J)                                 # (params, seeds, days, patches)
        J = Js.mean(1)
        Jse = Js.std(1, ddof=1) / np.sqrt(nf)
        cov = base.total[:, -1]
        print(f"window {spec}: truth {truth}; covered on day {report[-1]} "
              f"{cov.mean():.4f} m2 (sd {cov.std(ddof=1):.4f} over {nf + nt} seeds); "
              f"{n_p} patches; {time.perf_counter() - t0:.0f} s", flush=True)
        for i, p in enumerate(names):
            rel = np.linalg.norm(Jse[i]) / np.linalg.norm(J[i])
            print(f"  |dy/d{p}| per day " + ", ".join(
                f"{report[k]}: {np.sqrt(np.sum(w * J[i, k] ** 2)):.4f}" for k in range(len(report)))
                + f" (CRN sampling error of J {rel:.1%})", flush=True)
        win[name] = dict(J=J, Js=Js, Y=Yb, w=w, truth=truth, scale=scale)
    truth, scale = win[next(iter(win))]["truth"], win[next(iter(win))]["scale"]

    half = nf // 2

    def design(wins, days, split=True):
        """Predicted covariance (scaled units) of a joint fit on windows ``wins`` x ``days``.

        split: A from the two halves of the fit seeds, (J_1^T W J_2 + J_2^T W J_1) / 2, whose
        expectation is J^T W J (the CRN noise of J_1 and J_2 is independent), instead of
        Jhat^T W Jhat, which the noise of Jhat inflates.
        """
        ks = [report.index(d) for d in days]
        A = np.zeros((len(names), len(names)))
        G = np.zeros((nf + nt, len(names)))
        for nm in wins:
            W = win[nm]
            Jd = W["J"][:, ks]                          # (params, days, patches)
            Jw = Jd * W["w"] / len(ks)
            if split:
                J1 = W["Js"][:, :half][:, :, ks].mean(1)
                J2 = W["Js"][:, half:][:, :, ks].mean(1)
                x = np.einsum("idp,jdp->ij", J1 * W["w"] / len(ks), J2)
                A += 0.5 * (x + x.T)
            else:
                A += np.einsum("idp,jdp->ij", Jw, Jd)
            G += np.einsum("idp,sdp->si", Jw, W["Y"][:, ks])
        C = np.cov(G.T, ddof=1)
        Ai = np.linalg.inv(A)
        return Ai @ C @ Ai * (1 / nt + 1 / nf), A, C

    print(f"\npredicted s.d. of a joint fit of {names} ({nt} target + {nf} fit seeds; "
          "% of the value, T1 also % of its range); correlations; seeds for s.d. <= 2 %:")
    import itertools
    combos = [list(c) for r in range(1, len(win) + 1) for c in itertools.combinations(win, r)]
    day_sets = [report] + ([[report[-1]]] if len(report) > 1 else [])
    rows = []
    for c, ds, split in [(c, ds, sp) for c in combos for ds in day_sets for sp in (True, False)]:
        if True:
            V, A, C = design(c, ds, split)
            if np.any(np.linalg.eigvalsh(A) <= 0):
                print(f"  {'+'.join(c)}, days {ds}, {'split' if split else 'naive'} A: not "
                      "positive definite (sensitivities lost in the CRN noise)", flush=True)
                continue
            sd = np.sqrt(np.diag(V))
            corr = V / np.outer(sd, sd)
            alone = np.sqrt(np.diag(C) * (1 / nt + 1 / nf)) / np.diag(A)
            parts = []
            worst = 0.0
            for i, p in enumerate(names):
                v = sd[i] * scale[p] / truth[p]
                worst = max(worst, v)
                extra = f" = {sd[i]:.1%} of {scale[p]:g} K" if p in ("T0", "T1") else ""
                parts.append(f"{p} {v:.2%}{extra} (alone {alone[i] * scale[p] / truth[p]:.2%})")
            need = int(np.ceil(max(nf, nt) * (worst / 0.02) ** 2))
            cs = ", ".join(f"{names[i]}-{names[j]} {corr[i, j]:+.2f}"
                           for i in range(len(names)) for j in range(i + 1, len(names)))
            print(f"  {'+'.join(c)}, days {ds}, {'split' if split else 'naive'} A: "
                  + "; ".join(parts) + f"; corr {cs}; "
                  f"cond(A) {np.linalg.cond(A):.3g}; ~{need} + {need} seeds", flush=True)
            rows.append({"windows": c, "days": ds, "split": split, "sd_scaled": sd.tolist(),
                         "corr": corr.tolist(), "seeds_needed": need})
    if a.out:
        Path(a.out).mkdir(parents=True, exist_ok=True)
        np.savez(Path(a.out) / "discrete_sensitivity.npz",
                 **{f"{k}_{x}": v[x] for k, v in win.items() for x in ("Js", "Y", "w")})
        (Path(a.out) / "discrete_identifiability.json").write_text(json.dumps(
            {"settings": vars(a), "truth": truth, "scale": scale, "designs": rows}, indent=1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--discrete", action="store_true", help="the discrete study (docstring)")
    ap.add_argument("--window", action="append", default=[],
                    help="NAME:START_DATE:T_AIR of a discrete window (repeatable)")
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--report", default="10,20,30")
    ap.add_argument("--seeds", default="0-7")
    ap.add_argument("--target-seeds", default="100-107")
    ap.add_argument("--rel", type=float, default=0.1)
    ap.add_argument("--patch", type=float, default=0.2)
    ap.add_argument("--out", default="out/tune_identifiability")
    ap.add_argument("--ensemble", default="out/ens_bryum_1M")
    ap.add_argument("--day", type=int, default=30)
    ap.add_argument("--closure", default="near-field")
    ap.add_argument("--temperature", type=float, default=0.01)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--params", default="S1,T1,alpha_g")
    ap.add_argument("--floor", type=float, default=0.01)
    a = ap.parse_args()
    if a.discrete:
        if not a.window:
            a.window = ["march:2026-03-01:288.15"]
        if a.photons == 1_000_000:
            a.photons = 250_000
        discrete_study(a)
        return
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
