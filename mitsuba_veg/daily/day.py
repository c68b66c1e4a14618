"""The day step of the moss loop (paper 000 §3.7) and the loop over the days.

Each simulated day:

1. **light** — one photon pass (``integrators/photon_irradiance.py``) with two emitters: the day's
   sun path (``veg_sun_path``: every position of the sun that day, weighted by clear-sky DNI) and
   an isotropic sky (``veg_sky``), both normalised to a unit horizontal irradiance, gives each
   triangle its sun and sky fractions f_sun, f_sky (direct + indirect, front side). Moss cover
   enters as per-triangle albedo. With the climate's daily-mean beam B and diffuse D:
   S = B f_sun + D f_sky [W m-2];
2. **soil** (``soil.py``, eqs 3.2-3.16, per triangle): R → C_H (moss density) → θ, β → Ts → ιE →
   rhs, then the bucket (eq 3.6) with the day's evaporation and rain;
3. **moss** (``moss/population.py``, ``moss/propagules.py``): germination, growth and death,
   gemmae, spores, landing, conflicts; every ``external_spore_interval`` days a spore arrives
   from outside.

Everything per moss is a Dr.Jit array operation; per triangle, NumPy. Every ``checkpoint_every``
days the whole state is written atomically; a killed run resumes from the last checkpoint and
reproduces the uninterrupted run exactly (all random numbers derive from (seed, day)).

Subclass hooks (the world's loop, ``world/simulation.py``, uses them): :meth:`_extra_shapes`
(shapes added to the light scene), :meth:`_setup_extra` (set-up after the scene and the
population), :meth:`_checkpoint_extra` and :meth:`_load_extra` (state beyond soil and moss).
"""
from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
from tqdm.auto import tqdm

from .. import soil as soil_model
from ..errors import MitsubaVegError
from ..light.sunpath import day_sun_path
from ..moss.population import (FREE, GEMMA, MOSS, PROPAGULE, SPORE, MossPopulation, SlotQueue,
                               SpeciesTable, concat_u32)
from ..moss.propagules import land, settle, spore_direction, uniform_sphere
from ..moss.spatial import per_element_count
from ..outputs import RUN_OUTPUTS, clear_outputs
from ..scenario import Scenario
from ..backend import versions
from .checkpoint import Checkpoints
from .config import BANDS
from .site import MossSite

_PCG_STREAM = 0xDA3E39CB94B95BDB  # Dr.Jit's default PCG32 stream (lane i adds i)


