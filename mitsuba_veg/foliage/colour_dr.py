"""Differentiable colour of a spectrum: CIE 1931 XYZ, linear and encoded sRGB, CIELAB (Dr.Jit).

The weights are those of :func:`mitsuba_veg.foliage.spectra.spectrum_to_srgb`: the CIE 1931 2°
colour matching functions x̄, ȳ, z̄ and the illuminant's relative spectral power S(λ) from
colour-science (``colour.MSDS_CMFS``, ``colour.SDS_ILLUMINANTS``), linearly interpolated onto the
spectrum's wavelengths (zero outside the tables), normalised so that a perfect reflector has
Y = 1 on that grid:

    X = Σ_λ ρ(λ) S(λ) x̄(λ) / Σ_λ S(λ) ȳ(λ)        (Y, Z alike; CIE 15:2004)

Linear sRGB (IEC 61966-2-1, D65 white): [R G B]ᵀ = M [X Y Z]ᵀ with the matrix of
``spectrum_to_srgb``; encoded sRGB: 12.92 c for c <= 0.0031308, else 1.055 c^{1/2.4} - 0.055.
CIELAB (CIE 1976 L*a*b*, CIE 15:2004) against the white (X_n, Y_n, Z_n) of a perfect
reflector under the same illuminant and weights, so that it has L* = 100, a* = b* = 0:

    L* = 116 f(Y/Y_n) - 16,  a* = 500 (f(X/X_n) - f(Y/Y_n)),  b* = 200 (f(Y/Y_n) - f(Z/Z_n))
    f(t) = t^{1/3} for t > (6/29)³, else t / (3 (6/29)²) + 4/29

Dr.Jit functions take and return tuples of three ``Float64`` arrays (one value per leaf); the
``*_np`` twins do the same in NumPy (for targets and tests). Every function is smooth where it
is used: branches are selected on inputs clamped into their own domain, so gradients stay finite.
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from mitsuba_veg.errors import ParameterError

from .prospect_dr import Float64

__all__ = ["SRGB_FROM_XYZ", "XYZ_FROM_SRGB", "colour_weights", "white_point", "spectrum_to_xyz",
           "xyz_to_linear_srgb", "srgb_encode", "xyz_to_lab", "spectrum_to_srgb",
           "xyz_to_lab_np", "lab_to_xyz_np", "srgb_decode_np", "srgb_encode_np",
           "srgb_to_xyz_np", "xyz_to_srgb_np"]

#: XYZ -> linear sRGB (IEC 61966-2-1; the matrix of ``spectra.spectrum_to_srgb``)
SRGB_FROM_XYZ = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])
#: linear sRGB -> XYZ (the exact inverse, so that targets round-trip)
XYZ_FROM_SRGB = np.linalg.inv(SRGB_FROM_XYZ)

_DELTA = 6.0 / 29.0
_SRGB_KNEE = 0.0031308

_WEIGHTS: dict = {}


def colour_weights(wavelength, illuminant="D65") -> np.ndarray:
    """Weights W (n_wl, 3) [-] with XYZ = Σ_λ ρ(λ) W(λ) (CIE 1931 2° observer).

    W(λ) = S(λ) (x̄, ȳ, z̄)(λ) / Σ_λ S(λ) ȳ(λ), the colour matching functions and illuminant
    interpolated linearly onto ``wavelength`` (zero outside the tables), so that a perfect
    reflector has Y = 1 (module docstring). Weights of named illuminants are cached.

    Parameters
    ----------
    wavelength : array_like
        (n_wl,) 1-D wavelength grid [nm] (at least 2 values, overlapping 360-830 nm).
    illuminant : str or array_like
        A name of ``colour.SDS_ILLUMINANTS`` (default ``"D65"``) or one relative power per
        wavelength [-] (non-negative, not all zero).

    Returns
    -------
    numpy.ndarray
        (n_wl, 3) weights [-].

    Raises
    ------
    ParameterError
        When the grid is not 1-D, misses the visible, or the illuminant is unknown or invalid.
    """
    wl = np.asarray(wavelength, dtype=np.float64)
    if wl.ndim != 1 or wl.size < 2:
        raise ParameterError("wavelength", np.shape(wavelength), "a 1-D grid of wavelengths [nm]",
                             "pass the spectrum's wavelengths, e.g. np.arange(400, 831)")
    named = isinstance(illuminant, str)
    key = (float(wl[0]), float(wl[-1]), len(wl), float(wl.sum()), illuminant) if named else None
    if key is not None and key in _WEIGHTS:
        return _WEIGHTS[key]
    import colour
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz = np.stack([np.interp(wl, cmfs.wavelengths, cmfs.values[:, i], left=0, right=0)
                    for i in range(3)], 1)
    if named:
        if illuminant not in colour.SDS_ILLUMINANTS:
            raise ParameterError("illuminant", illuminant, "a name in colour.SDS_ILLUMINANTS "
                                 "(e.g. 'D65', 'A') or one value per wavelength")
        sd = colour.SDS_ILLUMINANTS[illuminant]
        s = np.interp(wl, sd.wavelengths, sd.values, left=0, right=0)
    else:
        s = np.asarray(illuminant, dtype=np.float64)
        if s.shape != wl.shape or not np.all(np.isfinite(s)) or (s < 0).any() or s.sum() <= 0:
            raise ParameterError("illuminant", f"array of shape {s.shape}",
                                 f"{wl.shape}: one non-negative relative power per wavelength",
                                 "or a name such as 'D65'")
    w = xyz * s[:, None]
    ysum = w[:, 1].sum()
    if ysum <= 0:
        raise ParameterError("wavelength", (float(wl[0]), float(wl[-1])),
                             "a grid overlapping the visible (360-830 nm)",
                             "give wavelengths in nm")
    w = w / ysum
    if key is not None:
        _WEIGHTS[key] = w
    return w


def white_point(weights) -> np.ndarray:
    """XYZ of a perfect reflector under the weights' illuminant (Y = 1).

    Parameters
    ----------
    weights : array_like
        (n_wl, 3) weights from :func:`colour_weights`.

    Returns
    -------
    numpy.ndarray
        (3,) X_n, Y_n, Z_n [-].
    """
    return np.asarray(weights, dtype=np.float64).sum(0)


def spectrum_to_xyz(spectrum, weights, n_leaves: int = 1):
    """(X, Y, Z) of Dr.Jit spectra with ``weights`` from :func:`colour_weights`.

    Parameters
    ----------
    spectrum : drjit array
        Flat ``Float64`` spectra, ``n_leaves`` × n_wl values, leaf after leaf (e.g. reflectance
        [-]).
    weights : array_like
        (n_wl, 3) weights [-] on the spectrum's wavelengths.
    n_leaves : int
        Number of spectra (default 1).

    Returns
    -------
    tuple of Float64
        (X, Y, Z) [-], each a ``Float64`` of width ``n_leaves``.

    Raises
    ------
    ParameterError
        When the spectrum does not have ``n_leaves`` × n_wl values.
    """
    w = np.asarray(weights, dtype=np.float64)
    n = w.shape[0]
    if dr.width(spectrum) != n * n_leaves:
        raise ParameterError("spectrum", f"{dr.width(spectrum)} values",
                             f"{n_leaves} × {n} (leaves × wavelengths of the weights)",
                             "compute the weights on the spectrum's wavelengths")
    out = []
    for i in range(3):
        wi = Float64(w[:, i])
        if n_leaves == 1:
            out.append(dr.sum(spectrum * wi))
        else:
            out.append(dr.block_sum(spectrum * dr.tile(wi, n_leaves), n))
    return tuple(out)


def xyz_to_linear_srgb(xyz):
    """Linear sRGB (unclipped) from XYZ.

    [R G B]ᵀ = M [X Y Z]ᵀ with :data:`SRGB_FROM_XYZ` (IEC 61966-2-1, D65 white).

    Parameters
    ----------
    xyz : tuple of drjit array
        (X, Y, Z) [-].

    Returns
    -------
    tuple of drjit array
        (R, G, B) linear sRGB [-], unclipped.
    """
    X, Y, Z = xyz
    M = SRGB_FROM_XYZ.tolist()       # Python floats: NumPy scalars would capture the product
    return tuple(M[i][0] * X + M[i][1] * Y + M[i][2] * Z for i in range(3))


def srgb_encode(rgb, clip: bool = False):
    """sRGB transfer function (IEC 61966-2-1) on linear values.

    12.92 c for c <= 0.0031308, else 1.055 c^{1/2.4} - 0.055.

    Parameters
    ----------
    rgb : tuple of drjit array
        Linear sRGB channels [-].
    clip : bool
        Clip to [0, 1] first (as ``spectrum_to_srgb``); without it the linear segment continues
        below 0 and the power law above 1, so out-of-gamut colours keep a gradient (default
        False).

    Returns
    -------
    tuple of drjit array
        Encoded sRGB channels [-].
    """
    out = []
    for c in rgb:
        if clip:
            c = dr.clip(c, 0.0, 1.0)
        cp = dr.maximum(c, _SRGB_KNEE)        # the power branch only sees its own domain
        out.append(dr.select(c <= _SRGB_KNEE, 12.92 * c, 1.055 * dr.power(cp, 1.0 / 2.4) - 0.055))
    return tuple(out)


def _lab_f(t):
    tc = dr.maximum(t, _DELTA ** 3)
    return dr.select(t > _DELTA ** 3, dr.cbrt(tc), t / (3.0 * _DELTA ** 2) + 4.0 / 29.0)


def xyz_to_lab(xyz, white):
    """CIELAB (L*, a*, b*) from XYZ against the reference white ``white`` (X_n, Y_n, Z_n).

    CIE 1976 L*a*b* (CIE 15:2004), formulas in the module docstring.

    Parameters
    ----------
    xyz : tuple of drjit array
        (X, Y, Z) [-].
    white : array_like
        Reference white (X_n, Y_n, Z_n) [-], e.g. :func:`white_point`.

    Returns
    -------
    tuple of drjit array
        (L*, a*, b*) [-] (L* 0-100).
    """
    X, Y, Z = xyz
    Xn, Yn, Zn = (float(v) for v in white)
    fx, fy, fz = _lab_f(X / Xn), _lab_f(Y / Yn), _lab_f(Z / Zn)
    return 116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)


def spectrum_to_srgb(wavelength, spectrum, exposure: float = 1.0, n_leaves: int = 1,
                     illuminant="D65", clip: bool = True):
    """Encoded sRGB of Dr.Jit spectra.

    The Dr.Jit twin of :func:`mitsuba_veg.foliage.spectra.spectrum_to_srgb` (same weights,
    matrix, clipping): XYZ (:func:`spectrum_to_xyz`) times ``exposure``, linear sRGB, encoded.

    Parameters
    ----------
    wavelength : array_like
        (n_wl,) wavelengths of the spectra [nm].
    spectrum : drjit array
        Flat ``Float64`` spectra (``n_leaves`` × n_wl values, leaf after leaf), reflectance or
        transmittance [-].
    exposure : float
        Factor on XYZ before encoding [-] (default 1).
    n_leaves : int
        Number of spectra (default 1).
    illuminant : str or array_like
        Illuminant of :func:`colour_weights` (default ``"D65"``).
    clip : bool
        Clip linear sRGB to [0, 1] before encoding (default True).

    Returns
    -------
    tuple of drjit array
        (R, G, B) encoded sRGB [-], each of width ``n_leaves``.
    """
    xyz = spectrum_to_xyz(spectrum, colour_weights(wavelength, illuminant), n_leaves)
    rgb = xyz_to_linear_srgb(tuple(c * exposure for c in xyz))
    return srgb_encode(rgb, clip=clip)


# ------------------------------------------------------------------------------------------
# NumPy twins (targets, tests)
# ------------------------------------------------------------------------------------------
def _lab_f_np(t):
    t = np.asarray(t, dtype=np.float64)
    return np.where(t > _DELTA ** 3, np.cbrt(np.maximum(t, _DELTA ** 3)),
                    t / (3.0 * _DELTA ** 2) + 4.0 / 29.0)


def xyz_to_lab_np(xyz, white) -> np.ndarray:
    """CIELAB from XYZ (..., 3) against ``white``.

    Parameters
    ----------
    xyz : array_like
        (..., 3) X, Y, Z [-].
    white : array_like
        (3,) reference white X_n, Y_n, Z_n [-].

    Returns
    -------
    numpy.ndarray
        (..., 3) L*, a*, b* [-].
    """
    x = np.asarray(xyz, dtype=np.float64) / np.asarray(white, dtype=np.float64)
    fx, fy, fz = (_lab_f_np(x[..., i]) for i in range(3))
    return np.stack([116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)], -1)


def lab_to_xyz_np(lab, white) -> np.ndarray:
    """XYZ (..., 3) from CIELAB against ``white`` (the inverse of :func:`xyz_to_lab_np`).

    Parameters
    ----------
    lab : array_like
        (..., 3) L*, a*, b* [-].
    white : array_like
        (3,) reference white X_n, Y_n, Z_n [-].

    Returns
    -------
    numpy.ndarray
        (..., 3) X, Y, Z [-].
    """
    lab = np.asarray(lab, dtype=np.float64)
    fy = (lab[..., 0] + 16.0) / 116.0
    f = np.stack([fy + lab[..., 1] / 500.0, fy, fy - lab[..., 2] / 200.0], -1)
    t = np.where(f > _DELTA, f ** 3, 3.0 * _DELTA ** 2 * (f - 4.0 / 29.0))
    return t * np.asarray(white, dtype=np.float64)


def srgb_decode_np(srgb) -> np.ndarray:
    """Linear sRGB from encoded sRGB (0-1).

    Parameters
    ----------
    srgb : array_like
        Encoded sRGB values [-] in [0, 1].

    Returns
    -------
    numpy.ndarray
        Linear sRGB [-], the shape of ``srgb``.
    """
    c = np.asarray(srgb, dtype=np.float64)
    return np.where(c <= 12.92 * _SRGB_KNEE, c / 12.92,
                    ((np.maximum(c, 0.04) + 0.055) / 1.055) ** 2.4)


def srgb_encode_np(rgb, clip: bool = True) -> np.ndarray:
    """Encoded sRGB from linear sRGB (clipped to [0, 1] unless ``clip=False``).

    Parameters
    ----------
    rgb : array_like
        Linear sRGB values [-].
    clip : bool
        Clip to [0, 1] before encoding (default True).

    Returns
    -------
    numpy.ndarray
        Encoded sRGB [-], the shape of ``rgb``.
    """
    c = np.asarray(rgb, dtype=np.float64)
    if clip:
        c = np.clip(c, 0.0, 1.0)
    return np.where(c <= _SRGB_KNEE, 12.92 * c,
                    1.055 * np.maximum(c, _SRGB_KNEE) ** (1 / 2.4) - 0.055)


def srgb_to_xyz_np(srgb) -> np.ndarray:
    """XYZ (..., 3) of an encoded sRGB colour (..., 3).

    Parameters
    ----------
    srgb : array_like
        (..., 3) encoded sRGB [-] in [0, 1].

    Returns
    -------
    numpy.ndarray
        (..., 3) X, Y, Z [-] (:data:`XYZ_FROM_SRGB`).
    """
    return srgb_decode_np(srgb) @ XYZ_FROM_SRGB.T


def xyz_to_srgb_np(xyz, clip: bool = True) -> np.ndarray:
    """Encoded sRGB (..., 3) of XYZ (..., 3).

    Parameters
    ----------
    xyz : array_like
        (..., 3) X, Y, Z [-].
    clip : bool
        Clip linear sRGB to [0, 1] before encoding (default True).

    Returns
    -------
    numpy.ndarray
        (..., 3) encoded sRGB [-].
    """
    return srgb_encode_np(np.asarray(xyz, dtype=np.float64) @ SRGB_FROM_XYZ.T, clip)
