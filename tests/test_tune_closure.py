"""The near-field (pair) closure of the relaxed model against an ensemble of discrete runs.

The discrete runs (``Simulation``, Bryum argenteum on the moss garden, 8 seeds) and the
relaxed model (t = 0) start from the same scenario; the covered area in total and under the
roof is compared on reported days while the moss spreads. The mean-field closure grows
up to 1.3x faster than the discrete mean there (docs/tuning.md); the near-field closure must be
closer on every reported day and within the tolerances below; driven by each run's own weather
and daily light (``smooth.with_daily_light``) it must be within 10 % (each bound plus two
standard errors of the 8-run mean: its own noise). The full 40-day
comparison at the scenario's photon count is a slow test.
"""
from pathlib import Path

import drjit as dr
import numpy as np
import pytest

from mitsuba_veg import tune
from mitsuba_veg.tune import smooth
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.scenario import load_scenario
from mitsuba_veg.daily import Simulation

ROOT = Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"


def discrete_ensemble(days, photons, seeds, tmp, light=False, species=("bryum_argenteum",)):
    """Per seed and day: covered area in total and under the roof [m2] (``light``: also the
    runs' daily sun and sky fractions per triangle)."""
    out, f_sun, f_sky = [], [], []
    for s in seeds:
        scn = load_scenario(SCEN, [f"light.photons={photons}", f"light.seed={s}",
                                   f"moss.species={list(species)!r}",
                                   "simulation.checkpoint_every=0"])
        sim = Simulation(scn, tmp, days=days, progress=False)
        sim.setup()
        sim.initialise()
        rows, fs, fk = [], [], []
        for _ in range(days):
            rec = sim.step()
            rows.append((rec["covered_area_m2"], rec["regions"]["under_roof"]))
            fs.append(np.array(sim.last["f_sun"]))
            fk.append(np.array(sim.last["f_sky"]))
        out.append(rows)
        f_sun.append(fs)
        f_sky.append(fk)
    if light:
        return np.array(out), np.array(f_sun), np.array(f_sky)
    return np.array(out)                      # seed, day, (total, under_roof)


def relaxed_with_runs_light(days, seeds, f_sun, f_sky, closure="near-field",
                            species=("bryum_argenteum",)):
    """The relaxed model once per seed with that run's weather and daily light; the mean.
    The model's dispersal kernels are seed 0's for every run (a property of the model; one
    preparation's kernels serve the others: ``smooth.prepare`` keeps them)."""
    out = []
    for i, s in enumerate(seeds):
        base = tune.prepare(SCEN, days=days, species=list(species), photons=10_000,
                            light_every=days, overrides=[f"light.seed={s}"], seed=0)
        out.append(relaxed(smooth.with_daily_light(base, f_sun[i], f_sky[i]), closure))
    return np.mean(out, axis=0)


def relaxed(data, closure):
    model = tune.SmoothMossModel(data, temperature=0.0, closure=closure)
    with dr.suspend_grad():
        h = model.run(None, record=True).history
    return np.array([(r["covered_area_m2"], r["regions"]["under_roof"]) for r in h])


def mean_se(cover, report):
    """Relative standard error of the ensemble's mean cover on the reported days (rows) in
    total and under the roof (columns) [-]."""
    c = cover[:, np.array(report) - 1]
    return c.std(0, ddof=1) / np.sqrt(len(cover)) / c.mean(0)


def ratios(days, photons, tmp, report, ens=None):
    disc = (discrete_ensemble(days, photons, range(8), tmp) if ens is None else ens).mean(0)
    data = tune.prepare(SCEN, days=days, species=["bryum_argenteum"], photons=photons,
                        light_every=15)
    mf = relaxed(data, "mean-field")[np.array(report) - 1] / disc[np.array(report) - 1]
    nf = relaxed(data, "near-field")[np.array(report) - 1] / disc[np.array(report) - 1]
    return mf, nf


