"""PROSPECT-D in Dr.Jit: leaf reflectance and transmittance, differentiable in every input.

The one implementation of the model (:func:`mitsuba_veg.foliage.prospect.prospect_d` is its
NumPy face), from Féret, Gitelson, Noble &
Jacquemoud (2017), *PROSPECT-D: towards modeling leaf optical properties through a complete
lifecycle*, Remote Sensing of Environment 193, 204-215, with the coefficient table
:func:`coefficients` (shipped in ``prosail``), written with Dr.Jit arrays so that automatic
differentiation (forward and reverse mode) gives d(R, T)/d(N, Cab, Car, Anth, Cbrown, Cw, Cm).

Equations (λ [nm] implicit everywhere):

1. Absorption of one elementary plate (eq 1 of Féret et al. 2017, after Jacquemoud & Baret 1990)

       k = (Cab K_ab + Car K_car + Anth K_anth + Cbrown K_brown + Cw K_w + Cm K_m) / N

   Cab, Car, Anth [µg cm-2], Cbrown [-], Cw [cm], Cm [g cm-2], N [-]; K_i the specific
   absorption coefficients [cm2 µg-1, -, cm-1, cm2 g-1].

2. Transmissivity of the plate for diffuse light (Allen et al. 1969)

       τ(k) = (1 - k) e^{-k} + k² E1(k),       dτ/dk = 2 (k E1(k) - e^{-k})

   with the exponential integral E1(x) = ∫_x^∞ e^{-t}/t dt, dE1/dx = -e^{-x}/x:

       E1(x) = -γ - ln x - Σ_{n>=1} (-x)^n / (n n!)                      x <= 2.5 (30 terms)
       E1(x) = e^{-x} / (x + 1 - 1²/(x + 3 - 2²/(x + 5 - ...)))          x > 2.5  (30 levels)

   (Abramowitz & Stegun 5.1.11 and 5.1.22; the continued fraction is evaluated bottom-up at a
   fixed depth so that every lane runs the same instructions). Relative error < 1e-13 for
   1e-12 <= x <= 200 (``tests/test_tune_leaf_colour.py``). The value is computed without AD and
   the derivatives above are attached with ``dr.replace_grad``: exact first derivatives in both
   AD modes, and τ'(0) = -2 stays finite where E1 itself diverges.

3. Interfaces (Stern 1964; Allen 1973): t_av(α, n) is the mean transmissivity of a dielectric
   interface of refractive index n(λ) for isotropic light within a cone of half angle α. It
   depends on n(λ) only, so it is computed once in NumPy (:func:`calctav`):
   t_α = t_av(40°, n), t12 = t_av(90°, n), t21 = t12 / n², r_x = 1 - t_x.

4. Top plate and a generic plate (Allen et al. 1969):

       T_a = t_α τ t21 / (1 - r21² τ²),         R_a = r_α + r21 τ T_a
       t   = t12 τ t21 / (1 - r21² τ²),         r   = r12 + r21 τ t

5. The other N - 1 plates (Stokes 1862):

       D = sqrt((1 + r + t)(1 + r - t)(1 - r + t)(1 - r - t))
       a = (1 + r² - t² + D) / (2 r),           b = (1 - r² + t² + D) / (2 t)
       R_sub = a (b^{2(N-1)} - 1) / (a² b^{2(N-1)} - 1)
       T_sub = b^{N-1} (a² - 1) / (a² b^{2(N-1)} - 1)

   and for a lossless plate (r + t >= 1, i.e. k = 0): T_sub = t / (t + (1 - t)(N - 1)),
   R_sub = 1 - T_sub.

6. The leaf:  R = R_a + T_a R_sub t / (1 - R_sub r),   T = T_a T_sub / (1 - R_sub r).

Array types: ``dr.float64_array_t(mi.Float)``, i.e. ``drjit.llvm.ad.Float64`` under
``llvm_ad_spectral`` (``drjit.cuda.ad.Float64`` under ``cuda_ad_spectral``): the backend of the
active Mitsuba variant, so the arrays mix with the rest of the package, but in double precision
(the variant's ``mi.Float`` is float32, which would limit the agreement with the NumPy model to
~1e-7 and the exponential integral to ~1e-7).

Several leaves at once: give parameters as arrays of length m (or Dr.Jit arrays of width m);
the spectra are then flat arrays of m × n_wavelength values, leaf after leaf.
"""
from __future__ import annotations

