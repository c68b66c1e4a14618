"""The light schedule (``simulation.light_every``): a photon pass every N days, the days between
scaled by their own weather; checkpoints only where a resumed run needs no earlier pass."""
from pathlib import Path

import numpy as np
import pytest

from mitsuba_veg.daily import Simulation
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
SMALL = ["light.photons=60000", "simulation.frame_every=100", "moss.capacity=2000",
         "moss.initial=500"]


def _sim(out, days, extra=()):
    scn = load_scenario(SCEN, SMALL + list(extra))
    return Simulation(scn, out, days=days, progress=False)


def test_days_between_passes_reuse_the_fractions_with_their_own_weather(tmp_path):
    sim = _sim(tmp_path, 6, ["simulation.light_every=3"])
    sim.setup()
    sim.initialise()
    f_sun, f_sky, S, passes = [], [], [], []
    for _ in range(6):
        sim.step()
        f_sun.append(sim.last["f_sun"].copy())
        f_sky.append(sim.last["f_sky"].copy())
        S.append(sim.last["S"].copy())
        passes.append(sim.pipeline.light.held[0])
    assert passes == [0, 0, 0, 3, 3, 3]
    # the pass's fractions on the days it serves, new ones at the next pass
    for d in (1, 2):
        assert np.array_equal(f_sun[d], f_sun[0]) and np.array_equal(f_sky[d], f_sky[0])
    assert not np.array_equal(f_sun[3], f_sun[0])
    # each day's insolation from the held fractions and that day's own beam and diffuse
    w = sim.config.weather
    for d in range(6):
        # S = B f_sun + D f_sky (paper 000), written out
        hand = w.beam[d] * np.asarray(f_sun[d]) + w.diffuse[d] * np.asarray(f_sky[d])
        np.testing.assert_allclose(S[d], hand, rtol=1e-12, atol=1e-9)
    assert len({float(np.mean(s)) for s in S[:3]}) == 3    # the weather differs day to day


def test_days_between_passes_cost_no_photon_pass(tmp_path, monkeypatch):
    """Two photon passes in six days instead of six (counted, not timed: the stage's time on a
    shared machine says little)."""
    from mitsuba_veg.integrators.photon_irradiance import PhotonIrradianceIntegrator
    traced = []
    trace = PhotonIrradianceIntegrator.trace

    def counted(self, *a, **k):
        traced.append(k.get("photons"))
        return trace(self, *a, **k)
    monkeypatch.setattr(PhotonIrradianceIntegrator, "trace", counted)
    a = _sim(tmp_path / "a", 6)
    a.run()
    n_a = len(traced)
    b = _sim(tmp_path / "b", 6, ["simulation.light_every=3"])
    b.run()
    n_b = len(traced) - n_a
    print("light stage [s]: every day", a.timings["light"], "every third day",
          b.timings["light"])
    assert n_a == 6 and n_b == 2
    assert set(traced) == {60000}


def test_checkpoints_wait_for_a_pass_day_and_resume_exactly(tmp_path):
    ov = ["simulation.light_every=3", "simulation.checkpoint_every=4"]
    a = _sim(tmp_path / "a", 11, ov)
    sa = a.run()

    class Killed(Exception):
        pass

    def kill_after_day_8(sim, rec):
        if sim.day == 8:
            raise Killed

    b = _sim(tmp_path / "b", 11, ov)
    with pytest.raises(Killed):
        b.run(on_day=kill_after_day_8)
    # due after day 4, written after day 6 (day 6 traces a pass); none since
    assert int(np.load(tmp_path / "b" / "checkpoint.npz")["day"]) == 6
    sb = _sim(tmp_path / "b", 11, ov).run()
    assert sb["resumed"] and sb["settings"]["simulation"]["light_every"] == 3
    strip = lambda recs: [{k: v for k, v in r.items() if k != "seconds"} for r in recs]  # noqa
    assert strip(sb["days_record"]) == strip(sa["days_record"])


def test_light_every_out_of_range_is_refused(tmp_path):
    with pytest.raises(ParameterError, match=r"simulation\.light_every = 0"):
        _sim(tmp_path, 2, ["simulation.light_every=0"])


def test_leaves_fallen_since_the_pass_get_no_light(tmp_path):
    """A fast autumn in the world, a pass every third day: on the days between, the leaves
    that fell since the pass get no light (not their old flux over a zero area) and the
    leaves still on the tree keep the pass's irradiance scaled by the day's weather."""
    import shutil
    d = tmp_path / "scen"
    shutil.copytree(ROOT / "scenes" / "courtyard", d)
    text = (d / "scenario.toml").read_text()
    text = text[:text.index("# ---- the trees of the world")]
    text = text.replace('start_date = "2026-03-01"', 'start_date = "2026-09-07"')
    text += ('\n[[trees]]\nname = "oak"\nmodel = "weber_penn"\npreset = "quaking_aspen"\n'
             'position = [0.0, 0.0, 0.0]\nheight = 4.0\nseed = 3\n\n[phenology]\n'
             'autumn_onset_doy = 250\ninsolation_full = 60.0\ntime_weight = 0.5\n'
             'days_full = 3.0\n')
    (d / "scenario.toml").write_text(text)
    scn = load_scenario(d / "scenario.toml", ["light.photons=100000",
                                              "simulation.light_every=3"])
    sim = Simulation(scn, tmp_path / "run", days=6, progress=False)
    sim.setup()
    sim.initialise()
    fell_between = lit_between = 0
    on = None
    for day in range(6):
        sim.step()
        S = np.asarray(sim.last["light"].S_leaf)
        assert np.all(np.isfinite(S)), day
        if day % 3:
            # the leaves on the tree today: those that had not fallen by last night
            assert np.all(S[~on] == 0.0), day
            fell_between += int((~on).sum())
            lit_between += int((S[on] > 0).sum())
            assert S[on].mean() > 0
        on = np.asarray(sim.phen.on_tree).copy()
        print("day", day, "on the tree tonight", int(on.sum()), "lit", int((S > 0).sum()))
    # the autumn is fast enough to test both kinds of leaf on the days between passes
    assert fell_between > 0 and lit_between > 0


def test_ctrl_c_runs_on_to_the_next_pass_day_then_checkpoints(tmp_path, capsys):
    """Ctrl-C after day 4 with a pass every third day: the run goes on to day 6 (day 6 traces),
    writes its checkpoint there and stops; resumed, it ends as the uninterrupted run."""
    import os
    import signal
    from mitsuba_veg.daily.pipeline import Interrupted
    ov = ["simulation.light_every=3", "simulation.checkpoint_every=0"]

    def ctrl_c_after_day_4(sim, rec):
        if sim.day == 4:
            os.kill(os.getpid(), signal.SIGINT)

    b = _sim(tmp_path / "b", 9, ov)
    with pytest.raises(Interrupted) as e:
        b.run(on_day=ctrl_c_after_day_4)
    assert e.value.day == 6
    assert int(np.load(tmp_path / "b" / "checkpoint.npz")["day"]) == 6
    assert "next photon pass" in capsys.readouterr().out
    sb = _sim(tmp_path / "b", 9, ov).run()
    sa = _sim(tmp_path / "a", 9, ov).run()
    strip = lambda recs: [{k: v for k, v in r.items() if k != "seconds"} for r in recs]  # noqa
    assert sb["resumed"] and strip(sb["days_record"]) == strip(sa["days_record"])
