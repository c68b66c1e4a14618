"""Light-study tuning: fit emitter strengths or surface reflectances to a target light map.

People designing a planting measure (or specify) the light on the ground: a PAR map [W m-2] or
a red : far-red ratio map. :class:`LightStudy` traces the photon paths of a scene's emitters once
per band with the integrator's weights-mode pass
(:meth:`~mitsuba_veg.integrators.PhotonIrradianceIntegrator.trace_paths`: the
integrator's own emission sampling and ray casts, every photon continued with a weight instead of
Russian roulette) and replays them for any parameter values; :func:`fit_light` fits

- ``"strength.<emitter>"``: the emitter's strength (scale of its spectral power) [-];
- ``"albedo.<shape>"``: a shape's diffuse reflectance in every band [-];
- ``"albedo.<shape>.<band>"``: its reflectance in one band (a leaf-optics parameter: e.g. the
  far-red reflectance of a hedge sets the R:FR on the ground beside it) [-]

to a target map by Adam (Dr.Jit reverse mode through the replays). Quantities: ``"par"`` (band
irradiance 400-700 nm [W m-2] on the front side of every element), ``"r_fr"`` (photon flux ratio
red 655-665 nm : far-red 725-735 nm, as
:meth:`~mitsuba_veg.integrators.photon_irradiance.PhotonResult.red_far_red`), or any band of
``BANDS``. Loss: area-weighted mean squared relative difference (irradiance: divided by the
target's area-weighted mean; ratios: as they are) over the elements with a finite target.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..integrators.photon_irradiance import BANDS, PhotonIrradianceIntegrator, SceneIndex
from ..integrators.photon_replay import albedo_array
from ..units import umol_per_joule
from .discrete import patch_labels
from .fitting import param_names

__all__ = ["LightStudy", "LightFitResult", "fit_light"]



def _bands():
    return BANDS


class LightStudy:
    """Recorded photon paths of a scene, per emitter and band, and their differentiable replay.

    Parameters
    ----------
    scene : mitsuba.Scene
        The scene (emitters with ids; shapes loaded with ``optimize=False``).
    albedo : dict or array
        Base reflectance per shape id, a number or ``{band: number}`` [-] (shapes not listed: 0),
        or one value per element for every band.
    bands : sequence of str
        Bands of ``BANDS`` to trace ("par", "red", "far_red", "total" ...).
    emitters : sequence of str, optional
        Emitter ids (default: all emitters of the scene).
    photons : int
        Photons per emitter and band.
    max_depth : int
        Bounces recorded per photon.
    seed : int
        Seed of the passes (a different seed: independent photons).
    """

    def __init__(self, scene: mi.Scene, albedo: dict, bands=("par",), emitters=None,
                 photons: int = 200_000, max_depth: int = 8, seed: int = 0, index=None):
        B = _bands()
        self.bands = [b for b in bands]
        for b in self.bands:
            if b not in B:
                raise ParameterError("bands", b, "one of " + ", ".join(B))
        self.scene = scene
        self.index = SceneIndex.build(scene) if index is None else index
        ems = [e.id() for e in scene.emitters()]
        self.emitters = list(emitters) if emitters is not None else ems
        for e in self.emitters:
            if e not in ems:
                raise ParameterError("emitters", e, f"ids among {ems}")
        self.shape_slices = {sid: self.index.shape_slice(sid) for sid in self.index.shape_ids}
        self.base = {b: np.zeros(self.index.n_elements) for b in self.bands}
        if not isinstance(albedo, dict):             # one value per element, every band
            a = np.asarray(albedo, float)
            if a.shape != (self.index.n_elements,) or np.any(~(a >= 0)) or np.any(a > 1):
                raise ParameterError("albedo", f"array of shape {a.shape}",
                                     f"({self.index.n_elements},) values in [0, 1], or a dict")
            self.base = {b: a.copy() for b in self.bands}
            albedo = {}
        for sid, v in (albedo or {}).items():
            if sid not in self.shape_slices:
                raise ParameterError("albedo", sid, f"a shape id among {list(self.shape_slices)}")
            for b in self.bands:
                if isinstance(v, dict) and b not in v:
                    raise ParameterError(f"albedo[{sid!r}]", v, f"a number or a value for every "
                                         f"traced band {self.bands}")
                x = float(v[b] if isinstance(v, dict) else v)
                if not 0.0 <= x <= 1.0:
                    raise ParameterError(f"albedo[{sid!r}]", x, "[0, 1]")
                self.base[b][self.shape_slices[sid]] = x
        t0 = time.perf_counter()
        self.integrator = PhotonIrradianceIntegrator()
        self.paths = {(e, b): self.integrator.trace_paths(scene, e, photons,
                                                          seed * 7919 + 13 * k + 7 * j, max_depth,
                                                          band=B[b], index=self.index)
                      for k, e in enumerate(self.emitters) for j, b in enumerate(self.bands)}
        self.seconds = time.perf_counter() - t0
        self.F = dr.float64_array_t(mi.Float)

    def _canonical(self, name: str):
        parts = name.split(".")
        if parts[0] == "strength" and len(parts) == 2 and parts[1] in self.emitters:
            return ("strength", parts[1], None)
        if parts[0] == "albedo" and len(parts) in (2, 3) and parts[1] in self.shape_slices:
            if len(parts) == 3 and parts[2] not in self.bands:
                raise ParameterError("params", name, f"albedo.<shape>.<band> with a band among "
                                     f"{self.bands}")
            return ("albedo", parts[1], parts[2] if len(parts) == 3 else None)
        raise ParameterError("params", name, "strength.<emitter> (" + ", ".join(self.emitters)
                             + "), albedo.<shape> or albedo.<shape>.<band> (shapes "
                             + ", ".join(self.shape_slices) + ")")

    def default_value(self, name: str) -> float:
        """The study's base value of a parameter.

        Parameters
        ----------
        name : str
            ``strength.<emitter>``, ``albedo.<shape>`` or ``albedo.<shape>.<band>``.

        Returns
        -------
        float
            1 for a strength; the shape's mean base reflectance [-] in the band (default: the
            first traced band).
        """
        c = self._canonical(name)
        if c[0] == "strength":
            return 1.0
        b = c[2] or self.bands[0]
        return float(np.mean(self.base[b][self.shape_slices[c[1]]]))

    def irradiance(self, params: dict | None = None, band: str | None = None):
        """Front-side band irradiance per element.

        Parameters
        ----------
        params : dict, optional
            ``{name: value}`` (values may be Dr.Jit scalars with gradients).
        band : str, optional
            A traced band (default: the first).

        Returns
        -------
        Float64
            Irradiance per element [W m-2], differentiable in the parameter values.
        """
        band = band or self.bands[0]
        if band not in self.bands:
            raise ParameterError("band", band, f"one of the traced bands {self.bands}")
        F = self.F
        strength, alb = {}, {}
        for name, v in (params or {}).items():
            c = self._canonical(name)
            if c[0] == "strength":
                strength[c[1]] = v
            elif c[2] is None or c[2] == band:
                alb[c[1]] = v
        a = albedo_array(self.index.n_elements, self.base[band], alb, self.shape_slices, F)
        out = None
        for e in self.emitters:
            x = self.integrator.replay(self.paths[(e, band)], a, strength.get(e, 1.0),
                                       irradiance=True)
            out = x if out is None else out + x
        return out

    def quantity(self, params: dict | None, quantity: str):
        """A light quantity per element.

        Parameters
        ----------
        params : dict or None
            ``{name: value}``.
        quantity : str
            ``"r_fr"`` or a traced band's name.

        Returns
        -------
        Float64
            The red : far-red photon ratio [-] or the band's irradiance [W m-2] per element.
        """
        if quantity == "r_fr":
            B = _bands()
            for b in ("red", "far_red"):
                if b not in self.bands:
                    raise ParameterError("quantity", quantity, "a band among the traced "
                                         f"{self.bands}", "trace bands=('red', 'far_red')")
            r = self.irradiance(params, "red") * umol_per_joule(*B["red"])
            f = self.irradiance(params, "far_red") * umol_per_joule(*B["far_red"])
            return r / dr.maximum(f, 1e-30)
        return self.irradiance(params, quantity)


@dataclass
class LightFitResult:
    """The result of :func:`fit_light` (emitter strengths or reflectances fitted to a light map).

    Attributes
    ----------
    values : dict
        Fitted values, by parameter name.
    initial : dict
        Starting values.
    history : list
        Per step: loss, parameters and gradient.
    loss : float
        Final loss.
    seconds : float
        Wall time [s].
    stats : dict
        Timings and counts.
    """

    values: dict
    initial: dict
    history: list
    loss: float
    seconds: float = 0.0
    stats: dict = field(default_factory=dict)


def fit_light(study: LightStudy, target, params, quantity: str = "par", init: dict | None = None,
              mask=None, steps: int = 150, lr: float = 0.05, lr_final: float = 0.02,
              bounds: dict | None = None, method: str = "least_squares",
              patch: float | None = None) -> LightFitResult:
    """Fit light parameters so that ``quantity`` per element matches ``target``.

    Parameters
    ----------
    study : LightStudy
        The traced scene.
    target : array
        One value per element (NaN = ignore): band irradiance [W m-2] or the R:FR ratio [-].
    params : list of str
        Parameter names (module docstring).
    quantity : str
        ``"par"``, another traced band, or ``"r_fr"``.
    init : dict, optional
        Starting values (default: the study's).
    mask : bool array, optional
        Elements that count (e.g. the ground's); combined with the finite targets.
    steps, lr, lr_final : int, float, float
        ``method="adam"``: Adam steps and learning rate on the parameters scaled by their start
        (decaying to ``lr * lr_final``); ``method="least_squares"``: at most ``steps``
        evaluations.
    bounds : dict, optional
        ``{name: (lo, hi)}``; default strengths [0, 100], reflectances [0, 0.99].
    method : {"least_squares", "adam"}
        ``"least_squares"`` (default): SciPy's trust-region reflective least squares on the
        residuals with the Jacobian from Dr.Jit forward mode (one pass per parameter). The
        irradiance is linear in the strengths and polynomial in the reflectances, so
        Gauss-Newton steps converge in a few evaluations where Adam creeps along the valley of
        correlated parameters (sun and sky strength). ``"adam"``: Adam on the loss.
    patch : float, optional
        Compare area-weighted means over patches (the triangles of one shape within a cube of
        side ``patch`` [m]) instead of single triangles (``method="least_squares"`` only). A
        measured map and a photon pass are both noisy per triangle; with noise in the model's
        own light as well as in the target, a per-triangle least-squares fit is biased
        (errors in variables: on the moss garden with 300 k photons per map, sun and sky
        strength came out +9 % / -14 %); patches average the noise away.

    Returns
    -------
    LightFitResult
        Fitted and starting values, the history of the evaluations, the final loss, time and
        statistics.
    """
    t0 = time.perf_counter()
    params = param_names(params)
    if steps < 1:
        raise ParameterError("steps", steps, ">= 1")
    for p in params:
        study._canonical(p)
    if quantity != "r_fr" and quantity not in study.bands:
        raise ParameterError("quantity", quantity, f"'r_fr' or a traced band {study.bands}")
    n = study.index.n_elements
    tgt = np.asarray(target, float)
    if tgt.shape != (n,):
        raise ParameterError("target", f"shape {tgt.shape}", f"({n},): one value per element")
    ok = np.isfinite(tgt)
    if mask is not None:
        ok &= np.asarray(mask, bool)
    if not ok.any():
        raise ParameterError("target", "no finite value in the mask", "at least one element")
    if np.any(tgt[ok] < 0):
        raise ParameterError("target", float(tgt[ok].min()), ">= 0 (irradiance or ratio)")
    areas = np.asarray(study.index.areas, float)
    w = np.where(ok, areas, 0.0)
    w /= w.sum()
    norm = 1.0 if quantity == "r_fr" else float(np.sum(w * np.where(ok, tgt, 0.0)))
    if not norm > 0:
        raise ParameterError("target", "mean 0", "a target with light on the masked elements")
    F = study.F
    w_dr, t_dr = F(w / norm ** 2), F(np.where(ok, tgt, 0.0))
    start = {p: float((init or {}).get(p, study.default_value(p))) for p in params}
    bnd = {}
    for p in params:
        c = study._canonical(p)
        bnd[p] = tuple((bounds or {}).get(p, (0.0, 100.0) if c[0] == "strength" else (0.0, 0.99)))
        if not bnd[p][0] <= start[p] <= bnd[p][1]:
            raise ParameterError(f"init[{p!r}]", start[p], f"[{bnd[p][0]}, {bnd[p][1]}]")
    scale = {p: max(abs(start[p]), 0.05) for p in params}
    opt = mi.ad.Adam(lr=lr, beta_1=0.9, beta_2=0.9)
    for p in params:
        opt[p] = mi.Float(0.0)
    decay = lr_final ** (1.0 / max(steps - 1, 1))
    history = []

    def values():
        return {p: start[p] + scale[p] * float(np.asarray(dr.detach(opt[p]))[0]) for p in params}

    def evaluate(vals, grad: bool):
        xs = {}
        for p in params:
            x = F(vals[p])
            dr.make_opaque(x)
            if grad:
                dr.enable_grad(x)
            xs[p] = x
        q = study.quantity(xs, quantity)
        d = q - t_dr
        loss = dr.sum(d * d * w_dr)
        if grad:
            dr.backward(loss)
            g = {p: float(np.asarray(dr.grad(xs[p]))[0]) for p in params}
        else:
            g = {}
        return float(np.asarray(dr.detach(loss))[0]), g

    if method not in ("adam", "least_squares"):
        raise ParameterError("method", method, "'adam' or 'least_squares'")
    if patch is not None and method != "least_squares":
        raise ParameterError("patch", patch, "None with method='adam'",
                             "use method='least_squares' for patch means")
    if method == "least_squares":
        labels = None
        if patch is not None:
            labels = patch_labels(study.index.centroids, study.shape_slices, ok, float(patch))
        return _least_squares(study, params, quantity, start, bnd, scale, ok, w / norm ** 2,
                              t_dr, steps, t0, labels, areas)
    for k in range(steps):
        vals = values()
        loss, g = evaluate(vals, True)
        history.append({"step": k, "loss": loss, "params": vals, "grad": g})
        if not math.isfinite(loss):
            raise FloatingPointError(f"fit_light: non-finite loss at step {k}: {vals}")
        for p in params:
            dr.set_grad(opt[p], mi.Float(g[p] * scale[p]))
        opt.set_learning_rate(lr * decay ** k)
        opt.step()
        for p in params:
            lo, hi = (bnd[p][0] - start[p]) / scale[p], (bnd[p][1] - start[p]) / scale[p]
            opt[p] = dr.clip(dr.detach(opt[p]), lo, hi)
    vals = values()
    loss, _ = evaluate(vals, False)
    history.append({"step": steps, "loss": loss, "params": vals, "grad": {}})
    return LightFitResult(vals, start, history, loss, time.perf_counter() - t0,
                          {"quantity": quantity, "steps": steps, "lr": lr, "scales": scale,
                           "bounds": bnd, "photons": next(iter(study.paths.values())).photons})


def _least_squares(study, params, quantity, start, bnd, scale, ok, w, t_dr, steps, t0,
                   labels=None, areas=None):
    from scipy.optimize import least_squares
    F = study.F
    if labels is None:
        sw = np.sqrt(w[ok])

        def agg(x):
            return x[ok]
    else:
        lab = labels[ok]
        n_p = int(lab.max()) + 1
        pa = np.bincount(lab, weights=areas[ok], minlength=n_p)
        # w = area / sum(area) / norm^2 per element -> per patch: its share / norm^2
        sw = np.sqrt(np.bincount(lab, weights=w[ok], minlength=n_p))

        def agg(x):
            return np.bincount(lab, weights=(areas * x)[ok], minlength=n_p) / pa
    history = []

    def vals_of(z):
        return {p: start[p] + scale[p] * float(z[i]) for i, p in enumerate(params)}

    def res(z):
        v = vals_of(z)
        q = np.asarray(study.quantity({p: F(x) for p, x in v.items()}, quantity))
        r = sw * (agg(q) - agg(np.asarray(t_dr)))
        history.append({"step": len(history), "loss": float(r @ r), "params": v, "grad": {}})
        return r

    def jac(z):
        v = vals_of(z)
        J = np.zeros((len(sw), len(params)))
        for i, p in enumerate(params):
            xs = {k: F(x) for k, x in v.items()}
            dr.enable_grad(xs[p])
            q = study.quantity(xs, quantity)
            dr.forward(xs[p])
            J[:, i] = sw * agg(np.asarray(dr.grad(q))) * scale[p]
        return J

    lo = [(bnd[p][0] - start[p]) / scale[p] for p in params]
    hi = [(bnd[p][1] - start[p]) / scale[p] for p in params]
    sol = least_squares(res, np.zeros(len(params)), jac=jac, bounds=(lo, hi), method="trf",
                        max_nfev=max(int(steps), 2), x_scale=1.0)
    vals = vals_of(sol.x)
    loss = float(sol.fun @ sol.fun)
    history.append({"step": len(history), "loss": loss, "params": vals, "grad": {}})
    return LightFitResult(vals, start, history, loss, time.perf_counter() - t0,
                          {"quantity": quantity, "method": "least_squares", "nfev": sol.nfev,
                           "scales": scale, "bounds": bnd,
                           "photons": next(iter(study.paths.values())).photons})