import importlib.util
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, check_range

__all__ = ["WAVELENGTHS", "coefficients", "calctav", "check_parameter", "Float64", "PARAMETERS",
           "BOUNDS", "exp1", "plate_transmissivity", "prospect_d",
           "ProspectSpectra", "wavelength_indices"]

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
    """The PROSPECT-D specific absorption coefficients and refractive index (Féret et al. 2017).

    Read from ``prosail``'s data file (columns: λ, n, k_ab, k_car, k_anth, k_brown, k_w, k_m),
    once (cached).

    Returns
    -------
    ProspectCoefficients
        (2101,) arrays on 400-2500 nm by 1 nm: wavelength [nm], refractive index n [-], k_ab,
        k_car, k_anth [cm2 µg-1], k_brown [arbitrary], k_w [cm-1], k_m [cm2 g-1].

    Raises
    ------
    ImportError
        When ``prosail`` (with ``prospect_d_spectra.txt``) is not installed or the table has an
        unexpected layout.
    """
    data = np.loadtxt(_data_file(), comments="#")
    if data.shape != (2101, 8) or not np.allclose(data[:, 0], WAVELENGTHS):
        raise ImportError(f"unexpected PROSPECT-D table layout in {_data_file()}: {data.shape}")
    return ProspectCoefficients(*(np.ascontiguousarray(c) for c in data.T))


def calctav(alpha_deg: float, nr: np.ndarray) -> np.ndarray:
    """Average transmissivity of a dielectric interface for isotropic light within a cone.

    Stern 1964; Allen 1973: t_av(α, n) for isotropic incident light within a cone of half angle
    ``alpha_deg`` on an interface of refractive index ``nr`` (module docstring, step 3).

    Parameters
    ----------
    alpha_deg : float
        Half angle α of the incident cone [degrees] (40 for the top surface, 90 inside).
    nr : numpy.ndarray
        Refractive index n(λ) [-] per wavelength.

    Returns
    -------
    numpy.ndarray
        t_av [-] per wavelength, the shape of ``nr``.
    """
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


#: the inputs of PROSPECT-D, in the order of :func:`prospect_d`
PARAMETERS = ("N", "Cab", "Car", "Anth", "Cbrown", "Cw", "Cm")

#: allowed ranges (the ones :func:`mitsuba_veg.foliage.prospect.prospect_d` checks) and fixes
BOUNDS = {
    "N": (1.0, 4.0, "the leaf structure parameter N is 1-4 (1.5 for thin leaves)"),
    "Cab": (0.0, 200.0, "chlorophyll a+b in µg/cm2 (0-100 typical)"),
    "Car": (0.0, 60.0, "carotenoids in µg/cm2 (0-25 typical)"),
    "Anth": (0.0, 100.0, "anthocyanins in µg/cm2 (0-40 typical)"),
    "Cbrown": (0.0, 5.0, "brown pigments, arbitrary units 0-1"),
    "Cw": (0.0, 0.2, "equivalent water thickness in cm (0.005-0.05 typical)"),
    "Cm": (0.0, 0.1, "dry matter in g/cm2 (0.002-0.02 typical)"),
}

_EULER_GAMMA = 0.57721566490153286061
_E1_SPLIT = 2.5      # series below, continued fraction above
_E1_TERMS = 30       # series terms: (2.5)^30 / (30 · 30!) < 1e-19
_E1_DEPTH = 30       # continued-fraction levels: relative error < 1e-13 for x > 2.5


def _float64_type():
    # the Float64 array of the active variant's backend (LLVM or CUDA), with AD
    return dr.float64_array_t(mi.Float)


#: the Float64 array type of the active variant's backend (LLVM or CUDA), with AD
Float64 = _float64_type()


def _as_float64(x):
    """Dr.Jit Float64 from a Python number, NumPy array or Dr.Jit array (AD kept)."""
    if dr.is_array_v(x):
        return x if type(x) is Float64 else Float64(x)
    a = np.asarray(x, dtype=np.float64).ravel()
    # opaque: a new value must not become a new kernel literal (and a recompilation)
    return dr.opaque(Float64, float(a[0])) if a.size == 1 else Float64(a)


