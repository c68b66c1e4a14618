"""Same seed, same numbers, on every backend: the daily pipeline's repeatability.

Run on the CPU in CI and on a GPU by ``make test-gpu`` (cuda_ad_spectral): Dr.Jit's CUDA float
prefix sums and float atomics are not bitwise repeatable (mitsuba3 issue 1938), so everything a
day sums is an integer or a 64-bit fixed-point sum, and every sampling table is summed on the
host (arrays.DiscreteSampler). These tests hold the day to that.
"""
import gc
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mitsuba_veg as mv
from mitsuba_veg.arrays import DiscreteSampler, Tally
from mitsuba_veg.daily import Simulation
from mitsuba_veg.daily.config import BANDS
from mitsuba_veg.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent
COURTYARD = ROOT / "scenes" / "courtyard" / "scenario.toml"
SMALL = ["light.photons=60000", "moss.initial=100", "simulation.checkpoint_every=0",
         'simulation.start_date="2026-07-01"']


def _world(tmp, days=3, run=None):
    sim = Simulation(load_scenario(COURTYARD, SMALL), tmp, days=days, progress=False)
    sim.setup()
    sim.initialise()
    recs = [sim.step() for _ in range(days if run is None else run)]
    strip = [{k: v for k, v in r.items() if k != "seconds"} for r in recs]
    return sim, strip


def test_two_world_runs_with_one_seed_are_identical(tmp_path):
    """Trees, leaves, light, soil and moss: three days twice, every record and the moss
    population equal to the last bit."""
    a, ra = _world(tmp_path / "a")
    b, rb = _world(tmp_path / "b")
    assert ra == rb
    pa, pb = a.pop.to_numpy(), b.pop.to_numpy()
    for k in pa:
        assert np.array_equal(pa[k], pb[k]), k
    assert np.array_equal(np.asarray(a.state.O), np.asarray(b.state.O))
    assert np.array_equal(np.asarray(a.phen.H), np.asarray(b.phen.H))


def test_frozen_pass_equals_the_traced_pass(tmp_path):
    """The world's photon pass replayed from its recording (dr.freeze) gives the traced pass's
    tallies bit for bit, on other days (new sun path, photon split, seed) too, without being
    recorded again: also when an earlier scene's shapes and emitters, garbage in a reference
    cycle when the pass was first recorded, are collected in between (a recording's key holds
    the objects of Dr.Jit's pointer registry)."""
    gc_was = gc.isenabled()
    gc.disable()
    try:
        junk = [mi.load_dict({"type": "scene", "r": {"type": "rectangle"}, "s": {"type": "sphere"},
                              "e": {"type": "directional", "direction": [0, -1, 0]}})]
        junk.append(junk)
        del junk
        sim, _ = _world(tmp_path / "w", days=4, run=1)
        gc.collect()
    finally:
        if gc_was:
            gc.enable()
    light = sim.pipeline.light
    integ = sim.site.integrator
    for day in (1, 2, 3):
        dirs, w, _ = sim.inputs.sun.day(day)
        sim.site.sun.set_day(dirs, w, size=light.SUN_STEPS)
        kw = dict(photons=60000, seed=day, max_depth=8, bands=BANDS, tables=light.tables,
                  counts=light.counts[day])
        traced = integ.trace(sim.scene, **kw)
        f_traced = traced.flux.copy()
        frozen = integ.trace(sim.scene, frozen=True, **kw)
        assert np.array_equal(f_traced, frozen.flux)
        assert np.array_equal(traced.emitted, frozen.emitted)
        assert traced.rays_traced == frozen.rays_traced
    # the first day recorded it (the daily loop's own call), later days replayed it
    assert integ._frozen.n_cached_recordings == 1


