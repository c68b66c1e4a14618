"""The relaxed model against the mean of an ensemble of discrete runs, per region and day.

Reads the ensemble of ``experiments/tune_discrete_ensemble.py`` (``--ensemble``), runs the
relaxed model (:class:`mitsuba_veg.tune.SmoothMossModel`) with the same species, days and
scenario for each closure in ``--closures`` and prints, every ``--every`` days, the covered area
per region and in total: the discrete mean (and the standard error of the mean) and the relaxed
model's ratio to it. The largest deviation per closure over the reported days is printed last.

    python experiments/tune_closure.py --ensemble out/tune_ensemble --closures mean-field,near-field

``--discrete-light``: instead of its own up-front photon passes, the relaxed model is run once
per seed of the ensemble with that run's weather (``light.seed``) and the very light the run
computed every day (its photon noise and moss albedo included, ``smooth.with_daily_light``),
and the mean of those relaxed runs is compared: what is left is the life cycle and the spatial
closure (``--light-mean``: all relaxed runs get the mean of the runs' daily light, so the
photon noise is averaged away but the moss albedo stays). ``--per-seed``: one relaxed run per seed with that run's weather (the rain days follow
``light.seed``) and the relaxed model's own light passes. ``--light-check``: only compare the
runs' daily light with the relaxed model's passes (area means per region and shape, the
photon noise between runs). ``--save FILE`` keeps the relaxed
series (npz).
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

from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.tune import smooth  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def load_ensemble(folder: Path) -> dict:
    files = sorted(folder.glob("seed_*.npz"))
    runs = [np.load(f) for f in files]
    names = [str(x) for x in runs[0]["region_names"]]
    reg = np.array([r["regions"] for r in runs])          # [seed, day, region]
    tot = np.array([r["cover"] for r in runs])            # [seed, day]
    alive = np.array([r["alive"] for r in runs])
    settings = json.loads((folder / "settings.json").read_text())
    return {"n": len(runs), "names": names, "regions": reg, "total": tot, "alive": alive,
            "settings": settings, "files": files,
            "seeds": [int(f.stem.split("_")[1]) for f in files],
            "propagules": np.array([r["propagules"] for r in runs]),
            "events": np.array([r["events"] for r in runs])}


def relaxed_series(model, params=None) -> dict:
    with dr.suspend_grad():
        out = model.run(params, record=True, maps_every=1)
    names = sorted(out.history[0]["regions"])
    h = out.history
    data = model.data
    shapes = sorted(data.shape_slices)
    cov = np.array([out.maps[d + 1] for d in range(len(h))]) * data.areas     # day, triangle
    return {"shapes": np.array([[cov[d, data.shape_slices[k]].sum() for k in shapes]
                                for d in range(len(h))]), "shape_names": shapes,
            "triangles": cov,"regions": np.array([[r["regions"][k] for k in names] for r in h]),
            "total": np.array([r["covered_area_m2"] for r in h]),
            "alive": np.array([r["moss_alive"] for r in h]),
            "propagules": np.array([r["propagules"] for r in h]),
            "germinated": np.array([r["events"]["germinated"] for r in h]),
            "settled": np.array([r["events"]["settled"] for r in h]), "names": names}


def mean_series(series: list) -> dict:
    """The mean of relaxed series (one per seed)."""
    out = {k: np.mean([r[k] for r in series], axis=0) for k in series[0]
           if k not in ("names", "shape_names")}
    out["names"] = series[0]["names"]
    out["shape_names"] = series[0]["shape_names"]
    return out


def shape_table(ens: dict, rel: dict, data, every: int, label: str) -> None:
    """Covered area per shape: discrete mean (from the runs' moss per triangle) / relaxed."""
    names = rel["shape_names"]
    cap = data.areas
    disc = []
    for f in ens["files"]:
        c = np.load(f)["counts"][:rel["total"].shape[0]].astype(float)          # day, triangle
        cov = np.minimum(c * data.cell ** 2, cap)
        disc.append([[cov[d, data.shape_slices[k]].sum() for k in names]
                     for d in range(cov.shape[0])])
    dm = np.mean(disc, 0)
    print(f"{label}: covered area per shape [m2], discrete mean / relaxed ratio")
    for d in range(every, dm.shape[0] + 1, every):
        print(f"{d:4d} " + "  ".join(f"{k} {dm[d - 1, j]:.4f} / "
                                     f"{rel['shapes'][d - 1, j] / max(dm[d - 1, j], 1e-12):5.3f}"
                                     for j, k in enumerate(names)))


FACES = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0),
         "+z": (0, 0, 1), "-z": (0, 0, -1)}


