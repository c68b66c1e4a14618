"""The day as one pipeline of stages with explicit state, and the loop over the days.

One day (:meth:`DayPipeline.run_day`), every stage a function of (state, the day's inputs,
parameters) on Dr.Jit arrays of the variant's backend::

    leaves   phenology (leaf-out) -> canopy stage bins, hidden leaves  -> pass tables
    light    one photon pass (sun path + sky)  -> f_sun, f_sky, S per terrain element;
             band irradiances per leaf and per ground element            (daily/light.py)
    soil     eqs 3.2-3.16 and the bucket: Ts, rhs, theta, next water    (daily/soil.py)
    leaves   the day's leaf insolation -> autumn clock, leaf fall       (daily/leaves.py)
    growth   the leaves' light -> the year's sums of the trees that grow (daily/growth.py)
    moss     germination, growth, death, gemmae, spores                 (daily/moss.py)
    record   a few dozen sums on the device, read back once             (daily/record.py)

After 31 December (:meth:`Simulation.regrow`) the trees of ``model = "growth"`` grow one
generation from their year's light, Weber-Penn trees with ``adapt_yearly`` lose the subtrees
paper 002's death rule condemns and those with an ``age`` grow along their age curve: the light
scene is rebuilt with them; the soil water and the moss carry over (the terrain's elements come
first and do not change), the leaves start bare.

With ``simulation.light_every = N`` the light stage traces its pass every N-th day and the
days between scale the last pass by their own weather (:mod:`mitsuba_veg.daily.light`);
checkpoints are then written on days after which a pass follows, so that a resumed run needs
no earlier pass (:meth:`Simulation.resumable`).

A moss-only scenario is a world without trees (no leaves stage). State (:class:`DayState`):
the soil water, the moss population and its spot grid, the leaves; nothing of it is read back
on a normal day: the host reads the day's record and, on their days, writes maps, snapshots
and checkpoints (:class:`Simulation`). The year's sun paths and clear-sky band shapes are
computed at set-up (:class:`~mitsuba_veg.daily.inputs.DayInputs`); a day's numbers enter its
kernels as opaque inputs, so every day runs the same compiled kernels.

A killed run resumes from its last checkpoint and reproduces the uninterrupted run exactly: all
random numbers derive from (seed, day), every sum is an integer or fixed-point sum.
"""
from __future__ import annotations

import gc
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
from tqdm.auto import tqdm

from ..arrays import host_array
from ..backend import versions
from ..errors import MitsubaVegError
from ..integrators.scene_index import forget_scene_index
from ..light import sensors as sensors_mod
from ..moss.population import MOSS, PROPAGULE
from ..scenario import Scenario
from ..world.phenology import Phenology
from ..world.tree_record import RECORD, write_initial_trees
from . import checkpoint as ckpt
from ..outputs import atomic_write
from ..parallel import map_on_cores
from ..world.trees import (adapt_tree, adapts, age_tree, ages, obstacles, regrow,
                           tree_state)
from .config import MossConfig
from .growth import DayGrowth, YearLight, floor_figure, floor_year, floor_years_figure
from .inputs import DayInputs
from .leaves import DayLeaves
from .light import DayLight
from .moss import DayMoss, MossState
from .record import DayRecord
from .site import Site, build_site
from .soil import day_soil


__all__ = ["DayState", "DayPipeline", "HostFields", "Simulation", "Interrupted"]

@dataclass
class DayState:
    """The state of a run between two days (module docstring).

    Attributes
    ----------
    day : int
        Days simulated so far.
    O : mi.Float64
        Soil water per terrain element [mm].
    moss : MossState
        Population and spot grid.
    leaves : Phenology or None
        The leaves (a world).
    history : list of dict
        Every day's record.
    sensor_days : list of numpy.ndarray
        Every day's sensor readings (with sensors).
    year : YearLight or None
        The growth year's leaf light so far (trees of ``model = "growth"``).
    growth_log : list of dict
        One row per tree and year-end growth step (generation, tips, deaths, size).
    floor_log : list of dict
        One row per year: the floor's DLI, R:FR, gap fraction and moss cover.
    """

    day: int
    O: object
    moss: MossState
    leaves: Phenology | None = None
    history: list = field(default_factory=list)
    sensor_days: list = field(default_factory=list)
    year: YearLight | None = None
    growth_log: list = field(default_factory=list)
    floor_log: list = field(default_factory=list)