@pytest.fixture(scope="module")
def ensemble_20_days(tmp_path_factory):
    """8 discrete runs, 20 days, 250 k photons: cover and their daily light."""
    return discrete_ensemble(20, 250_000, range(8), tmp_path_factory.mktemp("ens"), light=True)


@pytest.mark.slow
def test_near_field_closer_to_discrete_mean(tmp_path, ensemble_20_days):
    report = [10, 20]
    mf, nf = ratios(20, 250_000, tmp_path, report, ensemble_20_days[0])
    # measured (8 seeds, 250 k photons, Meinel sun-path weights, before
    # main's 06870f2; the bounds also held after merging it): total mean-field 1.035 / 1.187,
    # near-field 1.016 / 1.091; under the roof mean-field 0.938 / 1.018, near-field
    # 0.915 / 0.941; with siblings and moss pairs (the default now) the near field's total
    # 0.967 on day 20, under the roof 0.896 / 0.878: the model's own light, without the runs'
    # photon noise, grows less under the roof (docs/tuning.md), and the discrete mean's s.e.
    # there is 7.4 % on day 20. With the pass in one launch (other photon streams) the 8 runs
    # are higher (day 20: 0.0870 m2 in total, 0.0317 under the roof, 1.4 s.e. above 24 runs'
    # 0.0840 / 0.0293, which match the earlier pass's 24 runs, 0.0834 / 0.0291) and the
    # near field's own light of seed 0 is low among seeds 0-3 (under the roof 0.0239 against
    # 0.0252): total 0.891, under the roof 0.755 on day 20 (0.92 / 0.82 of the 24 runs). The
    # bounds: the model's allowance plus two standard errors of the ensemble's mean
    se = mean_se(ensemble_20_days[0], report)
    assert np.all(np.abs(nf[:, 0] - 1) < 0.10 + 2 * se[:, 0]), (nf, se)
    assert np.all(np.abs(nf[:, 1] - 1) < 0.15 + 2 * se[:, 1]), (nf, se)
    # the mean-field excess this closure removes, independent of the ensemble's noise
    # (measured 1.082 / 0.891 = 1.21 on day 20). Whether the near field is closer to the
    # discrete mean than the mean field on day 20 is not resolved by 8 runs (s.e. 3.6 % in
    # total; 1.082 / 0.891 against these, 1.12 / 0.92 against 24 runs): the slow 40-day test
    # asserts it on days 20-40, where the mean field's excess is larger
    assert mf[-1, 0] / nf[-1, 0] > 1.12, (mf, nf)


@pytest.mark.slow
def test_near_field_with_the_runs_light(ensemble_20_days):
    """Driven by each run's own weather and daily light (photon noise, moss albedo), the
    near-field model is within 10 % of the discrete mean on days 10 and 20 in total, and
    within 12 % under the roof, each plus two standard errors of the 8-run mean (its s.e.
    under the roof is 5-7 % on day 20); with 16
    runs at 1 M photons the model is within 8.5 % on days 5-50, docs/tuning.md)."""
    cover, f_sun, f_sky = ensemble_20_days
    rel = relaxed_with_runs_light(20, range(8), f_sun, f_sky)
    r = rel[[9, 19]] / cover.mean(0)[[9, 19]]
    # measured (Meinel sun-path weights, before main's 06870f2; passed after merging it):
    # total 1.016 / 1.059, under the roof 0.962 / 0.954; with siblings 0.974 / 0.959 and
    # 0.948 / 0.907; with moss pairs (the default) 0.973 / 0.948 and 0.945 / 0.891; with the
    # pass in one launch 0.951 / 0.905 and 0.860 / 0.822: these 8 runs' cover is 1.4 s.e.
    # above 24 runs' (test above), so the bounds add two standard errors of the ensemble's mean
    se = mean_se(cover, [10, 20])
    assert np.all(np.abs(r[:, 0] - 1) < 0.10 + 2 * se[:, 0]), (r, se)
    assert np.all(np.abs(r[:, 1] - 1) < 0.12 + 2 * se[:, 1]), (r, se)


