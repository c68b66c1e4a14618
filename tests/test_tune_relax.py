"""Relaxed moss life cycle (mitsuba_veg.tune): the relaxations and their t -> 0 limit, which must
be the discrete life cycle of moss/population.py."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mitsuba_veg.moss.species import SPECIES
from mitsuba_veg.tune import relax
from mitsuba_veg.tune.lifecycle import discrete_life_cycle, relaxed_life_cycle

F64 = dr.float64_array_t(mi.Float)


def test_heaviside_limits_and_stability():
    x = F64([-1.0, -1e-3, 0.0, 1e-3, 1.0, 1e6, -1e6])
    exact = np.asarray(relax.heaviside(x, 0.0))
    assert exact.tolist() == [0, 0, 0, 1, 1, 1, 0]
    assert np.asarray(relax.heaviside(x, 0.0, strict=False))[2] == 1
    for t in (0.1, 1e-3, 1e-6):
        h = np.asarray(relax.heaviside(x, t))
        assert np.all(np.isfinite(h)) and np.all((h >= 0) & (h <= 1))
        assert h[2] == pytest.approx(0.5)
    h = np.asarray(relax.heaviside(x, 1e-6))
    assert np.allclose(h[[0, 1, 4, 5, 6]], [0, 0, 1, 1, 0])
    # logistic: H_t(x) = 1 / (1 + exp(-x/t))
    assert np.asarray(relax.heaviside(F64([0.1]), 0.05))[0] == pytest.approx(1 / (1 + math.exp(-2)))


def test_soft_floor_limit_and_derivative():
    xs = np.linspace(0.0, 5.0, 501)
    x = F64(xs)
    assert np.array_equal(np.asarray(relax.soft_floor(x, 0.0)), np.floor(xs))
    assert np.asarray(relax.soft_floor(F64([0.0]), 0.05))[0] == pytest.approx(0.0, abs=1e-8)
    for t in (0.02, 0.005):
        f = np.asarray(relax.soft_floor(x, t))
        away = np.abs(xs - np.round(xs)) > 10 * t
        assert np.abs(f - np.floor(xs))[away].max() < 1e-3
    # monotone and continuous (no jumps larger than a step of the grid allows)
    f = np.asarray(relax.soft_floor(x, 0.05))
    assert np.all(np.diff(f) >= -1e-12) and np.abs(np.diff(f)).max() < 0.06
    # derivative: concentrated at the integers
    y = F64([0.5, 1.0, 2.0, 2.5])
    dr.enable_grad(y)
    dr.backward(dr.sum(relax.soft_floor(y, 0.05)))
    g = np.asarray(dr.grad(y))
    assert g[1] == pytest.approx(5.0, rel=1e-3) and g[2] == pytest.approx(5.0, rel=1e-3)
    assert g[0] < 0.01 and g[3] < 0.01  # H_t'(0.5) = 20 sigma(10) (1 - sigma(10)) ~ 9e-4


def test_binomial_tail_and_settle_fraction():
    p = np.linspace(0, 1, 11)
    for n, k in ((8, 8), (8, 3), (5, 0), (5, 6)):
        ref = [sum(math.comb(n, j) * q ** j * (1 - q) ** (n - j) for j in range(k, n + 1))
               for q in p]
        assert np.allclose(np.asarray(relax.binomial_tail(F64(p), n, k)), ref, atol=1e-12)
    a = np.array([0.0, 1e-6, 1e-3, 0.5, 3.0, 50.0])
    ref = np.where(a > 0, -np.expm1(-a) / np.where(a > 0, a, 1), 1.0)
    assert np.allclose(np.asarray(relax.settle_fraction(F64(a))), ref, rtol=1e-9)


# ---- the life cycle: relaxed cohorts against the discrete population ------------------------
N, DAYS = 40, 60
G0 = 0.2  # G_moss of the starting moss: low, so that bad spells kill some


def make_environment(seed=7):
    """Daily S, Ts, rhs per triangle with good and bad spells (so that moss germinate, grow,
    make gemmae and spores, and die), and the starting moss / gemmae / spores per triangle."""
    rng = np.random.default_rng(seed)
    d = np.arange(DAYS)[:, None]
    S = np.clip(50 + 60 * np.sin(d / 6 + rng.random(N) * 6) + rng.normal(0, 30, (DAYS, N)), 0, None)
    Ts = 285 + 8 * np.sin(d / 9 + rng.random(N) * 6) + rng.normal(0, 1.5, (DAYS, N))
    rhs = np.clip(1.0 + 0.2 * np.sin(d / 5 + rng.random(N) * 6) + rng.normal(0, 0.05, (DAYS, N)),
                  0.5, 1.5)
    start = [rng.integers(0, 4, N) for _ in range(3)]
    return [x.astype(np.float32) for x in (S, Ts, rhs)], start


@pytest.fixture(scope="module")
def environment():
    return make_environment()


@pytest.fixture(scope="module")
def discrete(environment):
    return run_discrete(environment)


def run_discrete(environment):
    return discrete_life_cycle(SPECIES["bryum_argenteum"], *environment, growth0=G0,
                               capacity=2048)


def run_relaxed(environment, t):
    return relaxed_life_cycle(SPECIES["bryum_argenteum"], *environment, t, growth0=G0)


def test_discrete_run_has_all_events(discrete):
    # the environment exercises germination, death, gemmae and spores
    assert discrete["gemmae"].sum() > 500 and discrete["spores"].sum() > 500
    moss = discrete["moss"].sum(1)
    assert moss.max() > moss[0] and (np.diff(discrete["moss"], axis=0) < 0).sum() > 5


def test_temperature_zero_is_the_discrete_life_cycle(environment, discrete):
    r = run_relaxed(environment, 0.0)
    for k in r:
        # identical up to float32 (discrete) / float64 (relaxed) rounding at exact ties
        mismatch = np.abs(r[k] - discrete[k]) > 1e-9
        assert mismatch.mean() < 0.005, k


def test_relaxation_converges_to_the_discrete_life_cycle(environment, discrete):
    errs = []
    for t in (0.1, 0.01, 0.001):
        r = run_relaxed(environment, t)
        e = {k: np.abs(r[k] - discrete[k]).sum() / discrete[k].sum() for k in r}
        e.update({f"{k}_total": np.abs(r[k].sum(0) - discrete[k].sum(0)).sum() / discrete[k].sum()
                  for k in ("gemmae", "spores")})
        errs.append(e)
    for k in errs[0]:
        assert errs[0][k] > errs[1][k] > errs[2][k], k
    # measured: moss 0.26 / 0.048 / 0.002, totals 0.19 / 0.044 / 0.003 (the daily gemma count
    # converges slowest: a relaxed step spreads one release over neighbouring days)
    assert errs[2]["moss"] < 0.01 and errs[2]["spores"] < 0.01
    assert errs[2]["gemmae_total"] < 0.01 and errs[2]["spores_total"] < 0.01
    assert errs[2]["gemmae"] < 0.05


def test_expired_propagules_free_their_spots_the_same_day():
    """A gemma that fails its last test (age L1 + 1 = 61) is gone before the day's newcomers
    settle, in the relaxed ring as in ``MossPopulation.live_day`` (the capacity's room)."""
    import mitsuba as mi
    from mitsuba_veg.moss.population import GEMMA as KIND_GEMMA, PROPAGULE, MossPopulation, \
        SpeciesTable
    from mitsuba_veg.moss.species import PARAMETER_FIELDS
    from mitsuba_veg.tune.lifecycle import CohortLifeCycle, species_fitness
    sp = SPECIES["bryum_argenteum"]
    n, days = 3, 66
    S = np.full(n, 5000.0, np.float32)        # far above the light range: G ~ 0, no germination
    Ts, rhs = np.full(n, 290.0, np.float32), np.full(n, 1.0, np.float32)
    pop = MossPopulation(64, SpeciesTable([sp]))
    z = mi.Float(np.zeros(n, np.float32))
    pop.add(PROPAGULE, mi.UInt32(np.zeros(n, np.uint32)), KIND_GEMMA,
            mi.UInt32(np.arange(n, dtype=np.uint32)), mi.Point3f(z, z, z),
            mi.Vector3f(z, z, z), 0.0)
    life = CohortLifeCycle(n, days, 0.0, precision="float64")
    s = life.seed_propagules(life.empty(), "gemma", np.ones(n))
    p = {f: float(getattr(sp, f)) for f in PARAMETER_FIELDS}
    G = species_fitness(p, F64(Ts), F64(rhs), F64(S))
    disc, rel = [], []
    for d in range(days):
        _, _, ev = pop.live_day(mi.Float(S), mi.Float(Ts), mi.Float(rhs))
        assert ev.germinated == 0
        disc.append(pop.count(PROPAGULE))
        s, Gm, Dg, _ = life.live(s, G, p, d)
        rel.append(float(np.sum(np.asarray(life.waiting(s)))))   # what the day's room sees
        life.produce(s, Gm, Dg)
        life.push(s, "gemma", np.zeros(n), d)
        life.push(s, "spore", np.zeros(n), d)
    assert disc[59] == n and disc[60] == 0          # tested at age 61 on day 60, then freed
    assert rel == pytest.approx(disc)
