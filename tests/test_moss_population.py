"""Moss life cycle (paper 000 §3.6) on hand-made states: germination, growth, death, gemmae,
spores, landing of propagules, occupancy conflicts, clumps, slot reuse."""
import math

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
import mitsuba as mi
import drjit as dr

from mitsuba_veg.moss import SPECIES
from mitsuba_veg.moss.fitness_model import fitness as g_fn
from mitsuba_veg.moss.population import (FREE, GEMMA, MOSS, PROPAGULE, SPORE, MossPopulation,
                                         SpeciesTable)
from mitsuba_veg.moss.propagules import land, settle, spore_direction
from mitsuba_veg.moss.spatial import SpotGrid, per_element_count
from mitsuba_veg.integrators.photon_irradiance import SceneIndex
from mitsuba_veg.light import validation as V

BRYUM = SPECIES["bryum_argenteum"]   # alpha_g 0.3, tau_g 0.1, tau_b 0.4, tau_d 0.1
POLY = SPECIES["polytrichum"]


def pop_with(n_slots=8, species=(BRYUM,), priority=None):
    return MossPopulation(n_slots, SpeciesTable(list(species), priority))


def add(pop, state, growth, elem=0, pos=(0, 0, 0), kind=GEMMA, species=0):
    n = 1
    return pop.add(state, mi.UInt32([species]), kind, mi.UInt32([elem]),
                   mi.Point3f(*[mi.Float([float(c)]) for c in pos]),
                   mi.Vector3f(mi.Float([0.0]), mi.Float([1.0]), mi.Float([0.0])),
                   mi.Float([float(growth)]) if n else growth)


def env(S, Ts, rhs, n=1):
    f = lambda v: mi.Float(np.full(n, v, np.float32))  # noqa: E731
    return f(S), f(Ts), f(rhs)


def G_of(sp, S, Ts, rhs):
    return (g_fn(Ts, sp.T0, sp.T1, sp.nT) * g_fn(rhs, sp.rh0, sp.rh1, sp.nrh)
            * g_fn(S, sp.S0, sp.S1, sp.nS))


def state(pop):
    return np.asarray(pop.state)


def test_growth_and_death_by_hand():
    """G = 0 (far too much light): D = 0.3 (0 - 0.1) = -0.03 per day; G_moss 0.15 -> 0.12
    (alive) -> 0.09 < tau_d = 0.1 while declining -> dead."""
    pop = pop_with()
    add(pop, MOSS, 0.15)
    S, Ts, rhs = env(1e4, 288.15, 1.0)
    no = mi.Bool(np.zeros(8, bool))
    pop.live_day(S, Ts, rhs, no)
    assert state(pop)[0] == MOSS
    assert np.asarray(pop.growth)[0] == pytest.approx(0.12, abs=1e-6)
    _, _, ev = pop.live_day(S, Ts, rhs, no)
    assert state(pop)[0] == FREE and ev.died == 1


