"""The moss scenario: the daily loop of paper 000 (§3.7) with outputs and checkpoints.

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
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import signal
import threading
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from . import soil as soil_model
from .climate import ClimateTable, daily_weather, load_csv
from .errors import MitsubaVegError, ParameterError, check_range
from .integrators.photon_irradiance import PhotonIrradianceIntegrator, SceneIndex
from .light.sunpath import day_sun_path
from .moss.population import (FREE, GEMMA, MOSS, PROPAGULE, SPORE, MossPopulation, SlotQueue,
                               SpeciesTable, concat_u32)
from .moss.propagules import land, settle, spore_direction, uniform_sphere
from .moss.spatial import SpotGrid, max_per_element, per_element_count
from .moss.species import SPECIES, Species, load_species
from .scenario import Scenario, load_scenario
from .terrain import Terrain

BANDS = ("total", "par", "red", "far_red")
_PCG_STREAM = 0xDA3E39CB94B95BDB  # Dr.Jit's default PCG32 stream (lane i adds i)

#: [moss] defaults (scenario fields, documented in docs/moss.md)
MOSS_DEFAULTS = {
    "species": ["bryum_argenteum", "hypnum_plumaeforme", "polytrichum"],
    "capacity": 16384,          # slots (paper: at most 16384 moss)
    "initial": 200,             # moss placed at random on the surfaces at the start
    "initial_growth": 1.0,      # their G_moss (established moss)
    "size": 0.01,               # [m] moss size = cell of the spot grid (paper: 1 cm)
    "gemma_distance": 0.02,     # k of eq 3.22 [m]
    "spore_distance": 0.25,     # l of eq 3.23 [m]
    "external_spore_interval": 5,   # days between spores arriving from outside (0 = none)
    "clump_neighbours": 8,      # occupied neighbour cells that make a moss "inside a clump"
    "albedo": [0.10, 0.07, 0.05, 0.45],   # moss reflectance per band (total, par, red, far-red)
    "priority": None,           # species priority for occupancy conflicts (default all 0)
    "shapes": None,             # shapes moss may live on (default: all meshes)
}
SIM_DEFAULTS = {"days": 300, "start_date": "2026-03-01", "checkpoint_every": 10,
                "frame_every": 10}


@dataclass
class DayRecord:
    day: int
    date: str
    alive: dict
    propagules: int
    covered_area_m2: float
    mean_S: float
    mean_Ts: float
    mean_rhs: float
    mean_theta: float
    events: dict
    regions: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)


class MossSimulation:
    """Build from a :class:`~mitsuba_veg.scenario.Scenario`; :meth:`run` the days."""

    #: smallest batch of propagules traced at a time while the population is full (the batch
    #: doubles until the free slots are used up; results do not depend on it)
    release_batch = 4096

    def __init__(self, scenario: Scenario, out_dir, days: int | None = None,
                 progress: bool = True):
        self.scn = scenario
        self.out = Path(out_dir)
        self.progress = progress
        src = str(scenario.path)
        sim = {**SIM_DEFAULTS, **scenario.get("simulation", {})}
        self.days = int(days if days is not None else sim["days"])
        check_range("simulation.days", self.days, 1, 100_000, source=src)
        try:
            self.start = _dt.date.fromisoformat(str(sim["start_date"]))
        except ValueError:
            raise ParameterError("simulation.start_date", sim["start_date"], "YYYY-MM-DD",
                                 None, src) from None
        self.checkpoint_every = int(sim["checkpoint_every"])
        self.frame_every = int(sim["frame_every"])
        m = {**MOSS_DEFAULTS, **scenario.get("moss", {})}
        self.moss_cfg = m
        check_range("moss.capacity", m["capacity"], 16, 50_000_000, source=src)
        check_range("moss.initial", m["initial"], 0, m["capacity"], source=src,
                    fix="no more initial moss than the capacity")
        check_range("moss.size", m["size"], 1e-4, 1.0, source=src, fix="moss size in metres")
        check_range("moss.gemma_distance", m["gemma_distance"], 0.0, 100.0, source=src)
        check_range("moss.spore_distance", m["spore_distance"], 0.0, 100.0, source=src)
        check_range("moss.external_spore_interval", m["external_spore_interval"], 0, 100_000,
                    source=src)
        check_range("moss.clump_neighbours", m["clump_neighbours"], 1, 26, source=src)
        if len(m["albedo"]) != len(BANDS) or any(not (0 <= a <= 1) for a in m["albedo"]):
            raise ParameterError("moss.albedo", m["albedo"], f"{len(BANDS)} values in [0, 1] "
                                 f"(bands {', '.join(BANDS)})", None, src)
        self.species = self._species(m, src)
        self.light_cfg = {"photons": scenario.get("light.photons"),
                          "max_depth": scenario.get("light.max_depth"),
                          "indirect": scenario.get("light.indirect"),
                          "seed": scenario.get("light.seed")}
        self.seed = int(self.light_cfg["seed"])
        self._setup_climate(src)
        self.timings = {"setup": 0.0, "light": 0.0, "soil": 0.0, "moss": 0.0, "output": 0.0}

    # ---- configuration ----------------------------------------------------------------------
    def _species(self, m, src) -> list[Species]:
        known = dict(SPECIES)
        custom = self.scn.get("species_file")
        if custom:
            known.update(load_species(self.scn.file("species_file")))
        out = []
        names = m["species"]
        if isinstance(names, str) or not names:
            raise ParameterError("moss.species", names, "a non-empty list of species keys", None,
                                 src)
        for k in names:
            if k not in known:
                raise ParameterError("moss.species", k, "one of " + ", ".join(sorted(known)),
                                     "use a built-in species or add it in a species_file", src)
            out.append(known[k])
        return out

    def _setup_climate(self, src):
        c = self.scn.get("climate", {}) or {}
        allowed = {"temperature", "humidity", "precipitation", "rain_days", "wind",
                   "possible_sunshine", "sunshine", "angstrom_a", "angstrom_b", "csv"}
        for k in c:
            if k not in allowed:
                raise ParameterError(f"climate.{k}", c[k], "one of " + ", ".join(sorted(allowed)),
                                     "remove or rename the field", src)
        table = ClimateTable(**{k: v for k, v in c.items() if k != "csv"}, source=src)
        lat = float(self.scn.get("site.latitude"))
        if c.get("csv"):
            w = load_csv(self.scn.file("climate.csv"), lat, table)
            if len(w) < self.days:
                raise ParameterError("climate.csv", f"{len(w)} rows", f">= {self.days} rows "
                                     "(one per simulated day)", "add rows or run fewer days", src)
        else:
            w = daily_weather(table, lat, self.days, seed=self.seed,
                              start_day=self.start.timetuple().tm_yday)
        self.weather = w
        self.climate = table

    # ---- scene, terrain, soil ---------------------------------------------------------------
    def setup(self):
        t0 = time.perf_counter()
        base = self.scn.load_scene(daylight=False)
        d = {"type": "scene"}
        for sh in base.shapes():
            d[sh.id()] = sh
        self.terrain_shapes = [sh.id() for sh in base.shapes() if sh.is_mesh()]
        d.update(self._extra_shapes(base))
        d["sun"] = {"type": "veg_sun_path", "id": "sun"}
        d["sky"] = {"type": "veg_sky", "id": "sky", "distribution": "uniform",
                    "radiance": {"type": "uniform", "value": 1.0 / np.pi}}
        self.scene = mi.load_dict(d, optimize=False)
        self.sun = [e for e in self.scene.emitters() if e.id() == "sun"][0]
        self.index = SceneIndex.build(self.scene)
        self.integrator = PhotonIrradianceIntegrator()
        self._setup_terrain()
        lo, hi = np.array(self.index.aim_bbox.min), np.array(self.index.aim_bbox.max)
        size = float(self.moss_cfg["size"])
        span = float(np.max(hi - lo))
        smallest = span / (SpotGrid.max_cells_per_axis - 3)
        if size < smallest:
            raise ParameterError("moss.size", size, f">= {smallest:.3g} m for this scene "
                                 f"({span:.3g} m across: the spot grid holds at most "
                                 f"{SpotGrid.max_cells_per_axis:,d} cells per axis)",
                                 "use a larger moss size or a smaller scene",
                                 str(self.scn.path))
        self.grid = SpotGrid(lo, hi, size, int(self.moss_cfg["capacity"]))
        self.pop = MossPopulation(int(self.moss_cfg["capacity"]),
                                  SpeciesTable(self.species, self.moss_cfg["priority"]))
        self.O = soil_model.bucket_capacity(self.h, self.geology).astype(np.float64)  # saturated
        self.history: list[dict] = []
        self.day = 0
        self._moss_version = 0
        self._setup_extra()
        self.timings["setup"] += time.perf_counter() - t0

    def _extra_shapes(self, base) -> dict:
        """Shapes added to the light scene besides the scenario's (a world adds its trees)."""
        return {}

    def _setup_extra(self) -> None:
        """Set-up after the scene, terrain and population exist (a world: its canopy)."""

    def _setup_terrain(self):
        src = str(self.scn.path)
        idx = self.index
        n = idx.n_elements
        ground = self.scn.get("terrain.ground", "ground")
        meshes = [s for s in idx.shape_ids if s in idx.geometry]

        def need_shape(field, sid):
            if sid not in idx.geometry:
                raise ParameterError(field, sid, "a mesh id of the scene: " + ", ".join(meshes),
                                     "use one of the scene's shape ids (loaded with "
                                     "optimize=False)", src)
        need_shape("terrain.ground", ground)
        for sec in ("geology", "soil_depth_mm"):
            for sid in (self.scn.get(f"terrain.{sec}", {}) or {}):
                need_shape(f"terrain.{sec}.{sid}", sid)
        for name, reg in (self.scn.get("regions", {}) or {}).items():
            for sid in reg["shapes"]:
                need_shape(f"regions.{name}.shapes", sid)
        self.geology = np.full(n, soil_model.geology_code("asphalt"), np.int64)
        self.h = np.ones(n)
        geo_over = self.scn.get("terrain.geology", {}) or {}
        depth_over = self.scn.get("terrain.soil_depth_mm", {}) or {}
        living = self.moss_cfg["shapes"] or [s for s in self.terrain_shapes if s in idx.geometry]
        self.living = np.zeros(n, bool)
        for sid in idx.shape_ids:
            if sid not in idx.geometry:
                continue
            sl = idx.shape_slice(sid)
            v, f = idx.geometry[sid]
            terr = Terrain.from_arrays(v, f, name=sid)
            if sid == ground:
                shape = [s for s in self.scene.shapes() if s.id() == sid][0]
                terr = Terrain.from_mitsuba(shape)
                tex = self.scn.get("terrain.geology_texture")
                if tex:
                    path = self.scn.file("terrain.geology_texture")
                    try:
                        self.geology[sl] = terr.geology_from_texture(path)
                    except (OSError, ValueError, SyntaxError) as e:  # PIL: unreadable image
                        raise ParameterError("terrain.geology_texture", tex, "a readable PNG/JPEG "
                                             "image", f"replace {path.name} ({e})", src) from None
                base_y = self.scn.get("terrain.soil_base_y")
                self.h[sl] = terr.soil_depth_mm(base_y)
            if sid in geo_over:
                self.geology[sl] = soil_model.geology_code(geo_over[sid])
            if sid in depth_over:
                self.h[sl] = check_range(f"terrain.soil_depth_mm.{sid}", depth_over[sid], 1.0,
                                         1000.0, source=src)
            if sid in living:
                self.living[sl] = True
        for sid in living:
            if sid not in idx.geometry:
                raise ParameterError("moss.shapes", sid, f"mesh ids among {list(idx.geometry)}",
                                     None, src)
        self.living_dr = mi.Bool(self.living)
        self.M = max_per_element(idx.areas, self.grid_cell())
        self.base_albedo = self._base_albedo()
        self.regions = {}
        for name, reg in (self.scn.get("regions", {}) or {}).items():
            mask = np.zeros(n, bool)
            for sid in reg["shapes"]:
                sl = idx.shape_slice(sid)
                c = idx.centroids[sl]
                mask[sl] = np.all((c >= np.array(reg["min"])) & (c <= np.array(reg["max"])), 1)
            self.regions[name] = mask

    def grid_cell(self) -> float:
        return float(self.moss_cfg["size"])

    def _base_albedo(self) -> np.ndarray:
        """Albedo of the bare surfaces per element and band, from their BSDFs at the band
        centres (diffuse reflectance at the triangle's centroid)."""
        n = self.index.n_elements
        out = np.zeros((n, len(BANDS)))
        from .integrators.photon_irradiance import BANDS as B
        lam = [0.5 * (B[b][0] + B[b][1]) for b in BANDS]
        for sh in self.scene.shapes():
            if sh.id() not in self.terrain_shapes:
                continue  # only the terrain's albedo is replaced (moss cover)
            sl = self.index.shape_slice(sh.id())
            m = sl.stop - sl.start
            si = dr.zeros(mi.SurfaceInteraction3f, m)
            c = self.index.centroids[sl]
            si.p = mi.Point3f(*[mi.Float(c[:, k].astype(np.float32)) for k in range(3)])
            nrm = self.index.normals[sl]
            si.n = mi.Normal3f(*[mi.Float(nrm[:, k].astype(np.float32)) for k in range(3)])
            si.sh_frame = mi.Frame3f(si.n)
            si.wi = mi.Vector3f(0, 0, 1)
            si.wavelengths = mi.Spectrum(*lam)
            a = sh.bsdf().eval_diffuse_reflectance(si)
            out[sl] = np.stack([np.asarray(a[k]) for k in range(len(BANDS))], 1)
        return np.clip(out, 0.0, 1.0)

    # ---- one day ----------------------------------------------------------------------------
    def _date(self, day: int) -> _dt.date:
        return self.start + _dt.timedelta(days=day)

    def _rng(self, day: int, n: int, stream: int, offset: int = 0) -> mi.PCG32:
        """Lanes offset .. offset + n - 1 of the day's generator for ``stream`` (a batch of a
        larger draw gets the numbers the whole draw would give it)."""
        init = (self.seed * 1_000_003 + day * 7919 + stream * 104_729) & 0xFFFFFFFFFFFF
        # opaque: a literal seed would be baked into the kernel and recompiled every day
        return mi.PCG32(size=max(n, 1), initstate=dr.opaque(mi.UInt64, init + offset),
                        initseq=dr.opaque(mi.UInt64, (_PCG_STREAM + offset) % (1 << 64)))

    def _counts(self):
        """Live moss per element (cached until the population changes, i.e. per day step)."""
        key = (self.day, self._moss_version)
        if getattr(self, "_counts_cache", (None,))[0] != key:
            c = np.asarray(per_element_count(self.pop.elem, self.pop.moss,
                                             self.index.n_elements), dtype=np.float64)
            self._counts_cache = (key, c)
        return self._counts_cache[1]

    def light(self, day: int, counts: np.ndarray):
        """Daily-mean insolation S per element [W m-2] and the photon-pass result."""
        dirs, w, _ = day_sun_path(float(self.scn.get("site.latitude")),
                                  float(self.scn.get("site.longitude")), self._date(day))
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
        day = self.day
        t0 = time.perf_counter()
        counts = self._counts()
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
        counts = self._counts() if counts is None else counts
        return np.minimum(counts * self.grid_cell() ** 2, self.index.areas)

    def _record(self, day, S, st, theta, events, secs) -> dict:
        counts = self._counts()
        cov = self.covered_area(counts)
        soil = self.living
        a = self.index.areas[soil]

        def amean(x):
            return float(np.sum(np.asarray(x)[soil] * a) / a.sum())

        alive = dict(zip([s.name for s in self.species], self.pop.count_by_species(MOSS)))
        # where eq 3.16's linearised q_SAT(Ts) is off by > 10 % (cold shaded surfaces)
        off = np.abs(np.asarray(soil_model.linearisation_error(self.weather.T[day],
                                                               np.asarray(st.Ts)))) > 0.1
        return {"day": day + 1, "date": self._date(day).isoformat(), "alive": alive,
                "soil_linearisation_off": amean(off.astype(float)),
                "moss_alive": int(sum(alive.values())),
                "propagules": self.pop.count(PROPAGULE), "covered_area_m2": float(cov.sum()),
                "mean_S_W_m2": amean(S), "mean_Ts_K": amean(st.Ts), "mean_rhs": amean(st.rhs),
                "mean_theta": amean(theta), "events": events,
                "regions": {k: float(cov[m].sum()) for k, m in self.regions.items()},
                "seconds": secs}

    def initialise(self):
        self._moss_version += 1
        self._place_random(int(self.moss_cfg["initial"]), -1, MOSS, GEMMA,
                           float(self.moss_cfg["initial_growth"]), stream=3)

    # ---- checkpoints ------------------------------------------------------------------------
    @property
    def checkpoint_path(self) -> Path:
        return self.out / "checkpoint.npz"

    def save_checkpoint(self):
        d = self.pop.to_numpy()
        d.update(self._checkpoint_extra())
        d.update({"day": np.array(self.day), "O": self.O,
                  "history": np.array(json.dumps(self.history)),
                  "timings": np.array(json.dumps(self.timings)),
                  "fingerprint": np.array(self._fingerprint())})
        tmp = self.out / "checkpoint.tmp.npz"
        np.savez_compressed(tmp, **d)
        os.replace(tmp, self.checkpoint_path)

    def _checkpoint_extra(self) -> dict:
        """Arrays of the state beyond soil and moss (a world: its leaves)."""
        return {}

    def _load_extra(self, d: dict) -> None:
        """Restore what :meth:`_checkpoint_extra` saved."""

    def _fingerprint(self) -> str:
        """What must match for a checkpoint to be resumed: the settings of the run."""
        keep = {k: v for k, v in self.scn.data.items() if k != "simulation"}
        return json.dumps({"scenario": keep, "start": self.start.isoformat()}, sort_keys=True,
                          default=str)

    def load_checkpoint(self) -> bool:
        p = self.checkpoint_path
        if not p.exists():
            return False
        try:
            d = dict(np.load(p, allow_pickle=False))
            fingerprint, day = str(d["fingerprint"]), int(d["day"])
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
            raise ParameterError("checkpoint", str(p), "a complete checkpoint written by "
                                 "mitsuba-veg run", f"it cannot be read ({type(e).__name__}); "
                                 "run again with --fresh to start over") from None
        if fingerprint != self._fingerprint():
            raise ParameterError("checkpoint", str(p), "a checkpoint of the same scenario",
                                 "use --fresh (or another --out folder) to start afresh")
        if day > self.days:
            raise ParameterError("--days", self.days, f">= {day}: the checkpoint in "
                                 f"{self.out} already holds day {day}",
                                 f"pass --days {day} or more to resume, or --fresh to start "
                                 "over with fewer days")
        self.pop.load_numpy(d)
        self._load_extra(d)
        self.grid.rebuild(self.pop.pos, self.pop.state)
        self._moss_version += 1
        self.day = int(d["day"])
        self.O = np.asarray(d["O"], np.float64)
        self.history = json.loads(str(d["history"]))
        self.timings.update(json.loads(str(d["timings"])))
        return True

    def run(self, resume: bool = True, on_day=None) -> dict:
        """Run (or resume) to ``self.days`` days; returns the summary dict."""
        from .outputs import RUN_OUTPUTS, clear_outputs
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
            from tqdm.auto import tqdm
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
        from .variant import versions
        counts = self._counts()
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


