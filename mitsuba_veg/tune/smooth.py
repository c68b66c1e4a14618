"""The relaxed (differentiable) daily soil + moss model of paper 000 on a scenario's triangles.

Same physics as the discrete run (``daily/moss.py``), with three changes (docs/tuning.md):

1. **Expected densities instead of individuals.** Every moss on one triangle, of one species,
   germinated on the same day, has the same G_moss trajectory in the discrete model (G depends
   only on the triangle's light, soil and the species). So the population is held exactly as
   *cohorts*: per (triangle, species, birth day) a density ``n`` (moss per spot, a spot = one
   cell of the moss-size grid, M = area / size² spots per triangle), its growth offset ``B``
   (G_moss = cum - B with cum the running sum of the triangle's daily growth D) and its gemma
   counter ``K``. Waiting propagules are held per (triangle, species, kind, day made) in a ring
   of L1 + 1 age slots, so their age L of eq 3.24 is exact.
2. **Thresholds relaxed with a temperature t** (:mod:`.relax`): death, germination, the gemma
   staircase and the spore condition use the logistic ``H_t``; ``t -> 0`` gives the discrete
   rules (``t = 0``: exact indicators).
3. **Space in expectation**: propagules spread with the precomputed landing kernels of eqs
   3.22-3.23 (:mod:`.dispersal`); one individual per spot becomes a Poisson occupancy of the free
   spots; "inside a clump" (>= 8 moss neighbours) becomes the binomial tail of the triangle's
   moss density; the global capacity scales the day's newcomers (gemmae first, then spores,
   as the discrete run settles them); the initial moss and the spores from outside arrive as
   expected (area-weighted) densities. ``closure="near-field"`` adds a
   pair approximation: per triangle the density of occupied neighbour-cell pairs, so that a
   gemma (which lands within ``gemma_distance`` of its parent) finds its cell free with
   probability 1 - q, q = P(a neighbour cell of an occupied cell is occupied), instead of the
   triangle's 1 - occupancy, and the clump rule uses q; a newcomer's pairs count the
   neighbours it shares with its parent (triplets, the overlap of the gemma kernel with its
   own shift, ``Kernel.near_overlap``), a gemma competes for its cell with the arrivals
   next to its parent rather than the triangle's mean, and the near field is the one a parent
   reaches from its fixed point, where its spores that stay close land too
   (``Kernel.sibling_share``, ``Kernel.far_share``), and seen from a moss, the parent of
   every propagule, whose neighbourhood holds its own offspring (the moss pairs; docs/tuning.md).

The light comes from up-front photon passes (the integrator's weights-mode paths replayed by
:meth:`~mitsuba_veg.integrators.PhotonIrradianceIntegrator.replay`: the day's sun path every
``light_every`` days, interpolated linearly in between, plus one sky pass), so it can be
differentiated w.r.t. albedo and emitter strength; moss does not change the albedo here (the
discrete run recomputes light daily with moss albedo). Soil: ``soil.py`` unchanged (eqs
3.2-3.16, bucket eq 3.6) on Dr.Jit arrays. Float64 throughout.

Usage::

    data = prepare("scenes/moss_garden/scenario.toml", days=60, species=["bryum_argenteum"])
    model = SmoothMossModel(data, temperature=0.05)
    out = model.run({"S1": 55.0})            # RunResult: out.cover (Float64 per triangle)
"""
from __future__ import annotations

import copy
import dataclasses
import datetime as _dt
import hashlib
import math
import time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import soil as soil_model
from ..errors import ParameterError
from ..integrators.photon_irradiance import PhotonIrradianceIntegrator, PhotonPathRecord
from ..integrators.photon_replay import albedo_array, irradiance
from ..daily import prepare_site
from ..light.sunpath import day_sun_path
from ..moss.species import PARAMETER_FIELDS
from ..scenario import Scenario, load_scenario
from . import relax
from .dispersal import dispersal_kernel, pooled_share, sibling_overlap
from .lifecycle import (GEMMA_STEP, SPORE_THRESHOLD, CohortLifeCycle, SpeciesState,
                        real_type, species_fitness)

__all__ = ["ModelData", "LightSetup", "prepare", "with_daily_light", "SmoothMossModel", "State", "SpeciesState",
           "RunResult", "CLIMATE_PARAMS", "GEMMA_STEP", "SPORE_THRESHOLD", "NEIGHBOUR_CELLS"]

#: spatial closures of :class:`SmoothMossModel` (docs/tuning.md)
CLOSURES = ("mean-field", "near-field")
NEIGHBOUR_CELLS = 8       #: neighbour cells of a moss on a surface (in-plane part of the 26)
#: climate parameters that can be tuned: name -> ClimateTable field (the value replaces the
#: table's; a per-day series is shifted by the difference)
CLIMATE_PARAMS = {"T": "temperature", "rh": "humidity"}
_ALIASES = {"climate.temperature": "T", "climate.humidity": "rh"}


# ------------------------------------------------------------------------------------------
# Static inputs from a scenario
# ------------------------------------------------------------------------------------------
@dataclass
class LightSetup:
    """Up-front photon passes: sun-path fractions on ``days`` (interpolated), one sky pass.

    ``f_sun[k]``, ``f_sky``: NumPy per-element fractions of the unobstructed horizontal beam /
    diffuse irradiance (front side) for the bare albedo; ``paths_sun[k]``, ``paths_sky``: the
    recorded paths for differentiable replays (None when not kept).
    """

    days: list
    f_sun: list
    f_sky: np.ndarray
    paths_sun: list | None = None
    paths_sky: PhotonPathRecord | None = None
    photons: int = 0
    seconds: float = 0.0
    #: per light day, the sky fractions (None: the one ``f_sky`` on every day); set by
    #: :func:`with_daily_light`
    f_sky_days: list | None = None

    def weights(self, day: int):
        """Which passes light ``day``, and how they are interpolated.

        Parameters
        ----------
        day : int
            The day (0-based).

        Returns
        -------
        k0, k1 : int
            The passes before and after ``day``.
        w : float
            Weight [-]: the day's fractions are (1 - w) f[k0] + w f[k1].
        """
        ds = self.days
        if day <= ds[0]:
            return 0, 0, 0.0
        for k in range(len(ds) - 1):
            if ds[k] <= day <= ds[k + 1]:
                return k, k + 1, (day - ds[k]) / float(ds[k + 1] - ds[k])
        return len(ds) - 1, len(ds) - 1, 0.0


