"""``fit_leaf_colour``: fit PROSPECT-D contents (pigments, structure ...) to a target leaf colour.

    from mitsuba_veg import tune
    res = tune.fit_leaf_colour((0.32, 0.27, 0.22), params=("Cab", "Car", "Anth"), out="out/leaf")
    res.values     # {"Cab": ..., "Car": ..., "Anth": ...} [µg cm-2]
    res.files      # fitted.json, loss_curve.png, leaf_colour.png

The forward model is :func:`mitsuba_veg.foliage.prospect_dr.prospect_d` (PROSPECT-D in Dr.Jit,
Féret et al. 2017) followed by :mod:`mitsuba_veg.foliage.colour_dr` (CIE 1931 XYZ under D65 ->
linear sRGB / CIELAB); Dr.Jit differentiates the whole chain. The optimiser follows
:func:`mitsuba_veg.tune.fit`: Adam (``mi.ad.Adam``) on normalised parameters
x = (p - p_start) / scale, a learning rate that decays geometrically to ``lr * lr_final``,
parameters clipped into their bounds after every step, a tqdm progress bar, ``fitted.json`` and
``loss_curve.png``. ``method="least_squares"`` instead runs SciPy's trust-region least squares
with the residuals' Jacobian from Dr.Jit forward mode (tens of evaluations). Starts that are not
given come from a look-up table of random leaves (the classic PROSPECT inversion).

Targets:

- an encoded sRGB triple in [0, 1] (as :func:`mitsuba_veg.foliage.spectra.spectrum_to_srgb`
  gives: reflectance under D65 times ``exposure``), also ``{"srgb": (r, g, b)}``;
- ``{"lab": (L*, a*, b*)}`` (CIELAB against the perfect reflector under the illuminant);
- a measured spectrum: ``{"reflectance": values, "wavelength": nm}`` (or ``"transmittance"``;
  without ``wavelength``: 2101 values on the PROSPECT-D grid, 400-2500 nm by 1 nm), or such an
  array directly. It is interpolated onto the whole nanometres it covers.

Losses: ``"lab"`` (ΔE*ab² = ΔL*² + Δa*² + Δb*², CIE 1976), ``"rgb"`` (squared difference of
encoded sRGB, unclipped), ``"spectrum"`` (mean squared difference of the spectrum over the
target's wavelengths; the default for spectrum targets). A spectrum target with ``loss="lab"``
or ``"rgb"`` is reduced to its colour first.

Identifiability: a colour is three numbers, so at most three parameters can be fitted to it,
and only where the 3 × k Jacobian d(L*, a*, b*)/dp is well conditioned; see
:func:`colour_sensitivity` and docs/tuning.md ("Leaf colour").
"""
from __future__ import annotations

import json
import math
import numbers
import time
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..foliage import colour_dr as cdr
from ..foliage.pigments import LeafTraits
from ..foliage.prospect import WAVELENGTHS
from ..foliage.prospect_dr import BOUNDS, PARAMETERS, Float64, prospect_d
from ..plots import _mpl, loss_curve_figure

__all__ = ["fit_leaf_colour", "LeafColourFit", "LeafColourTarget", "parse_target",
           "predict_leaf_colour", "colour_sensitivity", "DEFAULTS", "SCALES"]

#: wavelengths that carry the colour (the CIE tables end at 830 nm, PROSPECT-D starts at 400)
COLOUR_RANGE = (400, 830)

#: default values of the inputs that are not given (a thin maple leaf, :class:`LeafTraits`,
#: with mid-autumn pigment contents as the start of a fit)
DEFAULTS = {"N": LeafTraits().N, "Cab": 30.0, "Car": 5.0, "Anth": 5.0,
            "Cbrown": LeafTraits().Cbrown, "Cw": LeafTraits().Cw, "Cm": LeafTraits().Cm}

#: natural scale of each input (the normalised Adam variable moves the value by this per unit)
SCALES = {"N": 0.3, "Cab": 10.0, "Car": 2.0, "Anth": 5.0, "Cbrown": 0.2, "Cw": 0.005,
          "Cm": 0.002}

_SIDES = ("reflectance", "transmittance")


# ------------------------------------------------------------------------------------------
# targets
# ------------------------------------------------------------------------------------------
@dataclass
class LeafColourTarget:
    """A parsed target: its colour (always) and, for spectrum targets, the spectrum."""

    kind: str                    # "srgb", "lab" or "spectrum"
    side: str                    # "reflectance" or "transmittance"
    xyz: np.ndarray              # CIE XYZ of the leaf (before exposure)
    lab: np.ndarray              # CIELAB (after exposure)
    srgb: np.ndarray             # encoded sRGB (after exposure, clipped for display)
    wavelength: np.ndarray | None = None   # [nm], whole nanometres (spectrum targets)
    spectrum: np.ndarray | None = None     # target spectrum on ``wavelength``


def _colour_weights(illuminant):
    wl = np.arange(COLOUR_RANGE[0], COLOUR_RANGE[1] + 1, dtype=np.float64)
    if not isinstance(illuminant, str):
        ill = np.asarray(illuminant, dtype=np.float64)
        if ill.shape == (len(WAVELENGTHS),):   # given on the PROSPECT-D grid: cut to 400-830
            illuminant = ill[: len(wl)]
    return wl, cdr.colour_weights(wl, illuminant)


