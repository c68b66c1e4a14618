"""Benchmark: cumulative insolation for a tree with >= 10,000 leaves over 60 days at hourly sun
steps, with ray-traced shadows (paper 003 §3.2). Target: under 30 s on the 2-core machine.

    .venv/bin/python benchmarks/autumn_insolation.py [--leaves 10000] [--days 60] [--repeat 3]

Reports (median of --repeat runs after one warm-up): sun path (SPA + SPCTRAL2), shadow-scene
build, the shadow-ray kernels, the total, and shadow rays per second; also with leaf
transmittance (multi-hit loop) and with the sky view factor.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--leaves", type=int, default=10_000)
    ap.add_argument("--days", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", help="write the numbers to this file")
    a = ap.parse_args(argv)

    import mitsuba_veg.foliage  # noqa: F401
    from mitsuba_veg.foliage.canopy import sphere_crown_tree
    from mitsuba_veg.foliage.insolation import leaf_insolation, shadow_scene, sun_path

    tree = sphere_crown_tree(a.leaves, seed=1)
    runs = []
    for rep in range(a.repeat + 1):
        t0 = time.perf_counter()
        path = sun_path(35.0, 139.0, "2026-10-01", a.days, step_hours=1.0)
        t1 = time.perf_counter()
        scene = shadow_scene(tree)
        t2 = time.perf_counter()
        res = leaf_insolation(scene, path)
        t3 = time.perf_counter()
        runs.append({"sun_path_s": t1 - t0, "scene_s": t2 - t1, "insolation_s": t3 - t2,
                     "total_s": t3 - t0, "rays": res.rays})
    med = {k: float(np.median([r[k] for r in runs[1:]])) for k in runs[0]}
    med["rays_per_s"] = med["rays"] / med["insolation_s"]
    t0 = time.perf_counter()
    leaf_insolation(scene, path, leaf_transmittance=0.1)
    med["with_leaf_transmittance_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    leaf_insolation(scene, path, sky=True, sky_rays=64)
    med["with_sky_view_64_rays_s"] = time.perf_counter() - t0
    out = {"leaves": a.leaves, "days": a.days, "daytime_steps": len(path),
           "first_run_total_s": runs[0]["total_s"], **med,
           "cumulative_MJ_m2_mean": float(res.cumulative.mean())}
    print(f"{a.leaves} leaves x {len(path)} daytime hourly steps ({a.days} days) = "
          f"{med['rays']:,.0f} shadow rays")
    print(f"  sun path {med['sun_path_s']:.2f} s, scene {med['scene_s']:.2f} s, insolation "
          f"{med['insolation_s']:.2f} s ({med['rays_per_s'] / 1e6:.1f} M rays/s), total "
          f"{med['total_s']:.2f} s (first run incl. compilation {runs[0]['total_s']:.2f} s)")
    print(f"  with leaf transmittance (multi-hit): {med['with_leaf_transmittance_s']:.2f} s; "
          f"with sky view factor: {med['with_sky_view_64_rays_s']:.2f} s")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=2)
    from _record import Recorder
    rec = Recorder("autumn_insolation", notes=f"{a.leaves:,d} leaves, {a.days} days from 1 "
                   f"October at 35° N, hourly ({len(path)} daytime steps); median of {a.repeat}")
    rec.add("insolation_s", med["insolation_s"], "s",
            f"insolation ({med['rays']:,.0f} shadow rays)")
    rec.add("total_s", med["total_s"], "s", "sun path + scene + insolation")
    rec.add("rays_per_s", med["rays_per_s"] / 1e6, "M rays/s", "shadow rays per second")
    rec.add("translucent_s", med["with_leaf_transmittance_s"], "s",
            "with leaf transmittance (multi-hit)")
    rec.add("sky_view_s", med["with_sky_view_64_rays_s"], "s", "with the sky view factor (64 rays)")
    rec.write()
    return out


if __name__ == "__main__":
    main()
