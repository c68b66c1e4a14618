"""Time to equal accuracy: photon pass vs per-triangle irradiancemeter path tracing.

Scene: the validation scene (ground grid, roof slab, wall; sun + uniform sky). Truth: Mitsuba's
path tracer with an irradiancemeter on every triangle at a very high sample count (+ direct sun
by shadow rays). Both methods are then run at increasing effort; for each we report wall time
and the RMS relative error over all triangles lit above 2 % of open ground, and the time each
needs to reach the target RMS (interpolated in log-log). Printed: the speed-up.

    python benchmarks/photon_vs_path.py [--target 0.02] [--grid 6]
"""
import argparse
import time

import numpy as np

import mitsuba_veg  # noqa: F401
import mitsuba as mi

from mitsuba_veg.light import photon_irradiance
from mitsuba_veg.light import validation as V


def all_triangles(d, scene):
    out = {}
    for s in scene.shapes():
        out[s.id()] = list(range(s.face_count()))
    return out


def path_all(d, tris, spp, seed=0):
    vals = {}
    t = time.perf_counter()
    for sid, ts in tris.items():
        vals[sid], _ = V.path_reference(d, sid, ts, spp=spp, seed=seed)
    return vals, time.perf_counter() - t


def rms(est, truth, mask):
    e = np.concatenate([est[k] for k in truth])
    t = np.concatenate([truth[k] for k in truth])
    m = np.concatenate([mask[k] for k in truth])
    return float(np.sqrt(np.mean((e[m] / t[m] - 1) ** 2)))


def time_to(target, times, errs):
    times, errs = np.log(np.asarray(times)), np.log(np.asarray(errs))
    order = np.argsort(times)
    times, errs = times[order], errs[order]
    if errs.min() > np.log(target):
        # extrapolate with the Monte-Carlo rate err ~ time^-1/2 from the best point
        i = int(np.argmin(errs))
        return float(np.exp(times[i] + 2 * (errs[i] - np.log(target)))), True
    for i in range(len(times)):
        if errs[i] <= np.log(target):
            if i == 0:
                return float(np.exp(times[0])), False
            f = (np.log(target) - errs[i - 1]) / (errs[i] - errs[i - 1])
            return float(np.exp(times[i - 1] + f * (times[i] - times[i - 1]))), False
    return float("nan"), True


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--target", type=float, default=0.02, help="target RMS relative error")
    ap.add_argument("--grid", type=int, default=6)
    ap.add_argument("--truth-spp", type=int, default=1 << 20)
    a = ap.parse_args()
    d = V.roof_wall_scene(sun_elevation=45.0, sun_azimuth=200.0, sky_radiance=0.05, n=a.grid)
    scene = mi.load_dict(d, optimize=False)
    tris = all_triangles(d, scene)
    n_tri = sum(len(v) for v in tris.values())
    print(f"scene: {n_tri} triangles; truth: path + irradiancemeter at {a.truth_spp} spp each")
    truth, t_truth = path_all(d, tris, a.truth_spp, seed=1000)
    open_ground = truth["ground"].max()
    mask = {k: v > 0.02 * open_ground for k, v in truth.items()}
    print(f"truth took {t_truth:.1f} s; {sum(m.sum() for m in mask.values())} triangles lit "
          f"above 2 % of open ground")

    res_p, res_q = [], []
    photon_irradiance(scene, photons=100_000)  # compile
    for n in [250_000, 1_000_000, 4_000_000, 16_000_000]:
        t = time.perf_counter()
        r = photon_irradiance(scene, photons=n, seed=3)
        # the pass is evaluated lazily: the time includes reading its result back
        est = {k: r.irradiance(k) for k in tris}
        dt = time.perf_counter() - t
        res_p.append((dt, rms(est, truth, mask)))
        print(f"photon pass {n:>11,d} photons: {dt:7.3f} s  RMS {res_p[-1][1]:.4f}")
    path_all(d, {"ground": [0]}, 64)  # compile
    for spp in [256, 1024, 4096, 16384]:
        est, dt = path_all(d, tris, spp, seed=7)
        res_q.append((dt, rms(est, truth, mask)))
        print(f"path tracing {spp:>7d} spp/triangle: {dt:7.3f} s  RMS {res_q[-1][1]:.4f}")
    tp, xp = time_to(a.target, *zip(*res_p))
    tq, xq = time_to(a.target, *zip(*res_q))
    print(f"time to RMS {a.target:.3f}: photon pass {tp:.3f} s{' (extrapolated)' if xp else ''}, "
          f"path tracing {tq:.3f} s{' (extrapolated)' if xq else ''} -> photon pass is "
          f"{tq / tp:.1f}x faster")
    from _record import Recorder
    rec = Recorder("photon_vs_path",
                   notes=f"roof, wall and ground ({n_tri} triangles), sun 45° + sky; truth: "
                         f"path + irradiancemeter at {a.truth_spp:,d} spp per triangle")
    pct = f"{100 * a.target:g} %"
    rec.add("photon_s_at_target", tp, "s",
            f"photon pass to {pct} RMS{' (extrapolated)' if xp else ''}")
    rec.add("path_s_at_target", tq, "s",
            f"path tracing + irradiancemeter to {pct} RMS{' (extrapolated)' if xq else ''}")
    rec.add("speedup_at_target", tq / tp, "ratio",
            f"photon pass faster than path tracing at {pct} RMS")
    rec.write()


if __name__ == "__main__":
    main()