def _as_spectrum(values, wavelength, side):
    v = np.asarray(values, dtype=np.float64).ravel()
    if wavelength is None:
        if v.shape != WAVELENGTHS.shape:
            raise ParameterError(f"target {side}", f"{v.size} values",
                                 f"{len(WAVELENGTHS)} values (400-2500 nm by 1 nm) or a "
                                 "'wavelength' array of the same length",
                                 "pass {'reflectance': values, 'wavelength': nm}")
        wl_in = WAVELENGTHS
    else:
        wl_in = np.asarray(wavelength, dtype=np.float64).ravel()
        if wl_in.shape != v.shape or v.size < 2 or np.any(np.diff(wl_in) <= 0):
            raise ParameterError("target wavelength", f"{wl_in.size} values for {v.size}",
                                 "increasing wavelengths [nm], one per spectrum value",
                                 "sort the measurement by wavelength, drop duplicates")
    if not np.all(np.isfinite(v)) or v.min() < 0.0 or v.max() > 1.0:
        raise ParameterError(f"target {side}", f"values in [{np.nanmin(v):g}, {np.nanmax(v):g}]",
                             "[0, 1] (a reflectance or transmittance factor)",
                             "convert percent to fractions")
    lo, hi = max(400.0, math.ceil(wl_in[0])), min(2500.0, math.floor(wl_in[-1]))
    if hi - lo < 10:
        raise ParameterError("target wavelength", (float(wl_in[0]), float(wl_in[-1])),
                             "a range overlapping 400-2500 nm by >= 10 nm",
                             "give wavelengths in nm (not µm), inside PROSPECT-D's range")
    wl = np.arange(lo, hi + 1.0)
    return wl, np.interp(wl, wl_in, v)


def parse_target(target, side: str = "reflectance", exposure: float = 1.0,
                 illuminant="D65") -> LeafColourTarget:
    """Turn a target into a :class:`LeafColourTarget`.

    Parameters
    ----------
    target : array_like or dict
        An sRGB triple, ``{"srgb"|"lab"|"reflectance"|"transmittance": ...}`` (with
        ``"wavelength"`` [nm] for spectra), or a spectrum array (module docstring).
    side : {{"reflectance", "transmittance"}}
        Colour of the reflectance (the leaf seen from the lit side) or of the transmittance
        (seen against the light).
    exposure : float
        The factor the colour is made with (``spectrum_to_srgb(..., exposure)``) [-].
    illuminant : str or array_like
        'D65' (default), another name of ``colour.SDS_ILLUMINANTS``, or relative power on
        400-830 nm by 1 nm.

    Returns
    -------
    LeafColourTarget
        Its colour (XYZ, CIELAB, sRGB) and, for spectra, the spectrum on whole nanometres.
    """
    if side not in _SIDES:
        raise ParameterError("side", side, "'reflectance' or 'transmittance'",
                             "'reflectance': the leaf seen from the lit side")
    if not (isinstance(exposure, (int, float)) and math.isfinite(exposure) and exposure > 0):
        raise ParameterError("exposure", exposure, "a number > 0",
                             "use the exposure the target colour was made with (1.0)")
    wlc, W = _colour_weights(illuminant)
    white = cdr.white_point(W)
    kind, spec_wl, spec = None, None, None
    if isinstance(target, dict):
        keys = set(target) - {"wavelength"}
        if len(keys) != 1 or not keys <= {"srgb", "lab", "reflectance", "transmittance"}:
            raise ParameterError("target", sorted(target),
                                 "one of 'srgb', 'lab', 'reflectance', 'transmittance' "
                                 "(+ 'wavelength' with a spectrum)",
                                 "e.g. {'lab': (31.5, 12.2, 10.8)}")
        key = keys.pop()
        if key in _SIDES:
            side = key
            kind = "spectrum"
            spec_wl, spec = _as_spectrum(target[key], target.get("wavelength"), side)
        else:
            kind, value = key, target[key]
    else:
        a = np.asarray(target, dtype=np.float64) if not isinstance(target, str) else None
        if a is None or a.ndim != 1 or a.size < 3:
            raise ParameterError("target", target if isinstance(target, str)
                                 else f"array of shape {np.shape(target)}",
                                 "an sRGB triple (0-1), {'lab': (L, a, b)} or a spectrum",
                                 "e.g. (0.38, 0.26, 0.23) or {'reflectance': R, 'wavelength': nm}")
        if a.size == 3:
            kind, value = "srgb", a
        else:
            kind = "spectrum"
            spec_wl, spec = _as_spectrum(a, None, side)
    if kind == "srgb":
        v = np.asarray(value, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)) or v.min() < 0 or v.max() > 1:
            raise ParameterError("target srgb", v.tolist(), "three numbers in [0, 1]",
                                 "give an 8-bit colour as (r, g, b) / 255")
        xyz = cdr.srgb_to_xyz_np(v) / exposure
    elif kind == "lab":
        v = np.asarray(value, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)) or not 0 <= v[0] <= 100:
            raise ParameterError("target lab", v.tolist(), "(L*, a*, b*) with 0 <= L* <= 100",
                                 "give CIELAB (L* first), not sRGB or XYZ")
        xyz = cdr.lab_to_xyz_np(v, white) / exposure
    else:
        if spec_wl[0] > COLOUR_RANGE[0] or spec_wl[-1] < COLOUR_RANGE[1]:
            xyz = np.full(3, np.nan)   # no colour from a partial spectrum
        else:
            xyz = cdr.colour_weights(wlc, illuminant).T @ np.interp(wlc, spec_wl, spec)
    lab = cdr.xyz_to_lab_np(xyz * exposure, white)
    srgb = cdr.xyz_to_srgb_np(xyz * exposure)
    return LeafColourTarget(kind, side, xyz, lab, srgb, spec_wl, spec)