def with_daily_light(data: "ModelData", f_sun, f_sky) -> "ModelData":
    """A copy of ``data`` whose light is given for every day (e.g. recorded in a discrete run).

    The discrete run makes a new photon pass every day, with its own photon noise and the
    day's moss albedo; driving the relaxed model with that very light (and the run's weather,
    ``prepare(..., overrides=["light.seed=<s>"])``) leaves only the life cycle and the spatial
    closure to compare (``experiments/tune_closure.py --discrete-light``). The light is then a
    fixed input: albedo and emitter strengths cannot be tuned through it (the emitter
    strengths still scale it).

    Parameters
    ----------
    data : ModelData
        The prepared scenario (its ``days`` and triangles).
    f_sun, f_sky : array_like
        (days, triangles) sun and sky fractions of the unit horizontal beam and diffuse
        irradiance [-], front side, as the daily pipeline's light stage computes them.

    Returns
    -------
    ModelData
        A shallow copy with a :class:`LightSetup` holding one pass per day.

    Raises
    ------
    ParameterError
        If the arrays are not (at least ``data.days``, ``data.n``).
    """
    f_sun = np.asarray(f_sun, float)
    f_sky = np.asarray(f_sky, float)
    for name, a in (("f_sun", f_sun), ("f_sky", f_sky)):
        if a.ndim != 2 or a.shape[0] < data.days or a.shape[1] != data.n:
            raise ParameterError(name, a.shape, f"(>= {data.days}, {data.n}) (days, triangles)")
    days = list(range(data.days))
    light = LightSetup(days, [f_sun[d] for d in days], f_sky[0], None, None, 0, 0.0,
                       [f_sky[d] for d in days])
    return dataclasses.replace(data, light=light)


@dataclass
class ModelData:
    """Everything of a scenario the relaxed model needs (no gradients here)."""

    scenario: object
    days: int
    n: int
    areas: np.ndarray
    M: np.ndarray
    living: np.ndarray
    geology: np.ndarray
    h: np.ndarray
    O0: np.ndarray
    base_albedo: np.ndarray
    weather: object
    climate: object
    species: list
    species_keys: list
    moss_cfg: dict
    cell: float
    index: object
    shape_slices: dict
    regions: dict
    kernels: dict
    light: LightSetup
    start: _dt.date
    scene: object = None
    timings: dict = field(default_factory=dict)

    @property
    def ground_mask(self) -> np.ndarray:
        """The triangles of the ground shape (``terrain.ground``).

        Returns
        -------
        numpy.ndarray
            (triangles,) bool.
        """
        m = np.zeros(self.n, bool)
        gid = self.scenario.get("terrain.ground", "ground")
        if gid in self.shape_slices:
            m[self.shape_slices[gid]] = True
        return m


#: dispersal kernels of this process by :func:`_kernel_key`: they depend on the scene's
#: geometry, where moss lives, the spot grid and the species' distances only (not on the light,
#: the weather or the days), so the preparations of one scenario share them
_KERNELS: dict = {}


def _kernel_key(idx, living, grid, k_g, k_s, samples, seed, reach) -> str:
    """A digest of everything :func:`dispersal_kernel` and :func:`sibling_overlap` read."""
    h = hashlib.sha1()
    for a in (idx.centroids, idx.normals, idx.areas, np.asarray(living, bool),
              np.asarray(grid.lo, float)):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr((idx.n_elements, float(grid.cell), float(k_g), float(k_s),
                   [int(x) for x in samples], int(seed), int(reach))).encode())
    return h.hexdigest()


