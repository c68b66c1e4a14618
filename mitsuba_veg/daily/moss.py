"""The moss stage of a day (paper 000 §3.6-3.7): germination, growth and death, gemmae and
spores released, traced, landed and settled on the spot grid, and a spore from outside every
``external_spore_interval`` days.

The population (:class:`~mitsuba_veg.moss.population.MossPopulation`) and the spot grid
(:class:`~mitsuba_veg.moss.spatial.SpotGrid`) are the stage's state, Dr.Jit arrays of the
variant's backend; every step is a whole-array operation (no Python loop over moss or
propagules). The day reads the light, soil temperature and humidity of the terrain elements
from the earlier stages as device arrays.

All random numbers derive from (seed, day, stream): a resumed run draws the same ones.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..arrays import Pack, host_array, zero_index
from ..moss.population import (FREE, GEMMA, MOSS, PROPAGULE, SPORE, MossPopulation, SlotQueue,
                               SpeciesTable, concat_u32)
from ..moss.propagules import land, settle, spore_direction, uniform_sphere
from ..moss.spatial import SpotGrid, per_element_count

__all__ = ["parents_in_order", "MossState", "DayMoss"]

_PCG_STREAM = 0xDA3E39CB94B95BDB  # Dr.Jit's default PCG32 stream (lane i adds i)


def parents_in_order(gemma, spores) -> mi.UInt32:
    """The parent slots of the day's propagules in their order: every gemma parent by slot,
    then every spore parent by slot (a slot can be both), from one compress.

    Parameters
    ----------
    gemma, spores : mi.Bool
        Per slot: releases a gemma, releases a spore. ``gemma`` may also be a function of slot
        indices (mi.UInt32) giving the mask at them: then it is evaluated inside this kernel
        (a gather from an unevaluated mask evaluates it first, a kernel of its own).

    Returns
    -------
    mi.UInt32
        Parent slots, gemmae first (a lazy expression of the compressed lanes).
    """
    cap = dr.width(spores)
    lane = dr.arange(mi.UInt32, 2 * cap)
    second = lane >= cap
    slot = dr.select(second, lane - cap, lane)
    g = gemma(slot) if callable(gemma) else dr.gather(mi.Bool, gemma, slot)
    m = dr.select(second, dr.gather(mi.Bool, spores, slot), g)
    lanes = dr.compress(m)
    # arithmetic on the lanes, not a gather from ``slot`` (that would evaluate ``slot`` in a
    # kernel of its own): left lazy, it is computed inside the kernels that read it
    return dr.select(lanes >= cap, lanes - cap, lanes)


class MossState:
    """The population and its spot grid (the moss stage's state).

    Parameters
    ----------
    pop : MossPopulation
        The slots.
    grid : SpotGrid
        One cell per moss, in step with ``pop``.
    """

    def __init__(self, pop: MossPopulation, grid: SpotGrid):
        self.pop, self.grid = pop, grid


class DayMoss:
    """The moss stage (module docstring).

    Parameters
    ----------
    site : Site
        The run's site (scene for the propagules' flights, terrain, where moss may live).
    """

    #: smallest batch of propagules traced at a time while the population is full (the batch
    #: doubles until the free slots are used up; results do not depend on it)
    release_batch = 4096

    def __init__(self, site):
        self.site = site
        cfg = site.config
        self.cfg = cfg.moss_cfg
        self.seed = int(cfg.seed)
        self.n = site.n_terrain
        self.table = SpeciesTable(cfg.species, self.cfg["priority"])
        self._priorities = np.asarray(self.table.priority)
        areas = np.where(site.living, site.areas, 0.0)
        self._cdf = np.cumsum(areas) / areas.sum() if areas.sum() > 0 else None

    def new_state(self) -> MossState:
        """An empty population and grid.

        Returns
        -------
        MossState
            Capacity ``moss.capacity`` slots, all free.
        """
        pop = MossPopulation(int(self.cfg["capacity"]), self.table, n_elements=self.n)
        grid = self.site.new_grid()
        # the blocks of the living surfaces from the start: no hash-table rounds on the days
        # newcomers reach new ground (the same numbers either way)
        grid.reserve(*self._living_triangles())
        return MossState(pop, grid)

    def _triangles(self, tri: np.ndarray):
        """The corners of terrain triangles ``tri`` (global element indices), shape by shape:
        yields (which of ``tri``, p0, p1, p2) per terrain shape holding some of them, in that
        shape's vertex precision [m]."""
        idx = self.site.index
        for sid in self.site.terrain_shapes:      # a few shapes, not per moss
            if sid not in idx.geometry:
                continue
            v, f = idx.geometry[sid]
            sl = idx.shape_slice(sid)
            sel = (tri >= sl.start) & (tri < sl.stop)
            if sel.any():
                fc = f[tri[sel] - sl.start]
                yield sel, v[fc[:, 0]], v[fc[:, 1]], v[fc[:, 2]]

    def _living_triangles(self):
        """Corners (three (n, 3) arrays) and normals of the living terrain triangles [m]."""
        tri = np.flatnonzero(self.site.living)
        parts = list(self._triangles(tri))
        if not parts:
            return [np.zeros((0, 3))] * 4
        corners = [np.concatenate([np.asarray(p[k], np.float64) for p in parts])
                   for k in (1, 2, 3)]
        order = np.concatenate([tri[p[0]] for p in parts])
        return corners + [self.site.index.normals[order]]

    # ---- per element ------------------------------------------------------------------------
    def counts(self, st: MossState) -> mi.UInt32:
        """Live moss per terrain element (m of eq 3.5), on the device.

        Parameters
        ----------
        st : MossState
            The state.

        Returns
        -------
        mi.UInt32
            (terrain elements,) moss count [-]: the population's own count
            (:attr:`MossPopulation.per_element`), which its next changes update in place;
            read it (or copy it) before the next moss stage.
        """
        if st.pop.per_element is not None and st.pop.n_elements == self.n:
            return st.pop.per_element
        return per_element_count(st.pop.elem, st.pop.moss, self.n)

    def cover(self, counts, elems=None) -> mi.Float64:
        """Moss cover per terrain element: min(m size² / area, 1) [-].

        Parameters
        ----------
        counts : mi.UInt32
            Live moss per terrain element.
        elems : mi.UInt32, optional
            The terrain elements wanted (default: all, in order). With them the cover is
            computed at their width from ``counts`` and the areas, fused into the kernel that
            reads it (a gather from the cover of all elements would evaluate that first, in a
            kernel of its own); the values are the same.

        Returns
        -------
        mi.Float64
            Cover [-].
        """
        site = self.site
        m, area = mi.Float64(counts), site.d_areas
        if elems is not None:
            m = mi.Float64(dr.gather(mi.UInt32, counts, elems))
            area = dr.gather(mi.Float64, site.d_areas, elems)
        return dr.minimum(m * (site.grid_cell() ** 2) / dr.maximum(area, 1e-30), 1.0)

    # ---- one day ----------------------------------------------------------------------------
    def _rng(self, day: int, n: int, stream: int, offset: int = 0, extra=()):
        """Lanes offset .. offset + n - 1 of the day's generator for ``stream`` (a batch of a
        larger draw gets the numbers the whole draw would give it), and ``extra`` numbers as
        kernel inputs (UInt64 expressions) from the same host copy."""
        init = (self.seed * 1_000_003 + day * 7919 + stream * 104_729) & 0xFFFFFFFFFFFF
        # one host copy for the generator's seeds and the caller's numbers (each copy is a
        # task of its own when it is freed); never literals: a literal seed would be baked
        # into the kernel and recompiled every day
        pk = Pack(mi.UInt64, [init + offset, (_PCG_STREAM + offset) % (1 << 64), *extra])
        rng = mi.PCG32(size=max(n, 1), initstate=pk[0], initseq=pk[1])
        return rng, [pk[2 + j] for j in range(len(extra))]

    def fitness_columns(self, S, Ts, rhs) -> list:
        """The day's fitness per terrain element, one array per species (G of eq 3.17), as
        lazy expressions for the kernel of the elements' width that evaluates the soil: a
        kernel fewer than computing the table in the life cycle's. Pass them, evaluated, to
        :meth:`step` as ``table``.

        Parameters
        ----------
        S, Ts, rhs : mi.Float
            Insolation [W m-2], surface temperature [K] and relative humidity [-] per terrain
            element (the same values that :meth:`step` gets).

        Returns
        -------
        list of mi.Float
            G [-] per element, one array per species.
        """
        # (an opaque species index: a literal one would be gathered at once, a launch each)
        return [self.table.fitness(zero_index() + k, Ts, rhs, S)
                for k in range(len(self.table.species))]

    def step(self, st: MossState, day: int, S, Ts, rhs, table=None) -> dict:
        """The day's moss life cycle (eqs 3.17-3.24): germination, growth, death, release,
        landing and settling of gemmae and spores, and a spore from outside every
        ``external_spore_interval`` days.

        Parameters
        ----------
        st : MossState
            The population and grid (updated in place).
        day : int
            Simulated day (0-based).
        S, Ts, rhs : mi.Float
            Insolation [W m-2], surface temperature [K] and relative humidity [-] per terrain
            element.
        table : list of mi.Float, optional
            The day's fitness per element and species from :meth:`fitness_columns`, evaluated
            (else computed here).

        Returns
        -------
        dict
            The day's events (counts of births, deaths, propagules released, traced, settled,
            crowded out).
        """
        pop, grid, cfg = st.pop, st.grid, self.cfg
        # (the slots the grid must follow are found in the life cycle's kernel)
        cand, spores, ev = pop.live_day(S, Ts, rhs, table=table,
                                        changed_since=grid.state_copy)
        # deaths, expiry, germination (and the moss-neighbour counts)
        grid.sync(pop.state, changed=pop.changed, was=pop.changed_from)
        # only moss on the surface of a clump release gemmae: the grid keeps every moss's count
        # of moss neighbours, so the test is one read per moss
        clump = int(cfg["clump_neighbours"])
        gemma = cand & (grid.nb < clump)
        n_cand, n_s = ev.gemma_parents, ev.spore_parents
        first = None
        if n_cand + n_s == 0:
            n_g = 0
        elif self._all_at_once(pop, n_cand + n_s):
            # the day's parents in order from one compress; their number gives the gemmae's
            # (no count of its own: two launches fewer)
            first = parents_in_order(lambda i: dr.gather(mi.Bool, cand, i)
                                     & (dr.gather(mi.UInt32, grid.nb, i) < clump), spores)
            n_g = dr.width(first) - n_s
        else:
            cnt = dr.zeros(mi.UInt32, 1)
            dr.scatter_add(cnt, mi.UInt32(1), mi.UInt32(0), gemma, mode=dr.ReduceMode.Local)
            dr.eval(gemma, cnt)
            n_g = int(np.asarray(cnt)[0])
        ev.gemma_parents = n_g
        n = n_g + n_s
        placed = traced = crowded = 0
        if n:
            # the day's propagules in one order: gemmae, then spores (each by parent slot)
            placed, traced, crowded = self._release(st, day, gemma, spores, n_g, n_s, first)
        interval = int(cfg["external_spore_interval"])
        if interval and day % interval == interval - 1:
            self.place_random(st, 1, day, state=PROPAGULE, kind=SPORE, growth=0.0, stream=2)
        events = ev.__dict__.copy()
        events["propagules_released"] = n
        events["propagules_traced"] = traced
        events["propagules_settled"] = placed
        events["propagules_crowded_out"] = crowded
        return events

    def _exclusive(self, pop) -> bool:
        """Whether no newcomer can evict anyone today (equal species priorities and no
        occupant with a negative G_moss: an incumbent then always keeps its spot)."""
        pri = self._priorities
        return bool(np.all(pri == pri[0])) and pop.negative_growth == 0

    def _all_at_once(self, pop, n: int) -> bool:
        """Whether ``n`` propagules (or fewer) are traced in one batch (:meth:`_release`)."""
        return not self._exclusive(pop) or pop.free_slots >= n

    def _release(self, st: MossState, day: int, gemma, spores, n_g: int,
                 n_s: int, first=None) -> tuple[int, int, int]:
        """Release, land and settle the day's propagules (``gemma``, ``spores``: masks of their
        parent slots, ``n_g`` and ``n_s`` of them; gemmae first; ``first``: their parents in
        order when already listed, :func:`parents_in_order`). Returns (placed, traced,
        crowded out).

        Newcomers are placed in their order while free slots last; the propagules released
        after the last free slot was taken are *crowded out* (whether they would have landed
        or not). When no newcomer can evict anyone (every species has the same priority and no
        occupant has a negative G_moss: an incumbent then always keeps its spot), a propagule
        can only matter by taking a free slot, so the propagules are traced in order, in
        batches, until the free slots are used up, and the rest are not traced at all. The
        state that results is the one of tracing all of them at once (the batches see the
        earlier batches' newcomers in the grid, which win their cells by order), and so are the
        numbers placed and crowded out."""
        pop = st.pop
        n = n_g + n_s
        exclusive = self._exclusive(pop)
        free = pop.free_slots if exclusive else n
        batch = n if not exclusive or free >= n else min(n, max(self.release_batch, 2 * free))
        if batch >= n:
            # all at once: the parents in order from one compress of both masks
            q_g = q_s = None
            if first is None:
                first = parents_in_order(gemma, spores)
        else:
            q_g, q_s = SlotQueue(gemma, n_g), SlotQueue(spores, n_s)
        start = placed = 0
        last = -1       # order of the last newcomer placed
        full = exclusive and free == 0
        while start < n and not full:
            m = min(batch, n - start)
            if q_g is None:
                par = first
            else:
                par = q_g.take(m)
                if dr.width(par) < m:
                    par = concat_u32(par, q_s.take(m - dr.width(par)))
            order, landed, elem, p, nrm, species, is_spore = self._fly(st, day, par, n_g, start)
            keep, evicted, cells = settle(pop, st.grid, p, species, order, landed,
                                          may_evict=not exclusive)
            dr.eval(keep, evicted)
            pop.remove(evicted)  # none when no newcomer can evict anyone
            k_idx = dr.compress(keep)
            if dr.width(k_idx):
                gat = lambda t, a: dr.gather(t, a, k_idx)  # noqa: E731
                # the grid is in step unless this batch evicted someone
                k = self._add(st, PROPAGULE, gat(mi.UInt32, species),
                              dr.select(gat(mi.Bool, is_spore), mi.UInt32(SPORE), mi.UInt32(GEMMA)),
                              gat(mi.UInt32, elem), gat(mi.Point3f, p), gat(mi.Vector3f, nrm), 0.0,
                              sync=dr.width(evicted) > 0, cells=gat(mi.UInt32, cells))
                placed += k
                full = pop.free_after_add == 0
                if k and full:   # who came last matters only once the slots are used up
                    last = start + int(np.asarray(k_idx)[k - 1])
            start += m
            batch *= 2
        if not full and start == n:
            # exclusive: no slot was freed today after the counts; else count them
            full = (free - placed == 0) if exclusive else pop.count(FREE) == 0
        return placed, start, (n - 1 - last) if full else 0

    def _fly(self, st: MossState, day: int, par: mi.UInt32, n_g: int, start: int):
        """Propagules start .. start + m - 1 of the day (``par`` their parent slots; the day's
        first ``n_g`` are gemmae): release direction, path and landing (evaluated arrays: no
        lazy read of the population stays behind to make later writes copy it)."""
        pop, cfg = st.pop, self.cfg
        m = dr.width(par)
        # lane i of the day's generator (the same numbers whatever the batches)
        rng, (first, n_gemmae) = self._rng(day, m, 1, offset=start, extra=(start, n_g))
        order = dr.arange(mi.UInt32, m) + mi.UInt32(first)
        is_spore = order >= mi.UInt32(n_gemmae)
        u = mi.Point2f(rng.next_float32(), rng.next_float32())
        side = rng.next_float32()
        M = dr.gather(mi.Point3f, pop.pos, par)
        N = dr.gather(mi.Vector3f, pop.nrm, par)
        d = dr.select(is_spore, spore_direction(N, u, side), uniform_sphere(u))
        dist = dr.select(is_spore, float(cfg["spore_distance"]), float(cfg["gemma_distance"]))
        landed, elem, p, nrm = land(self.site.scene, self.site.index.lookup, M + N * 2e-3, d,
                                    dist, mi.Bool(True))
        landed &= dr.gather(mi.Bool, self.site.d_living, elem, landed & (elem < self.n))
        species = dr.gather(mi.UInt32, pop.species, par)
        dr.eval(order, landed, elem, p, nrm, species, is_spore)
        return order, landed, elem, p, nrm, species, is_spore

    def _add(self, st: MossState, state, species, kind, elem, pos, nrm, growth,
             sync: bool = True, cells=None):
        """Add settled individuals to the population and their spots to the grid (``sync``:
        first let the grid follow slots freed since it last did, e.g. by evictions; ``cells``:
        their pool cells, from settling)."""
        if sync:
            st.grid.sync(st.pop.state)  # evictions free cells before slots are reused
        slots = st.pop.add(state, species, kind, elem, pos, nrm, growth)
        k = dr.width(slots)
        if k < dr.width(elem):  # the population was full: the first k were placed
            first_k = dr.arange(mi.UInt32, k)
            pos = dr.gather(mi.Point3f, pos, first_k)
            cells = None if cells is None else dr.gather(mi.UInt32, cells, first_k)
        st.grid.insert(pos, slots, st.pop.state, cells,
                       newcomers_moss=not (isinstance(state, int) and state == PROPAGULE))
        return k

    def place_random(self, st: MossState, n: int, day: int, state, kind, growth, stream: int):
        """``n`` individuals at uniform random points of the living surfaces (area-weighted).

        Parameters
        ----------
        st : MossState
            The population and grid (updated in place).
        n : int
            How many to place.
        day : int
            The day (seeds the draw; -1 for the initial moss).
        state, kind : int
            Their population state (PROPAGULE or MOSS) and kind (GEMMA or SPORE).
        growth : float
            Their G_moss [-].
        stream : int
            Random stream of the draw.
        """
        if n <= 0 or self._cdf is None:
            return
        idx = self.site.index
        rng = np.random.default_rng([self.seed, day + 1, stream])
        tri = np.minimum(np.searchsorted(self._cdf, rng.random(n)), len(self._cdf) - 1)
        u = rng.random((n, 2))
        flip = u.sum(1) > 1
        u[flip] = 1 - u[flip]
        pts = np.zeros((n, 3))
        for sel, p0, p1, p2 in self._triangles(tri):
            pts[sel] = p0 + u[sel, :1] * (p1 - p0) + u[sel, 1:] * (p2 - p0)
        nrm = idx.normals[tri]
        pts = pts + nrm * 1e-4
        species = host_array(mi.UInt32, rng.integers(0, len(self.table.species), n))
        # aligned host buffers: on the LLVM backend Dr.Jit maps them, and an odd address of a
        # one-spore array compiled its kernels again with another alignment (arrays.host_array)
        P = mi.Point3f(*[host_array(mi.Float, pts[:, k]) for k in range(3)])
        N = mi.Vector3f(*[host_array(mi.Float, nrm[:, k]) for k in range(3)])
        # (when no newcomer can evict anyone, the evicted are not looked for: a launch and a
        # read-back fewer)
        keep, evicted, cells = settle(st.pop, st.grid, P, species,
                                      dr.arange(mi.UInt32, n), dr.full(mi.Bool, True, n),
                                      may_evict=not self._exclusive(st.pop))
        st.pop.remove(evicted)
        k = dr.compress(keep)
        if dr.width(k):
            g = lambda t, a: dr.gather(t, a, k)  # noqa: E731
            self._add(st, state, g(mi.UInt32, species), kind,
                      g(mi.UInt32, host_array(mi.UInt32, tri)), g(mi.Point3f, P),
                      g(mi.Vector3f, N), growth, sync=dr.width(evicted) > 0,
                      cells=g(mi.UInt32, cells))

    def initialise(self, st: MossState) -> None:
        """Place the initial moss (``moss.initial``) at random on the living surfaces.

        Parameters
        ----------
        st : MossState
            An empty state (updated in place).
        """
        self.place_random(st, int(self.cfg["initial"]), -1, MOSS, GEMMA,
                          float(self.cfg["initial_growth"]), stream=3)
