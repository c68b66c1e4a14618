"""One living world: terrain, buildings, trees, foliage and moss in one daily photon loop.

A scenario with ``[[trees]]`` runs this loop (:func:`mitsuba_veg.run` chooses it). Each day:

1. **leaves** — phenology (:mod:`.phenology`): leaf-out in spring, the leaves' autumn stage from
   their accumulated light, leaf fall; the canopy follows (:mod:`.canopy`: one leaf mesh, each
   triangle given the day's stage BSDF (PROSPECT-D reflectance and transmittance) and hidden
   from the photons once fallen, by per-triangle tables of the photon pass);
2. **light** — one photon pass over terrain, buildings, wood and leaves (the day's sun path and
   the sky, as in the moss loop): per-triangle irradiance of the terrain **and** the light on
   every leaf from the same pass. Bands total, PAR, red and far-red; the unit-spectrum emitters
   are scaled per band by the day's clear-sky beam and diffuse spectra (SPCTRAL2 at the noon
   sun) and the climate's beam and diffuse irradiance, so PAR [W m-2] and the red:far-red
   photon ratio under the crowns are those of daylight filtered by the leaves;
3. **soil and moss** — as in paper 000's loop, under the trees' shade;
4. the day's leaf insolation S_leaf [W m-2] x 86 400 s advances each leaf's autumn clock.

Per day the record adds, per tree: leaves on the tree, mean stage, absorbed PAR [W], the
ground's PAR and red:far-red under its crown; and the ground's PAR and R:FR in the open.

Sensors. The scenario's ``[[sensors]]`` (:mod:`mitsuba_veg.light.sensors`) are read by the same
daily pass, as sensor elements (they record the photons that cross them and cast no shadow),
under the trees of the day: daily-mean PPFD, red and far-red photon flux densities
[µmol m-2 s-1], R:FR [-] and shortwave [W m-2], direct (the sun's unscattered beam) and diffuse,
scaled like the ground (the day's climate beam and diffuse irradiance x the clear-sky band
shapes). The run writes them to ``sensors_daily.csv`` (tidy: time, sensor, band, component,
value, unit); each day's record gives their mean PPFD, DLI [mol m-2 d-1] and R:FR.
"""
from __future__ import annotations

import functools
import time
from types import MappingProxyType

import mitsuba as mi
import numpy as np

from ..climate import solar_declination
from ..errors import ParameterError
from ..foliage import leaf_spectra
from ..light.photon import band_range
from ..light import sensors as sensors_mod
from ..light.clear_sky import clear_sky_spectra
from ..light.validation import make_mesh
from ..units import umol_per_joule
from ..daily import BANDS, MossSimulation
from .canopy import Canopy
from .phenology import Phenology, PhenologyParams
from .trees import build_trees



@functools.lru_cache(maxsize=1024)
def band_shapes(latitude: float, day_of_year: int) -> dict:
    """Band-mean spectral irradiance per W m-2 of broadband irradiance [nm-1], beam and diffuse.

    Clear-sky beam and diffuse light (broadband: 300-4000 nm) at the day's noon sun (SPCTRAL2).
    Multiplied by a broadband daily mean [W m-2] they give the band-mean spectral irradiance
    [W m-2 nm-1]. The noon elevation is 90° − |latitude − declination| (declination of
    :func:`mitsuba_veg.climate.solar_declination`, FAO-56), at least 1°. Cached.

    Parameters
    ----------
    latitude : float
        Site latitude [degrees].
    day_of_year : int
        Day of the year (1-366).

    Returns
    -------
    mapping
        Read-only ``{"beam": {band: s}, "diffuse": {...}}`` for the bands of
        :data:`mitsuba_veg.daily.BANDS`, s [nm-1] (0 when the component is 0).
    """
    dec = float(np.degrees(solar_declination(day_of_year)))
    el = float(np.clip(90.0 - abs(latitude - dec), 1.0, 90.0))
    s = clear_sky_spectra(el, day_of_year=day_of_year)
    out = {}
    for comp, arr in (("beam", s.dni), ("diffuse", s.dhi)):
        total = float(np.trapezoid(arr, s.wavelengths))
        out[comp] = {}
        for b in BANDS:
            lo, hi = band_range(b)
            m = (s.wavelengths >= lo) & (s.wavelengths <= hi)
            out[comp][b] = float(arr[m].mean()) / total if total > 0 else 0.0
    # read-only views: the cache hands the same object to every caller
    return MappingProxyType({k: MappingProxyType(v) for k, v in out.items()})


