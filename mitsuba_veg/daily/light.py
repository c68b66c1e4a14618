"""The light stage of a day: one photon pass, and the irradiances the other stages read.

One pass (``integrators/photon_irradiance.py``, both emitters in one kernel launch) with the
day's sun path (``veg_sun_path``: every position of the sun that day, weighted by clear-sky
DNI) and an isotropic sky (``veg_sky``), both normalised to a unit horizontal irradiance of
1 W m-2 nm-1. Its tallies stay on the device; from them, as Dr.Jit expressions that the next
stages evaluate in their own kernels:

- per terrain element the sun and sky fractions f_sun, f_sky (front side, direct + indirect,
  "total" band / its width) and the insolation S = B f_sun + D f_sky [W m-2]
  (:func:`mitsuba_veg.soil.insolation`) with the day's broadband beam B and diffuse D;
- per leaf the band irradiances [W m-2] (both sides, both components: the unit emitters
  scaled per band by B and D times the day's clear-sky band shapes,
  :mod:`mitsuba_veg.daily.inputs`) and the insolation S_leaf [W m-2] that drives the autumn
  clock;
- per ground element the band irradiances of the front side (PAR, red, far-red: the R:FR
  under the crowns).

Moss cover enters the pass as per-element albedo; the leaves' stages and fall as per-triangle
BSDF and mode tables (:mod:`mitsuba_veg.world.canopy`). All three tables are device arrays
written in place each day: new contents, the same kernel.

A light schedule (``simulation.light_every = N``) traces a pass on the days whose number is a
multiple of N (and on the first day of a process or of a rebuilt scene); the days between keep
the last pass's tallies (per element and emitter the fraction of a unit horizontal irradiance)
and scale them by their own beam, diffuse and band shapes. The sun's path and the scene's
state (moss albedo, leaf stages, leaves out) are then those of the pass's day; the weather is
the day's own. Forest gap models take their light once a year; N = 3-7 costs a stand's moss a
lag of a few days in the light (docs/world.md measures it).

The photon split between sun and sky follows the power each sends towards the geometry, as
``trace`` does by default; it is computed for every day at set-up (the sun's exactly from its
directions and the aiming rectangle of each, the sky's by one pilot), not by a pilot pass and
a read-back every day.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..arrays import host_array
from ..integrators.photon_irradiance import (SURFACE, PassTables, PhotonIrradianceResult,
                                             aim_area, split_photons)
from ..light import sensors as sensors_mod
from ..light.photon import band_range
from ..soil import insolation
from ..world.canopy import LEAF_MESH
from .config import BANDS
from .inputs import DayInputs, DayValues

__all__ = ["WIDTH_TOTAL", "DayLightResult", "DayLight"]

#: width of the "total" band (360-830 nm): a unit emitter gives 470 W m-2 there
WIDTH_TOTAL = band_range("total")[1] - band_range("total")[0]


@dataclass
class DayLightResult:
    """The day's light on the device (lazy Dr.Jit expressions; see the module docstring).

    ``f_sun``, ``f_sky``, ``S`` per terrain element; ``leaf`` {band: W m-2} and ``S_leaf``
    [W m-2] per leaf (None without leaves); ``ground`` and ``ground_sky`` {band: W m-2} per
    ground element; ``sensors`` (n, quantities, components) NumPy readings (None without
    sensors); ``result`` the pass itself; ``S_leaf_net`` [W m-2] per leaf, the insolation on
    the side its geometric normal faces minus the other side's (only for worlds whose trees
    grow from their light, else None).
    """

    f_sun: object
    f_sky: object
    S: object
    leaf: dict | None
    S_leaf: object
    leaf_area: object
    ground: dict
    ground_sky: dict
    sensors: np.ndarray | None
    result: PhotonIrradianceResult
    S_leaf_net: object = None
    f_sky_ground: object = None


class DayLight:
    """The light stage (module docstring).

    Parameters
    ----------
    site : Site
        The run's site.
    inputs : DayInputs
        Every day's sun path, weather and band shapes.
    strength : tuple of float
        Factors on the sun's and the sky's light (1, 1: the site's; the pass is linear in each
        emitter's strength, so a tuning run scales the fractions instead of tracing again).
    """

    #: replay the photon pass's recorded kernels every day (``dr.freeze``) instead of
    #: tracing its Python again; results are bit-identical either way
    frozen = True
    #: the sun path table's fixed size: every 10 minutes of a day (a frozen pass needs the
    #: same array sizes every day)
    SUN_STEPS = 144

    def __init__(self, site, inputs: DayInputs, strength=(1.0, 1.0)):
        self.site, self.inputs = site, inputs
        self.strength = (float(strength[0]), float(strength[1]))
        cfg = site.config
        self.photons = int(cfg.light_cfg["photons"])
        self.max_depth = int(cfg.light_cfg["max_depth"])
        self.indirect = bool(cfg.light_cfg["indirect"])
        self.seed = int(cfg.seed)
        self.every = int(cfg.light_every)
        #: (day, PhotonIrradianceResult, leaf areas) of the last pass, reused until the next
        self.held = None
        # the leaves' net insolation (front - back) for trees that grow from their light
        self.leaf_net = any(wt.model == "growth" for wt in site.trees)
        idx = site.index
        integ = site.integrator
        modes, override = {}, {}
        c = site.canopy
        if c is not None and c.n_leaves:
            # tables that exist from the first day: the kernel keeps one shape all year
            modes[LEAF_MESH] = np.full(len(c.face_leaf), SURFACE, np.uint32)
            override[LEAF_MESH] = (c.stage_bsdfs, np.zeros(len(c.face_leaf), np.int64))
        if site.sensors is not None:
            modes[sensors_mod.SENSOR_SHAPE] = "sensor"
        # the bark's many triangles block and scatter light but are not recorded (nothing
        # reads their flux): a smaller accumulator
        record = [s for s in idx.shape_ids if s != "trees_bark"]
        refl = {sid: site.base_albedo[idx.shape_slice(sid)] for sid in site.terrain_shapes
                if sid in idx.geometry}
        self.tables: PassTables = integ.pass_tables(site.scene, len(BANDS), reflectance=refl,
                                                    modes=modes, bsdf_override=override,
                                                    record=record)
        rows = self.tables.rows if self.tables.rows is not None else \
            np.arange(idx.n_elements)
        n_t = site.n_terrain
        if not np.array_equal(rows[:n_t], np.arange(n_t)):
            raise RuntimeError("the terrain's elements must be the first of the index")
        self.d_terrain_rows = dr.arange(mi.UInt32, n_t)
        gsl = site.ground_slice
        self.d_ground_rows = host_array(mi.UInt32, rows[gsl])
        self.d_ground_area = host_array(mi.Float64, np.maximum(idx.areas[gsl], 1e-30))
        self.d_terrain_area = host_array(mi.Float64, np.maximum(site.areas, 1e-30))
        if c is not None and c.n_leaves:
            lsl = idx.shape_slice(LEAF_MESH)
            self.leaf_elems = (lsl.start, lsl.stop)
            # each leaf's first and (quads) second triangle: rows of the accumulator
            lrows = rows[lsl]
            first = c._first
            two = np.r_[np.diff(first), len(lrows) - first[-1]] == 2
            self.d_leaf_row_a = host_array(mi.UInt32, lrows[first])
            self.d_leaf_row_b = host_array(mi.UInt32, lrows[np.where(two, first + 1, first)])
            self.d_leaf_two = host_array(mi.Bool, two)
            # each leaf's first triangle in the leaf mesh (its mode: on the tree or hidden)
            self.d_leaf_first = host_array(mi.UInt32, first)
        else:
            self.leaf_elems = None
        if site.sensors is not None:
            ssl = idx.shape_slice(sensors_mod.SENSOR_SHAPE)
            self.d_sensor_rows = host_array(mi.UInt32, rows[ssl])
        self.d_moss_albedo = host_array(mi.Float, cfg.moss_cfg["albedo"])
        self.d_base_albedo = site.d_base_albedo
        self.counts = self._photon_split()
        self.band_index = {b: i for i, b in enumerate(BANDS)}
        dr.eval(self.d_ground_rows, self.d_ground_area, self.d_terrain_area,
                self.d_moss_albedo)

    # ---- set-up ---------------------------------------------------------------------------
    def _photon_split(self) -> np.ndarray:
        """(days, 2) photons of the sun and the sky on every day (module docstring)."""
        site, sun = self.site, self.inputs.sun
        lo, hi = band_range("total")
        sky_power = site.integrator.pilot_power(site.scene, site.sky, (lo, hi))
        areas = aim_area(site.index, -sun.directions)
        out = np.zeros((self.inputs.days, 2), np.int64)
        for k in range(self.inputs.days):
            a, b = int(sun.offsets[k]), int(sun.offsets[k + 1])
            w = sun.weights[a:b]
            # the pilot's expectation: weight x rectangle area, over the day's directions
            p_sun = float(np.sum(w * areas[a:b])) * (hi - lo) if b > a else 0.0
            out[k] = split_photons([p_sun, sky_power], self.photons)
        return out

    # ---- a day ----------------------------------------------------------------------------
    def __call__(self, vals: DayValues, cover, leaf_tables=None, leaf_area=None,
                 canopy=None) -> DayLightResult:
        """Trace the day's pass and return its light (module docstring).

        Parameters
        ----------
        vals : DayValues
            The day's inputs on the device.
        cover : mi.Float64 or callable
            Moss cover per terrain element [-] (0..1): the albedo follows it; or a function
            of terrain element indices (mi.UInt32) that gives their cover.
        leaf_tables : callable, optional
            :meth:`Canopy.trace_tables`: (modes, BSDF registry ids) at leaf triangles, a
            function of triangle indices, so that the tables are computed inside the kernel
            that writes the pass's tables.
        leaf_area : mi.Float64, optional
            Blade area of each leaf in the pass [m2] (:meth:`Canopy.displayed_area`).
        canopy : Canopy, optional
            The canopy (its leaf flux).

        Returns
        -------
        DayLightResult
            The day's light, on the device.
        """
        day = vals.day
        site = self.site
        if self.held is not None and not self.traces(day):
            _, res, pass_area = self.held
            shown = None
            if leaf_tables is not None and self.leaf_elems is not None:
                shown = leaf_tables(self.d_leaf_first)[0] == SURFACE
            return self._light(res, vals, leaf_area, canopy, pass_area, shown)
        # the pass held for the days between goes before the new one is made (its tallies:
        # 3.4 GB on a hectare; freed first, their memory serves the new pass)
        self.held = None
        dirs, w, _ = self.inputs.sun.day(day)
        site.sun.set_day(dirs, w, size=max(self.SUN_STEPS, len(w)))
        t = self.tables
        # moss cover as albedo of the terrain (the pass's reflectance table, written in place)
        n4 = site.n_terrain * 4
        leaves = leaf_tables is not None and self.leaf_elems is not None
        n_l = self.leaf_elems[1] - self.leaf_elems[0] if leaves else 0
        # the albedo and the leaf tables are written by one kernel of the larger width (lanes
        # past a table's end write nothing; the terrain has elements, the canopy leaves)
        wide = max(n4, n_l)
        j = dr.arange(mi.UInt32, wide)
        on = True if wide == n4 else j < n4
        j4 = dr.minimum(j, n4 - 1) if wide > n4 else j
        c = mi.Float(cover(j4 // 4) if callable(cover) else dr.gather(mi.Float64, cover, j4 // 4))
        alb = (1.0 - c) * dr.gather(mi.Float, self.d_base_albedo, j4) + \
            c * dr.gather(mi.Float, self.d_moss_albedo, j4 % 4)
        dr.scatter(t.refl[0], alb, j4, on)
        if leaves:
            jl = dr.minimum(j, n_l - 1) if wide > n_l else j
            modes, regs = leaf_tables(jl, j < n_l)
            k = jl + self.leaf_elems[0]
            dr.scatter(t.modes, modes, k, j < n_l)
            dr.scatter(t.bsdf_table, regs, k, j < n_l)
        dr.eval(t.refl[0], t.modes, t.bsdf_table)
        seed = (self.seed * 10_007 + day) & 0x7FFFFFFF
        res = site.integrator.trace(site.scene, photons=self.photons, seed=seed,
                                    max_depth=self.max_depth, bands=BANDS,
                                    indirect=self.indirect, tables=t,
                                    counts=self.counts[day], frozen=self.frozen, wait=False)
        # (not waited for here: the stage's sums launch behind the pass, and the day waits for
        # both at the light stage's end)
        self.held = (day, res, leaf_area)
        return self._light(res, vals, leaf_area, canopy)

    def traces(self, day: int) -> bool:
        """Whether day ``day`` is a pass day of the schedule (module docstring; the first day of
        a process or scene traces whatever its number).

        Parameters
        ----------
        day : int
            Day number [d].

        Returns
        -------
        bool
            ``day % light_every == 0``.
        """
        return day % self.every == 0

    def _light(self, res, vals: DayValues, leaf_area, canopy, pass_area=None,
               shown=None) -> DayLightResult:
        """The day's light from a pass's tallies and the day's own weather and band shapes;
        ``pass_area``: the leaves' areas on the pass's day, when it was an earlier day, and
        ``shown``: which leaves are on the tree today."""
        site = self.site
        s_sun, s_sky = self.strength
        kt = self.band_index["total"]
        rows = self.d_terrain_rows
        f_sun = res.device_flux(0, kt, rows) / self.d_terrain_area / WIDTH_TOTAL
        f_sky = res.device_flux(1, kt, rows) / self.d_terrain_area / WIDTH_TOTAL
        if s_sun != 1.0:
            f_sun = f_sun * s_sun
        f_sky_ground = res.device_flux(1, kt, self.d_ground_rows) / self.d_ground_area \
            / WIDTH_TOTAL
        if s_sky != 1.0:
            f_sky = f_sky * s_sky
            f_sky_ground = f_sky_ground * s_sky
        wd = vals.weather
        B, D = wd["beam"], wd["diffuse"]
        S = insolation(B, D, f_sun, f_sky)
        # the ground's bands, front side [W m-2]
        ground, ground_sky = {}, {}
        for b, k in self.band_index.items():
            sb = B * vals.shapes["beam", b] * s_sun
            sd = D * vals.shapes["diffuse", b] * s_sky
            fs = res.device_flux(0, k, self.d_ground_rows)
            fk = res.device_flux(1, k, self.d_ground_rows)
            ground[b] = (sb * fs + sd * fk) / self.d_ground_area
            ground_sky[b] = sd * fk / self.d_ground_area
        leaf = S_leaf = S_net = None
        if canopy is not None and self.leaf_elems is not None:
            area = dr.maximum(leaf_area, 1e-12)
            if pass_area is not None:
                # the pass's irradiance on the leaves on the tree on both days; a leaf fallen
                # since gets none (its flux over an infinite area), one out since none yet
                # (it was hidden in the pass)
                on = leaf_area > 0 if shown is None else shown
                area = dr.select(on, dr.maximum(pass_area, 1e-12), dr.inf)
            leaf = {}
            lf = {}
            for b, k in self.band_index.items():
                for e in (0, 1):
                    # a leaf's flux: its triangles' (one, or two for a quad), both sides
                    fa = res.device_flux(e, k, self.d_leaf_row_a, side="both")
                    fb = res.device_flux(e, k, self.d_leaf_row_b, side="both")
                    lf[e, b] = fa + dr.select(self.d_leaf_two, fb, 0.0)
                sb = B * vals.shapes["beam", b] * s_sun
                sd = D * vals.shapes["diffuse", b] * s_sky
                leaf[b] = (sb * lf[0, b] + sd * lf[1, b]) / area
            # the leaves' insolation as the terrain's S (total band, flat unit spectrum)
            S_leaf = (B * s_sun * lf[0, "total"] + D * s_sky * lf[1, "total"]) / area \
                / WIDTH_TOTAL
            if self.leaf_net:
                # front minus back (the light vector of the trees that grow from their light)
                kt = self.band_index["total"]
                nf = []
                for e in (0, 1):
                    d = [res.device_flux(e, kt, r, side="front")
                         - res.device_flux(e, kt, r, side="back")
                         for r in (self.d_leaf_row_a, self.d_leaf_row_b)]
                    nf.append(d[0] + dr.select(self.d_leaf_two, d[1], 0.0))
                S_net = (B * s_sun * nf[0] + D * s_sky * nf[1]) / area / WIDTH_TOTAL
        sensors = self._sensors(res, vals) if site.sensors is not None else None
        return DayLightResult(f_sun, f_sky, S, leaf, S_leaf, leaf_area, ground, ground_sky,
                              sensors, res, S_net, f_sky_ground)

    def _sensors(self, res, vals: DayValues) -> np.ndarray:
        """The day's sensor readings (n, quantities, components), read back (they are written
        out every day)."""
        site = self.site
        n = len(site.sensors)
        s_sun, s_sky = self.strength
        rows = self.d_sensor_rows
        parts = []
        for b in sensors_mod.PASS_BANDS:
            k = self.band_index["total" if b == "shortwave" else b]
            # the front side only: a sensor reads the light on its face (a square's upper
            # face, a dome's or sphere's outside), not what the ground reflects onto its back
            parts += [res.device_flux(0, k, rows, component="direct", side="front"),
                      res.device_flux(0, k, rows, component="indirect", side="front"),
                      res.device_flux(1, k, rows, side="front")]
        wd = vals.weather
        scal = [wd["beam"], wd["diffuse"]]
        for b in BANDS:
            scal += [vals.shapes["beam", b], vals.shapes["diffuse", b]]
        dr.eval(parts, scal)
        flux = np.stack([np.asarray(p) for p in parts]).reshape(len(sensors_mod.PASS_BANDS),
                                                                3, -1)
        sc = np.array([float(np.asarray(x)[0]) for x in scal])
        B, D = sc[0] * s_sun, sc[1] * s_sky
        shapes = {b: (sc[2 + 2 * i], sc[3 + 2 * i]) for i, b in enumerate(BANDS)}
        area = site.sensors.normalising_area()[:, None]

        def per_sensor(x):      # (faces,) flux of a unit emitter [W] -> per sensor [W m-2]
            out = np.zeros(n)
            np.add.at(out, site.sensor_owner, x)
            return out / area[:, 0]
        watts = np.zeros((n, 2, len(sensors_mod.PASS_BANDS)))   # direct, diffuse [W m-2]
        for j, b in enumerate(sensors_mod.PASS_BANDS):
            if b == "shortwave":
                # as the terrain's S: broadband daily means x the unit-spectrum fractions
                sb, sd = B / WIDTH_TOTAL, D / WIDTH_TOTAL
            else:
                sb, sd = B * shapes[b][0], D * shapes[b][1]
            watts[:, 0, j] = sb * per_sensor(flux[j, 0])
            watts[:, 1, j] = sb * per_sensor(flux[j, 1]) + sd * per_sensor(flux[j, 2])
        return sensors_mod.SensorReadings.from_watts(site.sensors, watts).values