def test_the_walk_in_two_parts_gives_the_numbers_of_one_loop(tmp_path):
    """``split_walk`` (the walk in two parts: every photon's first cast, then the photons that
    go on in dense lanes) gives the one loop's tallies bit for bit: fluxes, emitted, escaped,
    absorbed and truncated power and the casts, traced and replayed from a recording, in both
    kernel modes; with at most one hit (only crossings go on) too."""
    sim, _ = _world(tmp_path / "w", days=2, run=1)
    light = sim.pipeline.light
    integ = sim.site.integrator

    def numbers(split, **more):
        integ.split_walk = split
        r = integ.trace(sim.scene, photons=60000, seed=5, bands=BANDS, tables=light.tables,
                        counts=light.counts[1], **more)
        return [r.flux.copy(), r.emitted, r.escaped, r.absorbed, r.truncated, r.rays_traced]
    try:
        for mode in ("roulette", "weights"):
            casts = []
            for more in ({"max_depth": 8}, {"max_depth": 8, "frozen": True},
                         {"max_depth": 1}):
                one, two = numbers(False, mode=mode, **more), numbers(True, mode=mode, **more)
                for a, b in zip(one, two):
                    assert np.array_equal(a, b), (mode, more)
                casts.append(one[-1])
            # the second part had work: photons went on after their first cast
            assert casts[0] > 60000 * (1.1 if mode == "roulette" else 1.5)
    finally:
        del integ.split_walk                         # the class's default again
    # a recording per arrangement and mode (the day's own pass: one loop, roulette)
    assert integ._frozen.n_cached_recordings == 4


def test_tally_is_exact_and_order_free():
    """The record's sums: a sum over segments equals NumPy's float64 sum to 1e-12, a count is
    exact, and a shuffled input gives the same bits (integer atomics)."""
    rng = np.random.default_rng(0)
    x = rng.random(50_000)
    seg = rng.integers(0, 7, 50_000).astype(np.uint32)
    perm = rng.permutation(50_000)

    def sums(order):
        t = Tally()
        t.add("x", mi.Float64(x[order]), segments=mi.UInt32(seg[order]), n_segments=7)
        t.add("s", mi.Float64(x[order] - 0.5), signed=True)
        t.count("c", mi.Bool(x[order] > 0.5), segments=mi.UInt32(seg[order]), n_segments=7)
        return t.evaluate()
    a, b = sums(np.arange(50_000)), sums(perm)
    for k in a:
        assert np.array_equal(a[k], b[k]), k
    ref = np.array([x[seg == k].sum() for k in range(7)])
    assert np.allclose(a["x"], ref, rtol=1e-12)
    assert a["s"][0] == pytest.approx((x - 0.5).sum(), abs=1e-9)
    assert a["c"].tolist() == [int(((x > 0.5) & (seg == k)).sum()) for k in range(7)]
    t = Tally()
    t.add("bad", mi.Float64(np.array([1.0, -2.0])))
    assert np.isnan(t.evaluate()["bad"][0])          # a negative value in an unsigned sum