def test_moss_per_element_kept_by_every_change():
    """A population that knows its elements keeps m per element (eq 3.5) by its changes: added
    moss (+1), added propagules (0), germination (+1), death (-1), removal of a moss (-1) or a
    propagule (0); it always equals a fresh count, and a checkpoint load counts afresh. The
    day's event counters (two sets, the day's kernel zeroing the other) count each day anew."""
    pop = MossPopulation(8, SpeciesTable([BRYUM]), n_elements=3)
    fresh = lambda: np.asarray(per_element_count(pop.elem, pop.moss, 3)).tolist()  # noqa: E731
    kept = lambda: np.asarray(pop.per_element).tolist()  # noqa: E731
    add(pop, MOSS, 0.15, elem=0)      # dies on the first bad day (test above)
    add(pop, MOSS, 0.9, elem=2)
    add(pop, PROPAGULE, 0.0, elem=1, kind=GEMMA)
    add(pop, PROPAGULE, 0.0, elem=2, kind=GEMMA)
    assert kept() == fresh() == [1, 0, 1]
    good, bad = env(30.0, 286.65, 1.0), env(1e4, 288.15, 1.0)
    no = mi.Bool(np.zeros(8, bool))
    _, _, ev = pop.live_day(*good, no)          # both gemmae germinate
    assert ev.germinated == 2 and kept() == fresh() == [1, 1, 2]
    # bad days: the new moss die at once, the others decline below tau_d; each day's count
    # of deaths is that day's (the counters start from zero every day)
    died = []
    while kept()[0]:
        before = state(pop) == MOSS
        _, _, ev = pop.live_day(*bad, no)
        assert ev.died == int((before & (state(pop) == FREE)).sum()) and ev.germinated == 0
        assert kept() == fresh()
        died.append(ev.died)
    assert sorted(died)[-2:] == [1, 2] and sum(died) == 3 and len(died) > 4  # [0, .., 2, .., 1]
    add(pop, MOSS, 5.0, elem=2)
    slot = int(np.flatnonzero(state(pop) == MOSS)[-1])
    assert kept() == fresh() and kept()[2] >= 1
    pop.remove(mi.UInt32([slot]))               # a moss on element 2
    assert kept() == fresh()
    add(pop, PROPAGULE, 0.0, elem=0)
    pop.remove(mi.UInt32(np.flatnonzero(state(pop) == PROPAGULE).astype(np.uint32)))
    assert kept() == fresh() and sum(kept()) == int((state(pop) == MOSS).sum())
    d = pop.to_numpy()
    other = MossPopulation(8, SpeciesTable([BRYUM]), n_elements=3)
    other.load_numpy(d)
    assert np.asarray(other.per_element).tolist() == kept()


def test_good_day_grows_by_eq_3_20():
    pop = pop_with()
    add(pop, MOSS, 0.3)
    S, Ts, rhs = 30.0, 286.65, 1.0  # centre of Bryum's S and T ranges, rh inside
    G = float(G_of(BRYUM, S, Ts, rhs))
    pop.live_day(*env(S, Ts, rhs), mi.Bool(np.zeros(8, bool)))
    assert np.asarray(pop.growth)[0] == pytest.approx(0.3 + 0.3 * (G - 0.1), abs=1e-5)


def test_germination_rule_eq_3_24():
    """A gemma germinates when G g(L, -60, 60, 1) > tau_b; a spore needs L near its window."""
    S, Ts, rhs = 30.0, 286.65, 1.0
    G = float(G_of(BRYUM, S, Ts, rhs))
    pop = pop_with()
    add(pop, PROPAGULE, 0.0, kind=GEMMA)
    add(pop, PROPAGULE, 0.0, kind=SPORE)
    _, _, ev = pop.live_day(*env(S, Ts, rhs), mi.Bool(np.zeros(8, bool)))
    # day 1: L = 1
    expect_gemma = G * float(g_fn(1.0, -60.0, 60.0, 1.0)) > BRYUM.tau_b
    expect_spore = G * float(g_fn(1.0, 60.0, 365.0, 1.0)) > BRYUM.tau_b
    assert expect_gemma and not expect_spore  # the test means something
    assert state(pop)[0] == MOSS and state(pop)[1] == PROPAGULE
    assert ev.germinated == 1
    # the spore germinates once L is well inside its window (L = 200)
    pop.age = dr.select(dr.arange(mi.UInt32, 8) == 1, 199.0, pop.age)
    pop.live_day(*env(S, Ts, rhs), mi.Bool(np.zeros(8, bool)))
    assert state(pop)[1] == MOSS
    # a propagule in a hopeless place never germinates and is freed after its window
    pop2 = pop_with()
    add(pop2, PROPAGULE, 0.0, kind=GEMMA)
    for _ in range(61):
        pop2.live_day(*env(1e4, 288.15, 1.0), mi.Bool(np.zeros(8, bool)))
    assert state(pop2)[0] == FREE


