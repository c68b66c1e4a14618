"""PROSPECT-D leaf optics: hemispherical reflectance and transmittance of a leaf, 400-2500 nm.

Féret, Gitelson, Noble & Jacquemoud (2017), *PROSPECT-D: towards modeling leaf optical
properties through a complete lifecycle*, Remote Sensing of Environment 193, 204-215. The leaf is
a pile of N elementary absorbing plates (Allen et al. 1969, Stokes 1862): one plate's absorption
comes from the specific absorption coefficients k_i(λ) of its constituents,

    k(λ) = (Cab k_ab + Car k_car + Anth k_anth + Cbrown k_brown + Cw k_w + Cm k_m) / N
    τ(λ) = (1 - k) e^{-k} + k² E1(k)             (plate transmissivity, diffuse light)

and the plate's surfaces are dielectric interfaces with refractive index n(λ) (Stern 1964 / Allen
1973 average transmissivity for a cone of half angle α = 40° at the top surface, 90° inside).

The coefficient table (``dataSpec_PDB``, Féret et al. 2017, 1 nm steps 400-2500 nm) is read at
run time from the data file shipped in the PyPI package ``prosail`` (J. Gómez-Dans); the
package's Python code is not imported (it would pull in numba). This implementation is our own,
in NumPy, vectorised over leaves (``Cab`` etc. may be arrays: one spectrum per leaf).

Units: Cab, Car, Anth [µg cm-2]; Cbrown [arbitrary, 0-1]; Cw [cm] (= g cm-2 of water);
Cm [g cm-2]; N [-] (1-3; 1.2-1.8 for thin leaves such as maples).
"""
from __future__ import annotations

import importlib.util
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

#: wavelengths of the PROSPECT-D tables [nm]
WAVELENGTHS = np.arange(400, 2501, dtype=np.float64)


class ProspectCoefficients(NamedTuple):
    wavelength: np.ndarray  # [nm]
    nr: np.ndarray          # refractive index of the leaf material
    kab: np.ndarray         # chlorophyll a+b [cm2 µg-1]
    kcar: np.ndarray        # carotenoids [cm2 µg-1]
    kant: np.ndarray        # anthocyanins [cm2 µg-1]
    kbrown: np.ndarray      # brown pigments [arbitrary]
    kw: np.ndarray          # water [cm-1]
    km: np.ndarray          # dry matter [cm2 g-1]


def _data_file() -> Path:
    spec = importlib.util.find_spec("prosail")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(
            "PROSPECT-D needs the coefficient table shipped in the PyPI package 'prosail' "
            "(Féret et al. 2017, dataSpec_PDB). Install it: pip install 'prosail>=2.0.5'")
    for loc in spec.submodule_search_locations:
        p = Path(loc) / "prospect_d_spectra.txt"
        if p.exists():
            return p
    raise ImportError("the 'prosail' package has no prospect_d_spectra.txt; reinstall "
                      "prosail>=2.0.5")


@lru_cache(maxsize=1)
def coefficients() -> ProspectCoefficients:
    """The PROSPECT-D specific absorption coefficients and refractive index (Féret et al. 2017),
    read from ``prosail``'s data file (columns: λ, n, k_ab, k_car, k_anth, k_brown, k_w, k_m)."""
    data = np.loadtxt(_data_file(), comments="#")
    if data.shape != (2101, 8) or not np.allclose(data[:, 0], WAVELENGTHS):
        raise ImportError(f"unexpected PROSPECT-D table layout in {_data_file()}: {data.shape}")
    return ProspectCoefficients(*(np.ascontiguousarray(c) for c in data.T))


def _exp1(x):
    from scipy.special import exp1
    return exp1(x)


def calctav(alpha_deg: float, nr: np.ndarray) -> np.ndarray:
    """Average transmissivity of a dielectric interface for isotropic light within a cone of
    half angle ``alpha_deg`` (Stern 1964; Allen 1973), refractive index ``nr``."""
    n2 = nr * nr
    npx = n2 + 1.0
    nm = n2 - 1.0
    a = (nr + 1.0) ** 2 / 2.0
    k = -(n2 - 1.0) ** 2 / 4.0
    sa = np.sin(np.deg2rad(alpha_deg))
    b1 = np.sqrt((sa * sa - npx / 2.0) ** 2 + k) if alpha_deg != 90.0 else 0.0
    b2 = sa * sa - npx / 2.0
    b = b1 - b2
    ts = (k ** 2 / (6.0 * b ** 3) + k / b - b / 2.0) - (k ** 2 / (6.0 * a ** 3) + k / a - a / 2.0)
    tp1 = -2.0 * n2 * (b - a) / npx ** 2
    tp2 = -2.0 * n2 * npx * np.log(b / a) / nm ** 2
    tp3 = n2 * (1.0 / b - 1.0 / a) / 2.0
    tp4 = (16.0 * n2 ** 2 * (n2 ** 2 + 1.0) * np.log((2.0 * npx * b - nm ** 2)
                                                       / (2.0 * npx * a - nm ** 2))
           / (npx ** 3 * nm ** 2))
    tp5 = 16.0 * n2 ** 3 * (1.0 / (2.0 * npx * b - nm ** 2) - 1.0 / (2.0 * npx * a - nm ** 2)) \
        / npx ** 3
    tp = tp1 + tp2 + tp3 + tp4 + tp5
    return (ts + tp) / (2.0 * sa ** 2)


