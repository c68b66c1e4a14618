"""Photon-pass throughput against Mitsuba's raw ray casting on the same scene, same rays.

Prints, for each photon count: photons/s, ray casts/s of the whole pass (every cast counted,
emission, pilot and read-back included), and the ratio to the throughput of
  - scene.ray_intersect_preliminary (the BVH traversal alone: the headline ratio) and
  - scene.ray_intersect (full surface interaction, all fields evaluated; skipped for the
    instanced scene, where Mitsuba's per-instance virtual call makes it ~30-50x slower)
on the same number of incoherent rays drawn like the photons (same emitters, same aiming).
The three timings are interleaved in every repetition and the ratio is the median of the
per-repetition ratios, so that load from other processes on a shared machine hits both sides.
Dr.Jit kernels are compiled before timing.

    python benchmarks/photon_throughput.py [--scene garden|moss_garden|plants1000|world] [--reps 5]
        [--split]

``--split``: the pass also runs with its random walk in two parts and in one loop
(``PhotonKernel.split_walk``: the first casts, then the photons that go on in dense lanes),
interleaved; printed: their times and ratio (the tallies are compared and must be equal).

``world``: the light scene of ``benchmarks/world_year.py``'s courtyard world on 1 July (trees
in full leaf, > 100,000 leaves: one leaf mesh with its daily mode and stage tables, bark,
terrain; the day's sun path and the sky), traced as the daily loop traces it.
"""
import argparse
import os
import sys
import time

import numpy as np

import mitsuba as mi
import drjit as dr

sys.path.insert(0, os.path.dirname(__file__))
from _record import Recorder  # noqa: E402
from _scenes import garden_80k  # noqa: E402
from mitsuba_veg.integrators.photon_irradiance import PhotonIrradianceIntegrator, SceneIndex  # noqa
from mitsuba_veg.light import validation as V  # noqa: E402


def world_scene(start="2026-07-01"):
    """The benchmark world's light scene on ``start`` and a photon pass with the day's leaf,
    albedo and record tables (see benchmarks/world_year.py): (scene, pass, simulation)."""
    import shutil
    import tempfile
    from pathlib import Path

    from mitsuba_veg.daily import Simulation
    from mitsuba_veg.scenario import load_scenario
    from world_year import EXTRA
    root = Path(__file__).resolve().parent.parent
    tmp = Path(tempfile.mkdtemp())
    shutil.copytree(root / "scenes" / "courtyard", tmp / "courtyard")
    f = tmp / "courtyard" / "scenario.toml"
    f.write_text(f.read_text().replace("[phenology]", EXTRA + "\n[phenology]", 1))
    sim = Simulation(load_scenario(f, [f'simulation.start_date="{start}"']), tmp / "run",
                     days=1, progress=False)
    sim.setup()
    sim.initialise()
    sim.step()          # sets the day's sun path and the leaf tables
    shutil.rmtree(tmp, ignore_errors=True)
    sl = sim.index.shape_slice('trees_bark')
    print(f"world: {sim.canopy.n_leaves:,d} leaves ({len(sim.canopy.tri):,d} triangles), "
          f"bark {sl.stop - sl.start:,d} triangles")
    return sim.scene, WorldPass(sim), sim


class WorldPass:
    """The world's photon pass as the daily pipeline traces it: the integrator's ``trace`` with
    the light stage's device tables (albedo, leaf stages and modes, recorded shapes) and the
    day's photon split."""

    def __init__(self, sim):
        self.sim = sim
        self.integ = sim.site.integrator
        self.tables = sim.pipeline.light.tables
        self.counts = sim.pipeline.light.counts[0]

    def trace(self, scene, photons=1_000_000, seed=0, **kw):
        from mitsuba_veg.daily.config import BANDS
        counts = None if photons != int(self.counts.sum()) else self.counts
        return self.integ.trace(scene, photons=photons, seed=seed, bands=BANDS,
                                tables=self.tables, counts=counts, **kw)

    def __getattr__(self, name):
        return getattr(self.integ, name)


