"""Growth model (paper 001) timings: one tree, a 3 x 3 and a 10 x 10 forest, G = 10, sky
10 x 10 (the paper's settings), against Mitsuba's raw ray throughput measured in the same run.

    .venv/bin/python benchmarks/trees_growth.py [--reps 3] [--skip-10x10] [--out FILE.json]

For every case: wall time of grow_forest (median of --reps warm runs; the first, cold run
compiles the kernels and is reported separately), sky rays traced (H x V per leaf sphere per
generation) and rays/s. The raw reference: the leaf spheres of the case's last generation as one
Mitsuba ``ellipsoids`` shape (+ the ground), the same rays (every sphere centre x every sky
cell), one ``ray_intersect_preliminary`` each (the BVH traversal limit: one closest hit, no
counting). On that sphere set the three sphere-counting engines (grid, mitsuba, analytic) run
one light pass each. The paper reports 6.3 s for one tree on a Pentium 4 2.8 GHz.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _raw_rays_per_s(centers, radius, env, sky, reps=3):
    import drjit as dr
    import mitsuba as mi
    from mitsuba_veg.trees.leaflight import _rays, _sphere_shape, _vec3

    d = {"type": "scene", "leaf_spheres": _sphere_shape(centers, radius)}
    d.update(env.mitsuba_meshes())
    scene = mi.load_dict(d, optimize=False)
    N = sky.cells()[0]
    n = len(centers) * sky.M
    ts = []
    for r in range(reps + 1):
        s, o, dd = _rays(_vec3(centers + r * 1e-6), _vec3(N, mi.Vector3f), n, sky.M)
        dr.eval(o, dd)
        dr.sync_thread()
        t = time.perf_counter()
        pi = scene.ray_intersect_preliminary(mi.Ray3f(o, dd), coherent=False)
        dr.eval(pi.t, pi.prim_index)
        dr.sync_thread()
        if r:
            ts.append(time.perf_counter() - t)
    return n / float(np.median(ts)), n


def _engines(centers, radius, env, sky, alphas):
    from mitsuba_veg.trees.leaflight import leaf_sphere_light
    out = {}
    for eng in ("grid", "mitsuba", "analytic"):
        if eng == "analytic" and len(centers) > 6000:
            continue
        leaf_sphere_light(centers, radius, sky, alphas, env, eng)        # compile
        r = leaf_sphere_light(centers, radius, sky, alphas, env, eng)
        out[eng] = {"seconds": r.seconds, "rays_per_s": r.rays / r.seconds,
                    "loop_steps": r.stats.get("loop_steps")}
    return out


def run_case(name, positions, reps, p, env):
    from mitsuba_veg.trees import grow_forest
    from mitsuba_veg.trees.leaflight import Sky

    t = time.perf_counter()
    grow_forest(positions, p, 10, env, seed=0)
    cold = time.perf_counter() - t
    times, hist = [], None
    for _ in range(reps):
        h = []
        t = time.perf_counter()
        trees = grow_forest(positions, p, 10, env, seed=0, history=h)
        times.append(time.perf_counter() - t)
        hist = h
    wall = float(np.median(times))
    rays = sum(x["rays"] for x in hist)
    light_s = sum(x["light_s"] for x in hist)
    sky = Sky(p.sky_h, p.sky_v, p.light_ratio)
    centers = np.concatenate([tr.attrs["leaf_sphere_center"] for tr in trees])
    radius = p.leaf_radius * p.unit
    raw, nraw = _raw_rays_per_s(centers, radius, env, sky)
    alphas = {"light": p.alpha, "red": p.alpha_red, "far_red": p.alpha_far_red}
    eng = _engines(centers, radius, env, sky, alphas)
    res = {"case": name, "trees": len(positions), "seconds": wall, "cold_seconds": cold,
           "light_seconds": light_s, "rays": rays, "rays_per_s": rays / wall,
           "light_rays_per_s": rays / light_s, "raw_mitsuba_rays_per_s": raw,
           "ratio_to_raw": rays / wall / raw, "final_leaf_spheres": len(centers),
           "live_branches": sum(t.metrics()["live_branches"] for t in trees),
           "engines_last_generation": eng, "generations": hist}
    print(f"{name:>10s}: {wall:7.2f} s (cold {cold:.2f} s), {rays / 1e6:6.2f} M sky rays, "
          f"{rays / wall / 1e6:5.2f} M rays/s overall, {rays / light_s / 1e6:5.2f} M rays/s in "
          f"the light passes; raw Mitsuba ray_intersect_preliminary on the final spheres "
          f"{raw / 1e6:5.2f} M rays/s -> ratio {rays / wall / raw:.2f}")
    print(" " * 12 + "one light pass on the final spheres (" + f"{len(centers)}): " + ", ".join(
        f"{k} {v['seconds']:.3f} s ({v['rays_per_s'] / 1e6:.2f} M rays/s)" for k, v in eng.items()))
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--skip-10x10", action="store_true")
    ap.add_argument("--out", help="write the results as JSON")
    a = ap.parse_args(argv)
    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.trees import Environment, GrowthParams

    p = GrowthParams()
    print(f"paper 001 settings: G = 10, sky {p.sky_h} x {p.sky_v}, table 3.1; forests 12 m apart "
          "on an 80 m ground grid (paper: 6.3 s for one tree on a Pentium 4 2.8 GHz)")
    ground = Environment.flat_ground(160, n=20)
    results = [run_case("one tree", [(0.0, 0.0, 0.0)], a.reps, p, ground),
               run_case("3 x 3", [(12.0 * i, 0.0, 12.0 * j) for j in (-1, 0, 1)
                                  for i in (-1, 0, 1)], a.reps, p, ground)]
    if not a.skip_10x10:
        results.append(run_case("10 x 10", [(12.0 * i - 54, 0.0, 12.0 * j - 54) for j in range(10)
                                            for i in range(10)], 1, p, ground))
    if a.out:
        with open(a.out, "w") as f:
            json.dump(results, f, indent=2, default=str)
    from _record import Recorder
    rec = Recorder("trees_growth", notes="paper 001's settings (G = 10, table 3.1); forests 12 m "
                   "apart on an 80 m ground grid; paper: 6.3 s for one tree on a Pentium 4")
    for r in results:
        key = r["case"].replace(" ", "")
        rec.add(f"{key}_s", r["seconds"], "s", f"{r['case']}: 10 generations grown in their light")
        rec.add(f"{key}_ratio_to_raw", r["ratio_to_raw"], "ratio",
                f"{r['case']}: sky rays/s ÷ raw `ray_intersect_preliminary` rays/s")
    rec.write()


if __name__ == "__main__":
    main()