def test_daily_light_reproduces_the_passes():
    """with_daily_light given the light the model interpolates from its own passes gives the
    same run (the per-day path is only a different source of the same S)."""
    days = 6
    data = tune.prepare(SCEN, days=days, species=["bryum_argenteum"], photons=20_000,
                        light_every=3)
    L = data.light
    f_sun, f_sky = [], []
    for d in range(days):
        k0, k1, w = L.weights(d)
        f_sun.append((1 - w) * L.f_sun[k0] + w * L.f_sun[k1])
        f_sky.append(L.f_sky)
    a = relaxed(data, "near-field")
    b = relaxed(smooth.with_daily_light(data, f_sun, f_sky), "near-field")
    assert np.allclose(a, b, rtol=1e-5, atol=1e-9)
    with pytest.raises(ParameterError):
        smooth.with_daily_light(data, np.zeros((days - 1, data.n)), np.zeros((days, data.n)))


@pytest.mark.slow
def test_near_field_after_the_capacity_with_the_runs_light(tmp_path):
    """Bryum, 160 days, 1 M photons, 8 seeds: after the capacity (days 60-160) the near field
    driven by each run's weather and daily light is within 6 % in total and 11 % under the
    roof; with its own (noise-free) passes it stays well below under the roof: the light's
    photon noise is what makes the difference (docs/tuning.md, diagnosis 1)."""
    days, seeds = 160, range(8)
    cover, f_sun, f_sky = discrete_ensemble(days, 1_000_000, seeds, tmp_path, light=True)
    disc = cover.mean(0)
    rep = np.arange(60, days + 1, 20) - 1
    runs = relaxed_with_runs_light(days, seeds, f_sun, f_sky)[rep] / disc[rep]
    own = np.mean([relaxed(tune.prepare(SCEN, days=days, species=["bryum_argenteum"],
                                        photons=1_000_000, light_every=15,
                                        overrides=[f"light.seed={s}"]), "near-field")
                   for s in seeds], axis=0)[rep] / disc[rep]
    # measured (experiments/tune_closure.py --discrete-light / --per-seed on the same runs,
    # Meinel sun-path weights, before main's 06870f2; this test passed then, not re-run after):
    # runs' light total 1.015-1.048, under the roof 0.899-0.924; own light under the roof
    # 0.718-0.779
    assert np.all(np.abs(runs[:, 0] - 1) < 0.06), runs
    assert np.all(np.abs(runs[:, 1] - 1) < 0.11), runs
    assert np.all(own[:, 1] < 0.85), own


@pytest.mark.slow
def test_garden_300_days_with_the_runs_light(tmp_path):
    """The paper's garden (3 species, 300 days, 1 M photons, 8 seeds): the near field driven by
    each run's weather and daily light is within 10 % of the discrete mean in total and under
    the roof on every reported day, the spread phase (day 40) included (docs/tuning.md; ~12
    min on 2 cores)."""
    days, seeds = 300, range(8)
    sp = ("bryum_argenteum", "hypnum_plumaeforme", "polytrichum")
    cover, f_sun, f_sky = discrete_ensemble(days, 1_000_000, seeds, tmp_path, light=True,
                                            species=sp)
    rep = np.array([20, 40, 60, 100, 140, 200, 300]) - 1
    r = relaxed_with_runs_light(days, seeds, f_sun, f_sky, species=sp)[rep] / cover.mean(0)[rep]
    # measured (experiments/tune_closure.py --discrete-light on the same 8 seeds, siblings and
    # moss pairs): total 1.001 / 1.058 / 1.042 / 1.044 / 1.030 / 1.029 / 1.024, under the roof
    # 0.951 / 1.017 / 0.991 / 0.985 / 0.964 / 0.958 / 0.960 (without moss pairs: total 1.111
    # on day 40; without siblings either: 1.189)
    assert np.all(np.abs(r - 1) < 0.10), r