def load(name):
    if name == "world":
        return world_scene()
    if name == "garden":
        return garden_80k()
    if name == "plants1000":
        return mi.load_dict(V.plant_scene(1000, instanced=True), optimize=False)
    root = os.path.join(os.path.dirname(__file__), "..", "scenes", "moss_garden", "scene.xml")
    return mi.load_file(root, optimize=False)


def raw_rays(integ, scene, n, seed):
    """n rays distributed like the photons' first rays (all emitters, same aiming and
    stratification; the pass splits photons among emitters by power, this evenly)."""
    index = SceneIndex.build(scene)
    ems = scene.emitters()
    per = [n // len(ems) + (1 if i < n % len(ems) else 0) for i in range(len(ems))]
    O, D = [], []
    for i, (e, k) in enumerate(zip(ems, per)):
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed + i, k)
        lam = 360.0 + 470.0 * sampler.next_1d()
        # the same jittered-grid order of origins as the pass (neighbouring lanes, neighbouring
        # rays): the raw casts get the same memory coherence as the photons
        idx = dr.arange(mi.UInt32, k)
        o, d, w, t = integ._emit(scene, e, index, sampler, mi.Spectrum(lam, lam, lam, lam),
                                 mi.Bool(True), strata=(idx, int(np.sqrt(k))))
        dr.eval(o, d)
        O.append(np.stack([np.broadcast_to(np.asarray(c), (k,)) for c in (o.x, o.y, o.z)]))
        D.append(np.stack([np.broadcast_to(np.asarray(c), (k,)) for c in (d.x, d.y, d.z)]))
    return (np.concatenate(O, 1).astype(np.float32), np.concatenate(D, 1).astype(np.float32))