# ------------------------------------------------------------------------------------------
# exponential integral and plate transmissivity
# ------------------------------------------------------------------------------------------
def _exp1_value(x):
    """E1(x) for x >= 0 without AD (series / continued fraction, see the module docstring)."""
    x = dr.detach(x)
    # series branch; max() keeps log() finite in lanes that take the other branch
    xs = dr.minimum(x, _E1_SPLIT)
    term = Float64(1.0)
    acc = Float64(0.0)
    for n in range(1, _E1_TERMS + 1):
        term = term * (-xs) / n
        acc += term / n
    series = -_EULER_GAMMA - dr.log(xs) - acc
    # continued fraction, bottom-up at a fixed depth; x >= 2.5 keeps every level positive
    xc = dr.maximum(x, _E1_SPLIT)
    d = xc + (2 * _E1_DEPTH + 1)
    for m in range(_E1_DEPTH, 0, -1):
        d = xc + (2 * m - 1) - (m * m) / d
    cfrac = dr.exp(-xc) / d
    return dr.select(x <= _E1_SPLIT, series, cfrac)


def exp1(x):
    """Exponential integral E1(x) = ∫_x^∞ e^{-t}/t dt for x >= 0 (E1(0) = inf), differentiable.

    dE1/dx = -e^{-x}/x (Abramowitz & Stegun 5.1.26), attached with ``dr.replace_grad`` when
    ``x`` has gradients enabled. Series for x <= 2.5, continued fraction above (module
    docstring, step 2).

    Parameters
    ----------
    x : float, array_like or drjit array
        Argument [-], x >= 0 (numbers, NumPy or Dr.Jit arrays).

    Returns
    -------
    Float64
        E1(x) [-] as a Dr.Jit ``Float64`` (AD kept).
    """
    x = _as_float64(x)
    v = _exp1_value(x)
    if not dr.grad_enabled(x):
        return v
    xd = dr.detach(x)
    slope = -dr.exp(-xd) / xd
    return dr.replace_grad(v, slope * x)


def plate_transmissivity(k):
    """τ(k) = (1 - k) e^{-k} + k² E1(k): transmissivity of an elementary plate.

    For isotropic incident light (Allen et al. 1969); τ(0) = 1. Derivative attached
    analytically: dτ/dk = 2 (k E1(k) - e^{-k}).

    Parameters
    ----------
    k : float, array_like or drjit array
        Absorption k of the plate [-], k >= 0.

    Returns
    -------
    Float64
        τ(k) [-] as a Dr.Jit ``Float64`` (AD kept).
    """
    k = _as_float64(k)
    kd = dr.detach(k)
    e1 = _exp1_value(kd)
    pos = kd > 0.0
    kE1 = dr.select(pos, kd * e1, 0.0)          # k E1(k) -> 0 as k -> 0
    ek = dr.exp(-kd)
    tau = dr.select(pos, (1.0 - kd) * ek + kd * kE1, 1.0)
    if not dr.grad_enabled(k):
        return tau
    return dr.replace_grad(tau, 2.0 * (kE1 - ek) * k)


# ------------------------------------------------------------------------------------------
# constants per wavelength set
# ------------------------------------------------------------------------------------------
def wavelength_indices(wavelengths=None) -> np.ndarray:
    """Indices into the 1-nm PROSPECT-D grid (400-2500 nm).

    Parameters
    ----------
    wavelengths : None, tuple of float or array_like, optional
        ``None`` = all; ``(lo, hi)`` = the closed range [lo, hi] [nm] (hi − lo > 1); or an array
        of wavelengths [nm] on the grid (whole nanometres).

    Returns
    -------
    numpy.ndarray
        int64 indices into :data:`WAVELENGTHS`.

    Raises
    ------
    ParameterError
        When the range or a wavelength lies outside [400, 2500] nm, or a wavelength is not a
        whole nanometre.
    """
    if wavelengths is None:
        return np.arange(len(WAVELENGTHS))
    w = np.asarray(wavelengths, dtype=np.float64)
    if w.shape == (2,) and w[1] - w[0] > 1.0:
        lo, hi = float(w[0]), float(w[1])
        if not (400.0 <= lo < hi <= 2500.0):
            raise ParameterError("wavelengths", (lo, hi), "a range inside [400, 2500] nm",
                                 "e.g. wavelengths=(400, 830) for colours")
        return np.nonzero((WAVELENGTHS >= lo) & (WAVELENGTHS <= hi))[0]
    w = w.ravel()
    off_grid = (np.abs(w - np.round(w)) > 1e-9).any()
    if w.size == 0 or (w < 400).any() or (w > 2500).any() or off_grid:
        raise ParameterError("wavelengths", f"{w.size} values in [{w.min() if w.size else 0:g}, "
                             f"{w.max() if w.size else 0:g}]",
                             "whole nanometres in [400, 2500] (the PROSPECT-D table grid)",
                             "interpolate measured spectra onto the 1-nm grid first")
    return (np.round(w) - 400).astype(np.int64)


