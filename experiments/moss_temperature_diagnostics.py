"""Why warmer air (293.15 K) does not slow the moss down in this model (paper 000 fig 4.3).

Runs the moss garden for N days at 288.15 K and 293.15 K with a capacity large enough not to
saturate, and prints per 10 days: surface temperature Ts at the living moss (mean), the fitness
factors g(Ts), g(rhs), g(S) and G averaged over the moss, germinations and the covered area.
"""
import argparse
from pathlib import Path

import numpy as np

import mitsuba_veg  # noqa: F401
import drjit as dr
import mitsuba as mi

from mitsuba_veg.moss.fitness_model import fitness
from mitsuba_veg.scenario import load_scenario
from mitsuba_veg.daily import Simulation

SCENARIO = Path(__file__).resolve().parent.parent / "scenes" / "moss_garden" / "scenario.toml"


def diagnose(T, days, photons, capacity):
    scn = load_scenario(SCENARIO, [f"climate.temperature={T}", f"light.photons={photons}",
                                   f"moss.capacity={capacity}"])
    sim = Simulation(scn, f"/tmp/moss_diag_{T}", days=days, progress=False)
    sim.out.mkdir(parents=True, exist_ok=True)
    sim.setup()
    sim.initialise()
    rows = []
    for d in range(days):
        rec = sim.step()
        if (d + 1) % 10 == 0:
            st = np.asarray(sim.pop.state)
            live = st == 2
            e = np.asarray(sim.pop.elem)[live]
            sp = np.asarray(sim.pop.species)[live]
            Ts, rhs, S = sim.last["Ts"][e], sim.last["rhs"][e], sim.last["S"][e]
            gT = np.zeros(len(e))
            grh = np.zeros(len(e))
            gS = np.zeros(len(e))
            for k, s in enumerate(sim.species):
                m = sp == k
                gT[m] = fitness(Ts[m], s.T0, s.T1, s.nT)
                grh[m] = fitness(rhs[m], s.rh0, s.rh1, s.nrh)
                gS[m] = fitness(S[m], s.S0, s.S1, s.nS)
            rows.append((rec["day"], rec["moss_alive"], float(Ts.mean()) if len(e) else np.nan,
                         float(gT.mean()), float(grh.mean()), float(gS.mean()),
                         float((gT * grh * gS).mean()), rec["covered_area_m2"]))
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=60)
    ap.add_argument("--photons", type=int, default=250_000)
    ap.add_argument("--capacity", type=int, default=200_000)
    a = ap.parse_args()
    for T in (288.15, 293.15):
        print(f"T = {T} K  (day, moss, mean Ts at moss [K], mean g(Ts), g(rhs), g(S), G, "
              f"covered m2)")
        for r in diagnose(T, a.days, a.photons, a.capacity):
            print("  %4d %7d %8.2f %6.3f %6.3f %6.3f %6.3f %7.3f" % r)


if __name__ == "__main__":
    main()
