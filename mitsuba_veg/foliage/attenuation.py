"""Red / far-red attenuation of the trees' leaf spheres (paper 001) from leaf spectra.

Paper 001 attenuates a sky ray by α per leaf sphere it crosses, with α_l = 0.3 (light),
α_r = 0.3 (red, 660 nm) and α_fr = 0.7 (far-red, 730 nm), "light through leaves loses red more
than far-red". Since red must lose more than far-red, α is the **fraction of light that passes**
a leaf sphere (a multiplier), not the fraction removed.

Physically consistent reading used here (bi-Lambertian leaves, spherical leaf angles):
a beam crossing a leaf sphere either passes a gap (probability P_gap) or meets a leaf; of the
intercepted light the leaf absorbs 1 − R − T and scatters R and T diffusely. For a spherical
leaf-angle distribution the share of that scattered light that keeps going forward (into the
half-space ahead of the beam) is exactly T·5/6 + R·1/6 (a leaf at angle θ sends (1 + cos θ)/2
of its transmitted and (1 − cos θ)/2 of its reflected Lambertian lobe forward; interception is
∝ cos θ, so averaging over cos θ with density 2 cos θ gives 5/6 and 1/6). So

    α(λ) = P_gap + (1 − P_gap) (5 T(λ) + R(λ)) / 6

with P_gap from the sphere's leaf area, P_gap = exp(−G Ω L_path) (G = 0.5), or calibrated so that
the PAR-band α equals the paper's α_l = 0.3. With green PROSPECT-D leaves this gives
α_r ≈ 0.27 and α_fr ≈ 0.57 for α_l = 0.3 — close to the paper's 0.3 / 0.7; red autumn leaves
(chlorophyll gone, anthocyanin absorbing green, not red) pass much more red.

``absorbed_fraction`` gives the other reading (a single leaf removes 1 − R − T) for reference.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

from .spectra import LeafSpectra, leaf_spectra

__all__ = ["RED_NM", "FAR_RED_NM", "PAR_NM", "FORWARD_T", "FORWARD_R", "forward_scatter",
           "gap_from_alpha_l", "red_far_red_attenuation", "absorbed_fraction", "growth_alphas",
           "with_leaf_optics"]

#: the red band [nm]
RED_NM = (655.0, 665.0)
#: the far-red band [nm]
FAR_RED_NM = (725.0, 735.0)
#: the PAR band [nm]
PAR_NM = (400.0, 700.0)
#: share of transmitted light scattered forward by spherically oriented bi-Lambertian leaves
FORWARD_T = 5.0 / 6.0
#: share of reflected light scattered forward by spherically oriented bi-Lambertian leaves
FORWARD_R = 1.0 / 6.0


def forward_scatter(spectra: LeafSpectra, band) -> np.ndarray:
    """Band-mean share of intercepted light a leaf sends onward: (5 T + R) / 6.

    For a spherical leaf-angle distribution a bi-Lambertian leaf sends 5/6 of its transmitted and
    1/6 of its reflected light into the half-space ahead of the beam (module docstring).

    Parameters
    ----------
    spectra : LeafSpectra
        Leaf reflectance R and transmittance T (one leaf or several rows).
    band : tuple of float
        ``(lo, hi)`` band limits [nm], e.g. :data:`RED_NM`.

    Returns
    -------
    numpy.ndarray
        (5 T + R) / 6 averaged over the band [-], one value per leaf (the spectra's leading
        shape).
    """
    R, T = spectra.band_mean(*band)
    return FORWARD_T * T + FORWARD_R * R


def gap_from_alpha_l(alpha_l: float, spectra: LeafSpectra) -> np.ndarray:
    """P_gap such that the PAR pass factor of a leaf sphere equals ``alpha_l``.

    Solves α_l = P_gap + (1 − P_gap) s for P_gap, with s the leaves' PAR forward scatter
    :func:`forward_scatter`: P_gap = (α_l − s) / (1 − s).

    Parameters
    ----------
    alpha_l : float
        PAR pass factor of a leaf sphere [-] (paper 001: 0.3).
    spectra : LeafSpectra
        The leaves whose PAR optics set s.

    Returns
    -------
    numpy.ndarray
        Gap fraction P_gap [-] (one value per leaf of ``spectra``).

    Raises
    ------
    ParameterError
        When ``alpha_l`` is below the leaves' PAR forward scatter (no gap fraction >= 0 gives it).
    """
    s = forward_scatter(spectra, PAR_NM)
    if np.any(alpha_l < s):
        raise ParameterError("alpha_l", alpha_l, f">= the leaves' forward scatter in PAR "
                             f"({float(np.max(s)):.3f})", "use a larger alpha_l or a gap "
                             "fraction")
    return (alpha_l - s) / (1.0 - s)


def red_far_red_attenuation(spectra: LeafSpectra | None = None, *, tau=None, alpha_l: float = 0.3,
                            gap_fraction=None, lai_path=None, G: float = 0.5) -> dict:
    """α_r, α_fr (and α_l, α_par) of paper 001's leaf spheres from leaf spectra.

    α(λ band) = P_gap + (1 − P_gap) (5 T + R) / 6 (module docstring). Give ``spectra`` (a
    :class:`LeafSpectra`) or ``tau`` (autumn logical time: spectra from the stage table). The
    sphere's gap fraction comes from ``gap_fraction``, or ``lai_path`` (leaf area per unit area
    along a ray through the sphere: P_gap = exp(−G lai_path)), or by default from ``alpha_l`` (the
    paper's 0.3) with the leaves' PAR optics (calibrated on the green leaf, τ = 0, so that autumn
    leaves change α through their optics only).

    Parameters
    ----------
    spectra : LeafSpectra, optional
        Leaf reflectance and transmittance; default: the spectra at ``tau``.
    tau : float or array_like, optional
        Autumn logical time [-] in [0, 1] of the leaves, used when ``spectra`` is None (default
        0: green); refused together with ``spectra``.
    alpha_l : float
        PAR pass factor of a green leaf sphere [-] (default 0.3, paper 001), used when neither
        ``gap_fraction`` nor ``lai_path`` is given.
    gap_fraction : float or array_like, optional
        Gap fraction P_gap of the sphere [-] in [0, 1].
    lai_path : float or array_like, optional
        Leaf area per unit area along a ray through the sphere [m2 m-2].
    G : float
        Leaf projection function [-] in (0, 1] used with ``lai_path`` (0.5: spherical leaf
        angles).

    Returns
    -------
    dict
        ``alpha_r``, ``alpha_fr``, ``alpha_par`` (red 655-665 nm, far-red 725-735 nm, PAR
        400-700 nm pass factors [-]), ``alpha_l`` (= ``alpha_par``), ``gap_fraction`` [-] and the
        leaves' band-mean reflectance and transmittance ``R_r``, ``T_r``, ``R_fr``, ``T_fr``,
        ``R_par``, ``T_par`` [-].

    Raises
    ------
    ParameterError
        When both ``gap_fraction`` and ``lai_path`` are given, or both ``spectra`` and
        ``tau``, or a value is out of range.
    """
    if spectra is not None and tau is not None:
        raise ParameterError("spectra/tau", "both given", "one of them",
                             "pass the leaf spectra or the autumn time tau, not both")
    if spectra is None:
        spectra = leaf_spectra(tau=0.0 if tau is None else tau)
    given = sum(x is not None for x in (gap_fraction, lai_path))
    if given > 1:
        raise ParameterError("gap_fraction/lai_path", (gap_fraction, lai_path), "at most one")
    if gap_fraction is not None:
        pg = np.asarray(gap_fraction, float)
        if (pg < 0).any() or (pg > 1).any():
            raise ParameterError("gap_fraction", gap_fraction, "[0, 1]")
    elif lai_path is not None:
        check_range("G", G, 0.0, 1.0, lo_open=True)
        pg = np.exp(-G * np.asarray(lai_path, float))
    else:
        check_range("alpha_l", alpha_l, 0.0, 1.0)
        # calibrate on the green leaf (the paper's α_l describes its green trees), so that
        # autumn leaves change α through their optics only
        pg = gap_from_alpha_l(alpha_l, leaf_spectra(tau=0.0))
    out = {"gap_fraction": pg}
    for name, band in (("r", RED_NM), ("fr", FAR_RED_NM), ("par", PAR_NM)):
        s = forward_scatter(spectra, band)
        out[f"alpha_{name}"] = pg + (1.0 - pg) * s
        R, T = spectra.band_mean(*band)
        out[f"R_{name}"], out[f"T_{name}"] = R, T
    out["alpha_l"] = out["alpha_par"]
    return out


def absorbed_fraction(spectra: LeafSpectra) -> dict:
    """Fraction of red / far-red light one leaf absorbs, 1 − R − T (band means).

    The other reading of paper 001's α (a single leaf removes 1 − R − T), for reference.

    Parameters
    ----------
    spectra : LeafSpectra
        Leaf reflectance and transmittance.

    Returns
    -------
    dict
        ``{"r": ..., "fr": ...}``: absorptance [-] in the red (655-665 nm) and far-red
        (725-735 nm) bands, one value per leaf.
    """
    out = {}
    for name, band in (("r", RED_NM), ("fr", FAR_RED_NM)):
        R, T = spectra.band_mean(*band)
        out[name] = 1.0 - R - T
    return out


def growth_alphas(tau=None, alpha_l: float = 0.3, spectra: LeafSpectra | None = None) -> dict:
    """The growth model's (paper 001) attenuation parameters from leaf spectra.

    The gap fraction of a leaf sphere is calibrated on the green leaf so that green leaves keep
    α_l; autumn leaves (``tau`` > 0) change all three.

    Parameters
    ----------
    tau : float, optional
        Autumn logical time [-] in [0, 1] of the leaves (default: 0, green); not with
        ``spectra``.
    alpha_l : float
        PAR pass factor of a green leaf sphere [-] (default 0.3, paper 001).
    spectra : LeafSpectra, optional
        Leaf spectra to use instead of those at ``tau`` (refused together with ``tau``).

    Returns
    -------
    dict
        ``{"alpha": α_l, "alpha_red": α_r, "alpha_far_red": α_fr}`` [-] (float; names of
        ``mitsuba_veg.trees.growth.GrowthParams``).
    """
    a = red_far_red_attenuation(spectra, tau=tau, alpha_l=alpha_l)
    return {"alpha": float(a["alpha_par"]), "alpha_red": float(a["alpha_r"]),
            "alpha_far_red": float(a["alpha_fr"])}


def with_leaf_optics(params, tau=None, spectra: LeafSpectra | None = None):
    """A copy of a growth-parameter dataclass with α_l, α_r, α_fr from the leaves' spectra.

    The α values come from the leaves' spectra (autumn time ``tau`` or given ``spectra``,
    :func:`growth_alphas`) instead of the constants; ``params.alpha`` is taken as the green
    leaves' α_l.

    Parameters
    ----------
    params : GrowthParams
        A dataclass with fields ``alpha``, ``alpha_red``, ``alpha_far_red``
        (``mitsuba_veg.trees.growth.GrowthParams``).
    tau : float, optional
        Autumn logical time [-] in [0, 1] (default: 0, green); not with ``spectra``.
    spectra : LeafSpectra, optional
        Leaf spectra to use instead of those at ``tau`` (refused together with ``tau``).

    Returns
    -------
    GrowthParams
        A copy of ``params`` (``dataclasses.replace``) with the three α [-] replaced.

    Raises
    ------
    ParameterError
        When ``params`` is not such a dataclass.
    """
    if not dataclasses.is_dataclass(params) or not hasattr(params, "alpha_red"):
        raise ParameterError("params", type(params).__name__,
                             "a dataclass with alpha, alpha_red, alpha_far_red (GrowthParams)")
    return dataclasses.replace(params, **growth_alphas(tau, float(params.alpha), spectra))