class DayPipeline:
    """The stages of a day and :meth:`run_day`, which composes them (module docstring).

    Parameters
    ----------
    site : Site
        The run's site.
    inputs : DayInputs
        Every day's weather, sun path and band shapes.
    light_strength : tuple of float
        Factors on the sun's and the sky's light (see :class:`DayLight`).
    """

    def __init__(self, site: Site, inputs: DayInputs, light_strength=(1.0, 1.0)):
        self.site, self.inputs = site, inputs
        self.leaves = DayLeaves(site) if site.canopy is not None and site.canopy.n_leaves \
            else None
        self.light = DayLight(site, inputs, light_strength)
        self.growth = DayGrowth(site) if self.leaves is not None and \
            (self.light.leaf_net or any(ages(wt) or adapts(wt) for wt in site.trees)) \
            else None
        self.moss = DayMoss(site)
        self.record = DayRecord(site)
        self.scene_params = mi.traverse(site.scene) if self.leaves is not None else None
        # (the CPU's kernels run on Dr.Jit's threads after their launch returns: see
        # _stage_end)
        self._wait_stages = mi.variant().startswith("llvm")

    def _stage_end(self) -> None:
        """End a stage's time with its kernels run, on the CPU (:meth:`run_day`, Notes)."""
        if self._wait_stages:
            dr.sync_thread()

    def new_state(self, moss=None) -> DayState:
        """The state before the first day: buckets at field capacity, no moss, bare trees.

        Parameters
        ----------
        moss : MossState, optional
            A moss state to carry instead of a new, empty one (the year's end keeps its
            population and grid: a new grid would reserve its blocks for nothing).

        Returns
        -------
        DayState
            Day 0.
        """
        O = host_array(mi.Float64, self.site.O0)
        dr.eval(O)
        return DayState(0, O, self.moss.new_state() if moss is None else moss,
                        self.leaves.new_state() if self.leaves is not None else None,
                        year=self.growth.new_state() if self.growth is not None else None)

    def run_day(self, st: DayState) -> tuple[dict, dict]:
        """Simulate day ``st.day`` (the stages of the module docstring); ``st`` is updated.

        Parameters
        ----------
        st : DayState
            The state at the start of the day.

        Returns
        -------
        record : dict
            The day's record (:class:`DayRecord`).
        fields : dict
            The day's per-element fields on the device (``S``, ``Ts``, ``rhs``, ``theta``,
            ``f_sun``, ``f_sky`` per terrain element; ``light``: the DayLightResult).

        Notes
        -----
        The record's ``seconds`` are wall times of the stages. Dr.Jit launches kernels
        asynchronously: without a wait, a stage's time would be its Python's (the soil's 1 ms
        instead of its kernels' 30 ms on the courtyard world) and the next stage that reads a
        value back would carry its kernels. On the CPU (LLVM backend) each stage waits for its
        kernels: the world day measured the same with and without the waits
        (``benchmarks/world_day.py --time-only``). On a GPU the launches stay
        asynchronous (a wait would idle the device while Python traces the next stage): the
        light's time includes its pass (it waits), the soil's and the leaves' are the host's
        time to launch them, and the moss's and the record's include the kernels queued before
        their read-backs. On both, the stages' sum is the day's wall time.
        """
        day = st.day
        launches = _Launches()
        launches("before")
        date = self.inputs.date(day)
        vals = self.inputs.on_device(day)
        t0 = time.perf_counter()
        tables = leaf_area = None
        if self.leaves is not None:
            tables = self.leaves.start(st.leaves, date, self.scene_params)
            leaf_area = self.site.canopy.displayed_area()
        self._stage_end()
        launches("leaves")
        # the population's own count, kept up to date by its changes (no count each day)
        counts = self.moss.counts(st.moss)
        launches("moss")
        t1 = time.perf_counter()
        light = self.light(vals, lambda e: self.moss.cover(counts, e), tables, leaf_area,
                           self.site.canopy)
        dr.sync_thread()
        launches("light")
        t2 = time.perf_counter()
        soil = day_soil(self.site, vals, st.O, light.S, counts)
        Ts, rhs = soil.surface.Ts, soil.surface.rhs
        S32, Ts32, rhs32 = mi.Float(light.S), mi.Float(Ts), mi.Float(rhs)
        # the day's per-element fields in one kernel per width
        # (lE and beta too: left lazy they would hold the moss count, and the moss stage's
        # writes into it would copy it first)
        out = [soil.O, Ts, rhs, soil.theta, soil.surface.lE, soil.surface.beta, light.S,
               light.f_sun, light.f_sky, S32, Ts32, rhs32]
        if light.leaf is not None:
            out += [light.S_leaf, *light.leaf.values()]
        if self.growth is not None:
            out += self.growth.accumulate(st.year, light, vals)
        # the moss's fitness per element and species in the same kernel
        g_table = self.moss.fitness_columns(S32, Ts32, rhs32)
        dr.eval(out, g_table, *light.ground.values(), *light.ground_sky.values())
        # the moss stage writes the count in place: no other reference may be left to it
        # (Dr.Jit would copy the array first)
        del counts
        self._stage_end()
        launches("soil")
        t3 = time.perf_counter()
        if self.leaves is not None:
            self.leaves.end(st.leaves, date, light.S_leaf)
        self._stage_end()
        launches("leaves")
        t4 = time.perf_counter()
        events = self.moss.step(st.moss, day, S32, Ts32, rhs32, table=g_table)
        counts_after = self.moss.counts(st.moss)
        self._stage_end()
        launches("moss")
        t5 = time.perf_counter()
        if light.sensors is not None:
            st.sensor_days.append(light.sensors)
        secs = {"light": t2 - t1, "soil": t3 - t2, "moss": t5 - t4}
        if self.leaves is not None:
            secs["leaves"] = (t1 - t0) + (t4 - t3)
        rec = self.record(vals, date, light, soil, counts_after, st.moss.pop, events,
                          st.leaves, light.sensors, secs)
        rec["seconds"]["record"] = time.perf_counter() - t5
        launches("record")
        if launches.on:
            rec["launches"] = {"stages": launches.n, "kinds": launches.kinds,
                               "compiled": launches.compiled, "loaded": launches.loaded}
        st.O = soil.O
        st.history.append(rec)
        st.day += 1
        fields = {"S": light.S, "Ts": Ts, "rhs": rhs, "theta": soil.theta,
                  "f_sun": light.f_sun, "f_sky": light.f_sky, "light": light,
                  "counts": counts_after}
        return rec, fields


