"""The discrete moss run as a function of its parameters, and fits *of the discrete model*.

:class:`DiscreteMossModel` runs the daily pipeline (:class:`~mitsuba_veg.daily.Simulation`;
with ``world=True`` the scenario's trees in the light) with given parameter values on a fixed
set of seeds (common random numbers: the same seeds at every evaluation, so that two
evaluations differ only through the parameters) and returns the covered fraction per
triangle, per seed and day.

:func:`fit_discrete` fits the parameters of the discrete model to a target coverage map by
*defect correction* (output space mapping): the relaxed model R (:class:`SmoothMossModel`)
supplies the gradient, the discrete model D supplies the values. At iterate theta_k

    shift_k = D(theta_k) - R(theta_k)              (per triangle; mean over the seeds)
    theta_(k+1) = argmin_theta  loss(R(theta) + shift_k, target)

(an Adam fit of the relaxed model from theta_k, gradients by the day-by-day adjoint). A fixed
point has R(theta*) + shift = D(theta*), i.e. the *discrete* coverage matches the target as well as
the relaxed model's parameter directions allow; the relaxed model's error (the spatial closure,
docs/tuning.md) only enters through its Jacobian, which sets the rate of convergence, not the
answer. Linearised, the step is theta_(k+1) - theta_k = J_R^+ (target - D(theta_k)): a
Gauss-Newton step with the relaxed Jacobian in place of the discrete one (whose pathwise
derivative is zero almost everywhere: the discrete coverage is a step function of every
parameter). docs/tuning.md has the measurements.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..daily import Simulation
from ..moss.species import PARAMETER_FIELDS
from ..scenario import Scenario, load_scenario
from .fitting import param_names, parameter_bounds, parameter_scale, target_array
from .grad import value_and_grad

__all__ = ["DiscreteMossModel", "DiscreteResult", "DiscreteFitResult", "DiscreteExperiment",
           "fit_discrete", "fit_discrete_experiments",
           "patch_labels", "patch_cover", "patch_loss_value"]

_CLIMATE = ("T", "rh")


@dataclass
class DiscreteResult:
    """Discrete runs of one parameter set, one per seed."""

    params: dict                  # the parameter values of the runs
    seeds: list                   # the seeds (``light.seed``)
    report: list                  # reported days (1-based)
    cover: np.ndarray             # (seeds, len(report), n) covered fraction per terrain
    #                               triangle [-] (DiscreteMossModel.shape_slices' layout)
    total: np.ndarray             # (seeds, days) covered area [m2]
    regions: dict                 # name -> (seeds, days) covered area of the region [m2]
    seconds: float = 0.0

    def mean(self, day: int | None = None) -> np.ndarray:
        """Mean over the seeds of the covered fraction per triangle on ``day``.

        Parameters
        ----------
        day : int, optional
            A reported day (1-based) [d]; default: the last reported day.

        Returns
        -------
        ndarray
            (n,) mean covered fraction per terrain triangle [-].
        """
        k = len(self.report) - 1 if day is None else self.report.index(int(day))
        return self.cover[:, k].mean(0)


class DiscreteMossModel:
    """The discrete moss run of a scenario as a function of parameters, on fixed seeds.

    Parameters
    ----------
    scenario : path or Scenario
        The scenario (TOML path or loaded :class:`~mitsuba_veg.scenario.Scenario`).
    days : int
        Days to run [d].
    species : list of str, optional
        Species keys replacing ``moss.species``.
    seeds : iterable of int
        ``light.seed`` of the runs (light, rain days, placement and dispersal all change);
        the same seeds at every evaluation (common random numbers).
    photons : int, optional
        Photons per daily light pass (default: the scenario's).
    overrides : list of str
        Further ``KEY=VALUE`` scenario overrides.
    world : bool
        Keep the scenario's trees in the light (they shade the terrain); without, its
        ``[[trees]]`` are left out and the moss runs alone.

    Parameter names (as :class:`~mitsuba_veg.tune.SmoothMossModel`): species fields (``"S1"``,
    ``"bryum_argenteum.alpha_g"`` ...), ``"T"`` and ``"rh"`` (the daily air temperature [K] and
    humidity [-] shifted so that their mean is the value), ``"albedo.<shape>"`` (the bare
    surface's reflectance in the total band [-]) and ``"strength.sun"``, ``"strength.sky"``
    (emitter scale [-]).
    """

    def __init__(self, scenario, days: int, species=None, seeds=range(8),
                 photons: int | None = None, overrides=(), world: bool = False):
        scn = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
        if isinstance(scenario, Scenario) and overrides:
            raise ParameterError("overrides", list(overrides), "none with a loaded Scenario",
                                 "apply them when loading it (load_scenario(path, overrides))")
        data = copy.deepcopy(scn.data)
        if species is not None:
            data.setdefault("moss", {})["species"] = list(species)
        if photons is not None:
            data.setdefault("light", {})["photons"] = int(photons)
        data.setdefault("simulation", {})["checkpoint_every"] = 0
        self.scenario = Scenario(scn.path, data)
        if int(days) < 1:
            raise ParameterError("days", days, ">= 1")
        self.days = int(days)
        self.seeds = [int(s) for s in seeds]
        if not self.seeds:
            raise ParameterError("seeds", list(seeds), "at least one seed")
        self.world = bool(world)
        if self.world:
            if not (self.scenario.get("trees") or self.scenario.get("stand")):
                raise ParameterError("trees", None, "at least one [[trees]] entry or a [stand] "
                                     "for world=True",
                                     "add trees to the scenario or use world=False")
        else:
            # the moss alone: a world without trees (nor sensors)
            data = copy.deepcopy(self.scenario.data)
            data.pop("trees", None)
            data.pop("sensors", None)
            self.scenario = Scenario(self.scenario.path, data)
        sim = self._sim(self.seeds[0], {})
        site = sim.site
        # the terrain's elements (a world's tree leaves left out), shape by shape
        terrain = sorted((sim.index.shape_slice(sid).start, sid) for sid in site.terrain_shapes
                         if sid in sim.index.geometry)
        self.elements = np.concatenate([np.arange(sim.index.shape_slice(sid).start,
                                                  sim.index.shape_slice(sid).stop)
                                        for _, sid in terrain])
        self.shape_slices, k = {}, 0
        for _, sid in terrain:
            sl = sim.index.shape_slice(sid)
            self.shape_slices[sid] = slice(k, k + sl.stop - sl.start)
            k += sl.stop - sl.start
        self.n = len(self.elements)
        self.areas = np.asarray(sim.index.areas, float)[self.elements]
        self.centroids = np.asarray(sim.index.centroids, float)[self.elements]
        self.living = np.asarray(site.living, bool)[self.elements]
        self.cell = float(sim.moss_cfg["size"])
        self.species_keys = list(sim.moss_cfg["species"])
        self.species = list(sim.species)
        self.base_albedo = np.asarray(site.base_albedo[:, 0], float)[self.elements]
        self.region_masks = dict(site.regions)
        self.climate_mean = {"T": float(np.mean(sim.weather.T)),
                             "rh": float(np.mean(sim.weather.rh))}
        self.evaluations = 0

    def to_layout(self, cover, shape_slices: dict) -> np.ndarray:
        """A per-element array of this model (``self.shape_slices``' layout) in another model's
        layout, shape by shape.

        Parameters
        ----------
        cover : array_like
            (n,) values per terrain triangle of this model (e.g. covered fraction [-]).
        shape_slices : dict
            ``{shape_id: slice}`` of the other layout (e.g. ``ModelData.shape_slices``).

        Returns
        -------
        ndarray
            The values in the other layout (NaN where it has elements of no terrain shape).
        """
        n = max(sl.stop for sl in shape_slices.values())
        out = np.full(n, np.nan)
        for sid, sl in shape_slices.items():
            own = self.shape_slices.get(sid)
            if own is None or sl.stop - sl.start != own.stop - own.start:
                raise ParameterError("shape_slices", sid, "shapes of the discrete model's terrain "
                                     f"({list(self.shape_slices)}) with the same triangles")
            out[sl] = np.asarray(cover)[self.shape_slices[sid]]
        return out

    # ---- parameters -------------------------------------------------------------------------
    def _canonical(self, name: str):
        if name in _CLIMATE:
            return ("climate", name)
        if name.startswith("albedo."):
            sid = name.split(".", 1)[1]
            if sid not in getattr(self, "shape_slices", {sid: None}):
                raise ParameterError(name, None, f"albedo.<shape> with a shape among "
                                     f"{list(self.shape_slices)}")
            return ("albedo", sid)
        if name in ("strength.sun", "strength.sky"):
            if self.world:
                raise ParameterError("params", name, "species, climate or albedo parameters "
                                     "with world=True", "the trees' leaf light is not scaled: "
                                     "fit emitter strengths on a scenario without trees")
            return ("strength", name.split(".")[1])
        keys = getattr(self, "species_keys", None) or \
            list(self.scenario.get("moss.species", []) or [])
        if "." in name:
            key, f = name.split(".", 1)
            if key in keys and f in PARAMETER_FIELDS:
                return ("species", keys.index(key), f)
        elif name in PARAMETER_FIELDS:
            if len(keys) != 1:
                raise ParameterError("params", name, f"'<species>.{name}' with a species among "
                                     f"{keys}", "name the species (the run has several)")
            return ("species", 0, name)
        raise ParameterError("params", name, "a species field (" + ", ".join(PARAMETER_FIELDS)
                             + "), T, rh, albedo.<shape>, strength.sun or strength.sky")

    def default_value(self, name: str) -> float:
        """The scenario's value of a parameter.

        Parameters
        ----------
        name : str
            Parameter name (class docstring).

        Returns
        -------
        float
            The value (species field in its unit, mean air temperature [K], humidity [-],
            shape albedo [-], emitter strength 1).
        """
        c = self._canonical(name)
        if c[0] == "climate":
            return self.climate_mean[c[1]]
        if c[0] == "albedo":
            return float(np.mean(self.base_albedo[self.shape_slices[c[1]]]))
        if c[0] == "strength":
            return 1.0
        return float(getattr(self.species[c[1]], c[2]))

    def _sim(self, seed: int, params: dict):
        data = copy.deepcopy(self.scenario.data)
        data.setdefault("light", {})["seed"] = int(seed)
        scn = Scenario(self.scenario.path, data)
        sim = Simulation(scn, tempfile.gettempdir(), days=self.days, progress=False)
        cfg = sim.config
        albedo, strength = {}, [1.0, 1.0]
        for name, v in params.items():
            v = float(v)
            if not math.isfinite(v):
                raise ParameterError(f"params[{name!r}]", v, "a finite number")
            c = self._canonical(name)
            if c[0] == "species":
                cfg.species[c[1]] = dataclasses.replace(cfg.species[c[1]], **{c[2]: v})
            elif c[0] == "climate":
                w = cfg.weather
                if c[1] == "T":
                    cfg.weather = dataclasses.replace(w, T=w.T + (v - np.mean(w.T)))
                else:
                    if not 0.0 < v <= 1.0:
                        raise ParameterError("params['rh']", v, "(0, 1]")
                    cfg.weather = dataclasses.replace(w, rh=w.rh + (v - np.mean(w.rh)))
            elif c[0] == "albedo":
                if not 0.0 <= v <= 1.0:
                    raise ParameterError(f"params[{name!r}]", v, "[0, 1]")
                albedo[c[1]] = v
            else:
                if v < 0:
                    raise ParameterError(f"params[{name!r}]", v, ">= 0")
                strength[0 if c[1] == "sun" else 1] = v
        # the light stage's parameters: emitter strengths and bare albedos (no subclass)
        sim.light_strength = tuple(strength)
        sim.albedo = albedo
        sim.setup()
        return sim

    # ---- runs -------------------------------------------------------------------------------
    def run(self, params: dict | None = None, report=None, seeds=None) -> DiscreteResult:
        """Run every seed with ``params`` (other parameters: the scenario's).

        Parameters
        ----------
        params : dict, optional
            ``{name: value}`` (names as in the class docstring).
        report : list of int, optional
            Days (1-based) whose per-triangle cover is kept [d] (default: the last day).
        seeds : list of int, optional
            Seeds to run (default: the model's).

        Returns
        -------
        DiscreteResult
            Per-seed covers on the report days, daily covered areas, timing.
        """
        t0 = time.perf_counter()
        params = dict(params or {})
        report = [self.days] if report is None else sorted(int(d) for d in report)
        for d in report:
            if not 1 <= d <= self.days:
                raise ParameterError("report", d, f"days in [1, {self.days}]")
        seeds = self.seeds if seeds is None else [int(s) for s in seeds]
        covers, totals, regions = [], [], {k: [] for k in self.region_masks}
        for s in seeds:
            sim = self._sim(s, params)
            sim.initialise()
            cov, tot, reg = [], [], {k: [] for k in self.region_masks}
            for day in range(1, self.days + 1):
                rec = sim.step()
                tot.append(rec["covered_area_m2"])
                for k in reg:
                    reg[k].append(rec["regions"][k])
                if day in report:
                    c = sim.counts()[self.elements]
                    cov.append(np.minimum(c * self.cell ** 2, self.areas) / self.areas)
            covers.append(cov)
            totals.append(tot)
            for k in reg:
                regions[k].append(reg[k])
        self.evaluations += 1
        return DiscreteResult(params, seeds, report, np.asarray(covers), np.asarray(totals),
                              {k: np.asarray(v) for k, v in regions.items()},
                              time.perf_counter() - t0)


# ------------------------------------------------------------------------------------------
# the fit of the discrete model
# ------------------------------------------------------------------------------------------
@dataclass
class DiscreteFitResult:
    """The result of :func:`fit_discrete` (the discrete model fitted by defect correction).

    Attributes
    ----------
    values : dict
        Fitted values (the last iterate), by parameter name.
    initial : dict
        Starting values.
    iterations : list
        Per outer iteration: parameters, discrete loss, shift norm and more.
    discrete_loss : float
        Loss of the discrete mean at ``values``.
    seconds : float
        Wall time of the fit [s].
    files : dict
        Files written (name -> path).
    """

    values: dict                  # fitted values (the last iterate)
    initial: dict
    iterations: list              # per outer iteration: params, discrete loss, shift norm ...
    discrete_loss: float          # loss of the discrete mean at ``values``
    seconds: float = 0.0
    files: dict = field(default_factory=dict)


def patch_labels(centroids, shape_slices: dict, usable, size: float) -> np.ndarray:
    """Patch number of every triangle: triangles of one shape whose centroids fall into the same
    cube of side ``size`` form a patch; triangles not ``usable`` get -1.

    Parameters
    ----------
    centroids : array_like
        (n, 3) triangle centroids [m].
    shape_slices : dict
        ``{shape_id: slice}`` of the triangles of each shape.
    usable : array_like
        (n,) bool: triangles that take part.
    size : float
        Cube side [m].

    Returns
    -------
    ndarray
        (n,) int64 patch number (0 ... patches - 1), -1 for unused triangles.
    """
    if not size > 0:
        raise ParameterError("patch", size, "> 0 [m]")
    n = len(centroids)
    key = np.full((n, 4), -1, np.int64)
    for k, sl in enumerate(shape_slices.values()):
        key[sl, 0] = k
    key[:, 1:] = np.floor(np.asarray(centroids) / size).astype(np.int64)
    labels = np.full(n, -1, np.int64)
    ok = np.asarray(usable, bool) & (key[:, 0] >= 0)
    _, inv = np.unique(key[ok], axis=0, return_inverse=True)
    labels[ok] = inv.ravel()
    return labels


def patch_cover(cover, areas, labels) -> np.ndarray:
    """Area-weighted covered fraction of every patch (NumPy).

    Parameters
    ----------
    cover : array_like
        (n,) covered fraction per triangle [-].
    areas : array_like
        (n,) triangle areas [m2].
    labels : ndarray
        (n,) patch numbers (:func:`patch_labels`; -1 = not used).

    Returns
    -------
    ndarray
        (patches,) covered fraction per patch [-].
    """
    n_p = int(labels.max()) + 1
    ok = labels >= 0
    a = np.bincount(labels[ok], weights=areas[ok], minlength=n_p)
    c = np.bincount(labels[ok], weights=(np.asarray(cover, float) * areas)[ok], minlength=n_p)
    return c / np.maximum(a, 1e-30)


# The sqrt loss's transform of a patch cover c: sqrt(smax(c) + SQRT_FLOOR) with the smooth
# max smax(c) = (c + sqrt(c^2 + SMOOTH_WIDTH^2)) / 2 of c and 0. In the inner fit c is the
# relaxed cover shifted by the discrete defect, R(theta) + D(theta_k) - R(theta_k): on patches
# without discrete moss it sits at 0 +- float32 rounding at theta_k. A hard clip max(c, 0)
# switches such a patch's gradient on or off with the sign of the rounding, and the slope of
# sqrt(c + 1e-6) there (500) let those patches dominate: repeated adjoint calls at one point
# gave gradients of different sign (docs/tuning.md). The smooth max has slope 1/2 at 0 and
# differs from max(c, 0) by at most SMOOTH_WIDTH / 2; the floor is the cover resolution (one
# 1 cm2 individual per m2 of patch; a 16-seed mean on a 0.2 m patch resolves ~1.6e-4), which
# bounds the slope of the sqrt by 1 / (2 sqrt(1e-4)) = 50. The target gets the same transform,
# so a cover equal to the target has zero loss.
SMOOTH_WIDTH = 1e-4
SQRT_FLOOR = 1e-4


def _sqrt_cover(c):
    """sqrt(smooth max(c, 0) + SQRT_FLOOR) of a patch cover (NumPy), see SMOOTH_WIDTH.

    Parameters
    ----------
    c : ndarray
        Covered fraction per patch [-].

    Returns
    -------
    ndarray
        The transformed cover [-].
    """
    cs = 0.5 * (c + np.sqrt(c * c + SMOOTH_WIDTH ** 2))
    return np.sqrt(cs + SQRT_FLOOR)


def _patch_loss(shift, areas, labels, target_patch, kind: str, T):
    """Loss of the shifted relaxed cover, aggregated to patches (Dr.Jit, differentiable)."""
    n_p = len(target_patch)
    ok = labels >= 0
    pa = np.bincount(labels[ok], weights=areas[ok], minlength=n_p)
    idx = dr.uint32_array_t(T)(np.where(ok, labels, n_p).astype(np.uint32))
    a_dr = T(np.where(ok, areas, 0.0))
    inv = T(np.append(1.0 / np.maximum(pa, 1e-30), 0.0))
    w = T(np.append(pa / pa.sum(), 0.0))
    tg = T(np.append(target_patch, 0.0))

    if kind == "sqrt":
        g_tg = T(np.append(_sqrt_cover(np.asarray(target_patch, float)), 0.0))

    def loss(cover, target, weights, model):
        pc = dr.zeros(T, n_p + 1)
        dr.scatter_add(pc, (cover + shift) * a_dr, idx)
        c = pc * inv
        if kind == "sqrt":
            # smooth max(c, 0) and the sqrt floor of _sqrt_cover (the reason is there)
            cs = 0.5 * (c + dr.sqrt(c * c + SMOOTH_WIDTH ** 2))
            d = dr.sqrt(cs + SQRT_FLOOR) - g_tg
        else:
            d = c - tg
        return dr.sum(d * d * w)
    loss.__name__ = f"{kind} of patch cover (shifted by the discrete defect)"
    return loss


def patch_loss_value(cover, areas, labels, target_patch, kind: str = "sqrt") -> float:
    """The loss of :func:`fit_discrete` (patch cover) with NumPy.

    Parameters
    ----------
    cover : array_like
        (n,) covered fraction per triangle [-].
    areas : array_like
        (n,) triangle areas [m2].
    labels : ndarray
        (n,) patch numbers (:func:`patch_labels`).
    target_patch : ndarray
        (patches,) target covered fraction per patch [-].
    kind : {"sqrt", "mse"}
        Squared difference of the square roots (of the smooth maximum of the cover and 0 plus
        a floor, as the fit's Dr.Jit loss: see ``SMOOTH_WIDTH``) or of the fractions.

    Returns
    -------
    float
        Sum over the patches of the squared difference weighted by the patch's area fraction.
    """
    c = patch_cover(cover, areas, labels)
    ok = labels >= 0
    pa = np.bincount(labels[ok], weights=areas[ok], minlength=len(c))
    w = pa / pa.sum()
    if kind == "sqrt":
        d = _sqrt_cover(c) - _sqrt_cover(np.asarray(target_patch, float))
    else:
        d = c - target_patch
    return float(np.sum(w * d * d))


def _inner_adam(terms, params, theta, scale, bnd, steps, lr, lr_final):
    """Adam on a weighted sum of shifted relaxed losses from ``theta``, on the normalised
    parameters (p - theta) / scale as :func:`mitsuba_veg.tune.fit`.

    Parameters
    ----------
    terms : list of tuple
        ``(model, day, loss_fn, weight)``: the relaxed model run for ``day`` days, its loss and
        the loss's weight in the sum.
    params : list of str
        Parameter names.
    theta : dict
        Start values (physical units).
    scale, bnd : dict
        Scale and (lower, upper) bounds per parameter.
    steps : int
        Adam steps.
    lr, lr_final : float
        Learning rate and its final fraction (geometric decay).

    Returns
    -------
    tuple
        ``(values, loss)``: the last iterate (physical units) and its summed loss.
    """
    T = terms[0][0].T
    opt = mi.ad.Adam(lr=lr, beta_1=0.9, beta_2=0.9)
    for p in params:
        opt[p] = T(0.0)
    decay = lr_final ** (1.0 / max(steps - 1, 1))

    def physical():
        return {p: theta[p] + scale[p] * float(np.asarray(dr.detach(opt[p])).ravel()[0])
                for p in params}
    L = float("nan")
    for k in range(steps):
        vals = physical()
        L, G = 0.0, {p: 0.0 for p in params}
        for model, d, lf, wt in terms:
            r = value_and_grad(model, vals, lf, days=d)
            L += wt * r.loss
            for p in params:
                G[p] += wt * r.grad[p]
        if not math.isfinite(L) or not all(math.isfinite(g) for g in G.values()):
            raise FloatingPointError(f"fit_discrete: non-finite loss or gradient {L}, {G} at "
                                     f"{vals}")
        for p in params:
            dr.set_grad(opt[p], T(G[p] * scale[p]))
        opt.set_learning_rate(lr * decay ** k)
        opt.step()
        for p in params:
            lo, hi = (bnd[p][0] - theta[p]) / scale[p], (bnd[p][1] - theta[p]) / scale[p]
            opt[p] = dr.clip(dr.detach(opt[p]), lo, hi)
    return physical(), L


@dataclass
class DiscreteExperiment:
    """One experiment of a fit of the discrete model: a scenario's discrete model, its relaxed
    surrogate and the target map(s) of that scenario.

    Several experiments (e.g. the same garden in two seasons, or two plots) share the fitted
    parameters; :func:`fit_discrete_experiments` adds their losses. Each experiment's target
    comes from other seeds than its discrete model's (the fit's common random numbers).

    Parameters
    ----------
    discrete : DiscreteMossModel
        The discrete model of the experiment's scenario and days.
    surrogate : SmoothMossModel
        The relaxed model of the same scenario, days and species (the gradient).
    target : ndarray or dict
        Covered fraction per triangle [-] (the surrogate's element order, NaN = ignore) on the
        last day, or ``{day: map}``.
    name : str
        A label for the records.
    weight : float
        The weight of the experiment's loss in the sum [-].
    """

    discrete: DiscreteMossModel
    surrogate: object
    target: object
    name: str = ""
    weight: float = 1.0


def fit_discrete(discrete: DiscreteMossModel, surrogate, target, params, init: dict | None = None,
                 iterations: int = 5, steps: int = 25, lr: float = 0.08, lr_final: float = 0.05,
                 loss: str = "sqrt", patch: float = 0.2, tol: float = 0.01,
                 scales: dict | None = None, out=None, verbose: bool = False,
                 accept: str = "always", backtrack: int = 2) -> DiscreteFitResult:
    """Fit parameters of the *discrete* model to ``target`` by defect correction (module
    docstring).

    Parameters
    ----------
    discrete : DiscreteMossModel
        The discrete model (its seeds are the common random numbers of every evaluation).
    surrogate : SmoothMossModel
        The relaxed model of the same scenario, days and species; it supplies the gradients.
    target : ndarray or dict
        Covered fraction per triangle [-] (scene order, NaN = ignore) on the last day, or
        ``{day: map}`` for several days (a time series of maps: the loss is the mean over
        the days; growth rate and light thresholds act differently over time).
    params : list of str
        Parameter names (valid for both models).
    init : dict, optional
        Starting values (default: the scenario's).
    iterations : int
        Outer iterations (one discrete ensemble each) at most.
    steps : int
        Adam steps of the inner fit of the shifted relaxed model per iteration (as
        :func:`mitsuba_veg.tune.fit`: normalised parameters, bounds).
    lr : float
        The inner Adam's learning rate [-] (normalised parameters).
    lr_final : float
        Its geometric decay over the steps, down to ``lr * lr_final`` [-].
    loss : {"sqrt", "mse"}
        Squared difference of the square roots (default) or of the covered fractions, of
        *patches*: the area-weighted cover of the triangles of one shape within a cube of side
        ``patch``, weighted by the patch's area.
    patch : float
        Patch size [m]. A discrete map is a count of 1-cm individuals per triangle: per
        triangle it is mostly noise (and zero), and the square root of a noisy zero biases the
        fit; patches of 0.2 m on the garden hold 0-400 moss spots each.
    tol : float
        Stop when no parameter moved by more than ``tol`` times its scale in an iteration.
    scales : dict, optional
        Natural scale per parameter (default: :func:`mitsuba_veg.tune.fitting.parameter_scale`).
    out : path, optional
        Folder for ``fitted_discrete.json``.
    verbose : bool
        Print one line per outer iteration.
    accept : {"always", "decrease"}
        Outer step rule (:func:`fit_discrete_experiments`).
    backtrack : int
        Step halvings tried with ``accept="decrease"``.

    Returns
    -------
    DiscreteFitResult
        ``values`` (the last iterate), the per-iteration record (parameters, discrete loss,
        inner-fit loss) and the discrete loss at ``values``.
    """
    return fit_discrete_experiments([DiscreteExperiment(discrete, surrogate, target)], params,
                                    init=init, iterations=iterations, steps=steps, lr=lr,
                                    lr_final=lr_final, loss=loss, patch=patch, tol=tol,
                                    scales=scales, out=out, verbose=verbose, accept=accept,
                                    backtrack=backtrack)


def fit_discrete_experiments(experiments, params, init: dict | None = None,
                             iterations: int = 5, steps: int = 25, lr: float = 0.08,
                             lr_final: float = 0.05, loss: str = "sqrt", patch: float = 0.2,
                             tol: float = 0.01, scales: dict | None = None, out=None,
                             verbose: bool = False, accept: str = "always",
                             backtrack: int = 2) -> DiscreteFitResult:
    """Fit shared parameters of the *discrete* model to several experiments at once (defect
    correction, module docstring): the loss is the weighted sum over the experiments of each
    one's mean patch loss over its target days.

    Every outer iteration runs each experiment's discrete model (its seeds) at the iterate and
    shifts that experiment's relaxed model by its own defect; the inner Adam fit minimises the
    sum of the shifted relaxed losses. Parameters acting differently in the experiments (T1 in
    a cool and a warm season: below the temperature optimum a higher T1 lowers the fitness,
    above it raises it) are separated where one map alone leaves them on a ridge.

    With ``accept="decrease"`` the outer step is safeguarded: the step to the inner fit's end
    is taken only if the discrete loss there is below the current one, else the half step, the
    quarter step ... (``backtrack`` halvings); if none lowers it the fit stops where it is.
    The relaxed step (the defect frozen at the iterate) can run further along a ridge than the
    discrete model follows; this keeps each iterate the best the fit has seen, at the price of
    a discrete ensemble per rejected trial. ``"always"`` takes every step (plain defect
    correction).

    Parameters
    ----------
    experiments : list of DiscreteExperiment or tuple
        The experiments (``(discrete, surrogate, target)`` tuples are accepted).
    params : list of str
        Parameter names (valid for every experiment's models); shared by all experiments.
    init : dict, optional
        Starting values (default: the first experiment's scenario values).
    iterations : int
        Outer iterations (one discrete ensemble per experiment each) at most.
    steps : int
        Adam steps of the inner fit per iteration.
    lr : float
        The inner Adam's learning rate [-] (normalised parameters).
    lr_final : float
        Its geometric decay over the steps, down to ``lr * lr_final`` [-].
    loss : {"sqrt", "mse"}
        Patch loss (:func:`fit_discrete`).
    patch : float
        Patch size [m].
    tol : float
        Stop when no parameter moved by more than ``tol`` times its scale in an iteration.
    scales : dict, optional
        Natural scale per parameter (default: :func:`mitsuba_veg.tune.fitting.parameter_scale`
        of the first experiment's surrogate).
    out : path, optional
        Folder for ``fitted_discrete.json``.
    verbose : bool
        Print one line per outer iteration.
    accept : {"always", "decrease"}
        Take every outer step, or only steps (or halved steps) that lower the discrete loss.
    backtrack : int
        Step halvings tried after a rejected full step (``accept="decrease"``), >= 0.

    Returns
    -------
    DiscreteFitResult
        ``values`` (the last iterate; with ``"decrease"`` the one of lowest discrete loss), the
        per-iteration record (parameters, summed discrete loss, inner loss, with
        ``"decrease"`` the ``trials`` of the step and ``step``: the accepted fraction, 0 when
        none was; per-experiment losses and covered areas under ``"experiments"``;
        ``covered_m2_discrete`` / ``covered_m2_relaxed`` summed over the experiments on their
        last target day) and the summed discrete loss at ``values``.
    """
    t0 = time.perf_counter()
    params = param_names(params)
    if iterations < 1:
        raise ParameterError("iterations", iterations, ">= 1")
    if steps < 1:
        raise ParameterError("steps", steps, ">= 1")
    if loss not in ("sqrt", "mse"):
        raise ParameterError("loss", loss, "'sqrt' or 'mse'")
    if accept not in ("always", "decrease"):
        raise ParameterError("accept", accept, "'always' or 'decrease'")
    if isinstance(backtrack, bool) or not isinstance(backtrack, (int, np.integer)) \
            or backtrack < 0:
        raise ParameterError("backtrack", backtrack, "an integer >= 0")
    exps = []
    for i, e in enumerate(list(experiments)):
        if not isinstance(e, DiscreteExperiment):
            if not isinstance(e, (tuple, list)) or len(e) != 3:
                raise ParameterError(f"experiments[{i}]", type(e).__name__, "a "
                                     "DiscreteExperiment or a (discrete, surrogate, target) "
                                     "tuple")
            e = DiscreteExperiment(*e)
        exps.append(e)
    if not exps:
        raise ParameterError("experiments", [], "at least one experiment")
    names = [e.name or f"experiment {i}" for i, e in enumerate(exps)]
    if len(set(names)) != len(names):
        raise ParameterError("experiments", names, "distinct names")
    setups = []
    for e, nm in zip(exps, names):
        dm, sm = e.discrete, e.surrogate
        if not (math.isfinite(float(e.weight)) and float(e.weight) > 0):
            raise ParameterError(f"{nm}: weight", e.weight, "> 0")
        dm.to_layout(np.zeros(dm.n), sm.data.shape_slices)  # same terrain?
        if sm.days != dm.days:
            raise ParameterError(f"{nm}: surrogate.days", sm.days, f"{dm.days} (the discrete "
                                 "model's days)", "run both models for the same days")
        for p in params:
            dm._canonical(p)
            sm._canonical(p)
        target = e.target if isinstance(e.target, dict) else {dm.days: e.target}
        days = sorted(int(d) for d in target)
        for d in days:
            if not 1 <= d <= dm.days:
                raise ParameterError(f"{nm}: target", f"day {d}", f"days in [1, {dm.days}]",
                                     "give {day: map} for simulated days")
        data = sm.data
        tgt, labels, tgt_patch = {}, {}, {}
        for d in days:
            tgt[d] = target_array(sm, target[d])
            labels[d] = patch_labels(data.index.centroids, data.shape_slices,
                                     data.living & np.isfinite(tgt[d]), patch)
            tgt_patch[d] = patch_cover(np.where(np.isfinite(tgt[d]), tgt[d], 0.0), data.areas,
                                       labels[d])
        setups.append({"name": nm, "dm": dm, "sm": sm, "days": days, "labels": labels,
                       "tgt_patch": tgt_patch, "weight": float(e.weight)})
    first = setups[0]
    theta = {p: float((init or {}).get(p, first["dm"].default_value(p))) for p in params}
    start = dict(theta)
    scale = {p: float((scales or {}).get(p, parameter_scale(first["sm"], p))) for p in params}
    bnd = {p: parameter_bounds(first["sm"], p) for p in params}
    rows = []

    def discrete_eval(th):
        """Discrete means per experiment and day at ``th``, the summed loss, per-experiment
        records."""
        Ds, total, rec = [], 0.0, {}
        for s in setups:
            data = s["sm"].data
            r = s["dm"].run(th, report=s["days"])
            D = {d: s["dm"].to_layout(r.mean(d), data.shape_slices) for d in s["days"]}
            ld = float(np.mean([patch_loss_value(D[d], data.areas, s["labels"][d],
                                                 s["tgt_patch"][d], loss) for d in s["days"]]))
            total += s["weight"] * ld
            Ds.append(D)
            rec[s["name"]] = {"discrete_loss": ld, "covered_m2_discrete":
                              float(np.sum(D[s["days"][-1]] * data.areas))}
        return Ds, total, rec

    Ds, ld, rec = discrete_eval(theta)
    for k in range(iterations):
        terms, cov_r = [], 0.0
        for s, D in zip(setups, Ds):
            data, sm = s["sm"].data, s["sm"]
            with dr.suspend_grad():
                R = {d: np.asarray(sm.run(theta, days=d).cover, float) for d in s["days"]}
            for d in s["days"]:
                lf = _patch_loss(sm.T(D[d] - R[d]), data.areas, s["labels"][d],
                                 s["tgt_patch"][d], loss, sm.T)
                terms.append((sm, d, lambda res, m, lf=lf: lf(res.cover, None, None, m),
                              s["weight"] / len(s["days"])))
            c = float(np.sum(R[s["days"][-1]] * data.areas))
            rec[s["name"]]["covered_m2_relaxed"] = c
            cov_r += c
        new, inner = _inner_adam(terms, params, theta, scale, bnd, steps, lr, lr_final)
        move = max(abs(new[p] - theta[p]) / scale[p] for p in params)
        row = {"iteration": k, "params": dict(theta), "discrete_loss": ld,
               "covered_m2_discrete": sum(v["covered_m2_discrete"] for v in rec.values()),
               "covered_m2_relaxed": cov_r, "experiments": rec,
               "inner_loss": inner, "next": dict(new), "move": move}
        if verbose:
            cov = "; ".join(f"{nm}: discrete {v['covered_m2_discrete']:.4f} / relaxed "
                            f"{v['covered_m2_relaxed']:.4f} m2 (loss {v['discrete_loss']:.3e})"
                            for nm, v in rec.items())
            print(f"  iteration {k}: " + ", ".join(f"{p} {theta[p]:.5g} -> {new[p]:.5g}"
                                                    for p in params)
                  + f"; discrete loss {ld:.3e}; covered on the last target day: {cov}; "
                  f"{time.perf_counter() - t0:.0f} s", flush=True)
        if accept == "always":
            rows.append({**row, "seconds": time.perf_counter() - t0})
            theta = new
            Ds, ld, rec = discrete_eval(theta)
            if move < tol:
                break
            continue
        # safeguarded step: the full step, then halved ones, while the discrete loss rises
        trials, taken = [], 0.0
        for h in range(backtrack + 1):
            frac = 0.5 ** h
            cand = {p: theta[p] + frac * (new[p] - theta[p]) for p in params}
            Dc, lc, rc = discrete_eval(cand)
            trials.append({"step": frac, "params": cand, "discrete_loss": lc})
            if verbose:
                print(f"    step {frac:g}: discrete loss {lc:.3e} "
                      f"({'accepted' if lc < ld else 'rejected'}); "
                      f"{time.perf_counter() - t0:.0f} s", flush=True)
            if lc < ld:
                taken = frac
                theta, Ds, ld, rec = cand, Dc, lc, rc
                break
        rows.append({**row, "trials": trials, "step": taken,
                     "seconds": time.perf_counter() - t0})
        if taken == 0.0 or taken * move < tol:
            break
    rows.append({"iteration": len(rows), "params": dict(theta), "discrete_loss": ld,
                 "covered_m2_discrete": sum(v["covered_m2_discrete"] for v in rec.values()),
                 "experiments": rec, "seconds": time.perf_counter() - t0})
    if verbose:
        print("  final: " + ", ".join(f"{p} {theta[p]:.5g}" for p in params)
              + f"; discrete loss {ld:.3e}", flush=True)
    res = DiscreteFitResult(theta, start, rows, ld, time.perf_counter() - t0)
    if out is not None:
        import json
        o = Path(out)
        o.mkdir(parents=True, exist_ok=True)
        p = o / "fitted_discrete.json"
        p.write_text(json.dumps({"fitted": theta, "initial": start, "iterations": rows,
                                 "discrete_loss": ld,
                                 "experiments": [{"name": s["name"], "seeds": s["dm"].seeds,
                                                  "days": s["dm"].days,
                                                  "target_days": s["days"],
                                                  "weight": s["weight"]} for s in setups],
                                 "seeds": first["dm"].seeds, "days": first["dm"].days,
                                 "accept": accept, "backtrack": backtrack,
                                 "seconds": res.seconds}, indent=1))
        res.files["fitted"] = str(p)
    return res