class MossSimulation(Checkpoints, MossSite):
    """The moss loop: build from a :class:`~mitsuba_veg.scenario.Scenario`; :meth:`run` the
    days.

    Parameters
    ----------
    scenario : Scenario
        The loaded scenario.
    out_dir : path-like
        The run folder (checkpoint; the outputs are written by :func:`mitsuba_veg.daily.run.run`).
    days : int, optional
        Simulated days [d] (default: the scenario's ``simulation.days``).
    progress : bool
        Show a progress bar.
    """

    #: smallest batch of propagules traced at a time while the population is full (the batch
    #: doubles until the free slots are used up; results do not depend on it)
    release_batch = 4096

    def __init__(self, scenario: Scenario, out_dir, days: int | None = None,
                 progress: bool = True):
        super().__init__(scenario, days)
        self.out = Path(out_dir)
        self.progress = progress
        self.timings = {"setup": 0.0, "light": 0.0, "soil": 0.0, "moss": 0.0, "output": 0.0}

    def setup(self):
        """Build the site (:meth:`setup_site`), the empty population and the day counter; then
        :meth:`_setup_extra`."""
        t0 = time.perf_counter()
        self.setup_site()
        self.pop = MossPopulation(int(self.moss_cfg["capacity"]),
                                  SpeciesTable(self.species, self.moss_cfg["priority"]))
        self.history: list[dict] = []
        self.day = 0
        self._moss_version = 0
        self._setup_extra()
        self.timings["setup"] += time.perf_counter() - t0

    def _setup_extra(self) -> None:
        """Set-up after the scene, terrain and population exist (a world: its canopy)."""

    # ---- one day ----------------------------------------------------------------------------
    def _rng(self, day: int, n: int, stream: int, offset: int = 0) -> mi.PCG32:
        """Lanes offset .. offset + n - 1 of the day's generator for ``stream`` (a batch of a
        larger draw gets the numbers the whole draw would give it)."""
        init = (self.seed * 1_000_003 + day * 7919 + stream * 104_729) & 0xFFFFFFFFFFFF
        # opaque: a literal seed would be baked into the kernel and recompiled every day
        return mi.PCG32(size=max(n, 1), initstate=dr.opaque(mi.UInt64, init + offset),
                        initseq=dr.opaque(mi.UInt64, (_PCG_STREAM + offset) % (1 << 64)))

    def counts(self) -> np.ndarray:
        """Live moss per triangle (cached until the population changes, i.e. per day step).

        Returns
        -------
        numpy.ndarray
            (triangles,) moss count [-].
        """
        key = (self.day, self._moss_version)
        if getattr(self, "_counts_cache", (None,))[0] != key:
            c = np.asarray(per_element_count(self.pop.elem, self.pop.moss,
                                             self.index.n_elements), dtype=np.float64)
            self._counts_cache = (key, c)
        return self._counts_cache[1]

    def light(self, day: int, counts: np.ndarray):
        """The day's light: one photon pass with the day's sun path and the sky.

        Parameters
        ----------
        day : int
            Simulated day (0-based).
        counts : numpy.ndarray
            Live moss per triangle (its cover sets the albedo).

        Returns
        -------
        S : numpy.ndarray
            Daily-mean insolation per triangle [W m-2] (S = B f_sun + D f_sky).
        f_sun, f_sky : numpy.ndarray
            Sun and sky fractions per triangle [-] (per unit horizontal beam and diffuse).
        res : PhotonIrradianceResult
            The photon pass.
        """
        dirs, w, _ = day_sun_path(float(self.scn.get("site.latitude")),
                                  float(self.scn.get("site.longitude")), self.date(day))
        self.sun.set_day(dirs, w)
        cover = np.minimum(counts * self.grid_cell() ** 2 / np.maximum(self.index.areas, 1e-30),
                           1.0)[:, None]
        albedo = (1 - cover) * self.base_albedo + cover * np.asarray(self.moss_cfg["albedo"])[None]
        refl = {}
        for sid in self.terrain_shapes:  # trees keep their BSDFs (leaves transmit)
            sl = self.index.shape_slice(sid)
            if sid in self.index.geometry:
                refl[sid] = albedo[sl]
        res = self.integrator.trace(self.scene, photons=int(self.light_cfg["photons"]),
                                    seed=(self.seed * 10_007 + day) & 0x7FFFFFFF,
                                    max_depth=int(self.light_cfg["max_depth"]), bands=BANDS,
                                    indirect=bool(self.light_cfg["indirect"]), reflectance=refl)
        width = 470.0  # "total" band 360-830 nm; the emitters are 1 W m-2 nm-1 horizontal
        f_sun = res.element_irradiance("total", emitter="sun") / width
        f_sky = res.element_irradiance("total", emitter="sky") / width
        wd = self.weather
        S = wd.beam[day] * f_sun + wd.diffuse[day] * f_sky
        return S, f_sun, f_sky, res

    def soil(self, day: int, S: np.ndarray, counts: np.ndarray):
        """The day's soil heat and water (paper 000 eqs 3.2-3.16) per triangle; updates ``O``.

        Parameters
        ----------
        day : int
            Simulated day (0-based).
        S : numpy.ndarray
            Insolation per triangle [W m-2].
        counts : numpy.ndarray
            Live moss per triangle (its density sets C_H).

        Returns
        -------
        state : soil.SurfaceState
            Surface temperature ``Ts`` [K], relative humidity ``rhs`` [-] and fluxes [W m-2].
        theta : numpy.ndarray
            Soil water content per triangle [-] at the start of the day.
        """
        wd = self.weather
        C_H = soil_model.transfer_coefficient(np.minimum(counts / self.M, 1.0))
        theta = soil_model.water_content(self.O, self.h)
        st = soil_model.surface_state(S, wd.T[day], wd.rh[day], wd.U[day], wd.A[day], theta,
                                      self.geology, C_H)
        E = soil_model.evaporation_rate(st.lE)
        step = soil_model.bucket_step(self.O, E, wd.P[day], self.h, self.geology)
        self.O = np.asarray(step.O, dtype=np.float64)
        return st, theta

    def moss(self, day: int, S, Ts, rhs):
        """The day's moss life cycle (eqs 3.17-3.24): germination, growth, death, release,
        landing and settling of gemmae and spores, and a spore from outside every
        ``external_spore_interval`` days.

        Parameters
        ----------
        day : int
            Simulated day (0-based).
        S, Ts, rhs : numpy.ndarray
            Insolation [W m-2], surface temperature [K] and relative humidity [-] per triangle.

        Returns
        -------
        dict
            The day's events (counts of births, deaths, propagules released, traced, settled,
            crowded out).
        """
        pop, grid, cfg = self.pop, self.grid, self.moss_cfg
        f = lambda a: mi.Float(np.asarray(a, np.float32))  # noqa: E731
        cand, spores, ev = pop.live_day(f(S), f(Ts), f(rhs))
        grid.sync(pop.state)  # deaths, expiry, germination (and the moss-neighbour counts)
        # only moss on the surface of a clump release gemmae: the grid keeps every moss's count
        # of moss neighbours, so the test is one read per moss
        gemma = cand & (grid.nb < dr.opaque(mi.UInt32, int(cfg["clump_neighbours"])))
        dr.eval(gemma)
        n_g = int(np.asarray(dr.count(gemma))[0])
        n_s = ev.spore_parents
        ev.gemma_parents = n_g
        n = n_g + n_s
        placed = traced = crowded = 0
        if n:
            # the day's propagules in one order: gemmae, then spores (each by parent slot)
            placed, traced, crowded = self._release(day, SlotQueue(gemma, n_g),
                                                    SlotQueue(spores, n_s))
        interval = int(cfg["external_spore_interval"])
        if interval and day % interval == interval - 1:
            self._place_random(1, day, state=PROPAGULE, kind=SPORE, growth=0.0, stream=2)
        events = ev.__dict__.copy()
        events["propagules_released"] = n
        events["propagules_traced"] = traced
        events["propagules_settled"] = placed
        events["propagules_crowded_out"] = crowded
        return events

    def _release(self, day: int, gemmae: SlotQueue, spores: SlotQueue) -> tuple[int, int, int]:
        """Release, land and settle the day's propagules (``gemmae``, ``spores``: their parent
        slots, gemmae first). Returns (placed, traced, crowded out).

        Newcomers are placed in their order while free slots last; the propagules released
        after the last free slot was taken are *crowded out* (whether they would have landed
        or not). When no newcomer can evict anyone (every species has the same priority and no
        occupant has a negative G_moss: an incumbent then always keeps its spot), a propagule
        can only matter by taking a free slot, so the propagules are traced in order, in
        batches, until the free slots are used up, and the rest are not traced at all. The
        state that results is the one of tracing all of them at once (the batches see the
        earlier batches' newcomers in the grid, which win their cells by order), and so are the
        numbers placed and crowded out."""
        pop = self.pop
        n_g = gemmae.count
        n = n_g + spores.count
        pri = np.asarray(pop.table.priority)
        exclusive = bool(np.all(pri == pri[0])) and pop.negative_growth == 0
        free = pop.count(FREE) if exclusive else n
        batch = n if not exclusive or free >= n else min(n, max(self.release_batch, 2 * free))
        start = placed = 0
        last = -1       # order of the last newcomer placed
        full = exclusive and free == 0
        while start < n and not full:
            m = min(batch, n - start)
            par = gemmae.take(m)
            if dr.width(par) < m:
                par = concat_u32(par, spores.take(m - dr.width(par)))
            order, landed, elem, p, nrm, species, is_spore = self._fly(day, par, n_g, start)
            keep, evicted = settle(pop, self.grid, p, species, order, landed)
            dr.eval(keep, evicted)
            pop.remove(evicted)  # none when no newcomer can evict anyone
            k_idx = dr.compress(keep)
            if dr.width(k_idx):
                gat = lambda t, a: dr.gather(t, a, k_idx)  # noqa: E731
                # the grid is in step unless this batch evicted someone
                k = self._add(PROPAGULE, gat(mi.UInt32, species),
                              dr.select(gat(mi.Bool, is_spore), mi.UInt32(SPORE), mi.UInt32(GEMMA)),
                              gat(mi.UInt32, elem), gat(mi.Point3f, p), gat(mi.Vector3f, nrm), 0.0,
                              sync=dr.width(evicted) > 0)
                if k:
                    last = start + int(np.asarray(k_idx)[k - 1])
                placed += k
                full = pop.free_after_add == 0
            start += m
            batch *= 2
        if not full and start == n:
            full = pop.count(FREE) == 0
        return placed, start, (n - 1 - last) if full else 0

    def _fly(self, day: int, par: mi.UInt32, n_g: int, start: int):
        """Propagules start .. start + m - 1 of the day (``par`` their parent slots; the day's
        first ``n_g`` are gemmae): release direction, path and landing (evaluated arrays: no
        lazy read of the population stays behind to make later writes copy it)."""
        pop, cfg = self.pop, self.moss_cfg
        m = dr.width(par)
        # lane i of the day's generator (the same numbers whatever the batches)
        rng = self._rng(day, m, 1, offset=start)
        order = dr.arange(mi.UInt32, m) + dr.opaque(mi.UInt32, start)
        is_spore = order >= dr.opaque(mi.UInt32, n_g)
        u = mi.Point2f(rng.next_float32(), rng.next_float32())
        side = rng.next_float32()
        M = dr.gather(mi.Point3f, pop.pos, par)
        N = dr.gather(mi.Vector3f, pop.nrm, par)
        d = dr.select(is_spore, spore_direction(N, u, side), uniform_sphere(u))
        dist = dr.select(is_spore, float(cfg["spore_distance"]), float(cfg["gemma_distance"]))
        landed, elem, p, nrm = self._land(M + N * 2e-3, d, dist, mi.Bool(True))
        landed &= dr.gather(mi.Bool, self.living_dr, elem, landed)
        species = dr.gather(mi.UInt32, pop.species, par)
        dr.eval(order, landed, elem, p, nrm, species, is_spore)
        return order, landed, elem, p, nrm, species, is_spore

    def _add(self, state, species, kind, elem, pos, nrm, growth, sync: bool = True):
        """Add settled individuals to the population and their spots to the grid (``sync``:
        first let the grid follow slots freed since it last did, e.g. by evictions)."""
        if sync:
            self.grid.sync(self.pop.state)  # evictions free cells before slots are reused
        slots = self.pop.add(state, species, kind, elem, pos, nrm, growth)
        k = dr.width(slots)
        if k < dr.width(elem):  # the population was full: the first k were placed
            pos = dr.gather(mi.Point3f, pos, dr.arange(mi.UInt32, k))
        self.grid.insert(pos, slots, self.pop.state)
        return k

    def _land(self, origin, direction, dist, active):
        return land(self.scene, self.index.lookup, origin, direction, dist, active)

    def _place_random(self, n: int, day: int, state, kind, growth, stream: int):
        """n individuals at uniform random points of the living surfaces (area-weighted)."""
        if n <= 0:
            return
        areas = np.where(self.living, self.index.areas, 0.0)
        cdf = np.cumsum(areas) / areas.sum()
        rng = np.random.default_rng([self.seed, day + 1, stream])
        tri = np.minimum(np.searchsorted(cdf, rng.random(n)), len(cdf) - 1)
        u = rng.random((n, 2))
        flip = u.sum(1) > 1
        u[flip] = 1 - u[flip]
        pts = np.zeros((n, 3))
        for sid, (v, f) in self.index.geometry.items():  # a few shapes, not per moss
            sl = self.index.shape_slice(sid)
            sel = (tri >= sl.start) & (tri < sl.stop)
            if sel.any():
                fc = f[tri[sel] - sl.start]
                p0, p1, p2 = v[fc[:, 0]], v[fc[:, 1]], v[fc[:, 2]]
                pts[sel] = p0 + u[sel, :1] * (p1 - p0) + u[sel, 1:] * (p2 - p0)
        nrm = self.index.normals[tri]
        pts = pts + nrm * 1e-4
        species = rng.integers(0, len(self.species), n)
        P = mi.Point3f(*[mi.Float(pts[:, k].astype(np.float32)) for k in range(3)])
        N = mi.Vector3f(*[mi.Float(nrm[:, k].astype(np.float32)) for k in range(3)])
        keep, evicted = settle(self.pop, self.grid, P, mi.UInt32(species.astype(np.uint32)),
                               dr.arange(mi.UInt32, n), dr.full(mi.Bool, True, n))
        self.pop.remove(evicted)
        k = dr.compress(keep)
        if dr.width(k):
            g = lambda t, a: dr.gather(t, a, k)  # noqa: E731
            self._add(state, g(mi.UInt32, mi.UInt32(species.astype(np.uint32))), kind,
                      g(mi.UInt32, mi.UInt32(tri.astype(np.uint32))), g(mi.Point3f, P),
                      g(mi.Vector3f, N), growth, sync=dr.width(evicted) > 0)

    # ---- run --------------------------------------------------------------------------------
    def step(self) -> dict:
        """Simulate one day (light, soil, moss) and append its record to ``history``.

        Returns
        -------
        dict
            The day's record (``day`` 1-based, ``date``, moss alive per species, covered area
            [m2], area-mean S [W m-2], Ts [K], rhs and θ, events, regions, ``seconds``).
        """
        day = self.day
        t0 = time.perf_counter()
        counts = self.counts()
        S, f_sun, f_sky, res = self.light(day, counts)
        t1 = time.perf_counter()
        st, theta = self.soil(day, S, counts)
        t2 = time.perf_counter()
        events = self.moss(day, S, np.asarray(st.Ts), np.asarray(st.rhs))
        self._moss_version += 1
        t3 = time.perf_counter()
        self.timings["light"] += t1 - t0
        self.timings["soil"] += t2 - t1
        self.timings["moss"] += t3 - t2
        self.last = {"S": S, "Ts": np.asarray(st.Ts), "rhs": np.asarray(st.rhs),
                     "theta": np.asarray(theta), "f_sun": f_sun, "f_sky": f_sky}
        rec = self._record(day, S, st, theta, events, {"light": t1 - t0, "soil": t2 - t1,
                                                       "moss": t3 - t2})
        self.history.append(rec)
        self.day += 1
        return rec

    def covered_area(self, counts=None) -> np.ndarray:
        """Area covered by moss per triangle.

        Parameters
        ----------
        counts : numpy.ndarray, optional
            Live moss per triangle (default: :meth:`counts`).

        Returns
        -------
        numpy.ndarray
            (triangles,) covered area [m2]: min(moss x size², triangle area).
        """
        counts = self.counts() if counts is None else counts
        return np.minimum(counts * self.grid_cell() ** 2, self.index.areas)

    def _record(self, day, S, st, theta, events, secs) -> dict:
        counts = self.counts()
        cov = self.covered_area(counts)
        soil = self.living
        a = self.index.areas[soil]

        def amean(x):
            return float(np.sum(np.asarray(x)[soil] * a) / a.sum())

        alive = dict(zip([s.name for s in self.species], self.pop.count_by_species(MOSS)))
        # where eq 3.16's linearised q_SAT(Ts) is off by > 10 % (cold shaded surfaces)
        off = np.abs(np.asarray(soil_model.linearisation_error(self.weather.T[day],
                                                               np.asarray(st.Ts)))) > 0.1
        return {"day": day + 1, "date": self.date(day).isoformat(), "alive": alive,
                "soil_linearisation_off": amean(off.astype(float)),
                "moss_alive": int(sum(alive.values())),
                "propagules": self.pop.count(PROPAGULE), "covered_area_m2": float(cov.sum()),
                "mean_S_W_m2": amean(S), "mean_Ts_K": amean(st.Ts), "mean_rhs": amean(st.rhs),
                "mean_theta": amean(theta), "events": events,
                "regions": {k: float(cov[m].sum()) for k, m in self.regions.items()},
                "seconds": secs}

    def initialise(self):
        """Place the initial moss (``moss.initial``) at random on the living surfaces."""
        self._moss_version += 1
        self._place_random(int(self.moss_cfg["initial"]), -1, MOSS, GEMMA,
                           float(self.moss_cfg["initial_growth"]), stream=3)

    def run(self, resume: bool = True, on_day=None) -> dict:
        """Run (or resume) to ``self.days`` days.

        Parameters
        ----------
        resume : bool
            Resume from ``checkpoint.npz`` in the run folder when there is one.
        on_day : callable, optional
            ``on_day(sim, record)`` after every day (maps, snapshots).

        Returns
        -------
        dict
            The summary (:meth:`summary`).

        Raises
        ------
        Interrupted
            After Ctrl-C: the day in progress ends and a checkpoint is written first.
        """
        self.out.mkdir(parents=True, exist_ok=True)
        self.setup()
        resumed = resume and self.load_checkpoint()
        # half-written files of a process killed while writing (the real files are replaced
        # atomically, so these are never read)
        for pattern in ("checkpoint.tmp.npz", "*.json.tmp", "maps/.day_*.tmp.png",
                        "snapshots/.day_*.tmp.npz", "days.tmp.gif"):
            for q in self.out.glob(pattern):
                q.unlink()
        if not resumed:
            # a run that starts at day 0 owns the folder: maps, snapshots, renders and the GIF
            # of an earlier run would otherwise be shown as this run's
            clear_outputs(self.out, RUN_OUTPUTS)
            self.initialise()
        bar = None
        if self.progress:
            bar = tqdm(total=self.days, initial=self.day, unit="day", desc="moss days")
        stop = _InterruptFlag()
        try:
            with stop:
                while self.day < self.days:
                    rec = self.step()
                    if bar is not None:
                        bar.update(1)
                        bar.set_postfix(moss=rec["moss_alive"],
                                        cover=f"{rec['covered_area_m2']:.3f}m2")
                    t0 = time.perf_counter()
                    if on_day is not None:
                        on_day(self, rec)
                    if self.checkpoint_every and self.day % self.checkpoint_every == 0:
                        self.save_checkpoint()
                    self.timings["output"] += time.perf_counter() - t0
                    if stop.requested:
                        self.save_checkpoint()
                        raise Interrupted(self.day, self.checkpoint_path)
        finally:
            if bar is not None:
                bar.close()
        self.save_checkpoint()
        return self.summary(resumed)

    def summary(self, resumed=False) -> dict:
        """The run's summary (settings, final state, timings, every day's record).

        Parameters
        ----------
        resumed : bool, optional
            Whether the run was resumed from a checkpoint (recorded as ``resumed``); default False.

        Returns
        -------
        dict
            JSON-able: ``scenario``, ``days``, ``resumed``, ``settings`` (light, moss, climate,
            simulation), ``species``, ``spot_grid`` (``cell_m`` [m], cells, blocks), ``final``
            (``covered_area_m2`` [m2], ``moss_alive``, ``propagules``, ``alive_by_species``,
            per-region covered and total area [m2] and live moss, ``propagules_crowded_out``),
            ``timings_s`` (totals and ``per_day`` [s]), ``days_record`` (the daily records) and
            ``versions``.
        """
        counts = self.counts()
        cov = self.covered_area(counts)
        regions = {k: {"covered_area_m2": float(cov[m].sum()),
                       "area_m2": float(self.index.areas[m].sum()),
                       "moss_alive": int(counts[m].sum())} for k, m in self.regions.items()}
        last = self.history[-1] if self.history else {}
        n_days = max(len(self.history), 1)
        return {
            "scenario": str(self.scn.path), "days": self.days, "resumed": resumed,
            "settings": {"light": self.light_cfg, "moss": self.moss_cfg,
                         "climate": self.climate.__dict__, "simulation": {
                             "start_date": self.start.isoformat(),
                             "checkpoint_every": self.checkpoint_every}},
            "species": [s.name for s in self.species],
            "spot_grid": {"cell_m": self.grid.cell, "cells_allocated": self.grid.n_cells,
                          "blocks": self.grid.n_blocks},
            "final": {"covered_area_m2": float(cov.sum()),
                      "moss_alive": int(self.pop.count(MOSS)),
                      "propagules": int(self.pop.count(PROPAGULE)),
                      "alive_by_species": last.get("alive", {}), "regions": regions,
                      "propagules_crowded_out": sum(r["events"].get("propagules_crowded_out", 0)
                                                    for r in self.history)},
            "timings_s": {**self.timings, "per_day": {k: self.timings[k] / n_days
                                                      for k in ("light", "soil", "moss")}},
            "days_record": self.history, "versions": versions()}


class Interrupted(MitsubaVegError):
    """The run was interrupted (Ctrl-C / SIGINT) after a day; its checkpoint was written."""

    def __init__(self, day: int, checkpoint: Path):
        self.day, self.checkpoint = day, checkpoint
        super().__init__(f"interrupted after day {day}; checkpoint written to {checkpoint}. "
                         "Run the same command again to resume")


class _InterruptFlag:
    """While active (main thread only), Ctrl-C sets ``requested`` instead of raising, so the
    day in progress ends and a consistent checkpoint is written; a second Ctrl-C raises."""

    requested = False

    def __enter__(self):
        self._old = None
        if threading.current_thread() is threading.main_thread():
            self._old = signal.getsignal(signal.SIGINT)

            def handler(signum, frame):
                if self.requested:
                    raise KeyboardInterrupt
                self.requested = True
            signal.signal(signal.SIGINT, handler)
        return self

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
