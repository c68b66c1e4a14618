"""Red:far-red under a closed leaf layer over the courtyard: layer width and max_depth.

    python experiments/world_canopy_rfr.py [--half 3.5 6.0] [--depth 8 32] [--photons 300000]

A layer of random equilateral leaf triangles (4.9e-3 m2 each, LAI 6) at 1-2.5 m, ``2 half``
metres wide, is the only tree of a copy of ``scenes/courtyard`` (1 July, one day of the world
loop). Prints, for each width and ``light.max_depth``: R:FR (photon ratio 655-665 / 725-735 nm)
of the ground within 1 m of the middle, of its sun and sky parts, PAR there as a fraction of
open daylight's, and the share of each band's power truncated at ``max_depth``.
"""
from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def layer_scenario(tmp: Path, half: float, seed: int = 0) -> Path:
    import trimesh

    from mitsuba_veg.foliage.canopy import leaf_layer_triangles
    tri = leaf_layer_triangles(half, seed=seed)          # LAI 6, 4.9e-3 m2 leaves
    n = len(tri)
    d = tmp / "scen"
    shutil.copytree(ROOT / "scenes" / "courtyard", d)
    trimesh.Trimesh(tri.reshape(-1, 3), np.arange(3 * n).reshape(-1, 3),
                    process=False).export(d / "leaves.ply")
    trimesh.creation.cylinder(radius=0.1, height=2.5).apply_translation(
        [0, 1.25, 0]).export(d / "trunk.ply")
    text = (d / "scenario.toml").read_text()
    text = text[:text.index("# ---- the trees of the world")]
    text = text.replace('start_date = "2026-03-01"', 'start_date = "2026-07-01"')
    text += ('\n[[trees]]\nname = "layer"\nmodel = "mesh"\nposition = [0.0, 0.0, 0.0]\n'
             'file = "trunk.ply"\nleaves_file = "leaves.ply"\n\n[phenology]\n')
    (d / "scenario.toml").write_text(text)
    return d / "scenario.toml"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--half", type=float, nargs="+", default=[3.5, 6.0])
    ap.add_argument("--depth", type=int, nargs="+", default=[8, 32])
    ap.add_argument("--photons", type=int, default=300_000)
    a = ap.parse_args(argv)
    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.scenario import load_scenario
    from mitsuba_veg.daily import Simulation, band_shapes
    for half in a.half:
        tmp = Path(tempfile.mkdtemp())
        scen = layer_scenario(tmp, half)
        for depth in a.depth:
            scn = load_scenario(scen, [f"light.photons={a.photons}", f"light.max_depth={depth}",
                                       "moss.initial=50"])
            sim = Simulation(scn, tmp / f"run{depth}", days=1, progress=False)
            sim.setup()
            sim.initialise()
            sim.step()
            cen = sim.index.centroids[sim.site.ground_slice]
            mid = np.hypot(cen[:, 0], cen[:, 2]) < 1.0
            light = sim.last["light"]
            g = {k: np.asarray(v) for k, v in light.ground.items()}
            gs = {k: np.asarray(v) for k, v in light.ground_sky.items()}
            sun = {k: g[k] - gs[k] for k in g}

            def rfr(bands):
                return bands["red"][mid].sum() * 660 / (bands["far_red"][mid].sum() * 730)
            sh = band_shapes(float(scn.get("site.latitude")), sim.date(0).timetuple().tm_yday)
            B, D = sim.weather.beam[0], sim.weather.diffuse[0]
            par_open = (B * sh["beam"]["par"] + D * sh["diffuse"]["par"]) * 300.0
            open_rfr = ((B * sh["beam"]["red"] + D * sh["diffuse"]["red"]) * 660
                        / ((B * sh["beam"]["far_red"] + D * sh["diffuse"]["far_red"]) * 730))
            res = sim.last_result
            cut = res.truncated.sum(0) / res.emitted.sum(0)
            print(f"layer {2 * half:g} m x {2 * half:g} m ({sim.canopy.n_leaves:,d} leaves), "
                  f"max_depth {depth}: R:FR {rfr(g):.3f} (sun part {rfr(sun):.3f}, sky part "
                  f"{rfr(gs):.3f}; open daylight {open_rfr:.3f}), PAR "
                  f"{g['par'][mid].mean() / par_open:.3f} of open daylight's; truncated "
                  + ", ".join(f"{b} {x:.4f}" for b, x in zip(res.bands, cut)), flush=True)
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
