"""Soil surface model of paper 000 §3.5 (daily means): Ts and rhs of a soil element.

One function per equation of the paper (eqs 3.2-3.16, table 3.4, tables 3.5/3.6 constants); the
docstrings give the equation number and SI units in brackets. Every function is vectorised and
works on NumPy arrays (or Python numbers, which give NumPy float64 results) *and* on Dr.Jit
arrays (``mi.Float`` = ``drjit.llvm.ad.Float``, ``Float64``, CUDA types ...): the result is of
the kind given, so the whole model can be differentiated with Dr.Jit. No Python loop runs over
elements.

Daily order (§3.7), implemented by :func:`surface_state`::

    R (3.2-3.4) -> C_H (3.5, given by the caller) -> theta and beta (3.8-3.10)
      -> Ts = T + deltaT (3.11-3.13, 3.15) -> iota*E (3.14) -> rhs (3.16)

and the water balance of the day by :func:`bucket_step` (3.6-3.8) with ``E = iotaE / iota``.
Reading of the paper's order: theta of day *i* is the water left at the end of day *i-1*
(``theta = O_{i-1}/h``), from which beta, Ts, iotaE and rhs of day *i* follow; then
``O_i = O_{i-1} - (86400 E_i - P_i)`` (clamped to ``[0, O_SAT]``) is the state for day *i+1*.

Where the paper is ambiguous or dimensionally wrong this module follows the physically consistent
reading; each such choice is listed in ``docs/deviations.md``:

- eq 3.15 uses the exact derivative of eqs 3.12-3.13 (the printed leading 6.1078 must be e_SAT);
- eq 3.9 clamps ``theta_SAT - theta`` at 0 (saturated soil: F = 0, beta = 1);
- eq 3.10: ``D_ATM`` is a diffusivity [m2 s-1] (printed m-2 s-1), F(theta) a length [m];
- eq 3.6: the bucket cannot hold less than 0 mm (evaporation beyond the stored water is dropped
  and reported as ``deficit``), and overflow above ``O_SAT`` runs off.

Kept as printed but documented there as pitfalls: denser moss (larger C_H, eq 3.5) *raises*
evaporation; iota = 2.543e6 J/kg looks like a transposed 2.453e6; eq 3.16 blows up for
deltaT <= -q_SAT/Delta (about -15 K); asphalt (table 3.4) has beta = 1 at any theta.

NaN policy: NaN inputs propagate to NaN outputs (nothing is silently clamped away: the clamps
are written so that a NaN operand stays NaN). Invalid *categorical* input (a geology code other
than 0, 1, 2) raises :class:`~mitsuba_veg.errors.ParameterError`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import drjit as dr
import numpy as np

from . import arrays
from .errors import ParameterError

__all__ = [
    # constants
    "SIGMA", "P_ATM", "ALBEDO", "D_ATM", "LATENT_HEAT", "RHO_AIR", "CP_RHO",
    "C_H_MIN", "C_H_MAX", "SECONDS_PER_DAY", "H_WALL", "H_MAX",
    "HUMUS", "SAND", "ASPHALT", "GEOLOGY", "GeologyParams", "geology_code", "geology_parameters",
    # equations
    "cloud_factor", "sky_longwave", "net_radiation", "transfer_coefficient",
    "soil_depth", "bucket_capacity", "water_content", "bucket_step", "BucketStep", "SoilState",
    "evaporation_F", "evaporation_efficiency", "e_sat", "q_sat", "dq_sat_dT",
    "surface_temperature_offset", "latent_heat_flux", "evaporation_rate", "surface_humidity",
    "surface_state", "SurfaceState", "linearisation_error", "ElementGeology", "insolation",
    "soil_day", "SoilDay",
]

# ------------------------------------------------------------------------------------------
# Constants (paper 000, tables 3.5 and 3.6 and §3.5.2, values as printed)
# ------------------------------------------------------------------------------------------
SIGMA = 5.67e-8          #: Stefan-Boltzmann constant [W m-2 K-4]
P_ATM = 1013.0           #: air pressure p [hPa]
ALBEDO = 0.2             #: surface albedo ``ref`` [-]
D_ATM = 2.54e-5          #: molecular diffusivity of water vapour at 20 C [m2 s-1] (printed m-2 s-1)
LATENT_HEAT = 2.543e6    #: latent heat of vaporisation iota [J kg-1] (as printed; see deviations)
RHO_AIR = 1.19           #: air density rho [kg m-3]
CP_RHO = 1.21e3          #: volumetric heat capacity of air c_P*rho [J K-1 m-3]
C_H_MIN = 0.0015         #: bulk transfer coefficient over bare soil [-] (eq 3.5)
C_H_MAX = 0.0030         #: bulk transfer coefficient under dense moss [-] (eq 3.5)
SECONDS_PER_DAY = 86400.0  #: [s day-1] (eq 3.6: 24 x 60 x 60)
H_WALL = 1.0             #: soil depth used where no soil lies below along y (walls) [mm]
H_MAX = 1000.0           #: soil depths above this are capped [mm]

_LN10 = math.log(10.0)
_MAGNUS_A = 7.5          # eq 3.12: 10^(7.5 t / (t + 237.3)), t [C]; T - 35.85 = t + 237.3
_MAGNUS_B = 237.3        # [K]
_E0 = 6.1078             # e_SAT at 0 C [hPa]


# ------------------------------------------------------------------------------------------
# Geology (paper 000, table 3.4)
# ------------------------------------------------------------------------------------------
class GeologyParams(NamedTuple):
    """Parameters of one geology (table 3.4): F(theta) = F1 (theta_SAT - theta)^F2 [m]."""
    name: str
    F1: float         #: [m]  (so that F is a length; see eq 3.10)
    F2: float         #: [-]
    theta_sat: float  #: saturated volumetric water content [m3 m-3]


#: the integer codes of the geology classes
HUMUS, SAND, ASPHALT = 0, 1, 2
#: Table 3.4, keyed by geology code (0 humus, 1 sand, 2 asphalt). Humus and sand from the paper's
#: ref. [13]; the asphalt values are the paper's own assumption.
GEOLOGY: dict[int, GeologyParams] = {
    HUMUS: GeologyParams("humus", 2.16e2, 10.0, 0.490),
    SAND: GeologyParams("sand", 8.32e5, 16.6, 0.392),
    ASPHALT: GeologyParams("asphalt", 7.25e7, 19.4, 0.012),
}
_GEO_NAMES = {p.name: code for code, p in GEOLOGY.items()}
_GEO_COLS = {f: np.array([getattr(GEOLOGY[c], f) for c in sorted(GEOLOGY)], dtype=np.float64)
             for f in ("F1", "F2", "theta_sat")}


def geology_code(name: str) -> int:
    """Geology code of a geology name (table 3.4).

    ``"humus"`` -> 0, ``"sand"`` -> 1, ``"asphalt"`` -> 2; case and surrounding spaces are ignored.

    Parameters
    ----------
    name : str
        Geology name: ``"humus"``, ``"sand"`` or ``"asphalt"``.

    Returns
    -------
    int
        Geology code (0 humus, 1 sand, 2 asphalt).

    Raises
    ------
    ParameterError
        If ``name`` is not one of the geologies of table 3.4.
    """
    try:
        return _GEO_NAMES[str(name).strip().lower()]
    except KeyError:
        raise ParameterError("geology", name, "one of " + ", ".join(_GEO_NAMES),
                             "use one of the geologies of table 3.4") from None


# ------------------------------------------------------------------------------------------
# Backend dispatch: NumPy or Dr.Jit, decided by the inputs (mitsuba_veg.arrays)
# ------------------------------------------------------------------------------------------
_is_dr, _dr_type, _prep, _finish = arrays.is_dr, arrays.float_type, arrays.prep, arrays.finish
_nan_keep, _exp, _abs, _where = arrays.nan_keep, arrays.exp, arrays.abs_, arrays.where
_maximum, _minimum, _power, _safe_power = (arrays.maximum, arrays.minimum, arrays.power,
                                           arrays.safe_power)


def _as_codes(geology) -> np.ndarray:
    """Validate geology codes (read back to NumPy) and return them as an int array."""
    g = np.asarray(geology)
    if g.dtype.kind == "f":
        if not np.all(np.isfinite(g)) or not np.all(g == np.round(g)):
            raise ParameterError("geology", geology, "integer codes 0 (humus), 1 (sand), 2 (asphalt)",
                                 "pass integer geology codes (table 3.4)")
        g = g.astype(np.int64)
    elif g.dtype.kind not in "iu":
        raise ParameterError("geology", geology, "integer codes 0 (humus), 1 (sand), 2 (asphalt)",
                             "pass integer geology codes or use geology_code(name)")
    bad = (g < 0) | (g > 2)
    if np.any(bad):
        raise ParameterError("geology", g[bad].ravel()[:5].tolist() if g.ndim else int(g),
                             "integer codes 0 (humus), 1 (sand), 2 (asphalt)",
                             "fix the geology codes (table 3.4)")
    return g


class ElementGeology:
    """Geology codes of many elements, checked once, with their table 3.4 parameters cached per
    array type.

    Every function of this module that takes ``geology`` accepts one: a daily loop on Dr.Jit
    arrays then neither uploads the codes nor reads them back to check them every day.

    Parameters
    ----------
    codes : array_like of int
        Geology code per element (0 humus, 1 sand, 2 asphalt).

    Raises
    ------
    ParameterError
        If a code is not 0, 1 or 2.
    """

    def __init__(self, codes):
        self.codes = _as_codes(codes).reshape(-1)
        self._cache: dict = {}

    def __len__(self) -> int:
        return len(self.codes)

    def parameters(self, t=None):
        """(F1 [m], F2 [-], theta_SAT [m3 m-3]) per element, as NumPy float64 (``t`` None) or
        as arrays of the Dr.Jit type ``t`` (cached).

        Parameters
        ----------
        t : type, optional
            A Dr.Jit float array type.

        Returns
        -------
        tuple
            The three parameter arrays.
        """
        if t is None:
            return tuple(_GEO_COLS[f][self.codes] for f in ("F1", "F2", "theta_sat"))
        if t not in self._cache:
            # aligned copies (arrays.host_array: the kernels' code then does not depend on
            # where NumPy put the values)
            vals = tuple(arrays.host_array(t, _GEO_COLS[f][self.codes])
                         for f in ("F1", "F2", "theta_sat"))
            dr.eval(vals)
            self._cache[t] = vals
        return self._cache[t]


def geology_parameters(geology, *like):
    """Per-element ``(F1, F2, theta_SAT)`` of table 3.4 for geology codes ``geology``.

    The arrays are NumPy float64, or of the Dr.Jit type of the first Dr.Jit array among ``like``
    (or of ``geology``), gathered from the 3-entry table. Invalid codes raise ParameterError
    (a Dr.Jit ``geology`` is read back for this check).

    Parameters
    ----------
    geology : array_like of int or drjit array or ElementGeology
        Geology codes (0 humus, 1 sand, 2 asphalt); integral floats are accepted.
    *like : array_like or drjit array
        Other inputs of the caller; the first Dr.Jit array among them sets the result type.

    Returns
    -------
    F1 : numpy.ndarray or drjit array
        Coefficient F1 of eq 3.9 [m].
    F2 : numpy.ndarray or drjit array
        Exponent F2 of eq 3.9 [-].
    theta_sat : numpy.ndarray or drjit array
        Saturated volumetric water content theta_SAT [m3 m-3].

    Raises
    ------
    ParameterError
        If a code is not an integer in {0, 1, 2} (or is NaN / infinite).
    """
    if isinstance(geology, ElementGeology):
        return geology.parameters(_dr_type(*like))
    codes = _as_codes(geology)
    t = _dr_type(*like, geology)
    if t is None:
        return tuple(_GEO_COLS[f][codes] for f in ("F1", "F2", "theta_sat"))
    u = dr.uint32_array_t(t)
    idx = u(geology) if _is_dr(geology) else u(np.asarray(codes, dtype=np.uint32).ravel())
    return tuple(dr.gather(t, t(_GEO_COLS[f]), idx) for f in ("F1", "F2", "theta_sat"))


# ------------------------------------------------------------------------------------------
# §3.5.1 Heat energy R
# ------------------------------------------------------------------------------------------
def cloud_factor(A):
    """Cloud-effect coefficient C, eq (3.2): ``C = 0.826A^3 - 1.234A^2 + 1.135A + 0.298``.

    C(0) = 0.298 (overcast), C(1) = 1.025 (clear).

    Parameters
    ----------
    A : array_like or drjit array
        Sunshine ratio A = N/N0 [-] (sunshine hours / possible sunshine hours).

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Cloud factor C [-] (of the kind of ``A``).
    """
    (A,) = _prep(A)
    return _finish(((0.826 * A - 1.234) * A + 1.135) * A + 0.298)


def sky_longwave(T, C):
    """Downward longwave radiation from the sky, eq (3.3): ``L = sigma T^4 (1 - 0.26 C)``.

    Parameters
    ----------
    T : array_like or drjit array
        Air temperature [K].
    C : array_like or drjit array
        Cloud factor of eq 3.2 [-].

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Sky longwave radiation L [W m-2].
    """
    T, C = _prep(T, C)
    return _finish(SIGMA * T**4 * (1.0 - 0.26 * C))


def net_radiation(S, L, ref=ALBEDO):
    """Heat energy at the surface, eq (3.4): ``R = (1 - ref) S + L``.

    Parameters
    ----------
    S : array_like or drjit array
        Daily-mean insolation [W m-2].
    L : array_like or drjit array
        Sky longwave radiation [W m-2] (eq 3.3).
    ref : float, optional
        Surface albedo [-]; default ``ALBEDO`` = 0.2.

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Heat energy R [W m-2].
    """
    S, L = _prep(S, L)
    return _finish((1.0 - ref) * S + L)


# ------------------------------------------------------------------------------------------
# §3.5.2 Bulk transfer coefficient and moss density
# ------------------------------------------------------------------------------------------
def transfer_coefficient(m, M=1.0, C_H_min=C_H_MIN, C_H_max=C_H_MAX):
    """Bulk transfer coefficient, eq (3.5): ``C_H = C_Hmin + (C_Hmax - C_Hmin) m / M``.

    ``m/M`` is clamped to [0, 1] (NaN kept).

    Parameters
    ----------
    m : array_like or drjit array
        Moss within a fixed range of the soil element [-] (or a coverage fraction with ``M = 1``).
    M : array_like or drjit array, optional
        The most moss that fit there [-]; default 1.
    C_H_min : float, optional
        C_H over bare soil [-]; default ``C_H_MIN`` = 0.0015.
    C_H_max : float, optional
        C_H under dense moss [-]; default ``C_H_MAX`` = 0.0030.

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        C_H [-], in [0.0015, 0.0030] with the default bounds.
    """
    m, M = _prep(m, M)
    f = _minimum(_maximum(m / M, 0.0), 1.0)
    return _finish(C_H_min + (C_H_max - C_H_min) * f)


# ------------------------------------------------------------------------------------------
# §3.5.3 Bucket model, theta and beta
# ------------------------------------------------------------------------------------------
def soil_depth(h):
    """Soil depth h used by the bucket model, §3.5.3 [mm].

    Where there is no soil (``h <= 0``, walls) the paper uses 1 mm, and depths above 1000 mm are
    capped at 1000 mm. NaN stays NaN.

    Parameters
    ----------
    h : array_like or drjit array
        Soil thickness along y [mm].

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Soil depth for the bucket model [mm], in [1, 1000] (``H_WALL`` where ``h <= 0``).
    """
    (h,) = _prep(h)
    return _finish(_where(h <= 0.0, H_WALL, _minimum(h, H_MAX)))


def bucket_capacity(h, geology):
    """Bucket capacity, eq (3.7): ``O_SAT = h theta_SAT`` [mm].

    Parameters
    ----------
    h : array_like or drjit array
        Soil depth [mm] (see :func:`soil_depth`).
    geology : array_like of int or drjit array
        Geology codes (0 humus, 1 sand, 2 asphalt); theta_SAT [m3 m-3] from table 3.4.

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Bucket capacity O_SAT [mm].
    """
    (h,) = _prep(h)
    _, _, ts = geology_parameters(geology, h)
    h, ts = _prep(h, ts)
    return _finish(h * ts)


def water_content(O, h):
    """Volumetric soil water content, eq (3.8): ``theta = O / h`` [m3 m-3].

    Parameters
    ----------
    O : array_like or drjit array
        Water stored in the bucket [mm].
    h : array_like or drjit array
        Soil depth [mm].

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Volumetric water content theta [m3 m-3].
    """
    O, h = _prep(O, h)
    return _finish(O / h)


class BucketStep(NamedTuple):
    """Result of one day of the bucket model (all per soil element)."""
    O: Any        #: water stored at the end of the day [mm]
    theta: Any    #: volumetric water content O/h [m3 m-3]
    runoff: Any   #: water above O_SAT that ran off [mm]
    deficit: Any  #: evaporation demand that found no water (bucket empty) [mm]


def bucket_step(O, E, P, h, geology):
    """One day of the bucket model, eqs (3.6)-(3.8).

    ``O_i = O_{i-1} - (86400 E_i - P_i)`` with overflow above ``O_SAT = h theta_SAT`` (eq 3.7)
    running off, and ``theta = O_i / h`` (eq 3.8). Not in the paper: the store cannot go below
    0 mm; the missing water is returned as ``deficit`` (see docs/deviations.md).

    Parameters
    ----------
    O : array_like or drjit array
        Water stored at the end of the previous day [mm].
    E : array_like or drjit array
        Evaporation rate of the day [kg m-2 s-1 = mm s-1] (``E = iotaE / iota``,
        :func:`evaporation_rate`; negative = dew).
    P : array_like or drjit array
        Precipitation of the day [mm].
    h : array_like or drjit array
        Soil depth [mm] (see :func:`soil_depth`).
    geology : array_like of int or drjit array
        Geology codes (0 humus, 1 sand, 2 asphalt).

    Returns
    -------
    BucketStep
        ``(O, theta, runoff, deficit)``: water stored at the end of the day [mm], volumetric water
        content [m3 m-3], water above O_SAT that ran off [mm], evaporation demand that found no
        water [mm].
    """
    O, E, P, h = _prep(O, E, P, h)
    _, _, ts = geology_parameters(geology, O, E, P, h)
    O, E, P, h, ts = _prep(O, E, P, h, ts)
    o_sat = h * ts
    raw = O - (SECONDS_PER_DAY * E - P)
    runoff = _maximum(raw - o_sat, 0.0)
    deficit = _maximum(-raw, 0.0)
    new = _minimum(_maximum(raw, 0.0), o_sat)
    return BucketStep(_finish(new), _finish(new / h), _finish(runoff), _finish(deficit))


@dataclass
class SoilState:
    """Water state of soil elements for the bucket model (eqs 3.6-3.8).

    ``O`` water stored [mm], ``h`` soil depth [mm] (already through :func:`soil_depth`),
    ``geology`` codes (0 humus, 1 sand, 2 asphalt). Arrays may be NumPy or Dr.Jit.
    """
    O: Any
    h: Any
    geology: Any

    @classmethod
    def saturated(cls, h, geology) -> "SoilState":
        """A state with every bucket full (``O = O_SAT``).

        Parameters
        ----------
        h : array_like or drjit array
            Soil thickness along y [mm]; passed through :func:`soil_depth`.
        geology : array_like of int or drjit array
            Geology codes (0 humus, 1 sand, 2 asphalt).

        Returns
        -------
        SoilState
            Saturated state: ``O = h theta_SAT`` [mm] with the clamped depth ``h`` [mm].
        """
        h = soil_depth(h)
        return cls(bucket_capacity(h, geology), h, geology)

    @property
    def theta(self):
        """Volumetric water content theta = O/h [m3 m-3] (eq 3.8)."""
        return water_content(self.O, self.h)

    @property
    def capacity(self):
        """O_SAT = h theta_SAT [mm] (eq 3.7)."""
        return bucket_capacity(self.h, self.geology)

    def step(self, E, P) -> tuple["SoilState", BucketStep]:
        """Advance the buckets by one day (eq 3.6).

        Parameters
        ----------
        E : array_like or drjit array
            Evaporation rate of the day [mm s-1] (= [kg m-2 s-1]; negative = dew).
        P : array_like or drjit array
            Precipitation of the day [mm].

        Returns
        -------
        state : SoilState
            The state at the end of the day (same ``h`` and ``geology``).
        step : BucketStep
            The day's bucket result (stored water [mm], theta [m3 m-3], runoff [mm], deficit [mm]).
        """
        r = bucket_step(self.O, E, P, self.h, self.geology)
        return SoilState(r.O, self.h, self.geology), r


def evaporation_F(theta, geology):
    """Soil evaporation function, eq (3.9): ``F(theta) = F1 (theta_SAT - theta)^F2`` [m].

    F is a length (a soil surface resistance times D_ATM): ``F / D_ATM`` [s m-1] is the soil
    resistance to vapour transfer. ``theta_SAT - theta`` is clamped at 0, so a saturated (or
    over-saturated) soil has F = 0 (the printed power of a negative base is NaN).

    Parameters
    ----------
    theta : array_like or drjit array
        Volumetric water content [m3 m-3].
    geology : array_like of int or drjit array
        Geology codes (0 humus, 1 sand, 2 asphalt).

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        F(theta) [m].
    """
    (theta,) = _prep(theta)
    F1, F2, ts = geology_parameters(geology, theta)
    theta, F1, F2, ts = _prep(theta, F1, F2, ts)
    base = _maximum(ts - theta, 0.0)
    return _finish(F1 * _safe_power(base, F2))


def evaporation_efficiency(theta, C_H, U, geology):
    """Evaporation efficiency, eq (3.10): ``beta = (1 + C_H U F(theta) / D_ATM)^-1`` [-].

    F [m] from eq 3.9, D_ATM [m2 s-1]: ``C_H U F / D_ATM`` = soil resistance / aerodynamic
    resistance, dimensionless.

    Parameters
    ----------
    theta : array_like or drjit array
        Volumetric water content [m3 m-3].
    C_H : array_like or drjit array
        Bulk transfer coefficient [-] (eq 3.5).
    U : array_like or drjit array
        Wind speed [m s-1].
    geology : array_like of int or drjit array
        Geology codes (0 humus, 1 sand, 2 asphalt).

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Evaporation efficiency beta [-], in (0, 1].
    """
    F = evaporation_F(theta, geology)
    C_H, U, F = _prep(C_H, U, F)
    return _finish(1.0 / (1.0 + C_H * U * F / D_ATM))


# ------------------------------------------------------------------------------------------
# §3.5.4 Saturation humidity, surface temperature, latent heat, surface humidity
# ------------------------------------------------------------------------------------------
def e_sat(T):
    """Saturation vapour pressure, eq (3.12): ``6.1078 x 10^(7.5 (T-273.15)/(T-35.85))`` [hPa].

    e_sat(273.15) = 6.1078 hPa.

    Parameters
    ----------
    T : array_like or drjit array
        Temperature [K].

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Saturation vapour pressure e_SAT [hPa].
    """
    (T,) = _prep(T)
    return _finish(_E0 * _exp(_LN10 * _MAGNUS_A * (T - 273.15) / (T - 35.85)))


def q_sat(T, p=P_ATM):
    """Saturation specific humidity, eq (3.13).

    ``q_SAT = (0.622 e_SAT/p) / (1 - 0.378 e_SAT/p)`` [kg kg-1].

    Parameters
    ----------
    T : array_like or drjit array
        Temperature [K].
    p : float, optional
        Air pressure [hPa]; default ``P_ATM`` = 1013 hPa.

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Saturation specific humidity q_SAT [kg kg-1].
    """
    (T,) = _prep(T)
    e = e_sat(T)
    return _finish((0.622 * e / p) / (1.0 - 0.378 * e / p))


def dq_sat_dT(T, p=P_ATM):
    """Slope of the saturation specific humidity, eq (3.15): ``Delta = dq_SAT/dT`` [K-1].

    The exact derivative of eqs 3.12-3.13::

        Delta = e_SAT(T) ln(10) 7.5 * 237.3 / (T - 35.85)^2  *  0.622 p / (p - 0.378 e_SAT)^2

    The printed eq 3.15 has the constant 6.1078 where e_SAT(T) belongs, and a Clausius-Clapeyron
    factor (2500 - 2.4t)/(0.4615 (273.15 + t)^2) that differs from the derivative of eq 3.12 by
    about 0.1 %; see docs/deviations.md.

    Parameters
    ----------
    T : array_like or drjit array
        Temperature [K].
    p : float, optional
        Air pressure [hPa]; default ``P_ATM`` = 1013 hPa.

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Delta = dq_SAT/dT [K-1] (q_SAT in [kg kg-1]).
    """
    (T,) = _prep(T)
    e = e_sat(T)
    de_dT = e * (_LN10 * _MAGNUS_A * _MAGNUS_B) / (T - 35.85) ** 2
    return _finish(de_dT * 0.622 * p / (p - 0.378 * e) ** 2)


def surface_temperature_offset(R, T, rh, U, beta, C_H):
    """Surface minus air temperature, eq (3.11) [K].

    ::

        deltaT = Ts - T = [R - sigma T^4 - iota rho beta C_H U q_SAT (1 - rh)]
                          / [4 sigma T^3 + c_P rho C_H U + iota rho beta C_H U Delta]

    Numerator [W m-2], denominator [W m-2 K-1] (linearised energy balance
    R = sigma Ts^4 + H + iotaE).

    Parameters
    ----------
    R : array_like or drjit array
        Heat energy at the surface [W m-2] (eq 3.4).
    T : array_like or drjit array
        Air temperature [K].
    rh : array_like or drjit array
        Relative humidity of the air [-] (0..1).
    U : array_like or drjit array
        Wind speed [m s-1].
    beta : array_like or drjit array
        Evaporation efficiency [-] (eq 3.10).
    C_H : array_like or drjit array
        Bulk transfer coefficient [-] (eq 3.5).

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        deltaT = Ts - T [K].
    """
    R, T, rh, U, beta, C_H, q, D = _prep(R, T, rh, U, beta, C_H, q_sat(T), dq_sat_dT(T))
    k = LATENT_HEAT * RHO_AIR * beta * C_H * U
    num = R - SIGMA * T**4 - k * q * (1.0 - rh)
    den = 4.0 * SIGMA * T**3 + CP_RHO * C_H * U + k * D
    return _finish(num / den)


def latent_heat_flux(T, rh, U, beta, C_H, dT):
    """Latent heat flux, eq (3.14): ``iotaE = iota rho beta C_H U {q_SAT (1 - rh) + Delta dT}``.

    Parameters
    ----------
    T : array_like or drjit array
        Air temperature [K].
    rh : array_like or drjit array
        Relative humidity of the air [-] (0..1).
    U : array_like or drjit array
        Wind speed [m s-1].
    beta : array_like or drjit array
        Evaporation efficiency [-] (eq 3.10).
    C_H : array_like or drjit array
        Bulk transfer coefficient [-] (eq 3.5).
    dT : array_like or drjit array
        Surface minus air temperature Ts - T [K] (eq 3.11).

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Latent heat flux iotaE [W m-2] (negative = dew).
    """
    rh, U, beta, C_H, dT, q, D = _prep(rh, U, beta, C_H, dT, q_sat(T), dq_sat_dT(T))
    return _finish(LATENT_HEAT * RHO_AIR * beta * C_H * U * (q * (1.0 - rh) + D * dT))


def evaporation_rate(lE):
    """Evaporation rate ``E = iotaE / iota`` for eq 3.6 [kg m-2 s-1 = mm s-1].

    Parameters
    ----------
    lE : array_like or drjit array
        Latent heat flux iotaE [W m-2] (eq 3.14).

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Evaporation rate E [kg m-2 s-1 = mm s-1] (negative = dew).
    """
    (lE,) = _prep(lE)
    return _finish(lE / LATENT_HEAT)


def surface_humidity(T, rh, beta, dT):
    """Surface relative humidity, eq (3.16).

    ``rhs = beta + rh q_SAT (1 - beta)/(q_SAT + Delta dT)``.
    ``q_SAT + Delta dT`` is the linearised q_SAT(Ts). As printed, the value can exceed 1 (surface
    colder than the air's dew point) and the linearisation breaks down for very cold surfaces
    (dT -> -q_SAT/Delta, about -15 K at 288 K, makes the denominator 0).

    Parameters
    ----------
    T : array_like or drjit array
        Air temperature [K].
    rh : array_like or drjit array
        Relative humidity of the air [-] (0..1).
    beta : array_like or drjit array
        Evaporation efficiency [-] (eq 3.10).
    dT : array_like or drjit array
        Surface minus air temperature Ts - T [K] (eq 3.11).

    Returns
    -------
    numpy.ndarray, numpy scalar or drjit array
        Surface relative humidity rhs [-].
    """
    rh, beta, dT, q, D = _prep(rh, beta, dT, q_sat(T), dq_sat_dT(T))
    return _finish(beta + rh * q * (1.0 - beta) / (q + D * dT))


def linearisation_error(T, Ts):
    """Relative error of the linearised saturation humidity of eqs 3.11-3.16.

    ``(q_SAT(T) + Delta (Ts - T)) / q_SAT(Ts) - 1`` [-]. Within 10 % for Ts - T in
    [-5.8, +8.3] K at 278 K, [-6.3, +9.0] K at 288 K and [-6.7, +9.7] K at 298 K; the linearised
    value reaches 0 at Ts - T = -q_SAT/Delta (-14.3 / -15.4 / -16.6 K) and is negative below,
    where eq 3.16 gives rhs -> +inf and then negative values (docs/deviations.md, "000 eq 3.16").

    Parameters
    ----------
    T : array_like or drjit array
        Air temperature [K].
    Ts : array_like or drjit array
        Surface temperature [K].

    Returns
    -------
    numpy.ndarray or drjit array
        Relative error of the linearised q_SAT(Ts) [-] (a float for scalar input, as every
        function of this module).
    """
    T, Ts = _prep(T, Ts)
    lin = q_sat(T) + dq_sat_dT(T) * (Ts - T)
    return _finish(lin / q_sat(Ts) - 1.0)


class SurfaceState(NamedTuple):
    """Daily-mean soil surface state returned by :func:`surface_state`."""
    Ts: Any    #: surface temperature [K]
    rhs: Any   #: surface relative humidity [-]
    lE: Any    #: latent heat flux iotaE [W m-2]
    beta: Any  #: evaporation efficiency [-]


def surface_state(S, T, rh, U, A, theta, geology, C_H) -> SurfaceState:
    """Soil surface state of one day, §3.5 in the order of §3.7 (eqs 3.2-3.16).

    All arguments broadcast; NumPy in -> NumPy out, Dr.Jit in -> Dr.Jit out.
    Order: R (3.2-3.4) -> C_H (given) -> beta(theta) (3.9-3.10) -> deltaT, Ts (3.11)
    -> iotaE (3.14) -> rhs (3.16). The evaporation rate for :func:`bucket_step` is
    ``evaporation_rate(lE)``.

    Parameters
    ----------
    S : array_like or drjit array
        Daily-mean insolation [W m-2].
    T : array_like or drjit array
        Air temperature [K].
    rh : array_like or drjit array
        Relative humidity of the air [-] (0..1).
    U : array_like or drjit array
        Wind speed [m s-1].
    A : array_like or drjit array
        Sunshine ratio A = N/N0 [-].
    theta : array_like or drjit array
        Volumetric water content [m3 m-3] (from the bucket model).
    geology : array_like of int or drjit array
        Geology codes (0 humus, 1 sand, 2 asphalt).
    C_H : array_like or drjit array
        Bulk transfer coefficient [-] (eq 3.5).

    Returns
    -------
    SurfaceState
        ``(Ts, rhs, lE, beta)``: surface temperature [K], surface relative humidity [-],
        latent heat flux iotaE [W m-2], evaporation efficiency [-].
    """
    S, T, rh, U, A, theta, C_H = _prep(S, T, rh, U, A, theta, C_H)
    R = net_radiation(S, sky_longwave(T, cloud_factor(A)))
    beta = evaporation_efficiency(theta, C_H, U, geology)
    dT = surface_temperature_offset(R, T, rh, U, beta, C_H)
    lE = latent_heat_flux(T, rh, U, beta, C_H, dT)
    rhs = surface_humidity(T, rh, beta, dT)
    T, dT, rhs, lE, beta = _prep(T, dT, rhs, lE, beta)
    if _is_dr(dT) and not _is_dr(beta):  # beta depends on theta, C_H, U only: same kind as Ts
        beta = type(dT)(beta)
    return SurfaceState(_finish(T + dT), _finish(rhs), _finish(lE), _finish(beta))


class SoilDay(NamedTuple):
    """One day of the soil model of one set of elements (:func:`soil_day`)."""
    surface: SurfaceState  #: Ts [K], rhs [-], iotaE [W m-2], beta [-] of the day
    theta: Any             #: soil water content at the start of the day [m3 m-3]
    O: Any                 #: water stored at the end of the day [mm]


def insolation(beam, diffuse, f_sun, f_sky):
    """Daily-mean insolation of elements from their sun and sky fractions:
    ``S = B f_sun + D f_sky`` [W m-2] (paper 000 §3.4-3.5 with the photon pass's fractions).

    ``f_sun`` and ``f_sky`` are the element's irradiance under a unit daily-mean horizontal beam
    and a unit horizontal diffuse irradiance (the photon pass with unit emitters), so the day's
    broadband beam B and diffuse D scale them.

    Parameters
    ----------
    beam, diffuse : float or array_like or drjit array
        Daily-mean horizontal beam B and diffuse D irradiance [W m-2].
    f_sun, f_sky : array_like or drjit array
        Sun and sky fractions per element [-].

    Returns
    -------
    numpy.ndarray or drjit array
        S [W m-2] per element.
    """
    beam, diffuse, f_sun, f_sky = _prep(beam, diffuse, f_sun, f_sky)
    return _finish(beam * f_sun + diffuse * f_sky)


def soil_day(O, S, T, rh, U, A, P, h, geology, C_H) -> SoilDay:
    """One day of the soil heat and water model, paper 000 §3.7 order (eqs 3.2-3.16, 3.6-3.8).

    theta = O/h (the water left at the end of the previous day), then the surface state of the
    day (:func:`surface_state`), its evaporation (:func:`evaporation_rate`) and the bucket
    (:func:`bucket_step`). The one implementation of the chain: the daily run (Dr.Jit arrays of
    its backend) and the relaxed, differentiable model of ``tune`` both call it.

    Parameters
    ----------
    O : array_like or drjit array
        Water stored at the end of the previous day [mm].
    S : array_like or drjit array
        Daily-mean insolation [W m-2].
    T : float or array_like or drjit array
        Air temperature [K].
    rh : float or array_like or drjit array
        Relative humidity of the air [-].
    U : float or array_like or drjit array
        Wind speed [m s-1].
    A : float or array_like or drjit array
        Sunshine ratio [-].
    P : float or array_like or drjit array
        Precipitation of the day [mm].
    h : array_like or drjit array
        Soil depth [mm].
    geology : array_like of int or drjit array or ElementGeology
        Geology codes (0 humus, 1 sand, 2 asphalt).
    C_H : array_like or drjit array
        Bulk transfer coefficient [-] (eq 3.5, from the moss density).

    Returns
    -------
    SoilDay
        The surface state, theta at the start of the day [m3 m-3] and the water stored at the
        end of the day [mm].
    """
    theta = water_content(O, h)
    st = surface_state(S, T, rh, U, A, theta, geology, C_H)
    O_next = bucket_step(O, evaporation_rate(st.lE), P, h, geology).O
    return SoilDay(st, theta, O_next)
