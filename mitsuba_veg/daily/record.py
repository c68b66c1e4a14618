"""The record of a day: a few dozen numbers, summed on the device and read back in one go.

Every area-weighted mean, covered area, count and per-tree figure of the day's record is a
column of one :class:`~mitsuba_veg.arrays.Tally` (exact, repeatable fixed-point sums: the same
on every backend and in every thread order), evaluated in a few kernels and read back once; the
host turns the sums into the record's means and ratios.

A day's record: ``day`` (1-based), ``date``, live moss per species, propagules, covered area
[m2], area means over the living surfaces of S [W m-2], Ts [K], rhs [-], theta [-] and the share
where eq 3.16's linearisation is off by > 10 %, covered area per region [m2], the moss stage's
events and the stages' seconds. A world adds per tree (leaves, leaves on the tree, mean stage,
absorbed PAR [W], the ground under its crown) and the ground in the open (area [m2], PAR
[W m-2], R:FR [-] (total and of the sky's light), moss cover, S, Ts, rhs); with sensors, their
mean PPFD [µmol m-2 s-1], DLI [mol m-2 d-1] and R:FR.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..arrays import Tally, host_array
from ..foliage import leaf_spectra
from ..light import sensors as sensors_mod
from ..light.photon import band_range
from ..moss.population import MOSS, PROPAGULE
from ..soil import linearisation_error
from ..units import umol_per_joule

__all__ = ["DayRecord"]

_GROUND_FIELDS = ("par", "red", "far_red", "red_sky", "far_red_sky", "cover", "S", "Ts", "rhs")

# Bounds of the summed quantities (arrays.Tally: a column with a bound is summed in one kernel
# with a scale known before it; a value above its bound only costs that column a second,
# exact sum). Generous, so that they hold: the resolution of a sum stays below 1e-10 of it.
#: irradiance, insolation [W m-2] (the solar constant is 1361 W m-2)
_W_MAX = 1e5
#: surface temperature [K], relative humidity and volumetric water content [-], leaf stage [-]
_PER_UNIT_MAX = {"Ts": 1e4, "rhs": 1e3, "theta": 1e3, "stage": 1e3}


class DayRecord:
    """The day's record (module docstring).

    Parameters
    ----------
    site : Site
        The run's site (terrain, regions, ground, crowns, canopy, sensors).
    """

    def __init__(self, site):
        self.site = site
        n_sp = len(site.config.species)
        self.names = [s.name for s in site.config.species]
        self.n_sp = n_sp
        self._accumulators: dict = {}   # the day's sums' accumulators (arrays.Tally(reuse=))
        self.d_living = site.d_living
        self.d_area_living = dr.select(site.d_living, site.d_areas, 0.0)
        self.regions = list(site.regions)
        self.d_regions = [host_array(mi.Bool, site.regions[r]) for r in self.regions]
        gsl = site.ground_slice
        # the ground under each crown, and in the open, as (ground element, group) pairs: one
        # segmented sum per field for all groups (crowns of a stand overlap)
        groups = list(site.crowns) + [site.open_ground]
        pe = [np.flatnonzero(m) for m in groups]
        self.n_groups = len(groups)
        pair = np.concatenate(pe).astype(np.uint32) if pe else np.zeros(0, np.uint32)
        self.d_pair_elem = host_array(mi.UInt32, pair)
        # the pairs' global (terrain) elements and areas: every ground column is gathered at
        # the pairs' width straight from an evaluated array (a gather from an expression would
        # evaluate that expression first, a kernel per column)
        self.d_pair_terrain = host_array(mi.UInt32, pair + np.uint32(gsl.start))
        self.d_pair_area = host_array(mi.Float64, site.index.areas[gsl][pair])
        self.d_pair_group = host_array(mi.UInt32, np.repeat(np.arange(len(pe)),
                                                            [len(x) for x in pe]))
        c = site.canopy
        self.world = c is not None and c.n_leaves > 0
        if self.world:
            self.n_trees = len(site.trees)
            self.leaves_per_tree = np.bincount(c.tree_of, minlength=self.n_trees)
            # PAR absorptance of each stage bin's leaf spectra (bin centres, as the light scene)
            a = []
            for b in range(c.bins):
                R, T = leaf_spectra(stage=c.bin_stage(b)).band_mean(400, 700)
                a.append(1.0 - float(R) - float(T))
            self.d_a_par = host_array(mi.Float64, a)
        self.u_red = umol_per_joule(*band_range("red"))
        self.u_fr = umol_per_joule(*band_range("far_red"))
        # the largest areas [m2] (the bounds of the area-weighted columns)
        living_areas = np.asarray(site.areas)[np.asarray(site.living, bool)]
        self.a_max = max(float(living_areas.max()) if living_areas.size else 0.0, 1e-30)
        self.area_max = max(float(np.max(site.areas)) if len(site.areas) else 0.0, 1e-30)
        self.w_max = max(float(np.max(site.index.areas[gsl][pair])) if len(pair) else 0.0,
                         1e-30)
        self._leaf_bound = (None, 0.0)   # (canopy, its largest full blade area [m2])
        dr.eval(self.d_area_living, self.d_pair_elem, self.d_pair_terrain, self.d_pair_area)

    def __call__(self, vals, date, light, soil, counts, pop, events: dict, phen=None,
                 sensors=None, seconds: dict | None = None) -> dict:
        """Sum the day's figures on the device, read them back once and build the record.

        Parameters
        ----------
        vals : DayValues
            The day's inputs (its index and weather).
        date : datetime.date
            Its date.
        light : DayLightResult
            The day's light.
        soil : SoilDay
            The day's soil.
        counts : mi.UInt32
            Live moss per terrain element after the day's moss stage.
        pop : MossPopulation
            The population.
        events : dict
            The moss stage's events.
        phen : Phenology, optional
            The leaves (a world).
        sensors : numpy.ndarray, optional
            The day's sensor readings (n, quantities, components).
        seconds : dict, optional
            The stages' wall times [s], their kernels included on the CPU (what each covers:
            :meth:`mitsuba_veg.daily.pipeline.DayPipeline.run_day`).

        Returns
        -------
        dict
            The day's record (module docstring).
        """
        site = self.site
        day = vals.day
        # (the same columns every day: the accumulator is zeroed by the last day's kernel)
        t = Tally(reuse=self._accumulators)
        a = self.d_area_living
        live = self.d_living
        st = soil.surface
        cell2 = site.grid_cell() ** 2
        covered = dr.minimum(mi.Float64(counts) * cell2, site.d_areas)
        am, pm = self.a_max, _PER_UNIT_MAX
        t.add("area", a, mask=live, bound=am)
        t.add("S", light.S * a, mask=live, bound=am * _W_MAX)
        t.add("Ts", st.Ts * a, mask=live, bound=am * pm["Ts"])
        t.add("rhs", st.rhs * a, mask=live, signed=True, bound=am * pm["rhs"])
        t.add("theta", soil.theta * a, mask=live, bound=am * pm["theta"])
        off = dr.abs(linearisation_error(vals.weather["T"], st.Ts)) > 0.1
        t.add("off", dr.select(off, a, 0.0), mask=live, bound=am)
        t.add("covered", covered, bound=self.area_max)
        for r, m in zip(self.regions, self.d_regions):
            t.add("region:" + r, covered, mask=m, bound=self.area_max)
        t.count("alive", pop.state == MOSS, segments=pop.species, n_segments=self.n_sp)
        t.count("propagules", pop.state == PROPAGULE)
        if self.world:
            self._world_columns(t, light, soil, counts, phen)
        s = t.evaluate()
        area = s["area"][0]

        def amean(k):
            return float(s[k][0] / area) if area > 0 else float("nan")
        alive = {n: int(v) for n, v in zip(self.names, s["alive"])}
        rec = {"day": day + 1, "date": date.isoformat(), "alive": alive,
               "soil_linearisation_off": amean("off"),
               "moss_alive": int(sum(alive.values())), "propagules": int(s["propagules"][0]),
               "covered_area_m2": float(s["covered"][0]),
               "mean_S_W_m2": amean("S"), "mean_Ts_K": amean("Ts"), "mean_rhs": amean("rhs"),
               "mean_theta": amean("theta"), "events": events,
               "regions": {r: float(s["region:" + r][0]) for r in self.regions},
               "seconds": dict(seconds or {})}
        if sensors is not None:
            q, c = sensors_mod.QUANTITIES, sensors_mod.COMPONENTS
            ppfd = sensors[:, q.index("par"), c.index("total")]
            rfr = sensors[:, q.index("rfr"), c.index("total")]
            rec["sensors"] = {"count": int(len(ppfd)),
                              "mean_ppfd_umol_m2_s": float(np.mean(ppfd)),
                              "mean_dli_mol_m2_d": float(np.mean(ppfd)) * 0.0864,
                              "mean_red_far_red": float(np.nanmean(rfr))
                              if np.isfinite(rfr).any() else None}
        if self.world:
            self._world_record(rec, s)
        return rec

    # ---- the world's figures ----------------------------------------------------------------
    def _world_columns(self, t: Tally, light, soil, counts, phen) -> None:
        site, c = self.site, self.site.canopy
        # per leaf: on the tree, stage, absorbed PAR [W] (stage bin's PAR absorptance)
        on = phen.on_tree
        seg = c.d_tree_of
        t.count("leaves_on", on, segments=seg, n_segments=self.n_trees)
        t.add("stage_on", phen.stage, segments=seg, n_segments=self.n_trees, mask=on,
              bound=_PER_UNIT_MAX["stage"])
        a_par = dr.gather(mi.Float64, self.d_a_par, c._bin)
        # (a shown blade is at most its full area: the canopy's, found once per canopy)
        if self._leaf_bound[0] is not c:
            self._leaf_bound = (c, max(float(np.max(c.area)) if len(c.area) else 0.0, 1e-30))
        t.add("absorbed_par", light.leaf["par"] * light.leaf_area * a_par, segments=seg,
              n_segments=self.n_trees, bound=self._leaf_bound[1] * _W_MAX)
        # the ground under each crown and in the open: area-weighted sums over the (ground
        # element, group) pairs
        pe, pt, w = self.d_pair_elem, self.d_pair_terrain, self.d_pair_area
        g, gs = light.ground, light.ground_sky
        cover = dr.minimum(mi.Float64(dr.gather(mi.UInt32, counts, pt)) * site.grid_cell() ** 2
                           / dr.maximum(w, 1e-30), 1.0)
        at_pair = {"par": (g["par"], pe), "red": (g["red"], pe),
                   "far_red": (g["far_red"], pe), "red_sky": (gs["red"], pe),
                   "far_red_sky": (gs["far_red"], pe), "S": (light.S, pt),
                   "Ts": (soil.surface.Ts, pt), "rhs": (soil.surface.rhs, pt)}
        vals = {f: dr.gather(mi.Float64, x, i) for f, (x, i) in at_pair.items()}
        vals["cover"] = cover
        pg, ng, wm = self.d_pair_group, self.n_groups, self.w_max
        per_unit = {"cover": 1.0, "Ts": _PER_UNIT_MAX["Ts"], "rhs": _PER_UNIT_MAX["rhs"]}
        t.add("g:area", w, segments=pg, n_segments=ng, bound=wm)
        for f in _GROUND_FIELDS:
            t.add(f"g:{f}", vals[f] * w, segments=pg, n_segments=ng, signed=f == "rhs",
                  bound=wm * per_unit.get(f, _W_MAX))

    def _ground_stats(self, s: dict, k: int) -> dict:
        area = float(s["g:area"][k])
        if area <= 0:
            return {"area_m2": 0.0, "par_W_m2": None, "red_far_red": None,
                    "red_far_red_sky": None, "moss_cover": None, "S_W_m2": None,
                    "Ts_K": None, "rhs": None}

        def mean(f):
            return float(s[f"g:{f}"][k] / area)

        def rfr(red, fr):
            r = float(s[f"g:{red}"][k]) * self.u_red
            f = float(s[f"g:{fr}"][k]) * self.u_fr
            return r / f if f > 0 else None
        return {"area_m2": area, "par_W_m2": mean("par"),
                "red_far_red": rfr("red", "far_red"), "red_far_red_sky": rfr("red_sky",
                                                                              "far_red_sky"),
                "moss_cover": mean("cover"), "S_W_m2": mean("S"), "Ts_K": mean("Ts"),
                "rhs": mean("rhs")}

    def _world_record(self, rec: dict, s: dict) -> None:
        trees = {}
        for i, wt in enumerate(self.site.trees):
            on = int(s["leaves_on"][i])
            trees[wt.name] = {
                "leaves": int(self.leaves_per_tree[i]), "leaves_on_tree": on,
                "mean_stage": float(s["stage_on"][i] / on) if on else None,
                "absorbed_par_W": float(s["absorbed_par"][i]),
                "ground_under_crown": self._ground_stats(s, i)}
        rec["trees"] = trees
        rec["ground_open"] = self._ground_stats(s, len(self.site.trees))