def test_tally_with_bounds_sums_in_one_kernel_and_falls_back_when_a_bound_fails():
    """A column with a bound is summed in one kernel per width (no pass for its largest
    value): the same sums as without a bound to 1e-12, shuffled input gives the same bits; a
    lane above its bound makes that column be summed again exactly (equal bits to the sum
    without a bound); NaN gives NaN; a bound that is not a positive number is refused."""
    rng = np.random.default_rng(1)
    x = rng.random(40_000) * 3.0
    seg = rng.integers(0, 5, 40_000).astype(np.uint32)
    perm = rng.permutation(40_000)

    def sums(order, bound, launches=None):
        t = Tally()
        t.add("x", mi.Float64(x[order]), segments=mi.UInt32(seg[order]), n_segments=5,
              bound=bound)
        t.add("s", mi.Float64(x[order] - 1.5), signed=True, bound=bound)
        t.count("c", mi.Bool(x[order] > 1.5))
        if launches is None:
            return t.evaluate()
        dr.kernel_history()
        out = t.evaluate()
        launches.append(sum(e["type"] == dr.KernelType.JIT for e in dr.kernel_history()))
        return out
    free = sums(np.arange(40_000), None)
    was = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        n_free, n_bound = [], []
        sums(np.arange(40_000), None, n_free)
        bounded = sums(np.arange(40_000), 10.0, n_bound)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, was)
    assert n_free == [2] and n_bound == [1]       # one width: two kernels, or one
    shuffled = sums(perm, 10.0)
    for k in free:
        assert np.allclose(bounded[k], free[k], rtol=1e-12, atol=1e-9), k
        assert np.array_equal(bounded[k], shuffled[k]), k
    assert bounded["c"].tolist() == free["c"].tolist()
    # a bound that does not hold (x reaches 3): the column is summed again with its largest
    # value, the same bits as without a bound; the column within it keeps its one pass
    low = sums(np.arange(40_000), 2.0)
    assert np.array_equal(low["x"], free["x"])
    assert np.allclose(low["s"], free["s"], rtol=1e-12)
    t = Tally()
    t.add("nan", mi.Float64(np.array([1.0, np.nan])), bound=5.0)
    t.add("neg", mi.Float64(np.array([1.0, -2.0])), bound=5.0)
    r = t.evaluate()
    assert np.isnan(r["nan"][0]) and np.isnan(r["neg"][0])
    with pytest.raises(ValueError, match="bound"):
        Tally().add("z", mi.Float64(np.ones(3)), bound=0.0)


def test_tally_reusing_its_accumulator_needs_no_memset_and_sums_the_same():
    """A tally given a store of accumulators (a daily record: the same columns every day)
    starts from the accumulator the last evaluation's kernel zeroed: the same sums, day after
    day, with the bound's fallback too, and no memset launch after the first days."""
    rng = np.random.default_rng(4)
    store = {}
    was = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for day in range(5):
            x = rng.random(3_000) * (4.0 if day == 3 else 1.0)   # day 3: above the bound
            seg = rng.integers(0, 3, 3_000).astype(np.uint32)

            def tally(reuse):
                t = Tally(reuse=reuse)
                t.add("x", mi.Float64(x), segments=mi.UInt32(seg), n_segments=3, bound=2.0)
                t.count("c", mi.Bool(x > 0.5))
                return t
            ref = tally(None).evaluate()
            dr.kernel_history()
            got = tally(store).evaluate()
            kinds = [str(e["type"]).split(".")[-1] for e in dr.kernel_history()]
            for k in ref:
                assert np.array_equal(got[k], ref[k]), (day, k)
            assert got["c"].sum() == np.count_nonzero(x > 0.5)
            if day >= 2 and day != 3:
                assert "Memset" not in kinds and kinds.count("JIT") == 1, (day, kinds)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, was)


def test_sampling_table_is_summed_on_the_host():
    """veg_sun_path's and veg_sky's tables: the cumulative sums are NumPy's (float64, rounded
    once), the last entry with weight exactly 1, and draws follow the weights."""
    w = np.array([0.0, 3.0, 1.0, 0.0, 4.0, 0.0])
    d = DiscreteSampler(w)
    c = np.asarray(d.cdf)
    ref = np.cumsum(w / w.sum()).astype(np.float32)
    assert np.array_equal(c[:4], ref[:4]) and np.all(c[4:] == 1.0)
    u = dr.arange(mi.Float, 80_000) / 80_000.0
    k = np.asarray(d.sample(u))
    assert not np.isin(k, [0, 3, 5]).any()           # weight 0: never drawn
    assert np.allclose(np.bincount(k, minlength=6) / 80_000, w / w.sum(), atol=1e-4)
    idx, ur, p = d.sample_reuse(u)
    assert np.all((np.asarray(ur) >= 0) & (np.asarray(ur) < 1))
    assert np.allclose(np.asarray(p), (w / w.sum())[np.asarray(idx)])