# ------------------------------------------------------------------------------------------
# the forward model
# ------------------------------------------------------------------------------------------
def _values(values: dict | None) -> dict:
    out = dict(DEFAULTS)
    for k, v in (values or {}).items():
        if k not in PARAMETERS:
            raise ParameterError("parameter", k, ", ".join(PARAMETERS),
                                 "pigments are Cab, Car, Anth [µg cm-2]")
        out[k] = v
    return out


def _model(vals: dict, side: str, W: np.ndarray, wavelengths, exposure: float, check: bool):
    """Dr.Jit spectrum on ``wavelengths`` and (X, Y, Z) × exposure on 400-830 nm."""
    if wavelengths is None or (wavelengths[0] == COLOUR_RANGE[0]
                               and wavelengths[-1] == COLOUR_RANGE[1]):
        s = prospect_d(**vals, wavelengths=COLOUR_RANGE, check=check)
        spec = getattr(s, side)
        return spec, tuple(c * exposure for c in cdr.spectrum_to_xyz(spec, W)), s
    s = prospect_d(**vals, wavelengths=wavelengths, check=check)
    spec = getattr(s, side)
    xyz = None
    if wavelengths[0] <= COLOUR_RANGE[0] and wavelengths[-1] >= COLOUR_RANGE[1]:
        # the colour range is a contiguous block of the whole-nanometre grid
        i0 = int(COLOUR_RANGE[0] - wavelengths[0])
        n = COLOUR_RANGE[1] - COLOUR_RANGE[0] + 1
        part = dr.gather(Float64, spec, dr.arange(mi.UInt32, i0, i0 + n))
        xyz = tuple(c * exposure for c in cdr.spectrum_to_xyz(part, W))
    return spec, xyz, s


def predict_leaf_colour(values: dict | None = None, side: str = "reflectance",
                        exposure: float = 1.0, illuminant="D65") -> dict:
    """Colour of a PROSPECT-D leaf.

    Parameters
    ----------
    values : dict, optional
        Any of N [-], Cab, Car, Anth [µg cm-2], Cbrown [-], Cw, Cm [g cm-2] (others
        from :data:`DEFAULTS`).
    side : {{"reflectance", "transmittance"}}
        Colour of the reflectance (the leaf seen from the lit side) or of the transmittance
        (seen against the light).
    exposure : float
        The factor the colour is made with (``spectrum_to_srgb(..., exposure)``) [-].
    illuminant : str or array_like
        'D65' (default), another name of ``colour.SDS_ILLUMINANTS``, or relative power on
        400-830 nm by 1 nm.

    Returns
    -------
    dict
        ``{"xyz", "lab", "srgb", "linear_srgb", "wavelength", "spectrum"}`` (NumPy; ``srgb``
        clipped and encoded as ``spectrum_to_srgb``; wavelength [nm]).
    """
    if side not in _SIDES:
        raise ParameterError("side", side, "'reflectance' or 'transmittance'",
                             "'reflectance': the leaf seen from the lit side")
    wlc, W = _colour_weights(illuminant)
    with dr.suspend_grad():
        spec, xyz, _ = _model(_values(values), side, W, None, exposure, True)
        xyz = np.array([float(c[0]) for c in xyz])
    return {"xyz": xyz, "lab": cdr.xyz_to_lab_np(xyz, cdr.white_point(W)),
            "linear_srgb": xyz @ cdr.SRGB_FROM_XYZ.T, "srgb": cdr.xyz_to_srgb_np(xyz),
            "wavelength": wlc, "spectrum": np.asarray(spec, dtype=np.float64)}