def prepare(scenario, days: int | None = None, overrides=(), species=None,
            photons: int | None = None, light_every: int = 15, max_depth: int | None = None,
            kernel_samples=(64, 256), differentiable_light: bool = False, seed: int | None = None,
            progress: bool = False) -> ModelData:
    """Set up a scenario for the relaxed model: terrain, soil, climate, species (through
    :func:`~mitsuba_veg.daily.prepare_site`, so they are the discrete run's), the
    dispersal kernels and the up-front light.

    Parameters
    ----------
    scenario : Scenario or path-like
        The scenario, or its TOML file.
    days : int, optional
        Days to prepare [d] (default: the scenario's ``simulation.days``).
    overrides : sequence of str
        Scenario overrides ``"section.key=value"`` (when ``scenario`` is a path); the weather
        (rain days) follows ``light.seed`` as in the discrete run.
    species : list of str, optional
        Species keys replacing ``moss.species``.
    photons : int, optional
        Photons per light pass (default: the scenario's ``light.photons``).
    light_every : int
        Days between sun-path passes [d] (interpolated linearly in between).
    max_depth : int, optional
        Path depth of the passes (default: the scenario's ``light.max_depth``).
    kernel_samples : tuple of int
        Releases per living triangle for the (gemma, spore) dispersal kernels.
    differentiable_light : bool
        Keep the photon paths so that albedo and emitter strengths can be tuned (memory:
        ~ photons x max_depth x 5 bytes per pass).
    seed : int, optional
        Seed of the kernels and passes (default: the scenario's ``light.seed``).
    progress : bool
        Show a progress bar over the passes.

    Returns
    -------
    ModelData
        Everything the relaxed model needs.
    """

    t0 = time.perf_counter()
    scn = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    if species is not None:
        data = copy.deepcopy(scn.data)
        data.setdefault("moss", {})["species"] = list(species)
        scn = Scenario(scn.path, data)
    site = prepare_site(scn, days=days)
    sim = site.config
    idx = site.index
    n_days = sim.days
    seed = sim.seed if seed is None else int(seed)

    def full(a, fill):
        """A terrain array over every element of the scene (its other shapes: ``fill``)."""
        a = np.asarray(a)
        out = np.full((idx.n_elements,) + a.shape[1:], fill, dtype=a.dtype)
        out[:site.n_terrain] = a
        return out
    living = full(site.living, False)
    timings = {"setup": time.perf_counter() - t0}

    t1 = time.perf_counter()
    cfg = sim.moss_cfg
    k_g, k_s = float(cfg["gemma_distance"]), float(cfg["spore_distance"])
    # the gemmae's reach [cells]: a gemma lands at most k from its parent, plus the cell it
    # starts in
    reach = int(math.ceil(k_g / sim.grid_cell())) + 1
    key = _kernel_key(idx, living, site.grid, k_g, k_s, kernel_samples, seed, reach)
    kernels = _KERNELS.get(key)
    if kernels is None:
        kernels = {
            "gemma": dispersal_kernel(site.scene, idx, living, "gemma", k_g,
                                      int(kernel_samples[0]), seed, site.grid,
                                      near_radius=reach),
            "spore": dispersal_kernel(site.scene, idx, living, "spore", k_s,
                                      int(kernel_samples[1]), seed, site.grid,
                                      near_radius=reach),
        }
        for kind, dist in (("gemma", k_g), ("spore", k_s)):
            same, both = sibling_overlap(site.scene, idx, living, site.grid, kind, dist, k_g,
                                         2 * int(kernel_samples[0]), seed)
            kernels[kind].sibling_share = pooled_share(kernels["gemma"], same, both)
        if len(_KERNELS) >= 8:
            _KERNELS.pop(next(iter(_KERNELS)))
        _KERNELS[key] = kernels
    kernels = {k: copy.copy(v) for k, v in kernels.items()}
    timings["kernels"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    photons = int(photons if photons is not None else sim.light_cfg["photons"])
    max_depth = int(max_depth if max_depth is not None else sim.light_cfg["max_depth"])
    if not bool(sim.light_cfg["indirect"]):
        max_depth = 1
    light_every = max(int(light_every), 1)
    ldays = list(range(0, n_days, light_every))
    if ldays[-1] != n_days - 1:
        ldays.append(n_days - 1)
    alb = full(site.base_albedo[:, 0].astype(float), 0.0)
    tracer = PhotonIrradianceIntegrator()
    a_dr = dr.float64_array_t(mi.Float)(alb)
    lat, lon = float(scn.get("site.latitude")), float(scn.get("site.longitude"))
    f_sun, p_sun = [], []
    it = ldays
    if progress:
        from tqdm.auto import tqdm
        it = tqdm(ldays, desc="light passes", unit="pass")
    for k, d in enumerate(it):
        dirs, w, _ = day_sun_path(lat, lon, sim.date(d))
        if len(w) == 0:
            f_sun.append(np.zeros(idx.n_elements))
            p_sun.append(None)
            continue
        site.sun.set_day(dirs, w)
        p = tracer.trace_paths(site.scene, "sun", photons, seed * 7919 + 11 * k + 1, max_depth,
                               index=idx)
        f_sun.append(np.asarray(irradiance(p, a_dr)) / (p.band[1] - p.band[0]))
        p_sun.append(p if differentiable_light else None)
    p_sky = tracer.trace_paths(site.scene, "sky", photons, seed * 7919 + 3, max_depth, index=idx)
    f_sky = np.asarray(irradiance(p_sky, a_dr)) / (p_sky.band[1] - p_sky.band[0])
    # band irradiance / band width = fraction of the unit (1 W m-2 nm-1) horizontal irradiance
    light = LightSetup(ldays, f_sun, f_sky, p_sun if differentiable_light else None,
                       p_sky if differentiable_light else None, photons,
                       time.perf_counter() - t2)
    timings["light"] = light.seconds

    slices = {sid: idx.shape_slice(sid) for sid in idx.shape_ids}
    return ModelData(scenario=scn, days=n_days, n=idx.n_elements,
                     areas=np.asarray(idx.areas, float),
                     M=full(site.M, 1.0).astype(float), living=living,
                     geology=full(site.geology, 2), h=full(site.h, 1.0).astype(float),
                     O0=full(site.O0, 0.0).astype(float), base_albedo=alb, weather=sim.weather,
                     climate=sim.climate, species=list(sim.species),
                     species_keys=list(cfg["species"]), moss_cfg=dict(cfg), cell=float(cfg["size"]),
                     index=idx, shape_slices=slices,
                     regions={k: full(m, False) for k, m in site.regions.items()},
                     kernels=kernels, light=light, start=sim.start, scene=site.scene,
                     timings=timings)


# ------------------------------------------------------------------------------------------
# State
# ------------------------------------------------------------------------------------------
@dataclass
class State:
    """The relaxed moss model's state after a number of days.

    Attributes
    ----------
    day : int
        Days done (the next day to simulate).
    O : drjit array
        (n_el) bucket water [mm].
    species : list
        ``SpeciesState`` per species.
    per_species : int
        Arrays per species (``SpeciesState.FIELDS``).
    pair : drjit array or None
        (n_el) near-field closure: neighbour-pair density.
    pair_moss : drjit array or None
        (n_el) the pairs whose first cell holds moss.
    """

    day: int          # days done (the next day to simulate)
    O: object         # (n_el) bucket water [mm]
    species: list     # SpeciesState per species
    per_species: int = 6      # arrays per species (SpeciesState.FIELDS)
    pair: object = None       # (n_el) near-field closure: neighbour-pair density (or None)
    pair_moss: object = None  # (n_el) ... the pairs whose first cell holds moss (or None)

    def arrays(self) -> list:
        """All state arrays: O, each species' (:meth:`SpeciesState.arrays`), the pairs and the
        moss pairs if any.

        Returns
        -------
        list
            Dr.Jit float arrays.
        """
        out = [self.O]
        for s in self.species:
            out += s.arrays()
        if self.pair is not None:
            out.append(self.pair)
        if self.pair_moss is not None:
            out.append(self.pair_moss)
        return out

    def with_arrays(self, arrays, day=None) -> "State":
        """A state of this layout from arrays (inverse of :meth:`arrays`).

        Parameters
        ----------
        arrays : list
            As :meth:`arrays` returns them.
        day : int, optional
            Days done (default: this state's).

        Returns
        -------
        State
            The new state.
        """
        k = self.per_species
        n_sp = len(self.species)
        sp = [SpeciesState.from_arrays(arrays[1 + k * i:1 + k * (i + 1)])
              for i in range(n_sp)]
        rest = list(arrays[1 + k * n_sp:]) + [None, None]
        return State(self.day if day is None else day, arrays[0], sp, k, rest[0], rest[1])

    def detached(self) -> "State":
        """A copy without gradient tracking (opaque arrays).

        Returns
        -------
        State
            The detached state.
        """
        arr = [dr.detach(a) for a in self.arrays()]
        dr.make_opaque(arr)  # literals (e.g. zero slots) must not enter kernels as constants
        return self.with_arrays(arr)

    def nbytes(self) -> int:
        """Memory held by the state's arrays.

        Returns
        -------
        int
            Bytes.
        """
        return sum(dr.width(a) * (8 if dr.type_v(a) == dr.VarType.Float64 else 4)
                   for a in self.arrays())


@dataclass
class RunResult:
    """Output of :meth:`SmoothMossModel.run`."""

    state: State
    cover: object            # Float64 (n_el): covered fraction of each triangle (AD-tracked)
    moss_density: object     # Float64 (n_el): moss per spot, all species
    history: list = field(default_factory=list)
    maps: dict = field(default_factory=dict)
    seconds: float = 0.0

    def covered_area(self, data: ModelData, mask=None) -> float:
        """Covered area of the run's end.

        Parameters
        ----------
        data : ModelData
            The prepared scenario (triangle areas).
        mask : numpy.ndarray, optional
            (triangles,) bool: sum over these only.

        Returns
        -------
        float
            Covered area [m2].
        """
        c = np.asarray(self.cover) * data.areas
        return float(c[mask].sum() if mask is not None else c.sum())


@dataclass
class Resolved:
    """Parameters resolved for one evaluation (numbers or Float64 scalars with gradients)."""

    species: list           # dict per species: field -> value
    dT: object
    drh: object
    albedo: dict            # shape id -> value
    strength: dict          # "sun"/"sky" -> value


# ------------------------------------------------------------------------------------------
# The model
# ------------------------------------------------------------------------------------------
def _filled(v, fallback: float) -> np.ndarray:
    """Per-element estimate ``v`` with its NaNs replaced by the median of the finite values
    (``fallback`` if none is finite)."""
    v = np.asarray(v, float)
    ok = np.isfinite(v)
    return np.where(ok, v, np.median(v[ok]) if ok.any() else fallback)


class SmoothMossModel:
    """Relaxed daily soil + moss model over ``data`` (see module docstring).

    temperature: t of the relaxation (G units; 0 = exact thresholds, no gradients);
    cohort_days: birth days merged into one moss cohort (1 = exact; larger saves memory);
    dispersal / capacity / external: switch the spatial parts off for tests; precision:
    "float32" (default, about twice as fast) or "float64".

    closure: ``"mean-field"`` (offspring spread over the triangles they reach, no correlations)
    or ``"near-field"`` (pair approximation for the gemmae, see :meth:`step`); near_cells: z of
    the pair approximation, the number of cells around a parent's cell that its gemmae land in
    [cells] (None: per triangle from the gemma kernel, ``Kernel.near_cells``: 1 / sum p_k^2 of
    the landing cells, ~22 on the garden's ground); near_scale: factor on that z [-];
    near_overlap: theta of the triplet term, the share of a newcomer's other neighbour cells
    that are also its parent's neighbours [-] (None: per triangle from the gemma kernel,
    ``Kernel.near_overlap``, 0.19-0.28 on the garden; 0: the plain pair approximation);
    local_arrivals: the near field's gemmae compete for a free cell with the arrivals next to
    their parents (arrival-weighted over their origins), not with the triangle's mean arrivals
    (False: the mean, as before); siblings: the near field seen from a parent's fixed point,
    z = 1 / ``Kernel.sibling_share`` of the gemma kernel (the cells a parent at one point
    reaches; where not estimable, ``near_cells``) and spores that land beside their parent
    finding the cells its gemmae reach occupied (``far_share`` and ``sibling_share`` of the
    spore kernel; False: z pooled over the triangle, every spore sees the mean occupancy);
    moss_pairs: the propagules leave a moss, so they see the occupancy around a moss, q_m =
    w_m / c from the pairs whose first cell holds moss (tracked: germination carries a waiting
    propagule's pairs over, each newcomer adds its moss neighbours), not the mean over all
    occupants q = w / rho (False: the mean).
    Raises ParameterError for an unknown closure, z outside [1, 26] or theta outside [0, 1].
    """

    def __init__(self, data: ModelData, temperature: float = 0.05, cohort_days: int = 1,
                 dispersal: bool = True, capacity: bool = True, external: bool = True,
                 days: int | None = None, precision: str = "float32",
                 closure: str = "mean-field", near_cells: float | None = None,
                 near_scale: float = 1.0, near_overlap: float | None = None,
                 local_arrivals: bool = True, siblings: bool = True, moss_pairs: bool = True):
        if closure not in CLOSURES:
            raise ParameterError("closure", closure, "one of " + ", ".join(CLOSURES))
        self.closure = closure
        self.data = data
        self.days = int(days if days is not None else data.days)
        if self.days > data.days:
            raise ParameterError("days", self.days, f"<= {data.days} (the prepared days)",
                                 "prepare() the scenario for more days")
        self.cohort_days = max(int(cohort_days), 1)
        self.dispersal = bool(dispersal)
        self.capacity_on = bool(capacity)
        self.external = bool(external)
        n = data.n
        self.n = n
        self.T = real_type(precision)
        self.precision = precision
        self.life = CohortLifeCycle(n, self.days, temperature, cohort_days, precision)
        self.t = self.life.t_value
        self.C, self.Rg, self.Rs = self.life.C, self.life.Rg, self.life.Rs
        T = self.T
        self.M = T(data.M)
        self.h = data.h
        self._h = T(data.h)
        # codes checked once, parameters cached on the device (soil.ElementGeology)
        self.geology = soil_model.ElementGeology(data.geology)
        self.living = T(data.living.astype(float))
        self.areas = T(data.areas)
        self.cell2 = data.cell ** 2
        liv_area = np.where(data.living, data.areas, 0.0)
        self.area_frac = liv_area / max(liv_area.sum(), 1e-30)
        self.n_sp = len(data.species)
        cfg = data.moss_cfg
        self.capacity = float(cfg["capacity"])
        self.near_scale = float(near_scale)
        self.siblings = bool(siblings)
        self.moss_pairs = bool(moss_pairs) and closure == "near-field"
        self.near_cells = self._near_cells(near_cells)
        self.near_overlap = self._near_overlap(near_overlap)
        self.local_arrivals = bool(local_arrivals)
        self.spore_near = self._spore_near()
        self.interval = int(cfg["external_spore_interval"])
        self.clump = int(cfg["clump_neighbours"])
        self.initial = float(min(cfg["initial"], cfg["capacity"]))
        self.initial_growth = float(cfg["initial_growth"])
        w = data.weather
        self._weather = {k: np.asarray(getattr(w, k), float) for k in
                         ("T", "rh", "P", "U", "A", "beam", "diffuse")}

    def _near_cells(self, z):
        """z of the near-field closure per element: a number, or (None) the gemma kernel's
        effective number of landing cells around the parent's cell, with ``siblings`` those
        a parent reaches from its fixed point, 1 / ``sibling_share`` where estimable (NaN:
        the median)."""
        k = self.data.kernels["gemma"]
        est = k.near_cells
        if self.siblings and k.sibling_share is not None:
            with np.errstate(divide="ignore"):
                loc = 1.0 / np.asarray(k.sibling_share, float)
            base = np.asarray(est, float) if est is not None else np.full(len(loc), np.nan)
            est = np.where(np.isfinite(loc), loc, base)
        return self._near_field_value("near_cells", z, 1.0, 26.0, "cells around a cell", 8.0,
                                      self.near_scale, est)

    def _spore_near(self):
        """(far share, sibling share) of the spore kernel per element for the near field of
        the spores, or None (no closure, ``siblings=False``, or a kernel without them)."""
        if self.closure != "near-field" or not self.siblings:
            return None
        k = self.data.kernels["spore"]
        if k.far_share is None or k.sibling_share is None:
            return None
        return (self.T(np.clip(_filled(k.far_share, 1.0), 0.0, 1.0)),
                self.T(np.clip(_filled(k.sibling_share, 0.0), 0.0, 1.0)))

    def _near_overlap(self, theta):
        """theta of the near-field closure's triplet term per element: a number, or (None) the
        gemma kernel's estimate (NaN: the median)."""
        return self._near_field_value("near_overlap", theta, 0.0, 1.0, "a share", 0.0, 1.0,
                                      self.data.kernels["gemma"].near_overlap)

    def _near_field_value(self, name, value, lo, hi, what, fallback, scale, estimate):
        """A near-field closure quantity: ``value`` if given (checked against [lo, hi]), else
        the per-element ``estimate`` from the kernels (NaN: its median; none finite:
        ``fallback``) times ``scale``, clipped to [lo, hi]. None without the closure."""
        if self.closure != "near-field":
            return None
        if value is not None:
            value = float(value)
            if not (lo <= value <= hi):
                raise ParameterError(name, value, f"{lo:g} <= {name} <= {hi:g} ({what})")
            return dr.opaque(self.T, value)
        if estimate is None:
            raise ParameterError(name, None, "a number, or a gemma kernel estimated with the "
                                 "spot grid (prepare() does that)")
        return self.T(np.clip(_filled(estimate, fallback) * scale, lo, hi))

    # ---- parameters -------------------------------------------------------------------------
    def parameter_names(self) -> list[str]:
        """Names accepted in ``params`` (see :meth:`resolve`).

        Returns
        -------
        list of str
            Species parameters (``<species>.<field>``, and ``<field>`` with one species),
            climate (``T``, ``rh``), ``albedo.<shape>``, ``strength.sun``/``strength.sky``.
        """
        names = []
        for k in self.data.species_keys:
            names += [f"{k}.{f}" for f in PARAMETER_FIELDS]
        if self.n_sp == 1:
            names += list(PARAMETER_FIELDS)
        names += list(CLIMATE_PARAMS) + [f"albedo.{s}" for s in self.data.shape_slices]
        names += ["strength.sun", "strength.sky"]
        return names

    def _canonical(self, name: str):
        name = _ALIASES.get(name, name)
        if name in CLIMATE_PARAMS:
            return ("climate", name)
        if name.startswith("albedo."):
            sid = name.split(".", 1)[1]
            if sid not in self.data.shape_slices:
                raise ParameterError(name, None, f"albedo.<shape> with a shape among "
                                     f"{list(self.data.shape_slices)}")
            return ("albedo", sid)
        if name in ("strength.sun", "strength.sky"):
            return ("strength", name.split(".")[1])
        if "." in name:
            key, f = name.split(".", 1)
            if key not in self.data.species_keys or f not in PARAMETER_FIELDS:
                raise ParameterError("params", name, "one of " + ", ".join(self.parameter_names()))
            return ("species", self.data.species_keys.index(key), f)
        if name in PARAMETER_FIELDS:
            if self.n_sp != 1:
                raise ParameterError("params", name, f"'<species>.{name}' with a species among "
                                     f"{self.data.species_keys}",
                                     "name the species (the model has several)")
            return ("species", 0, name)
        raise ParameterError("params", name, "one of " + ", ".join(self.parameter_names()))

    def default_value(self, name: str) -> float:
        """The scenario's value of a parameter.

        Parameters
        ----------
        name : str
            A name of :meth:`parameter_names`.

        Returns
        -------
        float
            Its value in the scenario (units of the parameter).
        """
        c = self._canonical(name)
        if c[0] == "climate":
            return float(getattr(self.data.climate, CLIMATE_PARAMS[c[1]]))
        if c[0] == "albedo":
            return float(np.mean(self.data.base_albedo[self.data.shape_slices[c[1]]]))
        if c[0] == "strength":
            return 1.0
        return float(getattr(self.data.species[c[1]], c[2]))

    def resolve(self, params: dict | None) -> Resolved:
        """Species, climate, albedo and emitter values for one evaluation.

        Parameters
        ----------
        params : dict or None
            ``{name: value}`` overriding the scenario's values (numbers, or width-1 Dr.Jit
            floats with gradients).

        Returns
        -------
        Resolved
            The values (numbers become opaque Dr.Jit scalars: no recompilation).

        Raises
        ------
        ParameterError
            For an unknown name.
        """
        sp = [{f: float(getattr(s, f)) for f in PARAMETER_FIELDS} for s in self.data.species]
        dT, drh, albedo, strength = 0.0, 0.0, {}, {}
        for name, v in (params or {}).items():
            c = self._canonical(name)
            if not dr.is_array_v(v):  # opaque: a new value must not recompile the kernels
                v = dr.opaque(self.T, float(v))
            if c[0] == "species":
                sp[c[1]][c[2]] = v
            elif c[0] == "climate":
                ref = float(getattr(self.data.climate, CLIMATE_PARAMS[c[1]]))
                if c[1] == "T":
                    dT = v - ref
                else:
                    drh = v - ref
            elif c[0] == "albedo":
                albedo[c[1]] = v
            else:
                strength[c[1]] = v
        return Resolved(sp, dT, drh, albedo, strength)

    # ---- light ------------------------------------------------------------------------------
    def light(self, P: Resolved):
        """The sun and sky fractions, differentiable w.r.t. albedo (replays of the recorded
        paths) and emitter strengths.

        Parameters
        ----------
        P : Resolved
            The evaluation's values.

        Returns
        -------
        sun : list
            f_sun per light day [-] (Dr.Jit float arrays over the triangles).
        sky : Dr.Jit float array or list
            f_sky [-] (a list per light day with :func:`with_daily_light`).

        Raises
        ------
        ParameterError
            For albedo parameters without recorded paths.
        """
        T = self.T
        L = self.data.light
        if P.albedo:
            if L.paths_sky is None or L.paths_sun is None or L.f_sky_days is not None:
                raise ParameterError("params", list(P.albedo),
                                     "albedo parameters need prepare(..., "
                                     "differentiable_light=True)")
            a = albedo_array(self.n, self.data.base_albedo, P.albedo, self.data.shape_slices,
                             self.T)
            sun = []
            for p in L.paths_sun:
                sun.append(T(np.zeros(self.n)) if p is None else
                           irradiance(p, a) / (p.band[1] - p.band[0]))
            sky = irradiance(L.paths_sky, a) / (L.paths_sky.band[1] - L.paths_sky.band[0])
        else:
            sun = [T(f) for f in L.f_sun]
            sky = T(L.f_sky) if L.f_sky_days is None else [T(f) for f in L.f_sky_days]
        s_sun, s_sky = P.strength.get("sun", 1.0), P.strength.get("sky", 1.0)
        if not (isinstance(s_sun, float) and s_sun == 1.0):
            sun = [f * s_sun for f in sun]
        if not (isinstance(s_sky, float) and s_sky == 1.0):
            sky = [f * s_sky for f in sky] if isinstance(sky, list) else sky * s_sky
        return sun, sky

    def insolation(self, day: int, light):
        """S per element on ``day`` (daily mean).

        Parameters
        ----------
        day : int
            The day (0-based).
        light : tuple
            (sun, sky) of :meth:`light`.

        Returns
        -------
        Dr.Jit float array
            S = B f_sun + D f_sky per triangle [W m-2].
        """
        T = self.T
        sun, sky = light
        k0, k1, w = self.data.light.weights(day)
        fs = sun[k0] if k0 == k1 else sun[k0] * dr.opaque(T, 1.0 - w) + sun[k1] * dr.opaque(T, w)
        if isinstance(sky, list):     # a sky pass per light day (with_daily_light)
            sky = sky[k0] if k0 == k1 else \
                sky[k0] * dr.opaque(T, 1.0 - w) + sky[k1] * dr.opaque(T, w)
        wd = self._weather
        return soil_model.insolation(dr.opaque(T, wd["beam"][day]),
                                     dr.opaque(T, wd["diffuse"][day]), fs, sky)

    # ---- state ------------------------------------------------------------------------------
    def initial_state(self) -> State:
        """Day 0: saturated buckets, the initial moss as expected densities (area-weighted random
        points, species drawn uniformly: ``initial / n_species`` each, G_moss = initial_growth).

        Returns
        -------
        State
            The state of day 0.
        """
        T = self.T
        dens = self.initial / self.n_sp * self.area_frac / self.data.M
        sp = [self.life.seed_moss(self.life.empty(), dens, self.initial_growth)
              for _ in range(self.n_sp)]
        pair = pair_moss = None
        if self.closure == "near-field":
            # initial moss at independent random points: neighbour pairs of the mean field
            pair = T(dens * dens * self.n_sp * self.n_sp)
            if self.moss_pairs:
                pair_moss = T(pair)          # every occupant is a moss
        st = State(0, T(self.data.O0), sp, self.life.arrays_per_species, pair, pair_moss)
        dr.make_opaque(st.arrays())
        return st

    # ---- one day ----------------------------------------------------------------------------
    def environment(self, st: State, P: Resolved, light):
        """The day's light and soil (eqs 3.2-3.16, bucket 3.6) with the moss density at the start
        of the day.

        Parameters
        ----------
        st : State
            The state at the start of the day.
        P : Resolved
            The evaluation's values.
        light : tuple
            (sun, sky) of :meth:`light`.

        Returns
        -------
        S : Dr.Jit float array
            Insolation [W m-2].
        Ts : Dr.Jit float array
            Surface temperature [K].
        rhs : Dr.Jit float array
            Surface relative humidity [-].
        theta : Dr.Jit float array
            Soil water content at the start of the day [-].
        O : Dr.Jit float array
            Bucket water of the next day [mm].
        """
        T = self.T
        d = st.day
        wd = self._weather
        op = lambda v: dr.opaque(T, float(v))  # noqa: E731  day values: no recompilation
        S = self.insolation(d, light)
        c_tot = dr.zeros(T, self.n)
        for s in st.species:
            c_tot += self.life.moss(s)
        C_H = soil_model.transfer_coefficient(dr.minimum(c_tot, 1.0))
        Td = op(wd["T"][d]) + P.dT
        rhd = op(wd["rh"][d]) + P.drh
        # the discrete run's soil chain (soil.soil_day), on this model's arrays
        sd = soil_model.soil_day(st.O, S, Td, rhd, op(wd["U"][d]), op(wd["A"][d]),
                                 op(wd["P"][d]), self._h, self.geology, C_H)
        return S, sd.surface.Ts, sd.surface.rhs, sd.theta, sd.O

    def step(self, st: State, P: Resolved, light, record: dict | None = None) -> State:
        """Advance one day in the discrete day's order: light, soil, then the moss (germination,
        growth and death, gemmae, spores, landing and settling, a spore from outside).

        Near-field closure (``st.pair`` = w, per triangle the probability that a cell and a
        given one of its z neighbour cells are both occupied by an individual, moss or waiting
        propagule; occupancy rho per spot): losses of the day thin the occupants independently
        (``w *= s²``, s = surviving share); q = w / rho; a gemma settles in a free cell with
        probability 1 - q (its parent is next to it), a spore with 1 - rho; each newcomer adds
        its pairs, 2/z (1 + (z - 1) q_g) per gemma (the parent plus the other neighbours) and
        2 q10 per spore, q10 = (rho - w) / (1 - rho); a share theta (``near_overlap``) of a
        gemma's other neighbours are its parent's neighbours too, occupied with q q10 / rho
        (triplets by Kirkwood superposition), the rest with q10: q_g = theta q q10 / rho +
        (1 - theta) q10; a gemma competes for its free cell with g (1 + (z - 1) q_g m) / z
        arrivals a day (g: gemmae per moss, m: the moss share of the occupants, at its origin,
        arrival-weighted), not with the triangle's mean (``local_arrivals``); w is kept in
        [rho², rho]. With ``siblings`` z is the number of cells a parent reaches from its
        point, and a spore arrival finds its cell occupied with min(1 - f, q z P) + f rho (f:
        the spore kernel's far share, P: the chance that it lands in the cell of a gemma from
        the same point); those that settle near their parent add pairs as gemmae. With
        ``moss_pairs`` (``st.pair_moss`` = w_m, the pairs whose first cell holds moss, c the
        moss per spot) the propagules see the occupancy around a moss, q_m = w_m / c, in place
        of q (in the settling of gemmae and near spores, and in the clump surface, P(nb moss |
        moss) = q_m c / rho): old moss survives with s_m, the day's germinated (density g)
        bring the pairs of the waiting, w_m = (w_m s_m + g (w - w_m) / u) s, u = rho - c at
        the start of the day; each newcomer adds its moss neighbours, 1 / z (1 + (z - 1) q_g
        m) per gemma (its parent and the moss share m = c / rho of the others) and q10 m per
        spore; w_m is kept in [w - u, min(c, w)]. The start is the random placement, w = rho²
        (w_m = w: the initial occupants are moss). (Propagules that expire on a day are removed from
        the ring by ``push`` after this update, so their pairs are not thinned; only the clip
        to [rho², rho] on the next day bounds them.)

        Parameters
        ----------
        st : State
            The state at the start of the day.
        P : Resolved
            The evaluation's values.
        light : tuple
            (sun, sky) of :meth:`light`.
        record : dict, optional
            Filled with the day's S, Ts, rhs, theta, moss density and events.

        Returns
        -------
        State
            The state at the end of the day.
        """
        T = self.T
        d, n, M, life = st.day, self.n, self.M, self.life
        near = st.pair is not None
        if near:
            occ0, c0 = dr.zeros(T, n), dr.zeros(T, n)
            for s in st.species:
                c0 += life.moss(s)
                occ0 += life.moss(s) + life.waiting(s)
        S, Ts, rhs, theta, O = self.environment(st, P, light)
        # ---- steps 1-2 per species
        new_sp, Gms, Dgs, germinated = [], [], [], []
        for i, s in enumerate(st.species):
            G = species_fitness(P.species[i], Ts, rhs, S)
            ns, Gm, Dg, ngerm = life.live(s, G, P.species[i], d)
            new_sp.append(ns)
            Gms.append(Gm)
            Dgs.append(Dg)
            germinated.append(ngerm)
        # ---- steps 3-4: gemmae (only from the surface of clumps) and spores
        c_after = dr.zeros(T, n)
        occ = dr.zeros(T, n)
        for s in new_sp:
            m = life.moss(s)
            c_after += m
            occ += m + life.waiting(s)
        if near:
            # the pairs of the individuals still there (losses: independent thinning s, pairs s²)
            surv = dr.clip(occ / dr.maximum(occ0, 1e-12), 0.0, 1.0)
            pair = dr.clip(st.pair * surv * surv, occ * occ, occ)
            q = dr.select(occ > 1e-9, pair / dr.maximum(occ, 1e-12), occ)   # P(nb occ | occ)
            pair_m, q_par = None, q
            if st.pair_moss is not None:
                # the moss pairs: old moss survives with s_m, the germinated bring the pairs of
                # the waiting (P(nb occ | waiting) at the start of the day), the neighbour
                # survives with s
                germ = dr.zeros(T, n)
                for g in germinated:
                    germ += g
                q_u0 = dr.clip((st.pair - st.pair_moss) / dr.maximum(occ0 - c0, 1e-12), 0.0, 1.0)
                s_m = dr.clip((c_after - germ) / dr.maximum(c0, 1e-12), 0.0, 1.0)
                pair_m = (st.pair_moss * s_m + germ * q_u0) * surv
                pair_m = dr.clip(pair_m, dr.maximum(pair - (occ - c_after), 0.0),
                                 dr.minimum(c_after, pair))
                q_par = dr.select(c_after > 1e-9, pair_m / dr.maximum(c_after, 1e-12), q)
            ms = dr.clip(c_after / dr.maximum(occ, 1e-12), 0.0, 1.0)   # moss share m
            q_moss = q_par * ms                     # P(a neighbour holds moss | the cell does)
            # a newcomer gemma's other neighbours: occupied with q10 = P(occ | nb free), and
            # the share theta it shares with its parent with q q10 / rho (triplets, Kirkwood)
            q10 = dr.clip((occ - pair) / dr.maximum(1.0 - occ, 1e-12), 0.0, 1.0)
            q_sh = dr.clip(q * q10 / dr.maximum(occ, 1e-12), 0.0, 1.0)
            q_g = self.near_overlap * q_sh + (1.0 - self.near_overlap) * q10
            surface = 1.0 - relax.binomial_tail(dr.clip(q_moss, 0.0, 1.0), NEIGHBOUR_CELLS,
                                                self.clump)
            occ_live = occ
        else:
            surface = 1.0 - relax.binomial_tail(c_after, NEIGHBOUR_CELLS, self.clump)
        made_g, made_s, arr_g, arr_s, settled = [], [], [], [], []
        for i, s in enumerate(new_sp):
            gem, spo = life.produce(s, Gms[i], Dgs[i], surface)
            made_g.append(gem * M)
            made_s.append(spo * M)
        # ---- landing (expected: the kernels of eqs 3.22-3.23) and one individual per spot
        sn_share = None
        s_near = dr.zeros(T, n)             # spores settled beside their parent
        if self.dispersal:
            arr_g = [self.data.kernels["gemma"].apply(g) for g in made_g]
            arr_s = [self.data.kernels["spore"].apply(x) for x in made_s]
            A = dr.zeros(T, n)
            for a, b in zip(arr_g, arr_s):
                A += a + b
            free = dr.maximum(1.0 - occ, 0.0)
            sf = relax.settle_fraction(A / M) / M
            acc = free * sf                                   # spots taken per arrival
            # near field: a gemma lands next to its parent, where a cell is free with
            # probability 1 - q (pair closure) instead of the triangle's 1 - occ
            acc_g = dr.maximum(1.0 - q_par, 0.0) * sf if near else acc
            if near and self.local_arrivals:
                # ... and where its siblings and the gemmae of its parent's neighbours land
                # too: per cell next to a parent, g (1 + (z - 1) q_g m) / z arrivals a day (g:
                # gemmae per moss, m: moss share of the occupants), not the triangle's mean
                # A / M; each gemma carries its origin's value (arrival-weighted by the kernel)
                z = self.near_cells
                g_all, a_g = dr.zeros(T, n), dr.zeros(T, n)
                for g, a in zip(made_g, arr_g):
                    g_all += g
                    a_g += a
                per_moss = g_all / dr.maximum(M * c_after, 1e-12)
                a_src = per_moss * (1.0 + (z - 1.0) * q_g * ms) / z
                k = self.data.kernels["gemma"]
                a_loc = k.apply(g_all * a_src) / dr.maximum(a_g, 1e-12)
                a_loc = dr.maximum(a_loc, a_g / M)                # at least the mean
                a_s = A - a_g
                sf_g = relax.settle_fraction(a_loc + a_s / M) / M
                acc_g = dr.maximum(1.0 - q_par, 0.0) * sf_g
            acc_s = acc
            if near and self.spore_near is not None:
                # spores: those that land beside their parent (1 - far) land where its gemmae
                # land, occupied with q z P (P: a spore and a gemma from one point share a
                # cell), the far ones occupied with rho
                far, p_sib = self.spore_near
                sf_n = sf_g if self.local_arrivals else sf
                near_free = dr.maximum((1.0 - far) - dr.minimum(1.0 - far,
                                                               q_par * self.near_cells * p_sib),
                                       0.0)
                acc_s = near_free * sf_n + far * free * sf
                sn_share = near_free * sf_n / dr.maximum(acc_s, 1e-12)
            scale_g = scale_s = 1.0
            if self.capacity_on:
                # the discrete run settles the day's gemmae first, then the spores, while free
                # slots last (daily/moss.py, _release): the gemmae take the room first
                room = dr.maximum(self.capacity - dr.sum(M * occ), 0.0)
                want_g, want_s = dr.zeros(T, n), dr.zeros(T, n)
                for a, b in zip(arr_g, arr_s):
                    want_g += a * acc_g
                    want_s += b * acc_s
                wg, ws = dr.sum(M * want_g), dr.sum(M * want_s)
                scale_g = dr.minimum(1.0, room / dr.maximum(wg, 1e-12))
                room_s = dr.maximum(room - wg * scale_g, 0.0)
                scale_s = dr.minimum(1.0, room_s / dr.maximum(ws, 1e-12))
            new_g = [a * acc_g * scale_g for a in arr_g]
            new_s = [a * acc_s * scale_s for a in arr_s]
            if sn_share is not None:
                for x in new_s:
                    s_near += x * sn_share
            for ng, ns_ in zip(new_g, new_s):
                settled.append(ng + ns_)
                occ = occ + ng + ns_
        else:
            new_g = [dr.zeros(T, n) for _ in new_sp]
            new_s = [dr.zeros(T, n) for _ in new_sp]
        # ---- a spore from outside every `interval` days at a random point (area-weighted),
        # random species; it stays only on a free spot and within the capacity
        if self.external and self.interval and d % self.interval == self.interval - 1:
            free2 = dr.maximum(1.0 - occ, 0.0)
            room = 1.0
            if self.capacity_on:
                room = dr.clip(self.capacity - dr.sum(M * occ), 0.0, 1.0)
            ext = T(self.area_frac / self.data.M / self.n_sp) * free2 * room
            new_s = [x + ext for x in new_s]
        for s, ng, ns_ in zip(new_sp, new_g, new_s):
            life.push(s, "gemma", ng, d)
            life.push(s, "spore", ns_, d)
        new_pair = new_pair_m = None
        if near:
            # newcomers' neighbour pairs: a gemma's parent is a neighbour, its other z - 1
            # neighbour cells (and all z of a spore's) are occupied with q10 = P(occ | nb free)
            z = self.near_cells
            g_tot, s_tot = dr.zeros(T, n), dr.zeros(T, n)
            for ng, ns_ in zip(new_g, new_s):
                g_tot += ng
                s_tot += ns_
            occ_new = occ_live + g_tot + s_tot
            # (spores that settled beside their parent count as its gemmae do; the external
            # spore lands anywhere)
            new_pair = pair + (2.0 / z) * ((g_tot + s_near) * (1.0 + (z - 1.0) * q_g)
                                           + (s_tot - s_near) * z * q10)
            new_pair = dr.clip(new_pair, occ_new * occ_new, occ_new)
            if pair_m is not None:
                # a newcomer's moss neighbours: a gemma's parent and the moss share m of its
                # other occupied neighbours
                new_pair_m = pair_m + (1.0 / z) * (
                    (g_tot + s_near) * (1.0 + (z - 1.0) * q_g * ms)
                    + (s_tot - s_near) * z * q10 * ms)
                new_pair_m = dr.clip(new_pair_m, dr.maximum(new_pair - (occ_new - c_after), 0.0),
                                     dr.minimum(c_after, new_pair))
        out = State(d + 1, O, new_sp, st.per_species, new_pair, new_pair_m)
        # opaque, not just evaluated: a slot that is still a literal 0 would enter the kernels as
        # a constant, and the registers shift those constants around: a new kernel every day
        dr.make_opaque(out.arrays())
        if record is not None:
            record.update(S=S, Ts=Ts, rhs=rhs, theta=theta, c=c_after, germinated=germinated,
                          gemmae=made_g, spores=made_s, arrived=arr_g + arr_s, settled=settled,
                          settled_gemmae=new_g if self.dispersal else [])
        return out

    # ---- outputs ----------------------------------------------------------------------------
    def moss_density(self, st: State):
        """Moss per spot of each triangle, all species.

        Parameters
        ----------
        st : State
            The state.

        Returns
        -------
        Dr.Jit float array
            (triangles,) moss per spot [-].
        """
        c = dr.zeros(self.T, self.n)
        for s in st.species:
            c += self.life.moss(s)
        return c

    def cover(self, st: State):
        """Covered fraction of each triangle: min(moss x size², area) / area (as daily/moss.py).

        Parameters
        ----------
        st : State
            The state.

        Returns
        -------
        Dr.Jit float array
            (triangles,) covered fraction [-].
        """
        c = self.moss_density(st)
        a = self.areas
        return dr.minimum(c * self.M * self.cell2, a) / a

    def propagules(self, st: State):
        """Waiting propagules per spot of each triangle, all species and kinds.

        Parameters
        ----------
        st : State
            The state.

        Returns
        -------
        Dr.Jit float array
            (triangles,) propagules per spot [-].
        """
        p = dr.zeros(self.T, self.n)
        for s in st.species:
            p += self.life.waiting(s)
        return p

    def _record(self, st: State, rec: dict) -> dict:
        d = self.data
        cov = np.asarray(self.cover(st)) * d.areas
        c = np.asarray(self.moss_density(st)) * d.M
        liv = d.living
        a = d.areas[liv]

        def amean(x):
            return float(np.sum(np.asarray(x)[liv] * a) / a.sum())

        def tot(xs, per_spot=False):
            w = d.M if per_spot else 1.0
            return float(sum(np.sum(np.asarray(x) * w) for x in xs))

        per_sp = [float(np.sum(np.asarray(self.life.moss(s)) * d.M)) for s in st.species]
        return {"day": st.day, "covered_area_m2": float(cov.sum()),
                "moss_alive": float(c.sum()),
                "alive": dict(zip([s.name for s in d.species], per_sp)),
                "propagules": float(np.sum(np.asarray(self.propagules(st)) * d.M)),
                "mean_S_W_m2": amean(rec["S"]), "mean_Ts_K": amean(rec["Ts"]),
                "mean_rhs": amean(rec["rhs"]), "mean_theta": amean(rec["theta"]),
                "regions": {k: float(cov[m].sum()) for k, m in d.regions.items()},
                "events": {"germinated": tot(rec["germinated"], True),
                           "gemmae": tot(rec["gemmae"]), "spores": tot(rec["spores"]),
                           "arrived": tot(rec["arrived"]),
                           "settled": tot(rec["settled"], True)}}

    # ---- runs -------------------------------------------------------------------------------
    def run(self, params: dict | None = None, days: int | None = None, state: State | None = None,
            record: bool = False, maps_every: int = 0, light=None,
            progress: bool = False) -> RunResult:
        """Run ``days`` days (default the model's) from ``state`` (default day 0).

        Parameters
        ----------
        params : dict, optional
            ``{name: value}`` (numbers, or width-1 Dr.Jit floats with gradients enabled to
            differentiate).
        days : int, optional
            Days to run [d] (default: to the model's last day).
        state : State, optional
            Start state (default: :meth:`initial_state`).
        record : bool
            Keep a per-day summary like the discrete run's ``days_record`` in ``history``.
        maps_every : int
            Keep the per-triangle cover every so many days (NumPy) in ``maps`` (0: never).
        light : tuple, optional
            (sun, sky) of :meth:`light` (default: computed from ``params``).
        progress : bool
            Show a progress bar.

        Returns
        -------
        RunResult
            The end state, cover and moss density (AD-tracked), history, maps, seconds.

        Raises
        ------
        ParameterError
            If the run would go past the model's days.
        """
        t0 = time.perf_counter()
        P = self.resolve(params)
        light = self.light(P) if light is None else light
        st = self.initial_state() if state is None else state
        end = st.day + int(days if days is not None else self.days - st.day)
        if end > self.days:
            raise ParameterError("days", end, f"<= {self.days}")
        hist, maps = [], {}
        bar = None
        if progress:
            from tqdm.auto import tqdm
            bar = tqdm(total=end - st.day, desc="relaxed days", unit="day")
        while st.day < end:
            rec = {} if record else None
            st = self.step(st, P, light, rec)
            if record:
                hist.append(self._record(st, rec))
            if maps_every and st.day % maps_every == 0:
                maps[st.day] = np.asarray(self.cover(st))
            if bar is not None:
                dr.sync_thread()   # the bar's rate counts days run, not launched
                bar.update(1)
        if bar is not None:
            bar.close()
        dr.sync_thread()           # the last days' kernels in the run's time
        return RunResult(st, self.cover(st), self.moss_density(st), hist, maps,
                         time.perf_counter() - t0)