class WorldSimulation(MossSimulation):
    """The moss loop of paper 000 with the scenario's trees in the light (module docstring)."""

    def __init__(self, scenario, out_dir, days=None, progress=True):
        super().__init__(scenario, out_dir, days=days, progress=progress)
        src = str(scenario.path)
        ph = dict(scenario.get("phenology", {}) or {})
        bins = int(ph.pop("stage_bins", 4))
        try:
            self.phen_params = PhenologyParams(**ph).validate(src)
        except ParameterError as e:
            if e.source:
                raise
            raise ParameterError(f"phenology.{e.field}", e.value, e.allowed, e.fix,
                                 src) from None
        self.stage_bins = bins
        self.timings["leaves"] = 0.0

    # ---- set-up -------------------------------------------------------------------------
    def _extra_shapes(self, base) -> dict:
        t0 = time.perf_counter()
        self.trees = build_trees(self.scn.get("trees"), base, self.scn.root,
                                 str(self.scn.path), progress=False)
        self.tree_seconds = time.perf_counter() - t0
        self.canopy = Canopy(self.trees, self.stage_bins)
        shapes = self.canopy.shapes()
        # the scenario's sensors: one mesh, recorded and passed through by the daily pass
        self.sensors = sensors_mod.from_scenario(self.scn, base)
        self.sensor_days: list[np.ndarray] = []
        if self.sensors is not None:
            v, f, self.sensor_owner = self.sensors.mesh()
            shapes[sensors_mod.SENSOR_SHAPE] = make_mesh(sensors_mod.SENSOR_SHAPE, v, f,
                                                         albedo=0.0)
        return shapes

    def _setup_extra(self) -> None:
        self.params = mi.traverse(self.scene)
        c = self.canopy
        # sunnier (higher, outer) leaves unfold a few days earlier
        shift = np.zeros(c.n_leaves)
        for t_i, wt in enumerate(self.trees):
            m = c.tree_of == t_i
            if m.any():
                p = c.centre[m]
                h = (p[:, 1] - p[:, 1].min()) / max(float(np.ptp(p[:, 1])), 1e-9)
                shift[m] = -4.0 * h
        self.phen = Phenology(c.n_leaves, self.phen_params, seed=self.seed, leaf_out_shift=shift)
        # ground triangles under each crown (centroid within the crown radius of the trunk)
        ground = self.scn.get("terrain.ground", "ground")
        self.ground_id = ground
        sl = self.index.shape_slice(ground)
        # the bark's many triangles block and scatter light but are not recorded (nothing
        # reads their flux): a smaller accumulator and read-back every day
        self.integrator.record = [s for s in self.index.shape_ids if s != "trees_bark"]
        cen = self.index.centroids[sl]
        self.ground_slice = sl
        self.crowns = []
        for wt in self.trees:
            r, m = wt.crown_radius(), wt.crown_centre()
            d = np.hypot(cen[:, 0] - m[0], cen[:, 2] - m[1])
            self.crowns.append(d <= max(0.75 * r, 1e-6))
        self.open_ground = ~np.any(self.crowns, axis=0) if self.crowns else \
            np.ones(len(cen), bool)
        self.leaf_light = {"S": np.zeros(c.n_leaves), "par_W_m2": np.zeros(c.n_leaves)}
        self.ground_bands = {}

    # ---- a day --------------------------------------------------------------------------
    def step(self) -> dict:
        """Simulate one day: the leaves (phenology, canopy tables), then light, soil and moss.

        Returns
        -------
        dict
            The day's record (:meth:`MossSimulation.step`) plus ``trees`` (per tree: leaves,
            leaves on the tree, mean stage [-], absorbed PAR [W] and the ground under its
            crown), ``ground_open`` (area [m2], PAR [W m-2], R:FR [-], moss cover [-],
            S [W m-2], Ts [K], rhs [-]) and, with sensors, ``sensors`` (mean PPFD
            [µmol m-2 s-1], DLI [mol m-2 d-1], R:FR [-]).
        """
        t0 = time.perf_counter()
        date = self._date(self.day)
        self.phen.start_of_day(date)
        self.canopy.update(self.params, self.phen.tau, self.phen.grown, self.phen.on_tree)
        # the day's leaf state for the photon pass: per-triangle tables, not geometry
        modes, self.integrator.bsdf_override = self.canopy.trace_tables()
        if self.sensors is not None:
            modes = {**modes, sensors_mod.SENSOR_SHAPE: "sensor"}
        self.integrator.modes = modes
        self.timings["leaves"] += time.perf_counter() - t0
        self._leaf_seconds = time.perf_counter() - t0
        return super().step()

    def light(self, day: int, counts: np.ndarray):
        """The day's light: one photon pass over terrain, buildings, wood and leaves.

        The parent's pass (:meth:`MossSimulation.light`), then per leaf and per ground
        triangle the band irradiances [W m-2] (unit-spectrum emitters scaled by the day's beam
        and diffuse irradiance times :func:`band_shapes`), the leaves' insolation S_leaf
        [W m-2] (advances the phenology by S_leaf × 86 400 s), and the sensors' readings.

        Parameters
        ----------
        day : int
            Simulated day (0-based).
        counts : numpy.ndarray
            Live moss per triangle (its cover sets the albedo).

        Returns
        -------
        S : numpy.ndarray
            Daily-mean insolation per triangle [W m-2].
        f_sun, f_sky : numpy.ndarray
            Sun and sky fractions per triangle [-] (per unit horizontal beam and diffuse).
        res : PhotonIrradianceResult
            The photon pass.
        """
        S, f_sun, f_sky, res = super().light(day, counts)
        t0 = time.perf_counter()
        date = self._date(day)
        wd = self.weather
        shapes = band_shapes(float(self.scn.get("site.latitude")), date.timetuple().tm_yday)
        B, D = float(wd.beam[day]), float(wd.diffuse[day])
        c = self.canopy
        # the blades as the pass saw them (grown from their centres during leaf-out)
        shown = c.displayed_area()
        area = np.maximum(shown, 1e-12)
        width = {b: band_range(b)[1] - band_range(b)[0] for b in BANDS}
        # unit emitters: 1 W m-2 nm-1 horizontal -> fraction g = E / width
        ie = (res.emitters.index("sun"), res.emitters.index("sky"))
        # (n_leaf_triangles, 2 emitters, n_b): both sides, both components
        lflux = c.leaf_triangle_flux(res)
        # (einsum: 4-5x faster than sum(axis=(1, 2)) over the strided component/side axes)
        tris = np.stack([np.einsum("fcsb->fb", lflux[e]) for e in ie], 1)
        lf = c.leaf_flux(tris)                              # (n_leaves, 2, n_b)
        gsl = self.ground_slice
        gflux = res.shape_flux(self.ground_id)
        front = np.stack([gflux[e].sum(axis=1)[:, 0] for e in ie])  # (2, n_g, n_b)
        garea = np.maximum(self.index.areas[gsl], 1e-30)
        leaf, ground, ground_sky = {}, {}, {}
        for k, b in enumerate(res.bands):
            sb, sd = B * shapes["beam"][b], D * shapes["diffuse"][b]
            # band-mean spectral irradiance [W m-2 nm-1] x (flux of a unit emitter [W] = band
            # width x geometry) / area -> band irradiance [W m-2]
            leaf[b] = (sb * lf[:, 0, k] + sd * lf[:, 1, k]) / area
            ground[b] = (sb * front[0, :, k] + sd * front[1, :, k]) / garea
            ground_sky[b] = sd * front[1, :, k] / garea
        # the leaves' insolation as the terrain's S (total band, flat unit spectrum)
        kt = res.bands.index("total")
        S_leaf = (B * lf[:, 0, kt] + D * lf[:, 1, kt]) / area / width["total"]
        self.leaf_light = {"S": S_leaf, "par_W_m2": leaf["par"], "red_W_m2": leaf["red"],
                           "far_red_W_m2": leaf["far_red"]}
        self.ground_bands = ground
        self.ground_sky_bands = ground_sky
        self.leaf_area_in_pass = shown
        if self.sensors is not None:
            self.sensor_days.append(self._sensor_values(res, shapes, B, D, width))
        self.phen.end_of_day(date, S_leaf * 86400.0 / 1e6)
        dt = time.perf_counter() - t0
        self.timings["leaves"] += dt
        self.timings["light"] -= dt   # counted as leaves, not as the photon pass
        self._leaf_light_seconds = dt
        self.last_result = res
        return S, f_sun, f_sky, res

    def _sensor_values(self, res, shapes, B, D, width) -> np.ndarray:
        """The day's sensor readings (n, quantities, components) (module docstring)."""
        flux = res.shape_flux(sensors_mod.SENSOR_SHAPE)[:, :, :, 0]  # (E, faces, comp, bands)
        ie_sun, ie_sky = res.emitters.index("sun"), res.emitters.index("sky")
        n = len(self.sensors)
        area = self.sensors.normalising_area()[:, None]

        def per_sensor(x):      # (faces, bands) flux of unit emitters [W] -> per sensor
            out = np.zeros((n, x.shape[-1]))
            np.add.at(out, self.sensor_owner, x)
            return out / area
        sun_direct = per_sensor(flux[ie_sun, :, 0])
        sun_scattered = per_sensor(flux[ie_sun, :, 1])
        sky = per_sensor(flux[ie_sky].sum(axis=1))
        watts = np.zeros((n, 2, len(sensors_mod.PASS_BANDS)))   # direct, diffuse [W m-2]
        for j, b in enumerate(sensors_mod.PASS_BANDS):
            if b == "shortwave":
                # as the terrain's S: broadband daily means x the unit-spectrum fractions
                k = res.bands.index("total")
                sb, sd = B / width["total"], D / width["total"]
            else:
                k = res.bands.index(b)
                sb, sd = B * shapes["beam"][b], D * shapes["diffuse"][b]
            watts[:, 0, j] = sb * sun_direct[:, k]
            watts[:, 1, j] = sb * sun_scattered[:, k] + sd * sky[:, k]
        return sensors_mod.SensorReadings.from_watts(self.sensors, watts).values

    def write_sensors(self) -> str | None:
        """``sensors_daily.csv`` of the run so far: daily means.

        Tidy table (time, sensor, band, component, value, unit): PPFD, red and far-red photon flux
        densities [µmol m-2 s-1], R:FR [-] and shortwave [W m-2].

        Returns
        -------
        str or None
            The path written; None without sensors (or before the first day).
        """
        if self.sensors is None or not self.sensor_days:
            return None
        times = [self._date(d).isoformat() for d in range(len(self.sensor_days))]
        return sensors_mod.write_tidy_csv(self.out / "sensors_daily.csv",
                                          np.stack(self.sensor_days), self.sensors.names, times)

    # ---- records ------------------------------------------------------------------------
    def _record(self, day, S, st, theta, events, secs) -> dict:
        rec = super()._record(day, S, st, theta, events, secs)
        if self.sensors is not None and self.sensor_days:
            v = self.sensor_days[-1]
            q, c = sensors_mod.QUANTITIES, sensors_mod.COMPONENTS
            ppfd = v[:, q.index("par"), c.index("total")]
            rfr = v[:, q.index("rfr"), c.index("total")]
            rec["sensors"] = {"count": int(len(ppfd)),
                              "mean_ppfd_umol_m2_s": float(np.mean(ppfd)),
                              "mean_dli_mol_m2_d": float(np.mean(ppfd)) * 0.0864,
                              "mean_red_far_red": float(np.nanmean(rfr))
                              if np.isfinite(rfr).any() else None}
        c, ph = self.canopy, self.phen
        on = ph.on_tree
        # PAR absorptance per leaf from its stage's spectra (bin centres, as the light scene)
        a_par = self._bin_par_absorptance()[c.leaf_bins(ph.tau)]
        absorbed = self.leaf_light["par_W_m2"] * self.leaf_area_in_pass * a_par
        gsl = self.ground_slice
        area = self.index.areas[gsl]
        g, gs = self.ground_bands, self.ground_sky_bands
        cover = (self.covered_area() / np.maximum(self.index.areas, 1e-30))[gsl]
        Ts, rhs, Sg = np.asarray(st.Ts)[gsl], np.asarray(st.rhs)[gsl], np.asarray(S)[gsl]

        def rfr(bands, mask, w):
            red = float((bands["red"][mask] * w).sum()) * umol_per_joule(*band_range("red"))
            fr = float((bands["far_red"][mask] * w).sum()) * umol_per_joule(*band_range("far_red"))
            return red / fr if fr > 0 else None

        def ground_stats(mask):
            if not mask.any():
                return {"area_m2": 0.0, "par_W_m2": None, "red_far_red": None,
                        "red_far_red_sky": None, "moss_cover": None, "S_W_m2": None,
                        "Ts_K": None, "rhs": None}
            w = area[mask]

            def mean(x):
                return float((x[mask] * w).sum() / w.sum())
            return {"area_m2": float(w.sum()),
                    "par_W_m2": mean(g["par"]),
                    "red_far_red": rfr(g, mask, w), "red_far_red_sky": rfr(gs, mask, w),
                    "moss_cover": mean(cover), "S_W_m2": mean(Sg), "Ts_K": mean(Ts),
                    "rhs": mean(rhs)}

        trees = {}
        for t_i, wt in enumerate(self.trees):
            m = c.tree_of == t_i
            mo = m & on
            trees[wt.name] = {
                "leaves": int(m.sum()), "leaves_on_tree": int(mo.sum()),
                "mean_stage": float(ph.stage[mo].mean()) if mo.any() else None,
                "absorbed_par_W": float(absorbed[m].sum()),
                "ground_under_crown": ground_stats(self.crowns[t_i])}
        rec["trees"] = trees
        rec["ground_open"] = ground_stats(self.open_ground)
        # leaves: the canopy update and the per-leaf light (taken out of the photon pass's time)
        ll = getattr(self, "_leaf_light_seconds", 0.0)
        rec["seconds"] = {**rec["seconds"], "light": rec["seconds"]["light"] - ll,
                          "leaves": getattr(self, "_leaf_seconds", 0.0) + ll}
        return rec

    def _bin_par_absorptance(self) -> np.ndarray:
        if getattr(self, "_a_par", None) is None:
            a = []
            for b in range(self.canopy.bins):
                R, T = leaf_spectra(stage=self.canopy.bin_stage(b)).band_mean(400, 700)
                a.append(1.0 - float(R) - float(T))
            self._a_par = np.array(a)
        return self._a_par

    # ---- checkpoints --------------------------------------------------------------------
    def _checkpoint_extra(self) -> dict:
        out = {**self.phen.to_numpy(), **self.canopy.state()}
        if self.sensors is not None:
            n = len(self.sensors)
            out["sensor_days"] = (np.stack(self.sensor_days) if self.sensor_days else
                                  np.zeros((0, n, len(sensors_mod.QUANTITIES),
                                            len(sensors_mod.COMPONENTS))))
        return out

    def _load_extra(self, d: dict) -> None:
        try:
            self.phen.load_numpy(d)
            self.canopy.load_state(d, self.params)
            if self.sensors is not None:
                self.sensor_days = list(np.asarray(d["sensor_days"]))
        except (KeyError, ValueError) as e:
            raise ParameterError("checkpoint", str(self.checkpoint_path), "a checkpoint of the "
                                 "same world (its leaves)", f"use --fresh ({e})") from None

    def summary(self, resumed=False) -> dict:
        """The run's summary: the moss loop's, with the world's trees and the sensors.

        Adds ``world`` (trees with model, position [m], leaves, crown radius and centre [m], leaf
        elements and triangles, leaf-mesh updates, stage bins, phenology, tree build time [s]), the
        leaves' time per day [s], and ``sensors`` (file, per-sensor mean DLI [mol m-2 d-1] and R:FR
        [-] of the first 100).

        Parameters
        ----------
        resumed : bool
            Whether the run was resumed from a checkpoint.

        Returns
        -------
        dict
            The summary.
        """
        s = super().summary(resumed)
        s["world"] = {"trees": [{"name": wt.name, "model": wt.model,
                                 "position": wt.position.tolist(),
                                 "leaves": int(len(wt.leaf_area)),
                                 "crown_radius_m": wt.crown_radius(),
                                 "crown_centre_xz_m": wt.crown_centre().tolist(), **wt.info}
                                for wt in self.trees],
                      "leaf_elements": int(self.canopy.n_leaves),
                      "leaf_triangles": int(len(self.canopy.tri)),
                      # vertex updates of the leaf mesh in this process (leaf-out growth,
                      # hidden blades collapsed); stage and fall changes need none
                      "leaf_mesh_updates": int(self.canopy.mesh_updates),
                      "stage_bins": self.stage_bins,
                      "phenology": self.phen_params.to_dict(),
                      "trees_built_s": getattr(self, "tree_seconds", 0.0)}
        s["timings_s"]["per_day"]["leaves"] = self.timings["leaves"] / max(len(self.history), 1)
        path = self.write_sensors()
        if path is not None:
            v = np.stack(self.sensor_days)
            q, c = sensors_mod.QUANTITIES, sensors_mod.COMPONENTS
            ppfd = v[:, :, q.index("par"), c.index("total")]
            rfr = v[:, :, q.index("rfr"), c.index("total")]
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
