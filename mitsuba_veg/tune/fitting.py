"""``fit``: tune model parameters so that the relaxed moss run matches a target coverage map.

Example::

    from mitsuba_veg import tune
    res = tune.fit("scenes/moss_garden/scenario.toml", target, params=["S1", "T1"], steps=60,
                   days=30, species=["bryum_argenteum"], out="out/tune")
    res.values            # {"S1": ..., "T1": ...}
    res.files             # fitted.json, loss_curve.png, coverage.png

Adam (``mi.ad.Adam`` = ``drjit.opt.Adam``) runs on *normalised* parameters x = (p - p_start) /
scale (scale: a natural width, e.g. T1 - T0 for a temperature bound, 0.1 for an albedo), so one
learning rate fits all; the learning rate decays geometrically to ``lr * lr_final`` over the
steps; after every step the parameters are clipped into their bounds. Gradients come from
:func:`mitsuba_veg.tune.grad.value_and_grad` (day-by-day adjoint with checkpoints).

Target: per-element covered fraction (NumPy, one value per triangle of the scene in the
SceneIndex order, NaN = ignore), a ``{shape_id: array}`` dict, or a :class:`RunResult`.
Loss: ``"sqrt"`` (default: area-weighted mean squared difference of the square roots of the
covered fractions, over the elements with a finite target; the square root stabilises the
variance of a fraction and gives the many sparsely covered triangles a say: on the moss garden it
halved the condition number of the (S1, T1) problem against ``"mse"``), ``"mse"`` (of the
fractions themselves), ``"l1"`` (a smooth L1, Huber with delta 0.01) or a callable
``loss(cover, target, weights, model) -> width-1 Dr.Jit array``.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..moss.population import MOSS
from ..plots import _mpl, loss_curve_figure, plan_map
from .grad import loss_value, value_and_grad
from .smooth import ModelData, RunResult, SmoothMossModel, prepare

__all__ = ["fit", "FitResult", "target_array", "parameter_scale", "parameter_bounds",
           "coverage_loss", "coverage_figure", "coverage_from_checkpoint"]


@dataclass
class FitResult:
    """The result of :func:`fit` (the relaxed moss model fitted by Adam).

    Attributes
    ----------
    values : dict
        Fitted parameter values.
    initial : dict
        Starting values.
    history : list
        Per step: ``{"step", "loss", "params": {...}, "grad": {...}}``.
    loss : float
        Final loss (at ``values``).
    files : dict
        Files written (``fitted.json``, ``loss_curve.png``, ...).
    seconds : float
        Wall time of the fit [s].
    model : SmoothMossModel or None
        The model at the fitted values.
    stats : dict
        Timings and counts of the fit.
    """

    values: dict                  # fitted parameter values
    initial: dict                 # starting values
    history: list                 # per step: {"step", "loss", "params": {...}, "grad": {...}}
    loss: float                   # final loss (at ``values``)
    files: dict = field(default_factory=dict)
    seconds: float = 0.0
    model: SmoothMossModel | None = None
    stats: dict = field(default_factory=dict)


# ------------------------------------------------------------------------------------------
# parameter scales and bounds
# ------------------------------------------------------------------------------------------
def param_names(params) -> list[str]:
    """The names of the parameters to fit as a list (one name may be given as a string).

    Parameters
    ----------
    params : str or iterable of str
        One name or several.

    Returns
    -------
    list of str
        The names.

    Raises
    ------
    ParameterError
        When no name is given.
    """
    params = [params] if isinstance(params, str) else list(params)
    if not params:
        raise ParameterError("params", params, "at least one parameter name")
    return params


def parameter_scale(model: SmoothMossModel, name: str) -> float:
    """Natural scale of a parameter (the step that matters).

    Parameters
    ----------
    model : SmoothMossModel
        The relaxed model (its species give the ranges).
    name : str
        Parameter name.

    Returns
    -------
    float
        The width of its range for range bounds (T1 - T0 [K], S1 - S0 [W m-2], rh1 - rh0 [-]),
        0.1 for fractions, albedos and humidity, 0.2 for emitter strengths, 5 K for the air
        temperature.
    """
    c = model._canonical(name)
    if c[0] == "climate":
        return 5.0 if c[1] == "T" else 0.1
    if c[0] == "albedo":
        return 0.1
    if c[0] == "strength":
        return 0.2
    sp = model.data.species[c[1]]
    f = c[2]
    for lo, hi in (("T0", "T1"), ("rh0", "rh1"), ("S0", "S1")):
        if f in (lo, hi):
            return float(getattr(sp, hi) - getattr(sp, lo))
    return 0.1


def parameter_bounds(model: SmoothMossModel, name: str) -> tuple[float, float]:
    """Allowed interval of a parameter (validated ranges of table 3.7, physical limits).

    Parameters
    ----------
    model : SmoothMossModel
        The relaxed model.
    name : str
        Parameter name.

    Returns
    -------
    tuple of float
        (lower, upper) in the parameter's unit.
    """
    c = model._canonical(name)
    if c[0] == "climate":
        return (200.0, 340.0) if c[1] == "T" else (0.01, 1.0)
    if c[0] == "albedo":
        return (0.0, 0.99)
    if c[0] == "strength":
        return (0.0, 100.0)
    f = c[2]
    if f in ("T0", "T1"):
        return (150.0, 400.0)
    if f in ("rh0", "rh1"):
        return (0.0, 3.0)
    if f in ("S0", "S1"):
        return (0.0, 5000.0)
    if f in ("nT", "nrh", "nS"):
        return (0.05, 1.0)
    return (1e-3, 0.999)


# ------------------------------------------------------------------------------------------
# targets and losses
# ------------------------------------------------------------------------------------------
def target_array(model: SmoothMossModel, target) -> np.ndarray:
    """A per-element target covered fraction (NaN = not part of the loss).

    Parameters
    ----------
    model : SmoothMossModel
        The relaxed model (its elements give the layout).
    target : RunResult, dict or array_like
        A relaxed run, ``{shape_id: per-triangle array}`` or an (n,) array of covered
        fractions [-].

    Returns
    -------
    ndarray
        (n,) covered fraction per element [-], NaN where the target has none.
    """
    d = model.data
    if isinstance(target, RunResult):
        return np.asarray(target.cover, float)
    if isinstance(target, dict):
        out = np.full(d.n, np.nan)
        for sid, arr in target.items():
            if sid not in d.shape_slices:
                raise ParameterError("target", sid, f"a shape id among {list(d.shape_slices)}")
            sl = d.shape_slices[sid]
            a = np.asarray(arr, float)
            if a.shape != (sl.stop - sl.start,):
                raise ParameterError(f"target['{sid}']", f"shape {a.shape}",
                                     f"({sl.stop - sl.start},): one value per triangle")
            out[sl] = a
        return out
    a = np.asarray(target, float)
    if a.shape != (d.n,):
        raise ParameterError("target", f"array of shape {a.shape}",
                             f"({d.n},): one covered fraction per element of the scene")
    finite = a[np.isfinite(a)]
    if finite.size == 0:
        raise ParameterError("target", "all NaN", "at least one finite value")
    if finite.min() < -1e-6 or finite.max() > 1 + 1e-6:
        raise ParameterError("target", f"values in [{finite.min():g}, {finite.max():g}]",
                             "[0, 1] (covered fraction of each triangle)")
    return a


def coverage_loss(kind="mse"):
    """The loss function used by :func:`fit` for ``loss=kind``.

    Parameters
    ----------
    kind : {"mse", "sqrt", "l1"} or callable
        Squared difference, squared difference of square roots, a Huber-like L1 (0.01 wide
        quadratic core), or a callable ``(cover, target, weights, model) -> loss`` returned as
        it is.

    Returns
    -------
    callable
        ``loss(cover, target, weights, model)``: the weighted sum over the elements (Dr.Jit).
    """
    if callable(kind):
        return kind
    if kind not in ("sqrt", "mse", "l1"):
        raise ParameterError("loss", kind, "'sqrt', 'mse', 'l1' or a callable")

    def loss(cover, target, weights, model):
        diff = cover - target
        if kind == "sqrt":
            diff = dr.sqrt(cover + 1e-6) - dr.sqrt(target + 1e-6)
            e = diff * diff
        elif kind == "mse":
            e = diff * diff
        else:
            ad = dr.abs(diff)
            e = dr.select(ad < 0.01, 0.5 * diff * diff / 0.01, ad - 0.005)
        return dr.sum(e * weights)
    return loss


# ------------------------------------------------------------------------------------------
# fit
# ------------------------------------------------------------------------------------------
def _as_model(scenario, days, species, temperature, precision, prepare_kw,
              closure: str = "mean-field") -> SmoothMossModel:
    if isinstance(scenario, SmoothMossModel):
        return scenario
    if isinstance(scenario, ModelData):
        data = scenario
    else:
        data = prepare(scenario, days=days, species=species, **prepare_kw)
    return SmoothMossModel(data, temperature=temperature, days=days, precision=precision,
                           closure=closure)


def fit(scenario, target, params=("S1", "T1"), loss="sqrt", steps: int = 80, lr: float = 0.08,
        lr_final: float = 0.03, days: int | None = None, init: dict | None = None,
        temperature: float = 0.05, species=None, out="out/tune", progress: bool = True,
        precision: str = "float32", checkpoint_every: int | None = None, scales: dict | None = None,
        bounds: dict | None = None, plots: bool = True, beta_1: float = 0.9, beta_2: float = 0.9,
        closure: str = "mean-field", **prepare_kw) -> FitResult:
    """Fit ``params`` so that the relaxed run's covered fraction per triangle matches ``target``.

    Parameters
    ----------
    scenario : path, Scenario, ModelData or SmoothMossModel
        A scenario TOML path, a :class:`~mitsuba_veg.scenario.Scenario`, prepared
        :class:`ModelData` or a :class:`SmoothMossModel` (then ``days``, ``species``,
        ``temperature``, ``precision``, ``closure`` come from it).
    target : array_like, dict or RunResult
        Covered fraction per element [-] (:func:`target_array`; NaN = not in the loss).
    params : list of str
        Names (see :meth:`SmoothMossModel.parameter_names`: ``"S1"``,
        ``"bryum_argenteum.T1"``, ``"T"``, ``"rh"``, ``"albedo.roof"``, ``"strength.sun"`` ...).
    loss : {"sqrt", "mse", "l1"} or callable
        The loss (:func:`coverage_loss`), weighted by element area.
    steps : int
        Adam steps.
    lr : float
        Learning rate on the normalised parameters (p - init) / scale [-].
    lr_final : float
        Its geometric decay, down to ``lr * lr_final`` [-].
    days : int, optional
        Days to run [d] (default: the model's).
    init : dict, optional
        Starting values (default: the scenario's).
    temperature : float
        Relaxation temperature t of the thresholds [-].
    species : list of str, optional
        Species keys replacing ``moss.species``.
    out : path or None
        Folder for ``fitted.json``, ``loss_curve.png`` and ``coverage.png`` (None: write
        nothing).
    progress : bool
        Show a progress bar.
    precision : {"float32", "float64"}
        Floating-point precision of the relaxed model.
    checkpoint_every : int, optional
        Days between checkpoints of the day-by-day adjoint (:func:`value_and_grad`).
    scales : dict, optional
        Natural scale per parameter (default: :func:`parameter_scale`).
    bounds : dict, optional
        (lower, upper) per parameter (default: :func:`parameter_bounds`).
    plots : bool
        Write the figures.
    beta_1, beta_2 : float
        Adam's moment decay rates [-].
    closure : {"mean-field", "near-field"}
        The relaxed model's spatial closure (docs/tuning.md: the near field is closer to
        discrete runs while moss spreads).
    **prepare_kw : dict
        Further keywords for :func:`prepare` (``photons``, ``light_every``,
        ``differentiable_light`` ...; it is switched on when an albedo or strength is fitted).

    Returns
    -------
    FitResult
        Fitted values, starting values, the history of the steps, the final loss, written
        files, time and settings.
    """
    t0 = time.perf_counter()
    params = param_names(params)
    if steps < 1:
        raise ParameterError("steps", steps, ">= 1")
    for k in (init or {}):
        if k not in params:
            raise ParameterError("init", k, f"one of the fitted parameters {params}",
                                 "fit it (params=...) or drop its starting value")
    if any(p.startswith(("albedo.", "strength.")) for p in params):
        prepare_kw.setdefault("differentiable_light", True)
    model = _as_model(scenario, days, species, temperature, precision, prepare_kw, closure)
    for p in params:
        model._canonical(p)  # validates the names
    T = model.T
    tgt = target_array(model, target)
    mask = np.isfinite(tgt)
    w = np.where(mask, model.data.areas, 0.0)
    w = w / w.sum()
    tgt_dr = T(np.where(mask, tgt, 0.0))
    w_dr = T(w)
    lf = coverage_loss(loss)

    def loss_fn(res: RunResult, m):
        return lf(res.cover, tgt_dr, w_dr, m)

    start = {p: float((init or {}).get(p, model.default_value(p))) for p in params}
    scale = {p: float((scales or {}).get(p, parameter_scale(model, p))) for p in params}
    bnd = {p: tuple((bounds or {}).get(p, parameter_bounds(model, p))) for p in params}
    for p in params:
        if not bnd[p][0] <= start[p] <= bnd[p][1]:
            raise ParameterError(f"init[{p!r}]", start[p], f"[{bnd[p][0]}, {bnd[p][1]}]")

    # beta_2 = 0.9 (not 0.999): with a few dozen steps a long second-moment memory keeps the
    # large early gradients and freezes the last steps near the optimum
    opt = mi.ad.Adam(lr=lr, beta_1=beta_1, beta_2=beta_2)
    for p in params:
        opt[p] = T(0.0)
    decay = lr_final ** (1.0 / max(steps - 1, 1))
    history = []
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=steps, desc="fit", unit="step")

    def physical():
        return {p: start[p] + scale[p] * float(np.asarray(dr.detach(opt[p])).ravel()[0])
                for p in params}

    for k in range(steps):
        values = physical()
        r = value_and_grad(model, values, loss_fn, checkpoint_every=checkpoint_every)
        history.append({"step": k, "loss": r.loss, "params": values, "grad": r.grad,
                        "seconds": r.seconds})
        if not math.isfinite(r.loss) or not all(math.isfinite(g) for g in r.grad.values()):
            raise FloatingPointError(f"fit: non-finite loss or gradient at step {k}: "
                                     f"loss {r.loss}, grad {r.grad}, params {values}")
        for p in params:
            dr.set_grad(opt[p], T(r.grad[p] * scale[p]))
        opt.set_learning_rate(lr * decay ** k)
        opt.step()
        for p in params:  # bounds on the physical values
            lo, hi = ((bnd[p][0] - start[p]) / scale[p], (bnd[p][1] - start[p]) / scale[p])
            opt[p] = dr.clip(dr.detach(opt[p]), lo, hi)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(loss=f"{r.loss:.3e}",
                            **{p.split(".")[-1]: f"{v:.4g}" for p, v in values.items()})
    if bar is not None:
        bar.close()
    values = physical()
    final_loss = loss_value(model, values, loss_fn)
    history.append({"step": steps, "loss": final_loss, "params": values, "grad": {},
                    "seconds": 0.0})
    res = FitResult(values, start, history, final_loss, {}, time.perf_counter() - t0, model,
                    {"days": model.days, "temperature": model.t, "precision": model.precision,
                     "lr": lr, "lr_final": lr_final, "beta_1": beta_1, "beta_2": beta_2,
                     "scales": scale, "bounds": bnd,
                     "loss": loss if isinstance(loss, str)
                     else getattr(loss, "__name__", "custom")})
    if out is not None:
        res.files = write_outputs(res, Path(out), tgt, plots)
    return res


def write_outputs(res: FitResult, out: Path, target: np.ndarray, plots: bool = True) -> dict:
    """fitted.json, loss_curve.png and coverage.png (target vs fitted cover on the ground).

    Parameters
    ----------
    res : FitResult
        The fit.
    out : Path
        Output folder.
    target : ndarray
        (n,) target covered fraction per element [-].
    plots : bool
        Write the figures (else only ``fitted.json``).

    Returns
    -------
    dict
        ``{kind: path}`` of the written files.
    """
    out.mkdir(parents=True, exist_ok=True)
    files = {}
    summary = {"fitted": res.values, "initial": res.initial, "final_loss": res.loss,
               "steps": len(res.history) - 1, "seconds": res.seconds, "settings": res.stats,
               "history": [{"step": h["step"], "loss": h["loss"], "params": h["params"],
                            "grad": h["grad"]} for h in res.history]}
    p = out / "fitted.json"
    p.write_text(json.dumps(summary, indent=1))
    files["fitted"] = str(p)
    if not plots:
        return files
    p = loss_curve_figure(res.history, out / "loss_curve.png")
    files["loss_curve"] = str(p)
    m = res.model
    if m is not None:
        with dr.suspend_grad():
            cover = np.asarray(m.run(res.values).cover, float)
        p = out / "coverage.png"
        coverage_figure(m.data, {"target": target, "fitted": cover}, p)
        files["coverage"] = str(p)
    return files


def coverage_figure(data: ModelData, maps: dict, path, shape: str | None = None) -> str:
    """Plan view of covered fractions on the ground (one panel per entry of ``maps``).

    Parameters
    ----------
    data : ModelData
        The prepared scene.
    maps : dict
        ``{title: (n,) covered fraction [-]}``; with two maps a difference panel is added.
    path : path
        PNG to write.
    shape : str, optional
        Shape to draw (default: the scenario's ground).

    Returns
    -------
    str
        The written path.
    """
    plt = _mpl()
    gid = shape or data.scenario.get("terrain.ground", "ground")
    sl = data.shape_slices[gid]
    v, f = data.index.geometry[gid]
    vals = {k: np.asarray(x, float)[sl] for k, x in maps.items()}
    vmax = max([float(np.nanmax(x)) for x in vals.values()] + [0.02])
    panels = list(vals.items())
    if len(vals) == 2:  # target and fitted: show the difference too
        (na, a), (nb, b) = panels
        panels.append((f"{nb} - {na}", b - a))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 4.0))
    axes = np.atleast_1d(axes)
    for i, (ax, (name, x)) in enumerate(zip(axes, panels)):
        if i < len(vals):
            plan_map(ax, v, f, x, title=name, label="covered fraction", cmap="Greens",
                     vmin=0.0, vmax=vmax)
        else:
            r = max(float(np.nanmax(np.abs(x))), 1e-6)
            plan_map(ax, v, f, x, title=name, label="difference", cmap="RdBu_r", vmin=-r,
                     vmax=r)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def coverage_from_checkpoint(path, data: ModelData) -> np.ndarray:
    """Per-element covered fraction of a *discrete* run (its ``checkpoint.npz``), as the run
    computes it: min(moss on the triangle x size², area) / area. Use it as a fit target.

    Parameters
    ----------
    path : path
        The run's ``checkpoint.npz``.
    data : ModelData
        The prepared scene of the same scenario.

    Returns
    -------
    ndarray
        (n,) covered fraction per element [-].
    """
    d = np.load(path, allow_pickle=False)
    moss = np.asarray(d["state"]) == MOSS
    counts = np.bincount(np.asarray(d["elem"])[moss].astype(np.int64), minlength=data.n)
    if counts.shape != (data.n,):
        raise ParameterError("checkpoint", str(path), f"a run of a scene with {data.n} elements")
    return np.minimum(counts * data.cell ** 2, data.areas) / data.areas