def test_gemmae_every_half_and_spores_from_two():
    pop = pop_with()
    add(pop, MOSS, 0.45)     # will cross 0.5
    add(pop, MOSS, 2.1)      # growing above 2: spores (and crosses 2.5? no: 2.1 + D < 2.5)
    add(pop, MOSS, 0.45)     # crosses 0.5 but is inside a clump
    interior = mi.Bool([False, False, True] + [False] * 5)
    gemma, spores, ev = pop.live_day(*env(30.0, 286.65, 1.0, 1), interior)
    gm, sp = np.asarray(gemma), np.asarray(spores)
    assert gm.tolist()[:3] == [True, False, False]
    assert sp.tolist()[:3] == [False, True, False]
    # the interior moss's counter moved on: leaving the clump later (a declining day, no new
    # threshold crossed) gives no late gemma for the 0.5 it passed inside
    assert np.asarray(pop.gemmae)[2] == 1
    gemma, _, _ = pop.live_day(*env(1e4, 288.15, 1.0, 1), mi.Bool(np.zeros(8, bool)))
    assert not np.asarray(gemma)[2]
    # a declining moss above 2 makes no spores
    pop3 = pop_with()
    add(pop3, MOSS, 2.5)
    _, spores, _ = pop3.live_day(*env(1e4, 288.15, 1.0), mi.Bool(np.zeros(8, bool)))
    assert not np.asarray(spores)[0]


def test_free_slots_are_reused_and_overflow_counted():
    pop = pop_with(n_slots=4)
    for _ in range(4):
        add(pop, MOSS, 0.15)
    assert pop.count(MOSS) == 4
    add(pop, MOSS, 0.15)
    assert pop.overflow == 1
    pop.remove(mi.UInt32([1]))
    slots = add(pop, PROPAGULE, 0.0)
    assert np.asarray(slots).tolist() == [1]


def test_spore_directions_lie_in_the_45_degree_cones():
    n = 20000
    rng = np.random.default_rng(0)
    nrm = mi.Vector3f(0.0, 0.6, 0.8)
    u = mi.Point2f(mi.Float(rng.random(n).astype(np.float32)),
                   mi.Float(rng.random(n).astype(np.float32)))
    side = mi.Float(rng.random(n).astype(np.float32))
    d = spore_direction(nrm, u, side)
    cos = np.asarray(d.x) * 0 + np.asarray(d.y) * 0.6 + np.asarray(d.z) * 0.8
    ang = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    assert np.all((ang < 45.0 + 1e-3) | (ang > 135.0 - 1e-3))
    assert 0.45 < np.mean(ang < 45) < 0.55       # both cones used
    assert ang[ang < 45].max() > 40              # the whole cone, not a line


def plane_scene():
    gv, gf = V.grid_mesh(4, 4)
    rv, rf = V.box_mesh((-0.5, 0.5, -0.5), (0.5, 0.55, 0.5))
    d = {"type": "scene", "ground": V.make_mesh("ground", gv, gf, 0.2),
         "roof": V.make_mesh("roof", rv, rf, 0.3)}
    # a one-sided sheet facing down at y = 0.3 over x in [0.6, 0.9]: its top is a back face
    sv, sf = V.grid_mesh(1, 1, x=(0.6, 0.9), z=(-0.2, 0.2), y=0.3, up=False)
    d["sheet"] = V.make_mesh("sheet", sv, sf, 0.2)
    scene = mi.load_dict(d, optimize=False)
    return scene, SceneIndex.build(scene)


def test_propagules_land_fall_or_vanish():
    scene, idx = plane_scene()
    P = lambda *pts: mi.Point3f(*[mi.Float([p[k] for p in pts]) for k in range(3)])  # noqa
    D = lambda *ds: mi.Vector3f(*[mi.Float([d[k] for d in ds]) for k in range(3)])  # noqa
    origin = P((-0.8, 0.01, 0.0), (-0.8, 0.3, 0.0), (0.0, 0.6, 0.0), (0.75, 0.5, 0.0),
               (-0.8, 0.3, 0.0), (-0.8, 0.01, 0.98))
    direction = D((1, 0, 0), (0, 1, 0), (0, 1, 0), (0, 1, 0), (0, 0, 1), (0, 0, 1))
    landed, elem, p, n = land(scene, idx.lookup, origin, direction, 0.05, mi.Bool(True))
    landed = np.asarray(landed)
    y = np.asarray(p.y)
    gsl, rsl = idx.shape_slice("ground"), idx.shape_slice("roof")
    e = np.asarray(elem)
    # 0: sideways 5 cm, then falls 1 cm onto the ground
    assert landed[0] and gsl.start <= e[0] < gsl.stop and abs(y[0]) < 1e-3
    # 1: released at 0.35 m, falls onto the ground
    assert landed[1] and abs(y[1]) < 1e-3
    # 2: above the roof slab, falls onto its top
    assert landed[2] and rsl.start <= e[2] < rsl.stop and y[2] == pytest.approx(0.55, abs=1e-3)
    # 3: falls onto the back of the one-sided sheet: removed
    assert not landed[3]
    # 4: released at 0.3 m, moves 5 cm along +z, falls onto the ground below that point
    assert landed[4] and gsl.start <= e[4] < gsl.stop and abs(y[4]) < 1e-3
    assert np.asarray(p.z)[4] == pytest.approx(0.05, abs=1e-4)
    # 5: leaves the ground's edge (z > 1) and falls into nothing: removed
    assert not landed[5]