class _Launches:
    """Kernel launches of a day's stages, from Dr.Jit's kernel history when it is on
    (``dr.JitFlag.KernelHistory``: benchmarks/world_day.py); otherwise nothing is counted.
    Calling it with a stage's name adds the launches since the last call (the history is read
    and cleared) to that stage; ``kinds`` counts them by Dr.Jit's kernel type (JIT, reductions,
    memset/memcpy, host tasks), ``compiled`` the JIT kernels that missed the cache and ``loaded``
    those found in Dr.Jit's disk cache only (new to the process: a machine with an empty cache,
    e.g. a fresh GPU machine, compiles these too)."""

    def __init__(self):
        self.on = bool(dr.flag(dr.JitFlag.KernelHistory))
        self.n: dict = {}
        self.kinds: dict = {}
        self.compiled = 0
        self.loaded = 0

    def __call__(self, stage: str) -> None:
        if self.on:
            h = dr.kernel_history()
            self.n[stage] = self.n.get(stage, 0) + len(h)
            for x in h:
                k = str(x["type"]).split(".")[-1]
                self.kinds[k] = self.kinds.get(k, 0) + 1
                jit = x["type"] == dr.KernelType.JIT
                self.compiled += int(jit and not x["cache_hit"])
                self.loaded += int(jit and bool(x["cache_hit"]) and bool(x["cache_disk"]))


class HostFields(dict):
    """The day's per-element fields, read back from the device on first access (maps and
    tests read them; a normal day does not)."""

    def __init__(self, fields: dict):
        super().__init__()
        self._dev = fields

    def __missing__(self, key):
        v = self._dev[key]
        if dr.is_array_v(v):
            v = np.asarray(v, dtype=np.float64)
        self[key] = v
        return v

    def __contains__(self, key):
        return key in self._dev