def colour_sensitivity(values: dict | None = None, params=("Cab", "Car", "Anth"),
                       side: str = "reflectance", exposure: float = 1.0,
                       illuminant="D65") -> dict:
    """How well a colour pins down ``params``: the Jacobian J = d(L*, a*, b*)/dp (3 × k, per
    unit of each parameter) by reverse-mode AD, its singular values, and, when k <= 3 and J
    has full rank, ``per_delta_e``: the largest change of each parameter that moves the colour
    by ΔE*ab = 1 (the row norms of J⁻¹, pseudo-inverse for k < 3). k > 3 parameters are never
    identifiable from a colour (J has a null space); ``null_space`` gives its directions.

    Parameters
    ----------
    values : dict, optional
        The leaf (as :func:`predict_leaf_colour`).
    params : tuple of str
        The parameters to differentiate.
    side : {{"reflectance", "transmittance"}}
        Colour of the reflectance (the leaf seen from the lit side) or of the transmittance
        (seen against the light).
    exposure : float
        The factor the colour is made with (``spectrum_to_srgb(..., exposure)``) [-].
    illuminant : str or array_like
        'D65' (default), another name of ``colour.SDS_ILLUMINANTS``, or relative power on
        400-830 nm by 1 nm.

    Returns
    -------
    dict
        ``"params"``, ``"lab"`` (the leaf's CIELAB), ``"jacobian"`` (3 × k, ΔE units per unit
        of each parameter), ``"singular_values"``, ``"per_delta_e"`` (when defined) and
        ``"null_space"`` (k > 3).
    """
    params = [params] if isinstance(params, str) else list(params)
    wlc, W = _colour_weights(illuminant)
    white = cdr.white_point(W)
    base = _values(values)
    J = np.zeros((3, len(params)))
    lab_v = None
    for i in range(3):
        vals = dict(base)
        for p in params:
            vals[p] = dr.opaque(Float64, float(base[p]))   # not a literal: no recompilation
            dr.enable_grad(vals[p])
        _, xyz, _ = _model(vals, side, W, None, exposure, True)
        lab = cdr.xyz_to_lab(xyz, white)
        dr.backward(lab[i])
        J[i] = [float(dr.grad(vals[p])[0]) for p in params]
        lab_v = np.array([float(dr.detach(c)[0]) for c in lab])
    sv = np.linalg.svd(J, compute_uv=False)
    out = {"params": params, "lab": lab_v, "jacobian": J, "singular_values": sv}
    if len(params) <= 3 and sv.min() > 1e-12 * sv.max():
        rows = np.linalg.norm(np.linalg.pinv(J), axis=1)
        out["per_delta_e"] = {p: float(v) for p, v in zip(params, rows)}
    if len(params) > 3:
        out["null_space"] = np.linalg.svd(J)[2][3:]
    return out


# ------------------------------------------------------------------------------------------
# fit
# ------------------------------------------------------------------------------------------
#: ranges of the look-up table that picks a start when none is given (typical leaves)
LUT_RANGES = {"N": (1.0, 3.0), "Cab": (0.0, 80.0), "Car": (0.0, 20.0), "Anth": (0.0, 40.0),
              "Cbrown": (0.0, 1.0), "Cw": (0.002, 0.05), "Cm": (0.001, 0.03)}


@dataclass
class LeafColourFit:
    """The result of :func:`fit_leaf_colour` (pigments fitted to a colour or a spectrum).

    Attributes
    ----------
    values : dict
        Fitted parameters.
    initial : dict
        Starting values of the fitted parameters.
    fixed : dict
        Values of the parameters that were not fitted.
    history : list
        Per step: ``{"step", "loss", "params", "grad"}``.
    loss : float
        Final loss.
    target : LeafColourTarget
        What was fitted.
    colour : dict
        :func:`predict_leaf_colour` of the fit (the start's under ``"start"``).
    delta_e : float
        ΔE*ab between the fit's and the target's colour [-].
    files : dict
        Files written.
    seconds : float
        Wall time [s].
    stats : dict
        Timings and counts.
    """

    values: dict                 # fitted parameters
    initial: dict                # starting values of the fitted parameters
    fixed: dict                  # values of the parameters that were not fitted
    history: list                # per step: {"step", "loss", "params", "grad"}
    loss: float                  # final loss
    target: LeafColourTarget
    colour: dict                 # predict_leaf_colour of the fit (start: colour["start"])
    delta_e: float               # ΔE*ab between the fit's and the target's colour
    files: dict = field(default_factory=dict)
    seconds: float = 0.0
    stats: dict = field(default_factory=dict)


def _residual_fn(kind, tgt: LeafColourTarget, white, exposure):
    """r(spectrum, XYZ) -> list of Dr.Jit residuals; the loss is Σ r²: ΔE*ab² for "lab",
    the squared sRGB difference for "rgb", the mean squared spectrum difference for
    "spectrum". Target numbers enter the kernels as opaque values (no recompilation per
    target)."""
    if kind == "lab":
        t = [dr.opaque(Float64, float(v)) for v in tgt.lab]

        def f(spec, xyz):
            return [c - v for c, v in zip(cdr.xyz_to_lab(xyz, white), t)]
    elif kind == "rgb":
        t = [dr.opaque(Float64, float(v)) for v in
             cdr.srgb_encode_np(tgt.xyz * exposure @ cdr.SRGB_FROM_XYZ.T, clip=False)]

        def f(spec, xyz):
            rgb = cdr.srgb_encode(cdr.xyz_to_linear_srgb(xyz), clip=False)
            return [c - v for c, v in zip(rgb, t)]
    else:
        ref = Float64(tgt.spectrum)
        w = 1.0 / math.sqrt(len(tgt.spectrum))

        def f(spec, xyz):
            return [(spec - ref) * w]
    return f