def _check(name, v, lo, hi, fix):
    a = np.asarray(v, dtype=np.float64)
    bad = ~np.isfinite(a) | (a < lo) | (a > hi)
    if bad.any():
        raise ParameterError(name, float(a[bad].flat[0]) if a.ndim else float(a),
                             f"[{lo}, {hi}]", fix)
    return a


def prospect_d(N=1.5, Cab=40.0, Car=5.0, Anth=0.0, Cbrown=0.0, Cw=0.012, Cm=0.005,
               alpha: float = 40.0):
    """PROSPECT-D: ``(wavelengths [nm], reflectance, transmittance)``, 400-2500 nm by 1 nm.

    Parameters broadcast (NumPy rules): pass arrays of length m to get (m, 2101) spectra, one
    row per leaf. Reflectance and transmittance are directional-hemispherical for light
    arriving within ``alpha`` degrees of the normal (40°, the model's calibration).
    """
    N = _check("N", N, 1.0, 4.0, "the leaf structure parameter N is 1-3 (1.5 for thin leaves)")
    Cab = _check("Cab", Cab, 0.0, 200.0, "chlorophyll a+b in µg/cm2 (0-100 typical)")
    Car = _check("Car", Car, 0.0, 60.0, "carotenoids in µg/cm2 (0-25 typical)")
    Anth = _check("Anth", Anth, 0.0, 100.0, "anthocyanins in µg/cm2 (0-40 typical)")
    Cbrown = _check("Cbrown", Cbrown, 0.0, 5.0, "brown pigments, arbitrary units 0-1")
    Cw = _check("Cw", Cw, 0.0, 0.2, "equivalent water thickness in cm (0.005-0.05 typical)")
    Cm = _check("Cm", Cm, 0.0, 0.1, "dry matter in g/cm2 (0.002-0.02 typical)")
    check_range("alpha", alpha, 0.0, 90.0, lo_open=True)
    c = coefficients()
    shape = np.broadcast_shapes(N.shape, Cab.shape, Car.shape, Anth.shape, Cbrown.shape,
                                Cw.shape, Cm.shape)
    ex = (Ellipsis, None)
    N_, Cab_, Car_, Anth_, Cb_, Cw_, Cm_ = (np.broadcast_to(x, shape)[ex] for x in
                                            (N, Cab, Car, Anth, Cbrown, Cw, Cm))
    k = (Cab_ * c.kab + Car_ * c.kcar + Anth_ * c.kant + Cb_ * c.kbrown + Cw_ * c.kw
         + Cm_ * c.km) / N_
    kk = np.maximum(k, 1e-300)
    tau = np.where(k > 0, (1.0 - kk) * np.exp(-kk) + kk ** 2 * _exp1(kk), 1.0)

    nr = c.nr
    talf = calctav(alpha, nr)
    ralf = 1.0 - talf
    t12 = calctav(90.0, nr)
    r12 = 1.0 - t12
    t21 = t12 / (nr * nr)
    r21 = 1.0 - t21
    denom = 1.0 - r21 * r21 * tau * tau
    Ta = talf * tau * t21 / denom
    Ra = ralf + r21 * tau * Ta
    t = t12 * tau * t21 / denom
    r = r12 + r21 * tau * t

    # N-1 further layers (Stokes 1862)
    D = np.sqrt(np.maximum((1 + r + t) * (1 + r - t) * (1 - r + t) * (1 - r - t), 0.0))
    rq, tq = r * r, t * t
    a = (1 + rq - tq + D) / (2 * r)
    b = (1 - rq + tq + D) / (2 * t)
    bNm1 = np.power(b, N_ - 1.0)
    bN2 = bNm1 * bNm1
    a2 = a * a
    den = a2 * bN2 - 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        Rsub = a * (bN2 - 1.0) / den
        Tsub = bNm1 * (a2 - 1.0) / den
    lossless = (r + t) >= 1.0
    if np.any(lossless):
        Tl = t / (t + (1.0 - t) * (N_ - 1.0))
        Tsub = np.where(lossless, Tl, Tsub)
        Rsub = np.where(lossless, 1.0 - Tl, Rsub)
    den = 1.0 - Rsub * r
    T = Ta * Tsub / den
    R = Ra + Ta * Rsub * t / den
    return c.wavelength.copy(), R, T