@lru_cache(maxsize=16)
def _constants(idx_key: tuple, alpha: float) -> dict:
    idx = np.asarray(idx_key, dtype=np.int64)
    c = coefficients()
    nr = c.nr[idx]
    talf = calctav(alpha, nr)
    t12 = calctav(90.0, nr)
    t21 = t12 / (nr * nr)
    out = {name: Float64(getattr(c, attr)[idx]) for name, attr in
           (("Cab", "kab"), ("Car", "kcar"), ("Anth", "kant"), ("Cbrown", "kbrown"),
            ("Cw", "kw"), ("Cm", "km"))}
    out.update(talf=Float64(talf), ralf=Float64(1.0 - talf), t12=Float64(t12),
               r12=Float64(1.0 - t12), t21=Float64(t21), r21=Float64(1.0 - t21))
    return out


class ProspectSpectra(NamedTuple):
    """Leaf spectra as Dr.Jit ``Float64`` arrays (flat: leaf after leaf, n_wl values each)."""

    wavelength: np.ndarray   # [nm], the wavelengths computed
    reflectance: object      # Float64, m × n_wl
    transmittance: object    # Float64, m × n_wl
    n_leaves: int

    def numpy(self) -> tuple[np.ndarray, np.ndarray]:
        """(R, T) as NumPy arrays of shape (n_wl,) for one leaf, (m, n_wl) for several.

        Returns
        -------
        R, T : numpy.ndarray
            Reflectance and transmittance [-] (float64).
        """
        shape = (len(self.wavelength),) if self.n_leaves == 1 else (self.n_leaves, -1)
        return (np.asarray(self.reflectance, dtype=np.float64).reshape(shape),
                np.asarray(self.transmittance, dtype=np.float64).reshape(shape))


def check_parameter(name: str, x) -> int:
    """Refuse a PROSPECT-D input outside :data:`BOUNDS` (or not finite).

    Parameters
    ----------
    name : str
        One of :data:`PARAMETERS`.
    x : float, array_like or Dr.Jit array
        Its values (units as in :func:`prospect_d`).

    Returns
    -------
    int
        The number of values (leaves).
    """
    lo, hi, fix = BOUNDS[name]
    v = np.asarray(dr.detach(x) if dr.is_array_v(x) else x, dtype=np.float64).ravel()
    bad = ~np.isfinite(v) | (v < lo) | (v > hi)
    if bad.any():
        raise ParameterError(name, float(v[bad][0]), f"[{lo}, {hi}]", fix)
    return v.size