def _residual_np(kind, tgt: LeafColourTarget, white, exposure, spec, W, spec_wl):
    """NumPy residual norms² of many leaves (rows of ``spec``), for the look-up table."""
    if kind == "spectrum":
        return np.mean((spec - tgt.spectrum) ** 2, axis=-1)
    i0 = 0 if spec_wl is None else int(COLOUR_RANGE[0] - spec_wl[0])
    xyz = spec[:, i0:i0 + len(W)] @ W * exposure
    if kind == "lab":
        return np.sum((cdr.xyz_to_lab_np(xyz, white) - tgt.lab) ** 2, axis=-1)
    t = cdr.srgb_encode_np(tgt.xyz * exposure @ cdr.SRGB_FROM_XYZ.T, clip=False)
    return np.sum((cdr.srgb_encode_np(xyz @ cdr.SRGB_FROM_XYZ.T, clip=False) - t) ** 2, -1)


def _lut_start(names, vals0, bnd, n, seed, kind, tgt, white, exposure, side, W, spec_wl):
    """The best of ``n`` random leaves (uniform in :data:`LUT_RANGES` ∩ bounds over ``names``,
    the rest at ``vals0``): the classic look-up-table inversion of PROSPECT, used as a start."""
    rng = np.random.default_rng(seed)
    vals = dict(vals0)
    for p in names:
        lo, hi = max(LUT_RANGES[p][0], bnd[p][0]), min(LUT_RANGES[p][1], bnd[p][1])
        if hi <= lo:
            lo, hi = bnd[p]
        vals[p] = rng.uniform(lo, hi, n)
    with dr.suspend_grad():
        s = prospect_d(**vals, wavelengths=COLOUR_RANGE if spec_wl is None else spec_wl)
        spec = np.asarray(getattr(s, side), dtype=np.float64).reshape(n, -1)
    err = _residual_np(kind, tgt, white, exposure, spec, W, spec_wl)
    i = int(np.nanargmin(err))
    return {p: float(vals[p][i]) for p in names}, float(err[i])