@pytest.mark.slow
def test_near_field_40_days_full_light(tmp_path):
    report = [10, 20, 30, 40]
    mf, nf = ratios(40, 1_000_000, tmp_path, report)
    # measured (experiments/tune_closure.py --days 40 on the same 8 seeds, Meinel sun-path
    # weights, before main's 06870f2):
    # total mean-field 0.988 / 1.088 / 1.227 / 1.273, near-field 0.971 / 1.000 / 1.054 / 1.166;
    # under the roof near-field 0.876 / 0.818 / 0.840 / 0.918 (mean-field 0.898 / 0.886 /
    # 0.943 / 0.949)
    assert np.all(np.abs(nf[1:, 0] - 1) <= np.abs(mf[1:, 0] - 1)), (mf, nf)
    assert np.all(np.abs(nf[:, 0] - 1) < 0.20), nf
    assert np.all(np.abs(nf[:, 1] - 1) < 0.22), nf


def test_closure_arguments():
    data = tune.prepare(SCEN, days=2, species=["bryum_argenteum"], photons=10_000)
    with pytest.raises(ParameterError):
        tune.SmoothMossModel(data, closure="pairs")
    with pytest.raises(ParameterError):
        tune.SmoothMossModel(data, closure="near-field", near_cells=40)
    with pytest.raises(ParameterError, match="near_overlap"):
        tune.SmoothMossModel(data, closure="near-field", near_overlap=1.5)
    z = data.kernels["gemma"].near_cells
    assert np.nanmin(z) >= 1 and 10 < np.nanmedian(z) < 26      # cells within 2 cm
    th = data.kernels["gemma"].near_overlap
    assert np.nanmin(th) >= 0 and np.nanmax(th) <= 1 and 0.1 < np.nanmedian(th) < 0.6
    # theta = 0 is the plain pair approximation: a gemma's other neighbours occupied with q10,
    # fewer pairs than with shared neighbours occupied as next to its parent, so less settles
    d20 = tune.prepare(SCEN, days=20, species=["bryum_argenteum"], photons=10_000)
    sums = []
    for th in (0.0, 1.0):
        m = tune.SmoothMossModel(d20, temperature=0.0, closure="near-field", near_overlap=th)
        st = m.run(None).state
        sums.append((float(np.sum(np.asarray(st.pair))),
                     float(np.sum(np.asarray(m.moss_density(st))))))
    plain, tri = sums
    assert tri[0] > plain[0] and tri[1] < plain[1], (plain, tri)
    # gemmae competing with the arrivals next to their parents settle less than with the
    # triangle's mean arrivals
    cover = [float(np.sum(np.asarray(tune.SmoothMossModel(
        d20, temperature=0.0, closure="near-field", local_arrivals=la).run(None).cover)
        * d20.areas)) for la in (False, True)]
    assert cover[1] < cover[0], cover
    m = tune.SmoothMossModel(data, temperature=0.0, closure="near-field")
    st = m.run(None).state
    assert st.pair is not None and len(st.arrays()) == 1 + 6 + 2      # pairs, moss pairs
    occ = np.asarray(m.moss_density(st) + m.propagules(st))
    pair = np.asarray(st.pair)
    assert np.all(pair <= occ + 1e-6) and np.all(pair >= occ * occ - 1e-6)