def prospect_d(N=1.5, Cab=40.0, Car=5.0, Anth=0.0, Cbrown=0.0, Cw=0.012, Cm=0.005, *,
               alpha: float = 40.0, wavelengths=None, check: bool = True) -> ProspectSpectra:
    """PROSPECT-D in Dr.Jit: directional-hemispherical reflectance and transmittance of a leaf.

    Equations in the module docstring; differentiable in all seven inputs. Inputs are numbers,
    NumPy arrays or Dr.Jit arrays (e.g. ``Float64`` with ``dr.enable_grad``); length m gives m
    leaves (every input has 1 or m values). Agrees with ``prosail``'s PROSPECT-D to < 1e-10
    (``tests/test_leaf_spectra.py``).

    Parameters
    ----------
    N : float, array_like or drjit array
        Leaf structure parameter [-] (1-4; default 1.5).
    Cab, Car, Anth : float, array_like or drjit array
        Chlorophyll a+b, carotenoids, anthocyanins [µg cm-2] (defaults 40, 5, 0).
    Cbrown : float, array_like or drjit array
        Brown pigments [-] (arbitrary units, default 0).
    Cw : float, array_like or drjit array
        Equivalent water thickness [cm] (default 0.012).
    Cm : float, array_like or drjit array
        Dry matter [g cm-2] (default 0.005).
    alpha : float
        Half angle of the incident cone [degrees] (40°, the model's calibration).
    wavelengths : None, tuple of float or array_like, optional
        ``None`` (400-2500 nm), ``(lo, hi)`` [nm] or whole nanometres; only those are computed
        (``(400, 830)`` for colours); see :func:`wavelength_indices`.
    check : bool
        Validate the ranges (:data:`BOUNDS`; reads the values back; switch off inside tight
        loops that keep values in range themselves).

    Returns
    -------
    ProspectSpectra
        Wavelengths [nm] and flat ``Float64`` reflectance and transmittance [-] (m × n_wl
        values, leaf after leaf), and m.

    Raises
    ------
    ParameterError
        When an input is out of range or the inputs' lengths differ (other than 1).
    """
    check_range("alpha", alpha, 0.0, 90.0, lo_open=True)
    vals = dict(zip(PARAMETERS, (N, Cab, Car, Anth, Cbrown, Cw, Cm)))
    sizes = {name: (check_parameter(name, v) if check else dr.width(v) if dr.is_array_v(v)
                    else np.size(v)) for name, v in vals.items()}
    m = max(sizes.values())
    bad = [n for n, s in sizes.items() if s not in (1, m)]
    if bad:
        raise ParameterError(bad[0], f"{sizes[bad[0]]} values", f"1 or {m} (one per leaf)",
                             "give every parameter as one value or one value per leaf")
    idx = wavelength_indices(wavelengths)
    n_wl = len(idx)
    cst = _constants(tuple(int(i) for i in idx), float(alpha))

    def per_leaf(v):
        v = _as_float64(v)
        return dr.repeat(v, n_wl) if m > 1 and dr.width(v) > 1 else v

    def per_wl(c):
        return dr.tile(c, m) if m > 1 else c

    P = {name: per_leaf(v) for name, v in vals.items()}
    C = {name: per_wl(c) for name, c in cst.items()}

    # eq 1: absorption of one plate
    k = (P["Cab"] * C["Cab"] + P["Car"] * C["Car"] + P["Anth"] * C["Anth"]
         + P["Cbrown"] * C["Cbrown"] + P["Cw"] * C["Cw"] + P["Cm"] * C["Cm"]) / P["N"]
    tau = plate_transmissivity(k)

    # eq 4: top plate (incident cone α) and a generic plate (isotropic light)
    talf, ralf, t12, r12, t21, r21 = (C[s] for s in ("talf", "ralf", "t12", "r12", "t21",
                                                     "r21"))
    denom = 1.0 - r21 * r21 * tau * tau
    Ta = talf * tau * t21 / denom
    Ra = ralf + r21 * tau * Ta
    t = t12 * tau * t21 / denom
    r = r12 + r21 * tau * t

    # eq 5: N - 1 further plates (Stokes); lossless plates (k = 0) have their own limit, and
    # stand-in values keep the general branch finite there (no NaN in either AD direction)
    lossless = (r + t) >= 1.0
    rs = dr.select(lossless, 0.5, r)
    ts = dr.select(lossless, 0.25, t)
    D = dr.sqrt(dr.maximum((1.0 + rs + ts) * (1.0 + rs - ts) * (1.0 - rs + ts)
                           * (1.0 - rs - ts), 1e-300))
    rq, tq = rs * rs, ts * ts
    a = (1.0 + rq - tq + D) / (2.0 * rs)
    b = (1.0 - rq + tq + D) / (2.0 * ts)
    bNm1 = dr.exp((P["N"] - 1.0) * dr.log(b))        # b^(N-1), b > 1
    bN2 = bNm1 * bNm1
    a2 = a * a
    den = a2 * bN2 - 1.0
    Rsub = a * (bN2 - 1.0) / den
    Tsub = bNm1 * (a2 - 1.0) / den
    Tl = t / (t + (1.0 - t) * (P["N"] - 1.0))
    Rsub = dr.select(lossless, 1.0 - Tl, Rsub)
    Tsub = dr.select(lossless, Tl, Tsub)

    # eq 6: the leaf
    den = 1.0 - Rsub * r
    T = Ta * Tsub / den
    R = Ra + Ta * Rsub * t / den
    return ProspectSpectra(WAVELENGTHS[idx].copy(), R, T, int(m))
