"""Paper 000's experiments on the moss garden as measurable results (figs 4.1-4.3).

Reduced photon counts keep the runs short; experiments/moss_paper_experiments.py runs them at
full size and draws the comparison figures.
"""
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg as mv
from mitsuba_veg.moss.fitness_model import fitness
from mitsuba_veg.scenario import load_scenario
from mitsuba_veg.daily import Simulation

SCEN = Path(__file__).resolve().parent.parent / "scenes" / "moss_garden" / "scenario.toml"
FAST = ["light.photons=100000", "simulation.checkpoint_every=0"]


@pytest.mark.slow
def test_indirect_light_spreads_moss_under_the_roof(tmp_path):
    """Figs 4.1/4.2: after 300 days the moss area under the roof (back floor + roof underside)
    is clearly larger with indirect light."""
    on = mv.run(SCEN, out=tmp_path / "on", days=300, progress=False, frames=False,
                overrides=FAST + ["light.indirect=true"])
    off = mv.run(SCEN, out=tmp_path / "off", days=300, progress=False, frames=False,
                 overrides=FAST + ["light.indirect=false"])
    a_on = on["final"]["regions"]["under_roof"]["covered_area_m2"]
    a_off = off["final"]["regions"]["under_roof"]["covered_area_m2"]
    print(f"under-roof moss area: indirect on {a_on:.4f} m2, off {a_off:.4f} m2, "
          f"ratio {a_on / a_off:.2f}")
    assert a_on > 1.2 * a_off
    # and the light itself: indirect light lifts the insolation under the roof
    s_on = np.mean([r["mean_S_W_m2"] for r in on["days_record"]])
    s_off = np.mean([r["mean_S_W_m2"] for r in off["days_record"]])
    assert s_on > s_off


def _run(T, days, tmp):
    scn = load_scenario(SCEN, FAST + [f"climate.temperature={T}", "moss.capacity=100000"])
    sim = Simulation(scn, tmp, days=days, progress=False)
    sim.out.mkdir(parents=True, exist_ok=True)
    sim.setup()
    sim.initialise()
    for _ in range(days):
        rec = sim.step()
    live = np.asarray(sim.pop.state) == 2
    e = np.asarray(sim.pop.elem)[live]
    sp = np.asarray(sim.pop.species)[live]
    Ts = sim.last["Ts"][e]
    gT = np.zeros(len(e))
    for k, s in enumerate(sim.species):
        gT[sp == k] = fitness(Ts[sp == k], s.T0, s.T1, s.nT)
    return rec, float(Ts.mean()), float(gT.mean())


def test_air_temperature_effect_as_the_equations_give_it(tmp_path):
    """Fig 4.3 reports less moss at 293.15 K than at 288.15 K. Implemented faithfully, the soil
    model puts shaded surfaces well below air temperature (eq 3.11 with R < sigma T^4), so at
    288.15 K the moss sits *below* its species' optimum and warmer air helps: this test pins the
    direction and the mechanism (docs/deviations.md gives the numbers)."""
    r288, ts288, g288 = _run(288.15, 40, tmp_path / "t288")
    r293, ts293, g293 = _run(293.15, 40, tmp_path / "t293")
    print(f"day 40: cover {r288['covered_area_m2']:.3f} vs {r293['covered_area_m2']:.3f} m2; "
          f"Ts at moss {ts288:.2f} vs {ts293:.2f} K; g(Ts) {g288:.3f} vs {g293:.3f}")
    assert ts288 < 288.15 - 5.0 and ts293 < 293.15 - 5.0   # shaded surfaces run cold
    assert g293 > g288                                      # closer to the optimum
    assert r293["covered_area_m2"] > 1.5 * r288["covered_area_m2"]