def time_raw(scene, O, D, kind, r):
    """Seconds for one batch of raw intersections (fresh inputs: Dr.Jit could otherwise reuse
    a still-alive identical result)."""
    o = mi.Point3f(*[mi.Float(O[k] + np.float32(r * 1e-7)) for k in range(3)])
    d = mi.Vector3f(*[mi.Float(D[k]) for k in range(3)])
    dr.eval(o, d)
    dr.sync_thread()
    t = time.perf_counter()
    ray = mi.Ray3f(o, d)
    if kind == "full":
        si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False)
        dr.eval(si)
    else:
        pi = scene.ray_intersect_preliminary(ray, coherent=False)
        dr.eval(pi)
    dr.sync_thread()
    return time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="garden", choices=["garden", "moss_garden", "plants1000",
                                                             "world"])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--photons", type=int, nargs="*", default=[1_000_000, 4_000_000])
    ap.add_argument("--split", action="store_true",
                    help="also time the pass with the walk in two parts and in one loop "
                         "(PhotonKernel.split_walk), interleaved; their tallies are compared")
    a = ap.parse_args()
    scene = load(a.scene)
    integ = PhotonIrradianceIntegrator()
    if isinstance(scene, tuple):      # the world: its pass holds the day's leaf tables
        scene, integ, _ = scene
    index = SceneIndex.build(scene)
    print(f"scene {a.scene}: {index.n_elements} elements ({len(index.instances)} instances), "
          f"{len(scene.emitters())} emitters, variant {mi.variant()}, {os.cpu_count()} CPU "
          f"threads")
    full = a.scene != "plants1000"
    plugin = getattr(integ, "integ", integ)      # (the world's pass wraps the plugin)
    rec = Recorder(f"photon_throughput_{a.scene}",
                   notes=f"scene {a.scene}: {index.n_elements:,d} elements, "
                         f"{len(index.instances)} instances, {len(scene.emitters())} emitters; "
                         f"median of {a.reps} interleaved repetitions")
    for n in a.photons:
        tag = f"{n / 1e6:g}M"
        res = integ.trace(scene, photons=n, seed=0)  # compile
        if a.split:
            t_walk = {False: [], True: []}
            for r in range(a.reps + 1):
                flux = {}
                for split in (False, True):
                    plugin.split_walk = split
                    dr.sync_thread()
                    t = time.perf_counter()
                    res = integ.trace(scene, photons=n, seed=r + 1)
                    flux[split] = (res.flux, res.rays_traced)
                    dr.sync_thread()
                    if r:                            # the first repetition compiles
                        t_walk[split].append(time.perf_counter() - t)
                if not (np.array_equal(flux[False][0], flux[True][0])
                        and flux[False][1] == flux[True][1]):
                    raise SystemExit("the walk in two parts gave other tallies than one loop")
            del plugin.split_walk                    # the class's default again
            ratios = [b / o for o, b in zip(t_walk[False], t_walk[True])]
            print(f"{n:>9,d} photons: walk in one loop {np.median(t_walk[False]):.3f} s, in two "
                  f"parts {np.median(t_walk[True]):.3f} s: two parts / one loop "
                  f"{np.median(ratios):.2f} (per rep: {', '.join(f'{x:.2f}' for x in ratios)}; "
                  f"same tallies; the default: {'two parts' if type(plugin).split_walk else 'one loop'})")
            rec.add(f"split_over_one_loop_{tag}", float(np.median(ratios)), "ratio",
                    f"walk in two parts / in one loop, {tag} photons (time)")
        O, D = raw_rays(integ, scene, res.rays_traced, seed=99)
        time_raw(scene, O, D, "prelim", 0)
        if full:
            time_raw(scene, O, D, "full", 0)
        t_pass, t_pre, t_full, ratio_pre, ratio_full, rays = [], [], [], [], [], []
        for r in range(a.reps):
            t = time.perf_counter()
            res = integ.trace(scene, photons=n, seed=r + 1)
            rays.append(res.rays_traced)        # the bookkeeping read back: the pass has run
            dr.sync_thread()
            t_pass.append(time.perf_counter() - t)
            # the raw rays are timed on the same count of rays as this pass cast
            scale = res.rays_traced / O.shape[1]
            t_pre.append(time_raw(scene, O, D, "prelim", r + 1) * scale)
            ratio_pre.append(t_pre[-1] / t_pass[-1])
            if full:
                t_full.append(time_raw(scene, O, D, "full", r + 1) * scale)
                ratio_full.append(t_full[-1] / t_pass[-1])
        tp = float(np.median(t_pass))
        nr = int(np.median(rays))
        print(f"{n:>9,d} photons: pass {tp:.3f} s, {n / tp / 1e6:.2f} M photons/s, "
              f"{nr:,d} ray casts ({nr / n:.2f}/photon) = {nr / tp / 1e6:.2f} M casts/s")
        print(f"          ray_intersect_preliminary {nr / np.median(t_pre) / 1e6:.2f} M rays/s "
              f"-> ratio {np.median(ratio_pre):.2f} (per rep: "
              f"{', '.join(f'{x:.2f}' for x in ratio_pre)})")
        if full:
            print(f"          ray_intersect (full) {nr / np.median(t_full) / 1e6:.2f} M rays/s "
                  f"-> ratio {np.median(ratio_full):.2f}")
        rec.add(f"pass_s_{tag}", tp, "s", f"photon pass of {tag} photons")
        rec.add(f"photons_per_s_{tag}", n / tp / 1e6, "M photons/s", f"photons per second, {tag}")
        rec.add(f"casts_per_photon_{tag}", nr / n, "", f"ray casts per photon, {tag}")
        rec.add(f"ratio_preliminary_{tag}", float(np.median(ratio_pre)), "ratio",
                f"pass ray casts/s ÷ `ray_intersect_preliminary` rays/s, {tag} photons")
        if full:
            rec.add(f"ratio_full_{tag}", float(np.median(ratio_full)), "ratio",
                    f"pass ray casts/s ÷ `ray_intersect` rays/s, {tag} photons")
    rec.write()


if __name__ == "__main__":
    main()
