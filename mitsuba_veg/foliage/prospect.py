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
package's Python code is not imported (it would pull in numba). The model is written once, in
Dr.Jit (:mod:`mitsuba_veg.foliage.prospect_dr`, differentiable); :func:`prospect_d` here is its
NumPy face, vectorised over leaves (``Cab`` etc. may be arrays: one spectrum per leaf).

Units: Cab, Car, Anth [µg cm-2]; Cbrown [arbitrary, 0-1]; Cw [cm] (= g cm-2 of water);
Cm [g cm-2]; N [-] (1-4; 1.2-1.8 for thin leaves such as maples).
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from ..errors import check_range
from . import prospect_dr
from .prospect_dr import (WAVELENGTHS, ProspectCoefficients, calctav,  # noqa: F401 (re-exported)
                          coefficients)


__all__ = ["prospect_d"]

def prospect_d(N=1.5, Cab=40.0, Car=5.0, Anth=0.0, Cbrown=0.0, Cw=0.012, Cm=0.005,
               alpha: float = 40.0):
    """PROSPECT-D on NumPy arrays: reflectance and transmittance, 400-2500 nm by 1 nm.

    Parameters
    ----------
    N : float or array_like
        Leaf structure parameter [-] (1-4; 1.2-1.8 for thin leaves).
    Cab, Car, Anth : float or array_like
        Chlorophyll a+b, carotenoids, anthocyanins [µg cm-2].
    Cbrown : float or array_like
        Brown pigments [-] (0-1 typical).
    Cw : float or array_like
        Equivalent water thickness [cm].
    Cm : float or array_like
        Dry matter [g cm-2].
    alpha : float
        Half angle of the incident cone [deg] (40°, the model's calibration).

    Returns
    -------
    wavelength : numpy.ndarray
        (2101,) [nm].
    reflectance, transmittance : numpy.ndarray
        Directional-hemispherical [-], shape ``broadcast(parameters) + (2101,)``: the
        parameters broadcast (NumPy rules), one spectrum per leaf.
    """
    vals = []
    for name, v in zip(prospect_dr.PARAMETERS, (N, Cab, Car, Anth, Cbrown, Cw, Cm)):
        a = np.asarray(v, dtype=np.float64)
        prospect_dr.check_parameter(name, a)
        vals.append(a)
    check_range("alpha", alpha, 0.0, 90.0, lo_open=True)
    shape = np.broadcast_shapes(*(a.shape for a in vals))
    flat = [np.broadcast_to(a, shape).ravel() for a in vals]
    s = prospect_dr.prospect_d(*flat, alpha=alpha, check=False)
    dr.eval(s.reflectance, s.transmittance)
    R, T = s.numpy()
    n_wl = len(s.wavelength)
    return s.wavelength, R.reshape(shape + (n_wl,)), T.reshape(shape + (n_wl,))