def fit_leaf_colour(target, params=("Cab", "Car", "Anth"), init: dict | None = None,
                    steps: int = 500, loss: str | None = None, out=None, progress: bool = True,
                    method: str = "adam", lr: float = 0.1, lr_final: float = 0.001,
                    side: str = "reflectance", exposure: float = 1.0, illuminant="D65",
                    scales: dict | None = None, bounds: dict | None = None, lut: int = 1024,
                    seed: int = 0, beta_1: float = 0.9, beta_2: float = 0.9,
                    plots: bool = True) -> LeafColourFit:
    """Fit PROSPECT-D inputs ``params`` so that the leaf's colour (or spectrum) matches
    ``target`` (see the module docstring for the target forms and losses).

    params: names among N, Cab, Car, Anth, Cbrown, Cw, Cm (at most 3 for a colour target: a
    colour has three numbers). init: starting values of fitted parameters and the values of
    the fixed ones (default :data:`DEFAULTS`: a thin maple leaf). A fitted parameter without
    a start in ``init`` starts from the best of ``lut`` random leaves (look-up table over
    :data:`LUT_RANGES`; ``lut=0``: from :data:`DEFAULTS`).
    method: ``"adam"`` (``mi.ad.Adam`` on x = (p - p_start) / scale, ``steps`` steps, learning
    rate decaying geometrically from ``lr`` to lr · lr_final, beta_1, beta_2 its moment decay
    rates; bounds by clipping) or ``"least_squares"`` (SciPy's trust-region reflective
    least squares with bounds on the same normalised variables and the residuals' Jacobian by
    Dr.Jit forward-mode AD; at most ``steps`` evaluations; converges in tens of evaluations
    where weakly identifiable parameters leave Adam in a long, flat valley).
    side: colour of the reflectance (the leaf seen from the lit side) or the transmittance
    (seen against the light). exposure: the factor the target colour was made with
    (``spectrum_to_srgb(..., exposure)``). illuminant: 'D65' (default), another name of
    ``colour.SDS_ILLUMINANTS``, or relative power on 400-830 nm by 1 nm. scales, bounds:
    per-parameter overrides of :data:`SCALES` and of the model's ranges
    (:data:`~mitsuba_veg.foliage.prospect_dr.BOUNDS`). out: folder for ``fitted.json``,
    ``loss_curve.png`` and ``leaf_colour.png`` (None: write nothing).

    Parameters
    ----------
    target : array_like or dict
        The colour or spectrum (:func:`parse_target`).
    params : tuple of str
        Names among N, Cab, Car, Anth, Cbrown, Cw, Cm.
    init : dict, optional
        Starting and fixed values.
    steps : int
        Adam steps, or at most that many least-squares evaluations.
    loss : {"lab", "rgb", "spectrum"}, optional
        The loss (default: "spectrum" for spectrum targets, else "lab").
    out : path, optional
        Output folder.
    progress : bool
        Show a progress bar.
    method : {"adam", "least_squares"}
        The optimiser.
    lr : float
        Adam's learning rate on the normalised parameters [-].
    lr_final : float
        Its geometric decay, down to ``lr * lr_final`` [-].
    side : {"reflectance", "transmittance"}
        The side whose colour is the target.
    exposure : float
        The target's exposure factor [-].
    illuminant : str or array_like
        The illuminant.
    scales : dict, optional
        Overrides of :data:`SCALES`.
    bounds : dict, optional
        Overrides of the parameter ranges.
    lut : int
        Random leaves of the look-up-table start (0: none).
    seed : int
        Seed of the look-up table.
    beta_1, beta_2 : float
        Adam's moment decay rates [-].
    plots : bool
        Write the figures.

    Returns
    -------
    LeafColourFit
        Fitted, starting and fixed values, history, final loss, target, colour of the fit,
        ΔE*ab, files, time and settings.
    """
    t0 = time.perf_counter()
    params = [params] if isinstance(params, str) else list(params)
    if not params or len(set(params)) != len(params):
        raise ParameterError("params", params, "one or more distinct names of " +
                             ", ".join(PARAMETERS), "e.g. params=('Cab', 'Car', 'Anth')")
    for p in params:
        if p not in PARAMETERS:
            raise ParameterError("params", p, ", ".join(PARAMETERS),
                                 "pigments are Cab, Car, Anth [µg cm-2]")
    if not isinstance(steps, int) or steps < 1:
        raise ParameterError("steps", steps, "an integer >= 1", "500 for Adam (the default)")
    if method not in ("adam", "least_squares"):
        raise ParameterError("method", method, "'adam' or 'least_squares'",
                             "'least_squares' converges fastest on three-number colours")
    for name, v, lo, hi in (("lr", lr, 0.0, 10.0), ("lr_final", lr_final, 0.0, 1.0),
                            ("beta_1", beta_1, 0.0, 1.0), ("beta_2", beta_2, 0.0, 1.0)):
        if not (isinstance(v, (int, float)) and lo < v <= hi):
            raise ParameterError(name, v, f"({lo}, {hi}]", "keep the default")
    if not isinstance(lut, int) or lut < 0:
        raise ParameterError("lut", lut, "an integer >= 0 (0: no look-up-table start)",
                             "1024 (the default)")
    tgt = parse_target(target, side, exposure, illuminant)
    side = tgt.side
    if loss is None:
        loss = "spectrum" if tgt.kind == "spectrum" else "lab"
    if loss not in ("lab", "rgb", "spectrum"):
        raise ParameterError("loss", loss, "'lab', 'rgb' or 'spectrum'",
                             "'lab' (ΔE*ab) for colours, 'spectrum' for spectra")
    if loss == "spectrum" and tgt.kind != "spectrum":
        raise ParameterError("loss", loss, f"'lab' or 'rgb' for a {tgt.kind} target",
                             "a spectrum loss needs a measured spectrum as the target")
    if loss != "spectrum" and not np.all(np.isfinite(tgt.xyz)):
        raise ParameterError("target wavelength", (float(tgt.wavelength[0]),
                                                   float(tgt.wavelength[-1])),
                             "a spectrum covering 400-830 nm for a colour loss",
                             "use loss='spectrum'")
    if loss != "spectrum" and len(params) > 3:
        raise ParameterError("params", params, "at most 3 parameters for a colour target "
                             "(a colour is three numbers)",
                             "fix the others in init, or fit a reflectance spectrum")
    init = dict(init or {})
    for k in init:
        if k not in PARAMETERS:
            raise ParameterError("init", k, ", ".join(PARAMETERS),
                                 "pigments are Cab, Car, Anth [µg cm-2]")
    vals0 = _values(init)
    bnd = {}
    for p in params:
        lo, hi, fix = BOUNDS[p]
        b = tuple(float(x) for x in (bounds or {}).get(p, (lo, hi)))
        if len(b) != 2 or not (lo <= b[0] < b[1] <= hi):
            raise ParameterError(f"bounds[{p!r}]", b, f"lo < hi inside [{lo}, {hi}]", fix)
        bnd[p] = b
    for p, v in vals0.items():
        lo, hi, fix = BOUNDS[p]
        if p in bnd:
            lo, hi = bnd[p]
        if not (isinstance(v, numbers.Real) and lo <= float(v) <= hi):
            raise ParameterError(f"init[{p!r}]", v, f"[{lo}, {hi}]", fix)
    scale = {p: float((scales or {}).get(p, SCALES[p])) for p in params}
    for p, s in scale.items():
        if not (math.isfinite(s) and s > 0):
            raise ParameterError(f"scales[{p!r}]", s, "a number > 0",
                                 f"the default is {SCALES[p]}")

    wlc, W = _colour_weights(illuminant)
    white = cdr.white_point(W)
    spec_wl = tgt.wavelength if loss == "spectrum" else None
    model_exposure = 1.0 if loss == "spectrum" else exposure
    rf = _residual_fn(loss, tgt, white, exposure)
    start_from = "init"
    missing = [p for p in params if p not in init]
    if missing and lut > 0:
        best, err = _lut_start(missing, {k: float(v) for k, v in vals0.items()}, bnd, lut,
                               seed, loss, tgt, white, exposure, side, W, spec_wl)
        vals0.update(best)
        start_from = f"look-up table ({lut} leaves over {', '.join(missing)}; loss {err:.3g})"
    start = {p: float(vals0[p]) for p in params}
    fixed = {p: float(v) for p, v in vals0.items() if p not in params}

    # every number that differs between fits (start, scale, bounds, fixed inputs) enters the
    # kernels as an opaque value: new starts and targets reuse the compiled kernels
    opq = {p: (dr.opaque(Float64, start[p]), dr.opaque(Float64, scale[p])) for p in params}
    fixed_dr = {p: dr.opaque(Float64, v) for p, v in fixed.items()}
    xlo = {p: (bnd[p][0] - start[p]) / scale[p] for p in params}
    xhi = {p: (bnd[p][1] - start[p]) / scale[p] for p in params}

    def residuals(x):
        vals = dict(fixed_dr)
        vals.update({p: opq[p][0] + opq[p][1] * x[p] for p in params})
        spec, xyz, _ = _model(vals, side, W, spec_wl, model_exposure, False)
        return rf(spec, xyz)

    def total(r):
        return sum(dr.sum(ri * ri) for ri in r)

    history = []
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=steps, desc=f"leaf colour ({method})", unit="step")

    def record(k, lval, values, grads):
        history.append({"step": k, "loss": lval, "params": values, "grad": grads})
        if not math.isfinite(lval) or not all(math.isfinite(g) for g in grads.values()):
            raise FloatingPointError(f"fit_leaf_colour: non-finite loss or gradient at step "
                                     f"{k}: loss {lval}, grad {grads}, params {values}")
        if bar is not None:
            bar.update(1)
            post = {"loss": f"{lval:.3e}"}
            post.update({p: f"{v:.4g}" for p, v in values.items()})
            bar.set_postfix(refresh=False, **post)   # redraws at tqdm's own pace

    if method == "adam":
        values = _fit_adam(params, start, scale, xlo, xhi, residuals, total, record, steps, lr,
                           lr_final, beta_1, beta_2)
    else:
        values = _fit_least_squares(params, start, scale, xlo, xhi, residuals, record, steps)
    if bar is not None:
        bar.close()
    with dr.suspend_grad():
        final = float(total(residuals({p: dr.opaque(Float64, (values[p] - start[p]) / scale[p])
                                       for p in params}))[0])
    history.append({"step": len(history), "loss": final, "params": values, "grad": {}})
    colour = predict_leaf_colour({**fixed, **values}, side, exposure, illuminant)
    colour_start = predict_leaf_colour({**fixed, **start}, side, exposure, illuminant)
    delta_e = float(np.linalg.norm(colour["lab"] - tgt.lab)) if np.all(np.isfinite(tgt.lab)) \
        else float("nan")
    res = LeafColourFit(values, start, fixed, history, final, tgt,
                        {**colour, "start": colour_start}, delta_e, {},
                        time.perf_counter() - t0,
                        {"method": method, "loss": loss, "steps": steps,
                         "evaluations": len(history) - 1, "start_from": start_from,
                         "lr": lr, "lr_final": lr_final, "beta_1": beta_1, "beta_2": beta_2,
                         "scales": scale, "bounds": bnd, "side": side, "exposure": exposure,
                         "illuminant": illuminant if isinstance(illuminant, str) else "custom"})
    if out is not None:
        res.files = write_outputs(res, Path(out), plots)
    return res