def face_table(ens: dict, rel: dict, data, every: int, label: str) -> None:
    """Covered area per shape and face (triangles whose normal is within 25 deg of an axis;
    the rest: "other"): discrete mean / relaxed ratio."""
    groups = {}
    normals = np.asarray(data.index.normals, float)
    for k, sl in sorted(data.shape_slices.items()):
        idx = np.arange(sl.start, sl.stop)
        taken = np.zeros(len(idx), bool)
        for f, v in FACES.items():
            m = (normals[idx] @ np.array(v, float)) > np.cos(np.radians(25))
            if m.any():
                groups[f"{k} {f}"] = idx[m]
            taken |= m
        if (~taken).any():
            groups[f"{k} other"] = idx[~taken]
    disc = []
    for f in ens["files"]:
        c = np.load(f)["counts"][:rel["total"].shape[0]].astype(float)
        disc.append(np.minimum(c * data.cell ** 2, data.areas))
    dm = np.mean(disc, 0)                                   # day, triangle
    print(f"{label}: covered area per shape and face [m2] (area), discrete mean / relaxed ratio")
    def ratio(d, i):
        a, b = dm[d - 1, i].sum(), rel["triangles"][d - 1, i].sum()
        return "    -" if max(a, b) < 1e-4 else f"{b / max(a, 1e-12):5.3f}"   # < one moss
    for d in range(every, dm.shape[0] + 1, every):
        print(f"{d:4d} " + "  ".join(
            f"{g} ({data.areas[i].sum():.2f}) {dm[d - 1, i].sum():.4f} / {ratio(d, i)}"
            for g, i in groups.items()))


def light_table(ens: dict, data, days=(5, 30, 60, 100, 150, 200, 299)) -> None:
    """The runs' daily light against the relaxed model's own passes, per region and shape:
    area means of f_sun and f_sky (mean of the runs / relaxed), the median over triangles of
    the coefficient of variation of f_sun between the runs, the share of (run, triangle) with
    no sun photon."""
    L = data.light
    a = data.areas
    groups = dict(data.regions)
    for k, sl in data.shape_slices.items():
        m = np.zeros(data.n, bool)
        m[sl] = True
        groups[k] = m & data.living
    print("light: group day: f_sun runs / relaxed (ratio), f_sky runs / relaxed (ratio), "
          "CV of f_sun between runs, no-sun share")
    for d in days:
        if d >= data.days:
            continue
        fs = np.array([np.load(f)["f_sun"][d] for f in ens["files"]])
        fk = np.array([np.load(f)["f_sky"][d] for f in ens["files"]])
        k0, k1, w = L.weights(d)
        rs = (1 - w) * L.f_sun[k0] + w * L.f_sun[k1]
        for g, m in groups.items():
            am = a[m] / a[m].sum()
            ds, dk = (fs[:, m] @ am).mean(), (fk[:, m] @ am).mean()
            r_s, r_k = rs[m] @ am, L.f_sky[m] @ am
            mu, sd = fs[:, m].mean(0), fs[:, m].std(0)
            cv = np.median(sd[mu > 0] / mu[mu > 0]) if (mu > 0).any() else float("nan")
            print(f"  {g:10s} {d:3d}: sun {ds:.4f} / {r_s:.4f} ({r_s / ds:.3f})  sky {dk:.4f} / "
                  f"{r_k:.4f} ({r_k / dk:.3f})  CV {cv:.2f}  no sun {(fs[:, m] == 0).mean():.2f}")