def run(scenario, out="out/run", days: int | None = None, overrides=(), resume: bool = True,
        progress: bool = True, frames: bool = True, snapshot_every: int | None = None) -> dict:
    """Run a moss scenario (TOML path or Scenario) into ``out``; returns the summary dict
    (also written to ``out/summary.json``).

    The folder is claimed for the run (:class:`~mitsuba_veg.outputs.OutputFolder`: a second
    process writing into it is refused; a folder holding another kind of result is refused).
    ``resume=False`` (``--fresh``) discards the checkpoint and every output of an earlier run
    in the folder (maps, snapshots, GIF, renders); so does a run that finds no checkpoint.
    ``snapshot_every``: days between moss snapshots for exact animations (default: the
    scenario's ``simulation.frame_every``)."""
    from .outputs import RUN_OUTPUTS, DayFrames, OutputFolder, SnapshotWriter, write_summary
    scn = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    if scn.get("trees"):
        from .world import WorldSimulation
        sim = WorldSimulation(scn, out, days=days, progress=progress)
    else:
        sim = MossSimulation(scn, out, days=days, progress=progress)
    with OutputFolder(out, "run", info={"scenario": str(scn.path)}) as folder:
        if not resume:
            folder.clear(RUN_OUTPUTS)
        frames_writer = DayFrames(sim) if frames else None
        # living moss on frame days (exact animations)
        snapshots = SnapshotWriter(snapshot_every) if frames else None

        def on_day(s, rec):
            if frames_writer is not None:
                frames_writer(s, rec)
            if snapshots is not None:
                snapshots(s, rec)

        summary = sim.run(resume=resume, on_day=on_day)
        if frames_writer is not None:
            summary["files"] = frames_writer.finish()
            summary["files"]["snapshots"] = str(Path(out) / "snapshots")
        write_summary(Path(out) / "summary.json", summary)
    return summary