def _fit_adam(params, start, scale, xlo, xhi, residuals, total, record, steps, lr, lr_final,
              beta_1, beta_2) -> dict:
    # beta_2 = 0.9 (not 0.999), as in tune.fit: a long second-moment memory keeps the large
    # early gradients and freezes the last steps (400 steps from the corners of a ±30 % box:
    # ΔE up to 0.14 with 0.99, <= 4e-5 with 0.9)
    opt = mi.ad.Adam(lr=lr, beta_1=beta_1, beta_2=beta_2)
    for p in params:
        opt[p] = dr.opaque(Float64, 0.0)
    lo = {p: dr.opaque(Float64, xlo[p]) for p in params}
    hi = {p: dr.opaque(Float64, xhi[p]) for p in params}
    decay = lr_final ** (1.0 / max(steps - 1, 1))

    def physical():
        return {p: start[p] + scale[p] * float(dr.detach(opt[p])[0]) for p in params}

    for k in range(steps):
        values = physical()
        L = total(residuals({p: opt[p] for p in params}))
        dr.backward(L)
        grads = {p: float(dr.grad(opt[p])[0]) / scale[p] for p in params}
        record(k, float(L[0]), values, grads)
        opt.set_learning_rate(lr * decay ** k)
        opt.step()
        for p in params:  # bounds on the physical values
            opt[p] = dr.clip(dr.detach(opt[p]), lo[p], hi[p])
    return physical()