class Simulation:
    """A run of a scenario through the daily pipeline: build from a scenario, :meth:`run`
    the days.

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
    light_strength : tuple of float
        Factors on the sun's and the sky's light (tuning; default 1, 1).
    albedo : dict, optional
        ``{shape id: albedo}``: the bare reflectance in the total band [-] of terrain shapes,
        replacing their BSDF's (tuning).
    """

    def __init__(self, scenario: Scenario, out_dir, days: int | None = None,
                 progress: bool = True, light_strength=(1.0, 1.0), albedo=None):
        self.config = MossConfig(scenario, days)
        c = self.config
        self.scn, self.days, self.start, self.seed = c.scn, c.days, c.start, c.seed
        self.species, self.weather, self.climate = c.species, c.weather, c.climate
        self.moss_cfg, self.light_cfg = c.moss_cfg, c.light_cfg
        self.checkpoint_every, self.frame_every = c.checkpoint_every, c.frame_every
        self.out = Path(out_dir)
        self.progress = progress
        self.light_strength = light_strength
        self.albedo = dict(albedo or {})
        self.timings = {"setup": 0.0, "light": 0.0, "soil": 0.0, "moss": 0.0, "output": 0.0,
                        "record": 0.0}
        self.state: DayState | None = None
        self.last: dict = {}
        self._env = None        # the growth's obstacles (the scenario's meshes), built once
        self._year_out_s = 0.0  # seconds of the last year end's outputs (figures, tree files)

    # ---- set-up ---------------------------------------------------------------------------
    def setup(self) -> None:
        """Build the site, the year's inputs, the stages and the state of day 0."""
        t0 = time.perf_counter()
        c = self.config
        self.site = build_site(c)
        if self.albedo:
            self.site.set_albedo(self.albedo)
        self.inputs = DayInputs.build(float(c.scn.get("site.latitude")),
                                      float(c.scn.get("site.longitude")), c.start, c.days,
                                      c.weather)
        self.pipeline = DayPipeline(self.site, self.inputs, self.light_strength)
        self.state = self.pipeline.new_state()
        if self.pipeline.leaves is not None:
            self.timings["leaves"] = 0.0
        dr.sync_thread()    # the set-up's kernels in its time, not in the first day's
        self.timings["setup"] += time.perf_counter() - t0

    def initialise(self) -> None:
        """Place the initial moss (``moss.initial``) at random on the living surfaces."""
        self.pipeline.moss.initialise(self.state.moss)

    # ---- views of the site and the state (maps, snapshots, tests) -------------------------
    @property
    def index(self):
        """The light scene's :class:`SceneIndex`."""
        return self.site.index

    @property
    def scene(self):
        """The light scene."""
        return self.site.scene

    @property
    def trees(self) -> list:
        """The world's trees (empty without ``[[trees]]``)."""
        return self.site.trees

    @property
    def canopy(self):
        """The world's canopy (None without trees)."""
        return self.site.canopy

    @property
    def phen(self):
        """The leaves' phenology (None without trees)."""
        return self.state.leaves if self.state is not None else None

    @property
    def pop(self):
        """The moss population."""
        return self.state.moss.pop

    @property
    def grid(self):
        """The spot grid."""
        return self.state.moss.grid

    @property
    def day(self) -> int:
        """Days simulated so far."""
        return self.state.day

    @property
    def history(self) -> list:
        """Every day's record so far."""
        return self.state.history

    @property
    def sensors(self):
        """The scenario's sensors (None without)."""
        return self.site.sensors

    @property
    def last_result(self):
        """The last photon pass (PhotonIrradianceResult)."""
        return self.last["light"].result if "light" in self.last else None

    def date(self, day: int):
        """The calendar date of simulated day ``day`` (0-based).

        Parameters
        ----------
        day : int
            Day number [d].

        Returns
        -------
        datetime.date
            ``start + day``.
        """
        return self.config.date(day)

    def grid_cell(self) -> float:
        """The spot grid's cell, one moss [m].

        Returns
        -------
        float
            ``moss.size`` [m].
        """
        return self.config.grid_cell()

    def counts(self) -> np.ndarray:
        """Live moss per element of the scene, read back (maps).

        Returns
        -------
        numpy.ndarray
            (elements,) moss count [-] (0 off the terrain).
        """
        c = np.zeros(self.index.n_elements)
        c[:self.site.n_terrain] = np.asarray(self.pipeline.moss.counts(self.state.moss),
                                             dtype=np.float64)
        return c

    def covered_area(self, counts=None, elements: slice | None = None) -> np.ndarray:
        """Area covered by moss per element.

        Parameters
        ----------
        counts : numpy.ndarray, optional
            Live moss per element of the scene (default: the population's, read back).
        elements : slice, optional
            Only these elements (e.g. the ground's; without ``counts`` only the terrain's
            counts are read back: a hectare's scene has 21.6 M elements).

        Returns
        -------
        numpy.ndarray
            (elements,) covered area [m2]: min(moss x size², triangle area).
        """
        sl = slice(0, self.index.n_elements) if elements is None else elements
        if counts is None:
            m = np.zeros(sl.stop - sl.start)
            hi = min(sl.stop, self.site.n_terrain)
            if hi > sl.start:
                t = np.asarray(self.pipeline.moss.counts(self.state.moss), dtype=np.float64)
                m[:hi - sl.start] = t[sl.start:hi]
        else:
            m = np.asarray(counts)[sl]
        return np.minimum(m * self.grid_cell() ** 2, self.index.areas[sl])

    # ---- the days -------------------------------------------------------------------------
    def step(self) -> dict:
        """Simulate one day; its record is appended to ``history``.

        Returns
        -------
        dict
            The day's record.
        """
        # (no local reference to the stages: the regrowth lets the old scene go)
        if self.pipeline.growth is not None and self.day > 0 and \
                DayGrowth.is_year_end(self.date(self.day - 1)) and \
                not (self.state.growth_log and self.state.growth_log[-1]["day"] == self.day):
            # the night after 31 December (the day's records, maps and checkpoint of 31
            # December show the trees that grew that year)
            t0 = time.perf_counter()
            self.regrow()
            dr.sync_thread()    # the new scene's kernels in the growth's time
            # the year's figures and tree files are outputs (timed as such in regrow)
            self.timings["growth"] = self.timings.get("growth", 0.0) + \
                time.perf_counter() - t0 - self._year_out_s
        # the last day's fields hold its photon pass: let them go before the next pass is
        # made beside them (a hectare's tallies are 3.4 GB)
        self.last, self.last_fields = {}, None
        rec, fields = self.pipeline.run_day(self.state)
        self.last = HostFields(fields)
        self.last_fields = fields
        for k, v in rec["seconds"].items():
            self.timings[k] = self.timings.get(k, 0.0) + v
        return rec

    def regrow(self) -> list:
        """The year's end: every tree of ``model = "growth"`` grows one generation from the
        light its leaves received this year (:mod:`mitsuba_veg.daily.growth`), and the light
        scene is rebuilt with the new trees (module docstring).

        Returns
        -------
        list of dict
            One row per tree that grew (also appended to the state's ``growth_log``).
        """
        st = self.state
        g = self.pipeline.growth
        # the memory that the days and the old scene free stays with the process (Dr.Jit's
        # cache of freed buffers, the C heap): the new scene's buffers and the next pass's
        # tallies take it again, of the same sizes. Handed back to the system, it comes back
        # page by page at a cost where the machine reclaims freed pages (a VM with free page
        # reporting: 3-4 s per GB; the first pass after a hectare's rebuild took 8-12 s for
        # its 3.4 GB tallies instead of 1.1 s). The price: the hectare's year peaked at
        # 16.3 GB, not 15.9 (docs/forest.md)
        t0 = time.perf_counter()
        self._floor_year()
        self._year_out_s = time.perf_counter() - t0
        self.timings["output"] += self._year_out_s
        lights = g.tip_lights(st.year) if g.trees else {}
        leaf_lights = g.leaf_lights(st.year)
        year = self.date(self.day - 1).year
        if not lights and not g.ageing and not leaf_lights:  # bare all year: new sums
            st.year = g.new_state()
            st.growth_log.append({"year": year, "day": self.day, "tree": None,
                                  "grew": False})
            return []
        trees = list(self.site.trees)
        rows = []
        # obstacles of the new segments: the scene's meshes (walls, rocks, logs, terrain), one
        # environment for every tree; neighbouring crowns may interlace (an environment per
        # tree with its neighbours cost a 36-tree stand 4 s a year)
        if lights and self._env is None:
            # the scenario's own meshes do not change: one environment for the whole run
            self._env = obstacles(self.config.scn.load_scene(daylight=False))
        env = self._env if lights else None
        # Weber-Penn trees: paper 002's death rule from their leaves' year light, then a
        # year older (one row each)
        ageing = set(g.ageing)

        def wp_year(i):          # one tree's year (the trees on the machine's cores)
            t = trees[i]
            row = {"year": year, "day": self.day, "tree": t.name, "model": "weber_penn"}
            if i in leaf_lights:
                t, st_ = adapt_tree(t, leaf_lights[i])
                row.update(st_)
                row["live_segments"] = int(t.tree.alive.sum())
            if i in ageing:
                t = age_tree(t, 1)
                row.update({"age": t.info["age"], "height_m": float(t.info["height_m"])})
            row.update({"leaves": int(len(t.leaf_area)), "crown_radius_m": float(t.crown_radius())})
            return t, row

        wp_idx = sorted(ageing | set(leaf_lights))
        for i, (t, row) in zip(wp_idx, map_on_cores(wp_year, wp_idx)):
            trees[i] = t
            rows.append(row)
        for i, light in lights.items():
            old = trees[i]
            seed = (int(self.seed) * 7919 + 104_729 * i + year) & 0x7FFFFFFF
            trees[i] = regrow(old, light, env, seed)
            m = trees[i].tree.metrics()
            rows.append({"year": year, "day": self.day, "tree": old.name, "model": "growth",
                         "generation": int(trees[i].info["generations"]),
                         "tips": int(len(light.received["light"])),
                         "died": int(np.sum(light.received["light"]
                                            < trees[i].tree.attrs["params"]["death_threshold"])),
                         "received_mean": float(np.mean(light.received["light"])),
                         "received_min": float(np.min(light.received["light"])),
                         "red_far_red_mean": float(np.mean(light.ratio())),
                         "leaves": int(len(trees[i].leaf_area)),
                         "height_m": float(m["height"]),
                         "crown_radius_m": float(trees[i].crown_radius()),
                         "crown_shift_m": [float(x) for x in
                                           trees[i].crown_centre() - trees[i].position[[0, 2]]],
                         "live_segments": int(trees[i].tree.alive.sum())})
        g = st = None            # the old stages and state hold the old scene: let it go
        self._rebuild(trees)
        self.state.growth_log.extend(rows)
        t0 = time.perf_counter()
        self._write_trees(year)
        dt = time.perf_counter() - t0
        self._year_out_s += dt
        self.timings["output"] += dt
        return rows

    def _floor_year(self) -> dict:
        """The ending year's floor (its light maps, gap fraction, moss cover): a row of
        ``floor_log``, ``years/floor_<year>.png`` with its arrays per ground triangle in
        ``years/floor_<year>.npz``, and ``floor_years.png``."""
        st, site = self.state, self.site
        year = self.date(self.day - 1).year
        gsl = site.ground_slice
        cov = self.covered_area(elements=gsl) / np.maximum(site.index.areas[gsl], 1e-30)
        fl = floor_year(st.year, site.index.areas[gsl], cov)
        row = {"year": year, "day": self.day, **{k: v for k, v in fl.items() if k != "maps"}}
        st.floor_log.append(row)
        v, f = site.index.geometry[site.ground_id]
        floor_figure(self.out / "years" / f"floor_{year}.png", v, f, year, fl, site.trees)
        # the figure's numbers per ground triangle, for the user's own analysis
        folder = self.out / "years"
        with atomic_write(folder / f"floor_{year}.npz", folder / f".floor_{year}.tmp.npz") as t:
            np.savez_compressed(t, area_m2=site.index.areas[gsl], **fl["maps"])
        floor_years_figure(self.out / "floor_years.png", st.floor_log)
        return row

    def _write_trees(self, year: int) -> None:
        """``trees/<year>.npz`` in the run folder: the growth trees from the next day on (the
        render draws each day's trees from these)."""
        g = self.pipeline.growth
        d = {"day": np.array(self.day), "indices": np.array(g.trees, np.int64),
             "adapted": np.array(g.adapting, np.int64)}
        for i in g.trees:
            d.update(tree_state(self.site.trees[i], str(i)))
        for i in g.adapting:           # paper 002's dead subtrees: the live segments
            d[f"alive/{i}"] = np.asarray(self.site.trees[i].tree.alive, bool)
        folder = self.out / "trees"
        folder.mkdir(parents=True, exist_ok=True)
        with atomic_write(folder / f"{year}.npz", folder / f".{year}.tmp.npz") as tmp:
            np.savez_compressed(tmp, **d)
        # the table people open: one row per tree and year-end step
        cols = ["year", "tree", "model", "generation", "age", "tips", "died", "received_mean",
                "received_min", "red_far_red_mean", "leaf_light_mean", "leaves", "height_m",
                "crown_radius_m", "crown_shift_m", "live_segments"]
        lines = [",".join(cols)]
        for r in self.state.growth_log:
            if r.get("tree"):
                v = [r.get(c, "") if c != "crown_shift_m" or c not in r
                     else float(np.hypot(*r[c])) for c in cols]
                lines.append(",".join(f"{x:.6g}" if isinstance(x, float) else str(x) for x in v))
        with atomic_write(self.out / "trees_yearly.csv", self.out / ".trees_yearly.tmp.csv") as t:
            Path(t).write_text("\n".join(lines) + "\n")

    def _rebuild(self, trees: list) -> None:
        """A new site and pipeline with these trees (the leaf mesh built bare); the soil
        water, the moss, the records and the day carry over, the leaves start bare and the
        year's sums at zero."""
        old = self.state
        # the old scene, its tables and the day's fields go first: a large stand's rebuild
        # then holds one light scene, not two
        self.state = self.pipeline = self.site = None
        self.last, self.last_fields = {}, None
        forget_scene_index()
        gc.collect()                     # Mitsuba objects in reference cycles
        # the new leaves start bare: their blades out of the mesh from the start
        self.site = build_site(self.config, trees=trees, bare=True)
        if self.albedo:
            self.site.set_albedo(self.albedo)
        self.pipeline = DayPipeline(self.site, self.inputs, self.light_strength)
        # the moss keep their slots and cells (the grid's origin is the terrain's, which
        # the trees do not move)
        st = self.pipeline.new_state(moss=old.moss)
        st.day, st.O, st.history = old.day, old.O, old.history
        st.sensor_days, st.growth_log = old.sensor_days, old.growth_log
        st.floor_log = old.floor_log
        self.state = st

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
        initial = list(getattr(self.site, "trees", None) or [])
        resumed = resume and ckpt.load(self)
        # half-written files of a process killed while writing (the real files are replaced
        # atomically, so these are never read)
        for pattern in ("checkpoint.tmp.npz", "*.json.tmp", "maps/.day_*.tmp.png",
                        "snapshots/.day_*.tmp.npz", "days.tmp.gif", "trees/.*.tmp.npz",
                        ".trees_yearly.tmp.csv", "years/.*.tmp.png", "years/.*.tmp.npz",
                        ".floor_years.tmp.png"):
            for q in self.out.glob(pattern):
                q.unlink()
        # the trees the run starts with, for the commands that draw them later (render,
        # animate, hemiphoto) instead of re-growing them; a resumed run keeps its record
        if initial and not (resumed and (self.out / RECORD).is_file()):
            write_initial_trees(self.out, initial)
        if not resumed:
            t0 = time.perf_counter()
            self.initialise()
            dr.sync_thread()    # the initial moss's kernels in the set-up's time
            self.timings["setup"] += time.perf_counter() - t0
        bar = None
        if self.progress:
            bar = tqdm(total=self.days, initial=self.day, unit="day", desc="days")
        stop = _InterruptFlag()
        due = told = False
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
                    due |= bool(self.checkpoint_every) and self.day % self.checkpoint_every == 0
                    if due and self.resumable():
                        ckpt.save(self)
                        due = False
                    self.timings["output"] += time.perf_counter() - t0
                    if stop.requested and self.resumable():
                        ckpt.save(self)
                        raise Interrupted(self.day, self.checkpoint_path)
                    if stop.requested and not told:
                        told = True
                        tqdm.write("interrupted: running on to the next photon pass "
                                   f"(simulation.light_every = {self.pipeline.light.every}) "
                                   "for a checkpoint that resumes exactly")
        finally:
            if bar is not None:
                bar.close()
        t0 = time.perf_counter()
        ckpt.save(self)
        self.timings["output"] += time.perf_counter() - t0
        return self.summary(resumed)

    def resumable(self) -> bool:
        """Whether a checkpoint written now resumes exactly: the next day traces a new photon
        pass (``simulation.light_every``), so a resumed run needs no earlier pass.

        Returns
        -------
        bool
            Always with a pass every day.
        """
        return self.pipeline.light.traces(self.day)

    @property
    def checkpoint_path(self) -> Path:
        """The run's checkpoint file, ``<out>/checkpoint.npz``."""
        return self.out / "checkpoint.npz"

    # ---- the summary ----------------------------------------------------------------------
    def summary(self, resumed=False) -> dict:
        """The run's summary (settings, final state, timings, every day's record).

        Parameters
        ----------
        resumed : bool, optional
            Whether the run was resumed from a checkpoint (recorded as ``resumed``).

        Returns
        -------
        dict
            JSON-able: ``scenario``, ``days``, ``resumed``, ``settings`` (light, moss, climate,
            simulation), ``species``, ``spot_grid`` (``cell_m`` [m]), ``final``
            (``covered_area_m2`` [m2], ``moss_alive``, ``propagules``, ``alive_by_species``,
            per-region covered and total area [m2] and live moss, ``propagules_crowded_out``),
            ``timings_s`` (wall times [s]: ``setup`` with the initial moss, the days' stages
            summed as in the records (:meth:`DayPipeline.run_day` says what each covers),
            ``output``, ``growth``, and ``per_day``), ``days_record`` (the daily records),
            ``versions``; a world adds ``world`` (with trees that grow from their light its
            ``growth_years``: one row per tree and year-end step) and, with sensors,
            ``sensors``.
        """
        counts = self.counts()[:self.site.n_terrain]
        cov = np.minimum(counts * self.grid_cell() ** 2, self.site.areas)
        regions = {k: {"covered_area_m2": float(cov[m].sum()),
                       "area_m2": float(self.site.areas[m].sum()),
                       "moss_alive": int(counts[m].sum())} for k, m in self.site.regions.items()}
        hist = self.history
        last = hist[-1] if hist else {}
        n_days = max(len(hist), 1)
        per_day = {k: self.timings[k] / n_days for k in ("light", "soil", "moss")}
        if "leaves" in self.timings:
            per_day["leaves"] = self.timings["leaves"] / n_days
        s = {
            "scenario": str(self.scn.path), "days": self.days, "resumed": resumed,
            "settings": {"light": self.light_cfg, "moss": self.moss_cfg,
                         "climate": self.climate.__dict__, "simulation": {
                             "start_date": self.start.isoformat(),
                             "checkpoint_every": self.checkpoint_every,
                             "light_every": self.pipeline.light.every}},
            "species": [sp.name for sp in self.species],
            "spot_grid": {"cell_m": self.grid.cell},
            "final": {"covered_area_m2": float(cov.sum()),
                      "moss_alive": int(self.pop.count(MOSS)),
                      "propagules": int(self.pop.count(PROPAGULE)),
                      "alive_by_species": last.get("alive", {}), "regions": regions,
                      "propagules_crowded_out": sum(r["events"].get("propagules_crowded_out", 0)
                                                    for r in hist)},
            "timings_s": {**self.timings, "per_day": per_day},
            "days_record": hist, "versions": versions()}
        if self.site.canopy is not None and self.site.canopy.n_leaves:
            c = self.site.canopy
            s["world"] = {"trees": [{"name": wt.name, "model": wt.model,
                                     "position": wt.position.tolist(),
                                     "leaves": int(len(wt.leaf_area)),
                                     "crown_radius_m": wt.crown_radius(),
                                     "crown_centre_xz_m": wt.crown_centre().tolist(), **wt.info}
                                    for wt in self.site.trees],
                          "leaf_elements": int(c.n_leaves),
                          "leaf_triangles": int(len(c.tri)),
                          # vertex updates of the leaf mesh in this process (leaf-out growth,
                          # hidden blades taken out); stage and fall changes need none
                          "leaf_mesh_updates": int(c.mesh_updates),
                          "stage_bins": self.config.stage_bins,
                          "phenology": self.config.phenology.to_dict(),
                          "trees_built_s": self.site.tree_seconds}
            if self.state.year is not None:
                # the year-end growth steps of the trees that grow from their light
                s["world"]["growth_years"] = self.state.growth_log
                s["world"]["floor_years"] = self.state.floor_log
        path = self.write_sensors()
        if path is not None:
            v = np.stack(self.state.sensor_days)
            q, cc = sensors_mod.QUANTITIES, sensors_mod.COMPONENTS
            ppfd = v[:, :, q.index("par"), cc.index("total")]
            rfr = v[:, :, q.index("rfr"), cc.index("total")]
            names = self.sensors.names
            s["sensors"] = {
                "file": path, "count": len(names), "days": int(v.shape[0]),
                "units": "daily means: PPFD, red, far-red umol m-2 s-1; shortwave W m-2; "
                         "DLI mol m-2 d-1",
                # the first 100 sensors by name (all of them are in the CSV)
                "per_sensor": {names[i]: {"dli_mean_mol_m2_d": float(ppfd[:, i].mean() * 0.0864),
                                          "red_far_red_mean": float(np.nanmean(rfr[:, i]))
                                          if np.isfinite(rfr[:, i]).any() else None}
                               for i in range(min(len(names), 100))}}
        return s

    def write_sensors(self) -> str | None:
        """``sensors_daily.csv`` of the run so far: daily means.

        Tidy table (time, sensor, band, component, value, unit): PPFD, red and far-red photon
        flux densities [µmol m-2 s-1], R:FR [-] and shortwave [W m-2].

        Returns
        -------
        str or None
            The path written; None without sensors (or before the first day).
        """
        if self.sensors is None or not self.state.sensor_days:
            return None
        times = [self.date(d).isoformat() for d in range(len(self.state.sensor_days))]
        return sensors_mod.write_tidy_csv(self.out / "sensors_daily.csv",
                                          np.stack(self.state.sensor_days), self.sensors.names,
                                          times)


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