def events_table(ens: dict, rel: dict, every: int, label: str) -> None:
    """Moss alive, waiting propagules and germinations per day: discrete mean and relaxed."""
    ev = ens.get("events")
    if ev is None:
        return
    days = ens["total"].shape[1]
    print(f"{label}: discrete mean / relaxed: moss alive, propagules waiting, germinated a day")
    for d in range(every, days + 1, every):
        i = d - 1
        print(f"{d:4d}  alive {ens['alive'][:, i].mean():8.0f} / {rel['alive'][i]:8.0f}   "
              f"waiting {ens['propagules'][:, i].mean():7.0f} / {rel['propagules'][i]:7.0f}   "
              f"germinated {ev[:, i, 0].mean():6.0f} / {rel['germinated'][i]:6.0f}")


def compare(ens: dict, rel: dict, every: int, label: str, floor: float = 0.0) -> float:
    """Print the table; return the largest |relaxed / discrete - 1| over the reported days
    and the regions + total (where the discrete mean is above ``floor`` m2)."""
    days = ens["total"].shape[1]
    rep = [d for d in range(every, days + 1, every)]
    names = ens["names"] + ["total"]
    dm = np.concatenate([ens["regions"], ens["total"][..., None]], axis=2)   # seed, day, k
    rm = np.concatenate([rel["regions"], rel["total"][:, None]], axis=1)
    mean = dm.mean(0)
    sem = dm.std(0, ddof=1) / np.sqrt(dm.shape[0])
    print(f"{label}: covered area [m2], discrete mean of {ens['n']} (s.e.) / relaxed ratio")
    print("day  " + "  ".join(f"{n:>26s}" for n in names))
    worst = 0.0
    for d in rep:
        cells = []
        for k in range(len(names)):
            r = rm[d - 1, k] / max(mean[d - 1, k], 1e-12)
            if max(mean[d - 1, k], rm[d - 1, k]) < 1e-4:   # neither holds a moss (1 cm2)
                r = 1.0
            if mean[d - 1, k] > floor:
                worst = max(worst, abs(r - 1))
            cells.append(f"{mean[d - 1, k]:.4f} ({sem[d - 1, k]:.4f}) / {r:5.3f}")
        print(f"{d:4d} " + "  ".join(f"{c:>26s}" for c in cells))
    print(f"{label}: largest deviation {worst:.1%}", flush=True)
    return worst


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ensemble", default="out/tune_ensemble")
    ap.add_argument("--closures", default="mean-field,near-field")
    ap.add_argument("--temperature", type=float, default=0.0)
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--light-every", type=int, default=15,
                    help="days between the relaxed model's sun-path passes (1: a new pass, i.e. "
                         "new photon noise, every day as in the discrete run)")
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--near-cells", default="kernel",
                    help="z of the near-field closure (list; 'kernel': from the gemma kernel)")
    ap.add_argument("--near-scale", type=float, default=1.0,
                    help="factor on the kernel's z (near-field closure)")
    ap.add_argument("--near-overlap", default="kernel",
                    help="theta of the near-field triplet term (list; 'kernel': from the gemma "
                         "kernel, 0: the plain pair approximation)")
    ap.add_argument("--local-arrivals", default="1",
                    help="near field: settle fraction of gemmae from the arrivals next to their "
                         "parents (list of 0/1)")
    ap.add_argument("--siblings", default="1",
                    help="near field: a parent's fixed point (its z from two gemmae released "
                         "there, and spores landing beside it where its gemmae land) (list "
                         "of 0/1; 0: z from the whole triangle, spores anywhere)")
    ap.add_argument("--moss-pairs", default="1",
                    help="near field: the propagules see the occupancy around a moss (the "
                         "pairs whose first cell holds moss) (list of 0/1; 0: around the mean "
                         "occupant)")
    ap.add_argument("--days", type=int, default=0, help="compare the first days only")
    ap.add_argument("--floor", type=float, default=0.0,
                    help="ignore region-days whose discrete mean is below this [m2]")
    ap.add_argument("--discrete-light", action="store_true",
                    help="run the relaxed model per seed with that run's weather and daily light")
    ap.add_argument("--light-mean", action="store_true",
                    help="with --discrete-light: every relaxed run gets the mean of the runs' "
                         "daily light (photon noise averaged over the seeds)")
    ap.add_argument("--by-shape", action="store_true",
                    help="also print the covered area per shape (ground, roof, wall ...)")
    ap.add_argument("--by-face", action="store_true",
                    help="also print the covered area per shape and face (normal direction)")
    ap.add_argument("--light-check", action="store_true",
                    help="only compare the runs' daily light with the relaxed model's passes")
    ap.add_argument("--per-seed", action="store_true",
                    help="run the relaxed model per seed with that run's weather (own light)")
    ap.add_argument("--save", default="", help="write the relaxed series to this npz file")
    a = ap.parse_args()
    ens = load_ensemble(Path(a.ensemble))
    st = ens["settings"]
    days = a.days or ens["total"].shape[1]
    for k in ("regions", "total", "alive", "propagules", "events"):
        ens[k] = ens[k][:, :days]
    species = st["species"].split(",")
    over = list(st.get("set", []))
    if a.light_check:
        light_table(ens, tune.prepare(SCEN, days=days, species=species, photons=a.photons,
                                      light_every=a.light_every, overrides=over))
        return
    if a.discrete_light or a.per_seed:
        # one relaxed run per seed: that seed's weather (rain days), and its recorded daily
        # light (--discrete-light) or the relaxed model's own passes (seeded with it)
        datas = []
        for f, s in zip(ens["files"], ens["seeds"]):
            ov = over + [f"light.seed={s}"]
            if a.discrete_light:
                if a.light_mean:
                    if f == ens["files"][0]:
                        fs = np.mean([np.load(g)["f_sun"][:days] for g in ens["files"]], 0)
                        fk = np.mean([np.load(g)["f_sky"][:days] for g in ens["files"]], 0)
                else:
                    rec = np.load(f)
                    fs, fk = rec["f_sun"][:days], rec["f_sky"][:days]
                base = tune.prepare(SCEN, days=days, species=species, photons=10_000,
                                    light_every=days, overrides=ov)
                datas.append(smooth.with_daily_light(base, fs, fk))
            else:
                datas.append(tune.prepare(SCEN, days=days, species=species, photons=a.photons,
                                          light_every=a.light_every, overrides=ov))
    else:
        datas = [tune.prepare(SCEN, days=days, species=species, photons=a.photons,
                              light_every=a.light_every, overrides=over)]
    saved = {}
    for cl in a.closures.split(","):
        nf = cl == "near-field"
        for z, th, la, sb, mp in [(z, th, la, sb, mp)
                                  for z in (a.near_cells.split(",") if nf else ["kernel"])
                                  for th in (a.near_overlap.split(",") if nf else ["kernel"])
                                  for la in (a.local_arrivals.split(",") if nf else ["0"])
                                  for sb in (a.siblings.split(",") if nf else ["0"])
                                  for mp in (a.moss_pairs.split(",") if nf else ["0"])]:
            series = []
            for data in datas:
                model = tune.SmoothMossModel(data, temperature=a.temperature, closure=cl,
                                             near_cells=None if z == "kernel" else float(z),
                                             near_scale=a.near_scale,
                                             near_overlap=None if th == "kernel" else float(th),
                                             local_arrivals=la == "1",
                                             siblings=sb == "1", moss_pairs=mp == "1")
                series.append(relaxed_series(model))
            rel = mean_series(series)
            nf_lab = (f" z = {z}, theta = {th}, local arrivals {la}, siblings {sb}, "
                      f"moss pairs {mp}") if nf else ""
            lab = f"{cl}{nf_lab} (t = {a.temperature:g})"
            if a.discrete_light:
                lab += f", daily light and weather of the {len(datas)} runs"
            elif a.per_seed:
                lab += f", weather of the {len(datas)} runs"
            compare(ens, rel, a.every, lab, a.floor)
            events_table(ens, rel, a.every, lab)
            if a.by_shape:
                shape_table(ens, rel, datas[0], a.every, lab)
            if a.by_face:
                face_table(ens, rel, datas[0], a.every, lab)
            for k, v in rel.items():
                if k not in ("names", "shape_names", "triangles"):
                    saved[f"{cl}_{z}_{th}_{la}_{k}"] = v
    if a.save:
        np.savez_compressed(a.save, **saved)


if __name__ == "__main__":
    main()