def _fit_least_squares(params, start, scale, xlo, xhi, residuals, record, steps) -> dict:
    from scipy.optimize import least_squares

    def fun(xv):
        with dr.suspend_grad():
            r = residuals({p: dr.opaque(Float64, float(v)) for p, v in zip(params, xv)})
            rv = np.concatenate([np.asarray(ri, dtype=np.float64).ravel() for ri in r])
        values = {p: start[p] + scale[p] * float(v) for p, v in zip(params, xv)}
        record(len(_calls), float(rv @ rv), values, {})
        _calls.append(1)
        return rv

    def jac(xv):
        cols = []
        for j, p in enumerate(params):  # forward mode: one pass per parameter
            x = {q: dr.opaque(Float64, float(v)) for q, v in zip(params, xv)}
            dr.enable_grad(x[p])
            r = residuals(x)
            dr.forward(x[p])
            cols.append(np.concatenate([np.asarray(dr.grad(ri), dtype=np.float64).ravel()
                                        for ri in r]))
        return np.stack(cols, 1)

    _calls: list = []
    x0 = np.zeros(len(params))
    lo = np.array([xlo[p] for p in params])
    hi = np.array([xhi[p] for p in params])
    sol = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale=1.0,
                        xtol=1e-12, ftol=1e-15, gtol=1e-15, max_nfev=steps)
    return {p: start[p] + scale[p] * float(v) for p, v in zip(params, sol.x)}


# ------------------------------------------------------------------------------------------
# outputs
# ------------------------------------------------------------------------------------------
def write_outputs(res: LeafColourFit, out: Path, plots: bool = True) -> dict:
    """fitted.json, loss_curve.png and leaf_colour.png (swatches and spectra).

    Parameters
    ----------
    res : LeafColourFit
        The fit.
    out : Path
        Output folder.
    plots : bool
        Write the figures (else only ``fitted.json``).

    Returns
    -------
    dict
        ``{kind: path}`` of the written files.
    """
    out.mkdir(parents=True, exist_ok=True)
    t = res.target
    summary = {"fitted": res.values, "initial": res.initial, "fixed": res.fixed,
               "final_loss": res.loss, "delta_e": res.delta_e, "steps": len(res.history) - 1,
               "seconds": res.seconds, "settings": res.stats,
               "target": {"kind": t.kind, "side": t.side, "srgb": t.srgb.tolist(),
                          "lab": t.lab.tolist(), "xyz": t.xyz.tolist()},
               "colour": {k: np.asarray(res.colour[k]).tolist() for k in ("srgb", "lab", "xyz")},
               "history": res.history}
    p = out / "fitted.json"
    p.write_text(json.dumps(summary, indent=1, default=float))
    files = {"fitted": str(p)}
    if not plots:
        return files
    files["loss_curve"] = loss_curve_figure(res.history, out / "loss_curve.png",
                                            res.stats.get("loss", ""))
    files["leaf_colour"] = str(leaf_colour_figure(res, out / "leaf_colour.png"))
    return files


def leaf_colour_figure(res: LeafColourFit, path) -> str:
    """Swatches (start, target, fit) and the spectra (start, target if measured, fit).

    Parameters
    ----------
    res : LeafColourFit
        The fit.
    path : path
        PNG to write.

    Returns
    -------
    str
        The written path.
    """
    plt = _mpl()
    t = res.target
    fig = plt.figure(figsize=(10.5, 3.6))
    gs = fig.add_gridspec(1, 2, width_ratios=(1.0, 1.9))
    ax = fig.add_subplot(gs[0])
    sw = [("start", res.colour["start"]["srgb"]), ("target", t.srgb),
          ("fitted", res.colour["srgb"])]
    for i, (name, c) in enumerate(sw):
        ax.add_patch(plt.Rectangle((i * 1.1, 0), 1.0, 1.0, color=np.clip(c, 0, 1)))
        ax.text(i * 1.1 + 0.5, -0.12, name, ha="center", va="top", fontsize=9)
        ax.text(i * 1.1 + 0.5, 1.05, "sRGB\n" + " ".join(f"{int(round(255 * v))}"
                                                          for v in np.clip(c, 0, 1)),
                ha="center", va="bottom", fontsize=7)
    ax.set_xlim(-0.05, 3.25)
    ax.set_ylim(-0.35, 1.4)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(f"ΔE*ab (fit - target) = {res.delta_e:.3g}", fontsize=9)
    ax = fig.add_subplot(gs[1])
    wl = res.colour["wavelength"]
    fit_s, start_s = res.colour["spectrum"], res.colour["start"]["spectrum"]
    if t.spectrum is not None:   # a measured target: show its whole range (water, dry matter)
        wl = t.wavelength
        with dr.suspend_grad():
            fit_s, start_s = (np.asarray(getattr(prospect_d(**{**res.fixed, **v},
                                                            wavelengths=wl), t.side),
                                         dtype=np.float64)
                              for v in (res.values, res.initial))
    ax.plot(wl, start_s, color="0.6", lw=1.2, ls="--", label="start")
    if t.spectrum is not None:
        ax.plot(t.wavelength, t.spectrum, color="k", lw=2.2, label="target")
    ax.plot(wl, fit_s, color="tab:red", lw=1.2, label="fitted")
    ax.set_xlabel("wavelength [nm]")
    ax.set_ylabel(t.side)
    ax.set_xlim(wl[0], wl[-1])
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    txt = ", ".join(f"{k} {v:.3g}" for k, v in res.values.items())
    ax.set_title(f"fitted: {txt}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)
