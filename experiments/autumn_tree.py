"""A tree colouring through autumn: sunny outer leaves first, shaded inner leaves later
(paper 003 fig. 6-7), and the stage reached versus cumulative insolation.

    .venv/bin/python experiments/autumn_tree.py [--out out/foliage] [--leaves 8000] [--days 45]
                                                [--sky] [--no-render]

Sun path at 35° N, 139° E from 15 October, hourly; insolation per leaf with ray-traced shadows
(leaves and branches), autumn logical time τ (default AutumnParams, per-leaf random rates).
Writes
- ``autumn_tree_tau.png``: the tree seen from the south at four dates (leaf colours from the
  PROSPECT-D reflectance of each leaf's stage) and mean τ over time for outer / inner and
  south / north leaves;
- ``autumn_stage_vs_insolation.png``: Ishikura stage reached versus cumulative insolation;
- ``autumn_tree_render.png`` (unless --no-render): Mitsuba renders (path tracer, veg_leaf BSDFs
  with the stage spectra, SPCTRAL2 sun + Perez sky) at three dates;
- ``autumn_tree.json``: the numbers.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def leaf_colours(stage, exposure=2.2):
    """sRGB per leaf from the leaf-mean reflectance at its stage (61 tabulated levels)."""
    import mitsuba_veg.foliage as fo

    levels = np.linspace(1, 7, 61)
    s = fo.leaf_spectra(stage=levels)
    rgb = fo.spectrum_to_srgb(s.wavelength, s.reflectance, exposure)
    i = np.clip(np.round((np.asarray(stage) - 1) * 10).astype(int), 0, 60)
    return rgb[i]


def render_tree(tree, tau, when, lat=35.0, lon=139.0, size=256, spp=32, n_classes=7):
    import mitsuba as mi

    from mitsuba_veg.foliage.light_study import tree_scene
    from mitsuba_veg.light.clear_sky import _day_of_year, daylight_from_angles
    from mitsuba_veg.light.solar_position import sun_position

    az, el = (float(np.asarray(x)) for x in sun_position(lat, lon, when))
    em = daylight_from_angles(az, el, day_of_year=_day_of_year(when))
    # the ground to 100 km: from 3 m up its edge lies 0.002 degrees below the horizon (no black
    # band between the ground and the sky, which is zero below the horizon)
    scene, _ = tree_scene(tree, emitters=em, tau=tau, n_classes=n_classes, ground_extent=2.0e5,
                          ground_resolution=4, ground_albedo=0.12)
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 6},
         "sensor": {"type": "perspective", "fov": 38,
                    "to_world": mi.ScalarTransform4f().look_at(origin=[0.0, 3.2, 9.5],
                                                               target=[0.0, 2.3, 0.0],
                                                               up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": size, "height": size,
                             "pixel_format": "rgb"}}}
    for sh in scene.shapes():
        d[sh.id()] = sh
    for i, e in enumerate(scene.emitters()):
        d[f"em{i}"] = e
    sc = mi.load_dict(d, optimize=False)
    img = np.array(mi.render(sc, spp=spp))
    # exposure: daylight is ~1000 W m-2; map the ground-lit level to mid grey, then sRGB
    img = img / (np.percentile(img[..., 1], 99) + 1e-9) * 0.9
    img = np.clip(img, 0, 1)
    return np.where(img <= 0.0031308, 12.92 * img, 1.055 * img ** (1 / 2.4) - 0.055), (az, el)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/foliage")
    ap.add_argument("--leaves", type=int, default=8000)
    ap.add_argument("--days", type=int, default=45)
    ap.add_argument("--start", default="2026-10-15")
    ap.add_argument("--sky", action="store_true", help="add diffuse skylight to the insolation")
    ap.add_argument("--no-render", action="store_true")
    ap.add_argument("--spp", type=int, default=32)
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import mitsuba_veg.foliage  # noqa: F401
    from mitsuba_veg.foliage.autumn import AutumnParams, autumn_time, params_dict
    from mitsuba_veg.foliage.canopy import sphere_crown_tree
    from mitsuba_veg.foliage.insolation import leaf_insolation, sun_path

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    tree = sphere_crown_tree(a.leaves, seed=1)
    R, cy = 1.5, 3.0
    t0 = time.perf_counter()
    path = sun_path(35.0, 139.0, a.start, a.days)
    ins = leaf_insolation(tree, path, sky=a.sky)
    t_ins = time.perf_counter() - t0
    params = AutumnParams()
    st = autumn_time(ins, params, seed=0)
    pos = tree.leaves.position
    r = np.linalg.norm(pos - [0, cy, 0], axis=1)
    groups = {"outer (r > 0.8 R)": r > 0.8 * R, "inner (r < 0.4 R)": r < 0.4 * R,
              "south (z > 0.5 R)": pos[:, 2] > 0.5 * R, "north (z < -0.5 R)": pos[:, 2] < -0.5 * R}
    days = np.arange(a.days)
    tau_mean = {g: [float(st.tau(d)[m].mean()) for d in days] for g, m in groups.items()}
    dates = [a.days // 4, a.days // 2, (3 * a.days) // 4, a.days - 1]

    # ---- figure 1: the tree at four dates + mean τ over time --------------------------------
    fig = plt.figure(figsize=(16, 5.6), constrained_layout=True)
    gs = fig.add_gridspec(1, 5, width_ratios=[1, 1, 1, 1, 1.5])
    order = np.argsort(pos[:, 2])            # seen from the south (+z): far leaves first
    for k, d in enumerate(dates):
        ax = fig.add_subplot(gs[0, k])
        col = leaf_colours(st.stage(d))
        ax.scatter(pos[order, 0], pos[order, 1], c=col[order], s=9, marker="h", linewidths=0)
        ax.plot([0, 0], [0, cy], color="#4a3620", lw=3, zorder=0)
        ax.set_aspect("equal")
        ax.set_xlim(-1.8, 1.8)
        ax.set_ylim(0, 4.8)
        date = (np.datetime64(a.start) + np.timedelta64(int(d), "D"))
        ax.set_title(f"{date}  (day {d + 1})\nmean stage outer {1 + 6 * tau_mean['outer (r > 0.8 R)'][d]:.1f}"
                     f", inner {1 + 6 * tau_mean['inner (r < 0.4 R)'][d]:.1f}", fontsize=9)
        ax.set_xlabel("x (east) [m]")
        if k == 0:
            ax.set_ylabel("y (up) [m], seen from the south")
    ax = fig.add_subplot(gs[0, 4])
    styles = ["-", "--", "-.", ":"]
    for (g, v), ls in zip(tau_mean.items(), styles):
        ax.plot(days + 1, v, ls, label=g, lw=2)
    ax.set_xlabel(f"day from {a.start}")
    ax.set_ylabel("mean autumn logical time τ")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=9)
    sec = ax.secondary_yaxis("right", functions=(lambda t: 1 + 6 * t, lambda s: (s - 1) / 6))
    sec.set_ylabel("Ishikura stage")
    fig.suptitle(f"Autumn colouring of a {a.leaves}-leaf tree at 35° N: sunny outer leaves first "
                 f"(hourly sun, ray-traced shadows{', + sky' if a.sky else ''})", fontsize=11)
    p1 = out / "autumn_tree_tau.png"
    fig.savefig(p1, dpi=80)
    plt.close(fig)

    # ---- figure 2: stage vs cumulative insolation -------------------------------------------
    dsel = a.days // 2
    H = ins.cumulative_by_day()[:, dsel]
    S = st.stage(dsel)
    fig, ax = plt.subplots(figsize=(7.5, 5.2), constrained_layout=True)
    hb = ax.hexbin(H, S, gridsize=45, cmap="Greys", mincnt=1, bins="log")
    fig.colorbar(hb, ax=ax, label="leaves")
    edges = np.quantile(H, np.linspace(0, 1, 13))
    mids, means, sds = [], [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (H >= lo) & (H <= hi)
        mids.append(H[m].mean())
        means.append(S[m].mean())
        sds.append(S[m].std())
    ax.errorbar(mids, means, yerr=sds, color="crimson", marker="o", lw=2, capsize=3,
                label="binned mean ± sd")
    Hl = np.linspace(0, H.max(), 100)
    tau_det = np.clip((1 - params.time_weight) * Hl / params.insolation_full
                      + params.time_weight * (dsel + 1) / params.days_full, 0, 1)
    ax.plot(Hl, 1 + 6 * tau_det, "b--", label="model for a median leaf (ξ = 1)")
    ax.set_xlabel(f"cumulative insolation to day {dsel + 1} [MJ m$^{{-2}}$]")
    ax.set_ylabel("Ishikura stage reached")
    ax.set_ylim(0.8, 7.2)
    ax.legend(loc="lower right")
    ax.set_title(f"stage reached vs cumulative insolation ({a.leaves} leaves, day {dsel + 1}); "
                 f"r = {np.corrcoef(H, S)[0, 1]:.2f}", fontsize=10)
    p2 = out / "autumn_stage_vs_insolation.png"
    fig.savefig(p2, dpi=90)
    plt.close(fig)

    # ---- figure 3: renders ---------------------------------------------------------------------
    p3, t_render, sun = None, 0.0, []
    if not a.no_render:
        t1 = time.perf_counter()
        rdays = [dates[0], dates[1], dates[3]]
        imgs = []
        for d in rdays:
            when = str(np.datetime64(a.start) + np.timedelta64(int(d), "D")) + "T11:00:00+09:00"
            img, angles = render_tree(tree, st.tau(d), when, spp=a.spp)
            imgs.append((d, when, img))
            sun.append(angles)
        t_render = time.perf_counter() - t1
        fig, axs = plt.subplots(1, 3, figsize=(13, 4.6), constrained_layout=True)
        for ax, (d, when, img) in zip(axs, imgs):
            ax.imshow(img)
            ax.set_axis_off()
            ax.set_title(f"{when[:10]} (day {d + 1}), 11:00", fontsize=10)
        fig.suptitle("Mitsuba path tracing: veg_leaf BSDFs with PROSPECT-D spectra of each "
                     "leaf's stage, SPCTRAL2 sun + Perez sky, seen from the south", fontsize=10)
        p3 = out / "autumn_tree_render.png"
        fig.savefig(p3, dpi=90)
        plt.close(fig)

    res = {"leaves": a.leaves, "days": a.days, "start": a.start, "sky": a.sky,
           "sun_steps": len(path), "rays": ins.rays, "insolation_seconds": t_ins,
           "render_seconds": t_render, "params": params_dict(params),
           "cumulative_MJ_m2": {g: float(ins.cumulative[m].mean()) for g, m in groups.items()},
           "open_horizontal_MJ_m2": float(ins.open_daily.sum()),
           "mean_tau": {g: {str(d + 1): tau_mean[g][d] for d in dates} for g in groups},
           "corr_stage_insolation": float(np.corrcoef(H, S)[0, 1]),
           "png": [str(p1), str(p2)] + ([str(p3)] if p3 else [])}
    (out / "autumn_tree.json").write_text(json.dumps(res, indent=2))
    print(json.dumps({k: res[k] for k in ("insolation_seconds", "cumulative_MJ_m2", "mean_tau",
                                          "corr_stage_insolation", "render_seconds")}, indent=1))
    print("wrote", *res["png"])


if __name__ == "__main__":
    main()