@pytest.mark.slow
def test_fit_s1_to_discrete_mean(tmp_path):
    """S1 fitted with the near-field closure to the mean map of 8 discrete runs (30 days, the
    scenario's 1 M photons; experiments/tune_discrete_inverse.py measured 59.38 from 42). With
    250 k photons and 20 days the fit gave 56.2 (-6.3 %): the discrete runs depend on their
    photon count (docs/tuning.md)."""
    days, photons = 30, 1_000_000
    data = tune.prepare(SCEN, days=days, species=["bryum_argenteum"], photons=photons,
                        light_every=15)
    maps = []
    for s in range(8):
        scn = load_scenario(SCEN, [f"light.photons={photons}", f"light.seed={s}",
                                   "moss.species=['bryum_argenteum']",
                                   "simulation.checkpoint_every=0"])
        sim = Simulation(scn, tmp_path, days=days, progress=False)
        sim.setup()
        sim.initialise()
        for _ in range(days):
            sim.step()
        maps.append(np.minimum(sim.counts() * data.cell ** 2, data.areas) / data.areas)
    model = tune.SmoothMossModel(data, temperature=0.01, closure="near-field")
    res = tune.fit(model, np.mean(maps, axis=0), params=["S1"], init={"S1": 42.0}, steps=80,
                   out=None, progress=False)
    assert abs(res.values["S1"] / 60.0 - 1) < 0.05, res.values


def test_near_overlap_of_uniform_kernels():
    """theta of ``dispersal.near_overlap`` against exact shares: landing uniformly in the 8
    cells around the parent's (a square lattice's Moore neighbourhood), a cell at an edge
    offset shares 4 of its 7 other neighbours with the parent, at a corner 2: theta = 3 / 7;
    landing only at the 4 edge cells, a cell shares none of its 3 others: theta = 0. z
    (``near_cells``) is 8 and 4."""
    from mitsuba_veg.tune.dispersal import near_cells, near_overlap

    def code(o):
        return sum((o[k] + 8) * 17 ** k for k in range(3))
    rng = np.random.default_rng(1)
    moore = [(dx, dy, 0) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if (dx, dy) != (0, 0)]
    edges = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)]
    for offs, theta, z in ((moore, 3 / 7, 8.0), (edges, 0.0, 4.0)):
        codes = np.array([code(o) for o in offs])
        src = np.repeat(np.arange(4), 3000)
        off = codes[rng.integers(0, len(offs), len(src))]
        assert near_overlap(src, off, 5)[:4] == pytest.approx(theta, abs=0.02)
        assert near_cells(src, off, 5)[:4] == pytest.approx(z, rel=0.03)
        assert np.isnan(near_overlap(src, off, 5)[4])          # no landings sampled


def test_pooled_share_sums_the_gemma_neighbourhood():
    """``dispersal.pooled_share``: same / both over the element and the elements its gemmae
    reach (each once, whatever the weight), NaN below ``min_pairs``."""
    from mitsuba_veg.tune.dispersal import Kernel, pooled_share
    # 0 -> 0, 1 (twice the weight: still once), 2 -> 2, 3 -> nothing
    k = Kernel("gemma", 0.02, 4, np.array([0, 0, 1, 2]), np.array([0, 1, 0, 2]),
               np.array([0.25, 0.5, 0.25, 0.25]), 4)
    same = np.array([2.0, 6.0, 1.0, 0.0])
    both = np.array([10.0, 20.0, 4.0, 30.0])
    out = pooled_share(k, same, both, min_pairs=20.0)
    assert out[0] == pytest.approx(8.0 / 30.0)          # itself and 1
    assert out[1] == pytest.approx(8.0 / 30.0)          # itself and 0
    assert np.isnan(out[2])                             # 4 pairs only
    assert out[3] == 0.0                                # 30 pairs, none shared a cell


