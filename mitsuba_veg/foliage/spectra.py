"""Leaf spectra from pigments (PROSPECT-D) and their use: Mitsuba spectra, colours, band values.

``leaf_spectra(...)`` is the public entry point (re-exported as
``mitsuba_veg.foliage.leaf_spectra``).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mitsuba_veg.errors import ParameterError

from .colour_dr import colour_weights, xyz_to_srgb_np
from .pigments import LeafTraits, pigments_at_stage, stage_from_tau
from .prospect import prospect_d

__all__ = ["MITSUBA_MIN_NM", "LeafSpectra", "leaf_spectra", "mitsuba_spectrum", "spectrum_to_srgb"]

#: Mitsuba's spectral range starts at 360 nm, PROSPECT-D at 400 nm: below 400 nm the 400 nm
#: value is held constant (leaves absorb strongly in the UV-A too; documented in docs/foliage.md)
MITSUBA_MIN_NM = 360.0


class LeafSpectra(NamedTuple):
    """Directional-hemispherical leaf reflectance and transmittance (PROSPECT-D)."""

    wavelength: np.ndarray   # [nm], 400-2500 by 1 nm
    reflectance: np.ndarray  # (..., n_wl)
    transmittance: np.ndarray
    pigments: dict           # inputs used: Cab, Car, Anth [µg cm-2], N, Cw, Cm, Cbrown

    @property
    def absorptance(self) -> np.ndarray:
        """Leaf absorptance 1 − R − T [-], shape of ``reflectance``."""
        return 1.0 - self.reflectance - self.transmittance

    def at(self, wavelength_nm) -> tuple[np.ndarray, np.ndarray]:
        """(R, T) interpolated at wavelength(s) [nm] (last axis).

        Parameters
        ----------
        wavelength_nm : float or array_like
            Wavelength(s) [nm] in [400, 2500].

        Returns
        -------
        R, T : numpy.ndarray
            Reflectance and transmittance [-], shape ``(..., len(wavelength_nm))`` (leading axes as
            the spectra's).

        Raises
        ------
        ParameterError
            When a wavelength is outside [400, 2500] nm.
        """
        wl = np.atleast_1d(np.asarray(wavelength_nm, float))
        if (wl < 400).any() or (wl > 2500).any():
            raise ParameterError("wavelength_nm", wl.tolist(), "[400, 2500] nm")
        R = np.apply_along_axis(lambda r: np.interp(wl, self.wavelength, r), -1,
                                self.reflectance)
        T = np.apply_along_axis(lambda t: np.interp(wl, self.wavelength, t), -1,
                                self.transmittance)
        return R, T

    def band_mean(self, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
        """(R, T) averaged (flat weight) over [lo, hi] nm.

        Parameters
        ----------
        lo, hi : float
            Band limits [nm] (closed interval on the 1-nm grid).

        Returns
        -------
        R, T : numpy.ndarray
            Band-mean reflectance and transmittance [-], the spectra's leading shape (a 0-d array
            for one leaf).

        Raises
        ------
        ParameterError
            When no wavelength of the grid lies in the band.
        """
        m = (self.wavelength >= lo) & (self.wavelength <= hi)
        if not m.any():
            raise ParameterError("band", (lo, hi), "a range inside 400-2500 nm")
        return self.reflectance[..., m].mean(-1), self.transmittance[..., m].mean(-1)


def leaf_spectra(tau=None, *, stage=None, Cab=None, Car=None, Anth=None,
                 traits: LeafTraits = LeafTraits(), table=None) -> LeafSpectra:
    """Leaf reflectance and transmittance spectra, 400-2500 nm (PROSPECT-D, Féret et al. 2017).

    Give either autumn logical time ``tau`` ∈ [0, 1], or an Ishikura ``stage`` ∈ [1, 7], or the
    pigment contents ``Cab``, ``Car``, ``Anth`` [µg cm-2] directly (any of them overrides the
    stage table's value; with none of them and not all three contents, stage 1). Arrays broadcast:
    m values give (m, 2101) spectra. ``traits`` holds the leaf structure N, water Cw [cm], dry
    matter Cm [g cm-2] and brown pigments.

    Parameters
    ----------
    tau : float or array_like, optional
        Autumn logical time τ [-] in [0, 1] (stage = 1 + 6 τ).
    stage : float or array_like, optional
        Ishikura stage [-] in [1, 7].
    Cab, Car, Anth : float or array_like, optional
        Chlorophyll a+b, carotenoid, anthocyanin contents [µg cm-2].
    traits : LeafTraits
        N [-], Cw [cm], Cm [g cm-2], Cbrown [-] (default: a thin maple leaf).
    table : StageTable, optional
        Stage table (default: the shipped Ishikura table).

    Returns
    -------
    LeafSpectra
        Wavelengths (2101,) [nm], directional-hemispherical reflectance and transmittance [-]
        (shape ``broadcast + (2101,)``) and the inputs used.

    Raises
    ------
    ParameterError
        When both ``tau`` and ``stage`` are given, or an input is out of range.

    Examples
    --------
    >>> s = leaf_spectra(tau=0.0)          # a green maple leaf (stage 1)
    >>> R, T = s.at([660, 730])            # red, far-red
    """
    if tau is not None and stage is not None:
        raise ParameterError("tau/stage", (tau, stage), "one of them", "give tau or stage")
    if tau is not None:
        stage = stage_from_tau(tau)
    if stage is None and (Cab is None or Car is None or Anth is None):
        stage = 1.0
    pig = pigments_at_stage(stage, table) if stage is not None else {}
    if Cab is not None:
        pig["Cab"] = np.asarray(Cab, float)
    if Car is not None:
        pig["Car"] = np.asarray(Car, float)
    if Anth is not None:
        pig["Anth"] = np.asarray(Anth, float)
    wl, R, T = prospect_d(N=traits.N, Cab=pig["Cab"], Car=pig["Car"], Anth=pig["Anth"],
                          Cbrown=traits.Cbrown, Cw=traits.Cw, Cm=traits.Cm)
    pig = dict(pig, N=traits.N, Cw=traits.Cw, Cm=traits.Cm, Cbrown=traits.Cbrown)
    return LeafSpectra(wl, R, T, pig)


def mitsuba_spectrum(wavelength, values, lo: float = MITSUBA_MIN_NM) -> dict:
    """A Mitsuba ``regular`` spectrum dict from a spectrum on a regular 1-nm grid.

    Extended down to ``lo`` nm by holding the first value (Mitsuba samples 360-830 nm).

    Parameters
    ----------
    wavelength : array_like
        (n,) regular wavelength grid [nm].
    values : array_like
        n values (flattened), e.g. reflectance [-].
    lo : float
        Lowest wavelength of the result [nm] (default :data:`MITSUBA_MIN_NM`, 360 nm).

    Returns
    -------
    dict
        ``{"type": "regular", "wavelength_min" [nm], "wavelength_max" [nm], "values"}``
        (values as a comma-separated string).

    Raises
    ------
    ParameterError
        When ``values`` does not have one value per wavelength.
    """
    wl = np.asarray(wavelength, float)
    v = np.asarray(values, float).ravel()
    if wl.ndim != 1 or len(wl) != len(v):
        raise ParameterError("values", np.shape(values), f"one value per wavelength ({len(wl)})")
    step = float(wl[1] - wl[0])
    if lo < wl[0]:
        n_ext = int(round((wl[0] - lo) / step))
        v = np.concatenate([np.full(n_ext, v[0]), v])
        start = wl[0] - n_ext * step
    else:
        start = wl[0]
    return {"type": "regular", "wavelength_min": float(start), "wavelength_max": float(wl[-1]),
            "values": ", ".join(f"{x:.6g}" for x in v)}


# --------------------------------------------------------------------------------------------
# Colour (for pictures): reflectance under D65 -> XYZ -> sRGB, the pipeline of colour_dr.py
# --------------------------------------------------------------------------------------------
_cmfs = colour_weights   # (wavelengths) -> (n_wl, 3) XYZ weights under D65, Y of white = 1


def spectrum_to_srgb(wavelength, spectra, exposure: float = 1.0) -> np.ndarray:
    """Encoded sRGB of reflectance or transmittance spectra lit by D65.

    Parameters
    ----------
    wavelength : array_like
        (n_wl,) wavelengths [nm].
    spectra : array_like
        (..., n_wl) reflectance or transmittance [-].
    exposure : float
        Factor on XYZ before encoding (leaves reflect only 5-15 % in the visible).

    Returns
    -------
    numpy.ndarray
        (..., 3) gamma-encoded sRGB in [0, 1] (clipped), as
        :func:`mitsuba_veg.foliage.colour_dr.spectrum_to_srgb` in Dr.Jit.
    """
    w = colour_weights(np.asarray(wavelength, float))
    return xyz_to_srgb_np(np.asarray(spectra, float) @ w * exposure)
