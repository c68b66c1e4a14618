"""How often a propagule's landing cell is taken, around a moss and around a waiting propagule.

The discrete side (``Simulation``, the moss garden, one seed): on the given days, 16
virtual gemmae are released from the point of every moss and of every waiting propagule
(``land`` as the day's release does, 2 mm off the surface); the share whose landing cell
(another cell than the parent's, on a living triangle) holds an individual is printed per face.
The relaxed side (``SmoothMossModel``, near field, driven by that run's recorded daily light,
``--ensemble``): q = w / rho over all occupants, q_m = w_m / c around a moss and
(w - w_m) / u around a waiting propagule (the moss pairs), per face, weighted by the moss,
the occupants and the waiting. docs/tuning.md ("Seen from a moss") has the numbers.

    python experiments/tune_parent_occupancy.py --seed 0 --days 20,30,40 \
        --ensemble out/ens_garden300
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from mitsuba_veg import tune  # noqa: E402
from mitsuba_veg.daily import Simulation  # noqa: E402
from mitsuba_veg.moss.propagules import land, uniform_sphere  # noqa: E402
from mitsuba_veg.scenario import load_scenario  # noqa: E402
from mitsuba_veg.tune import smooth  # noqa: E402

SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
SPECIES = ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"]
FACES = [(1, 1, "+y"), (2, 1, "+z"), (2, -1, "-z"), (1, -1, "-y")]
RELEASES = 16


def faces_of(normals, slices, living):
    """{"shape face": triangle indices} for the faces whose normal is within ~25 deg of an axis."""
    out = {}
    for shape, sl in slices.items():
        idx = np.arange(sl.start, sl.stop)
        for ax, sg, nm in FACES:
            sel = idx[(normals[idx, ax] * sg > 0.9) & living[idx]]
            if len(sel):
                out[f"{shape} {nm}"] = sel
    return out


def discrete(seed: int, days: list[int], photons: int) -> None:
    scn = load_scenario(SCEN, [f"light.photons={photons}", f"light.seed={seed}",
                               f"moss.species={SPECIES!r}", "simulation.checkpoint_every=0"])
    sim = Simulation(scn, Path(tempfile.mkdtemp()), days=max(days), progress=False)
    sim.setup()
    sim.initialise()
    n = sim.index.n_elements
    living = np.zeros(n, bool)
    living[:sim.site.n_terrain] = sim.site.living
    slices = {sid: sim.index.shape_slice(sid) for sid in sim.index.geometry}
    faces = faces_of(sim.index.normals, slices, living)
    rng = np.random.default_rng(1)
    for d in range(max(days)):
        sim.step()
        if d + 1 not in days:
            continue
        pop = sim.pop
        state = np.asarray(pop.state)
        elem = np.asarray(pop.elem)
        for kind, code in (("moss", 2), ("waiting", 1)):
            src = np.repeat(np.flatnonzero(state == code), RELEASES).astype(np.uint32)
            if len(src) == 0:
                continue
            P = dr.gather(mi.Point3f, pop.pos, mi.UInt32(src))
            N = dr.gather(mi.Vector3f, pop.nrm, mi.UInt32(src))
            r = rng.random((len(src), 2)).astype(np.float32)
            dirs = uniform_sphere(mi.Point2f(mi.Float(r[:, 0]), mi.Float(r[:, 1])))
            landed, el, p, _ = land(sim.scene, sim.index.lookup, P + N * 2e-3, dirs,
                                    float(sim.moss_cfg["gemma_distance"]), mi.Bool(True))
            ok = np.asarray(landed & (sim.grid.index(p) != sim.grid.index(P)))
            el = np.asarray(el).astype(np.int64)
            ok &= (el >= 0) & (el < n)
            ok[ok] &= living[el[ok]]
            taken = np.asarray(sim.grid.occupant(p, mi.Bool(ok))) > 0
            parent = elem[src]
            for name, sel in faces.items():
                m = np.isin(parent, sel) & ok
                if m.sum() < 50:
                    continue
                print(f"discrete day {d + 1:3d} {name:10s} around a {kind:8s}: taken "
                      f"{taken[m].mean():.3f} ({m.sum()} landings, "
                      f"{np.isin(elem[state == code], sel).sum()} parents)", flush=True)


def relaxed(seed: int, days: list[int], ensemble: Path) -> None:
    rec = np.load(ensemble / f"seed_{seed}.npz")
    last = max(days)
    base = tune.prepare(SCEN, days=last, species=SPECIES, photons=10_000, light_every=last,
                        overrides=[f"light.seed={seed}"])
    data = smooth.with_daily_light(base, rec["f_sun"][:last], rec["f_sky"][:last])
    faces = faces_of(data.index.normals, data.shape_slices, data.living)
    M = np.asarray(data.M)
    model = tune.SmoothMossModel(data, temperature=0.0, closure="near-field")
    with dr.suspend_grad():
        P = model.resolve(None)
        L = model.light(P)
        st = model.initial_state()
        for d in range(last):
            st = model.step(st, P, L)
            if d + 1 not in days:
                continue
            c = np.asarray(model.moss_density(st)) * M
            u = np.asarray(model.propagules(st)) * M
            w, wm = np.asarray(st.pair) * M, np.asarray(st.pair_moss) * M
            for name, sel in faces.items():
                if c[sel].sum() < 20:
                    continue
                q = w[sel].sum() / (c + u)[sel].sum()
                q_m = wm[sel].sum() / c[sel].sum()
                q_u = (w - wm)[sel].sum() / max(u[sel].sum(), 1e-12)
                print(f"relaxed  day {d + 1:3d} {name:10s} q {q:.3f}  around a moss {q_m:.3f}  "
                      f"around a waiting {q_u:.3f}  (moss "
                      f"{c[sel].sum():.0f}, waiting {u[sel].sum():.0f})", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--days", default="20,30,40")
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--ensemble", default="out/ens_garden300",
                    help="the garden ensemble whose run of --seed gives the relaxed model its "
                         "daily light (experiments/tune_discrete_ensemble.py)")
    a = ap.parse_args()
    days = [int(x) for x in a.days.split(",")]
    discrete(a.seed, days, a.photons)
    relaxed(a.seed, days, Path(a.ensemble))


if __name__ == "__main__":
    main()