def test_occupancy_conflicts_and_priorities():
    grid = SpotGrid((-1, -1, -1), (1, 1, 1), 0.01, capacity=8)
    pop = pop_with(n_slots=8, species=(BRYUM, POLY), priority=[0.0, 5.0])
    add(pop, MOSS, 0.3, pos=(0.0, 0.0, 0.0), species=0)       # established Bryum at the origin
    add(pop, PROPAGULE, 0.0, pos=(0.2, 0.0, 0.0), species=0)  # a waiting Bryum gemma
    grid.rebuild(pop.pos, pop.state)
    pts = mi.Point3f(mi.Float([0.001, 0.002, 0.2005, 0.5, 0.5005]), mi.Float([0.0] * 5),
                     mi.Float([0.0] * 5))
    species = mi.UInt32([0, 0, 1, 0, 0])
    keep, evicted, _ = settle(pop, grid, pts, species, dr.arange(mi.UInt32, 5), mi.Bool(True))
    keep = np.asarray(keep).tolist()
    # 0, 1: Bryum gemmae on the established moss: it keeps its spot (0.3 > 0)
    # 2: a Polytrichum (priority 5) on the waiting Bryum gemma (0): it takes the spot
    # 3, 4: two newcomers in one empty cell: exactly one (the first) stays
    assert keep == [False, False, True, True, False]
    assert np.asarray(evicted).tolist() == [1]


@pytest.mark.parametrize("priority", [[150.0, 300.0], [0.01, 0.02], [-500.0, -200.0]])
def test_newcomers_of_one_cell_ranked_by_exact_priority(priority):
    """Two newcomers in one empty cell: the species of higher priority stays, however large,
    small or close the priorities are (the second species lands later in the day's order)."""
    grid = SpotGrid((-1, -1, -1), (1, 1, 1), 0.01, capacity=8)
    pop = pop_with(n_slots=8, species=(BRYUM, POLY), priority=priority)
    grid.rebuild(pop.pos, pop.state)
    pts = mi.Point3f(mi.Float([0.5, 0.5005]), mi.Float([0.0, 0.0]), mi.Float([0.0, 0.0]))
    keep, _, _ = settle(pop, grid, pts, mi.UInt32([0, 1]), dr.arange(mi.UInt32, 2), mi.Bool(True))
    assert np.asarray(keep).tolist() == [False, True]


def test_clump_interior_by_neighbour_count():
    grid = SpotGrid((-1, -1, -1), (1, 1, 1), 0.01, capacity=25)
    xs, zs = np.meshgrid(np.arange(-2, 3) * 0.01 + 0.005, np.arange(-2, 3) * 0.01 + 0.005)
    p = mi.Point3f(mi.Float(xs.ravel()), mi.Float(np.full(25, 0.001)), mi.Float(zs.ravel()))
    state = dr.full(mi.UInt32, MOSS, 25)
    grid.insert(p, dr.arange(mi.UInt32, 25), state)
    count = np.asarray(grid.neighbour_count(p)).reshape(5, 5)
    assert count[2, 2] == 8 and count[0, 0] == 3 and count[0, 2] == 5
    # a freed slot no longer counts
    grid.sync(dr.select(dr.arange(mi.UInt32, 25) == 7, 0, state))
    count = np.asarray(grid.neighbour_count(p)).reshape(5, 5)
    assert count[2, 2] == 7 and count[0, 0] == 3
    assert np.asarray(grid.occupant(p)).tolist() == [i + 1 if i != 7 else 0 for i in range(25)]
    assert np.asarray(per_element_count(mi.UInt32([0, 2, 2]), mi.Bool(True), 3)).tolist() == \
        [1, 0, 2]