def test_siblings_of_a_fixed_parent():
    """The near field seen from a parent's fixed point (``siblings=True``, the default): on the
    wall's back a gemma hops a few mm into the wall, so a parent reaches about half the cells
    its triangle's gemmae do (z ~5 against ~11) and a spore that stays on the wall lands
    where that parent's gemmae land (a third of the pairs share a cell); on the ground a
    parent reaches as many cells as its triangle, and most spores land far. The back of the
    wall grows slower, the ground as before."""
    data = tune.prepare(SCEN, days=25, species=["bryum_argenteum"], photons=10_000)
    nrm = data.index.normals

    def face(shape, axis, sign):
        sl = data.shape_slices[shape]
        i = np.arange(sl.start, sl.stop)
        return i[(nrm[i, axis] * sign > 0.9) & data.living[i]]
    back, ground = face("wall", 2, -1), face("ground", 1, 1)
    kg, ks = data.kernels["gemma"], data.kernels["spore"]
    with np.errstate(divide="ignore"):
        z_loc = 1.0 / kg.sibling_share
    # measured: z 11.0 / 22.5 (triangle), 5.3 / 26.1 (fixed point); spore pairs sharing a cell
    # 0.36 / 0.024; spores landing far 0.0 / 0.84
    assert np.nanmedian(z_loc[back]) < 0.7 * np.nanmedian(kg.near_cells[back])
    assert 0.8 < np.nanmedian(z_loc[ground]) / np.nanmedian(kg.near_cells[ground]) < 1.3
    assert np.nanmedian(ks.sibling_share[back]) > 0.2
    assert np.nanmedian(ks.sibling_share[ground]) < 0.08
    assert np.nanmedian(ks.far_share[back]) < 0.05 < 0.6 < np.nanmedian(ks.far_share[ground])
    moss = {}
    for sb in (False, True):
        m = tune.SmoothMossModel(data, temperature=0.0, closure="near-field", siblings=sb)
        with dr.suspend_grad():
            c = np.asarray(m.run(None).moss_density) * data.M
        moss[sb] = (c[back].sum(), c[ground].sum())
    # measured: back 181.8 -> 137.2, ground 286.3 -> 286.9
    assert moss[True][0] < 0.85 * moss[False][0], moss
    assert moss[True][1] == pytest.approx(moss[False][1], rel=0.03), moss


def test_moss_pairs_see_the_parents_neighbourhood():
    """``moss_pairs`` (the default): the pairs whose first cell holds moss, w_m, are kept apart
    from the pairs of all occupants, w. A moss's own gemmae settle around it while the waiting
    newcomers sit mostly alone, so q_m = w_m / c exceeds q = w / rho once the moss spreads (the
    discrete garden, seed 0, day 30, on the ground: 0.23 around a moss, 0.075 around a waiting
    propagule); its gemmae find fewer free cells and less moss grows. Bookkeeping: w - u <=
    w_m <= min(c, w), and at day 0, with moss only, w_m = w."""
    data = tune.prepare(SCEN, days=30, species=["bryum_argenteum"], photons=10_000)
    ground = data.living.copy()
    sl = data.shape_slices["ground"]
    ground[:sl.start] = False
    ground[sl.stop:] = False
    runs = {}
    for mp in (False, True):
        m = tune.SmoothMossModel(data, temperature=0.0, closure="near-field", moss_pairs=mp)
        st0 = m.initial_state()
        if mp:
            assert np.array_equal(np.asarray(st0.pair_moss), np.asarray(st0.pair))
        with dr.suspend_grad():
            st = m.run(None).state
        runs[mp] = (m, st)
    m, st = runs[True]
    assert runs[False][1].pair_moss is None and len(st.arrays()) == 1 + 6 + 2
    c = np.asarray(m.moss_density(st))
    u = np.asarray(m.propagules(st))
    w, wm = np.asarray(st.pair), np.asarray(st.pair_moss)
    assert np.all(wm <= np.minimum(c, w) + 1e-6) and np.all(wm >= w - u - 1e-6)
    g = ground & (c > 1e-4)
    M = np.asarray(data.M)[g]
    q = (w[g] * M).sum() / ((c + u)[g] * M).sum()
    q_m = (wm[g] * M).sum() / (c[g] * M).sum()
    # measured: 0.132 around the mean occupant, 0.239 around a moss
    assert q_m > 1.4 * q, (q, q_m)
    moss = [float((np.asarray(runs[mp][0].moss_density(runs[mp][1])) * data.M)[ground].sum())
            for mp in (False, True)]
    # measured: 437.5 -> 400.2 moss on the ground
    assert moss[1] < 0.95 * moss[0], moss