def test_clump_counts_moss_only():
    """Waiting propagules fill a spot but are not moss: they count for the clump test only
    once they germinate."""
    grid = SpotGrid((-1, -1, -1), (1, 1, 1), 0.01, capacity=9)
    xs, zs = np.meshgrid(np.arange(-1, 2) * 0.01 + 0.005, np.arange(-1, 2) * 0.01 + 0.005)
    p = mi.Point3f(mi.Float(xs.ravel()), mi.Float(np.full(9, 0.001)), mi.Float(zs.ravel()))
    state = mi.UInt32([PROPAGULE] * 4 + [MOSS] + [PROPAGULE] * 4)
    grid.insert(p, dr.arange(mi.UInt32, 9), state)
    centre = dr.gather(mi.Point3f, p, mi.UInt32([4]))
    assert np.asarray(grid.neighbour_count(centre)).tolist() == [0]
    assert np.asarray(grid.neighbour_count(centre, moss_only=False)).tolist() == [8]
    grid.sync(mi.UInt32([MOSS] * 3 + [PROPAGULE] * 6))  # three germinate
    assert np.asarray(grid.neighbour_count(centre)).tolist() == [3]


def test_spot_grid_against_brute_force():
    """Days of random arrivals, germination, deaths and reuse of slots, spread so that blocks
    are allocated, the pool grows and the block table is rehashed: every answer equals a
    brute-force search over the population."""
    rng = np.random.default_rng(5)
    cap, cell = 3000, 0.01
    grid = SpotGrid((0, 0, 0), (1.0, 0.05, 1.0), cell, capacity=cap)
    state = np.zeros(cap, np.uint32)
    pos = np.zeros((cap, 3), np.float32)

    def cells(P):
        c = np.floor((P - grid.lo.astype(np.float32)) * np.float32(1.0 / cell)).astype(np.int64)
        return c[:, 0] + 1000 * c[:, 1] + 1000_000 * c[:, 2], c

    to_p = lambda P: mi.Point3f(*[mi.Float(np.ascontiguousarray(P[:, k])) for k in range(3)])  # noqa: E731
    for day in range(25):
        n = 800
        P = (rng.random((n, 3)) * [1.0, 0.05, 1.0]).astype(np.float32)
        P[n // 2:] = P[rng.integers(0, n // 2, n - n // 2)]  # repeated cells
        rank = rng.permutation(n).astype(np.uint64)
        first = np.asarray(grid.first_per_cell(grid.key(to_p(P)), mi.UInt64(rank)))
        c, _ = cells(P)
        best = {}
        for i in range(n):
            if c[i] not in best or rank[i] < rank[best[c[i]]]:
                best[c[i]] = i
        assert first.tolist() == [best[c[i]] == i for i in range(n)]
        live = {cc: s + 1 for s, cc in zip(np.flatnonzero(state), cells(pos[state > 0])[0])}
        occ = np.asarray(grid.occupant(to_p(P)))
        assert occ.tolist() == [live.get(cc, 0) for cc in c]
        # moss neighbours of every occupied slot, brute force
        occupied = np.flatnonzero(state)
        if len(occupied):
            _, co = cells(pos[occupied])
            moss_cells = {tuple(x) for x in cells(pos[state == MOSS])[1]}
            want = [sum((x + dx, y + dy, z + dz) in moss_cells for dx, dy, dz in NB)
                    for x, y, z in co]
            got = np.asarray(grid.neighbour_count(to_p(pos[occupied])))
            assert got.tolist() == want
            # the counts the grid keeps per moss slot, updated as cells change
            is_moss = state[occupied] == MOSS
            kept = np.asarray(grid.moss_neighbours(mi.UInt32(occupied[is_moss].astype(np.uint32))))
            assert kept.tolist() == np.asarray(want)[is_moss].tolist()
        # winners in free cells settle into free slots (a fifth of them as moss at once, like
        # the initial moss); some germinate, some die
        new = np.flatnonzero(first & (occ == 0))
        free = np.flatnonzero(state == 0)[:len(new)]
        new = new[:len(free)]
        state[free], pos[free] = PROPAGULE, P[new]
        state[free[rng.random(len(free)) < 0.2]] = MOSS
        grid.insert(to_p(P[new]), mi.UInt32(free.astype(np.uint32)), mi.UInt32(state.copy()))
        state[(state == PROPAGULE) & (rng.random(cap) < 0.5)] = MOSS
        state[rng.random(cap) < 0.3] = 0
        grid.sync(mi.UInt32(state.copy()))  # a copy: mi.UInt32 of a NumPy array is a view
    assert grid.rehashes >= 1 and grid.block_cap > cap // 8
    # a grid rebuilt from the population (checkpoint load) keeps the same counts
    moss = np.flatnonzero(state == MOSS).astype(np.uint32)
    before = np.asarray(grid.moss_neighbours(mi.UInt32(moss)))
    grid.rebuild(to_p(pos), mi.UInt32(state.copy()))
    assert np.asarray(grid.moss_neighbours(mi.UInt32(moss))).tolist() == before.tolist()
    assert before.max() >= 3  # dense enough for the counts to mean something


NB = [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
      if (dx, dy, dz) != (0, 0, 0)]


def test_reserved_blocks_take_every_landing_point():
    """``SpotGrid.reserve`` allocates every block that a landing point on the triangles can
    fall in (lifted 1e-4 m along the normal, as ``land`` lifts it): 20,000 random points on a
    tilted square and a wall find their cells without a block being added; a budget too small
    for the surfaces reserves nothing (the blocks then come as newcomers reach them)."""
    rng = np.random.default_rng(1)
    th = np.radians(17.0)
    rot = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    square = np.array([[0, 0, 0], [0.5, 0, 0], [0.5, 0, 0.5], [0, 0, 0.5]]) @ rot.T \
        + [0.013, 0.2, 0.007]
    wall = np.array([[0.6, 0, 0], [0.6, 0.3, 0], [0.6, 0.3, 0.4], [0.6, 0, 0.4]])
    tris = [(q[0], q[1], q[2]) for q in (square, wall)] + [(q[0], q[2], q[3])
                                                          for q in (square, wall)]
    p0, p1, p2 = (np.array([t[k] for t in tris], float) for k in range(3))
    n = np.cross(p1 - p0, p2 - p0)
    n /= np.linalg.norm(n, axis=1)[:, None]
    grid = SpotGrid((0, 0, 0), (1, 1, 1), 0.01, capacity=5000)
    k = grid.reserve(p0, p1, p2, n)
    # 0.37 m2 of surface in blocks of 4 cm: at least area / block face, at most 4x that
    assert k == grid.n_blocks and 0.37 / 0.04 ** 2 < k < 4 * 0.37 / 0.04 ** 2
    m = 20_000
    t = rng.integers(0, len(p0), m)
    u = rng.random((m, 2))
    flip = u.sum(1) > 1
    u[flip] = 1 - u[flip]
    P = (p0[t] + u[:, :1] * (p1[t] - p0[t]) + u[:, 1:] * (p2[t] - p0[t]) + 1e-4 * n[t])
    P = P.astype(np.float32)
    cells = grid.cells(mi.Point3f(*[mi.Float(np.ascontiguousarray(P[:, c])) for c in range(3)]))
    assert grid.n_blocks == k and dr.width(cells) == m
    # reserving again adds nothing
    assert grid.reserve(p0, p1, p2, n) == 0 and grid.n_blocks == k
    small = SpotGrid((0, 0, 0), (1, 1, 1), 0.01, capacity=5000)
    small.reserve_bytes = k * small.block_bytes // 8
    assert small.reserve(p0, p1, p2, n) == 0 and small.n_blocks == 0
