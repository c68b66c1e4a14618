"""Environmental fitness, growth and germination of moss, paper 000 §3.6 (eqs 3.17-3.20, 3.24).

Pure, vectorised functions: NumPy in -> NumPy out (Python numbers give NumPy float64), Dr.Jit in
-> Dr.Jit out, differentiable with Dr.Jit (the power of eq 3.19 has a finite derivative at
s = 1/2). NaN inputs propagate to NaN. The moss population (G_moss of eq 3.21, death, gemmae,
spores, falling propagules) is not here.

Note on eq 3.19 as printed: ``g`` lies in ``[1/2 - (1/2)^n, 1/2 + (1/2)^n]``, which is [0, 1]
only for n = 1. For n = 0.5 (nrh of Bryum argenteum and Hypnum plumaeforme) g reaches
1/2 + sqrt(1/2) = 1.207 at the centre of the range and -0.207 far outside it. This module keeps the
printed formula (see docs/deviations.md).
"""
from __future__ import annotations

import math

from ..errors import ParameterError
from ..arrays import abs_ as _abs
from ..arrays import exp as _exp
from ..arrays import finish as _finish
from ..arrays import prep as _prep
from ..arrays import safe_power as _safe_power
from ..arrays import where as _where
from .species import get_species

__all__ = ["s", "fitness", "daily_fitness", "daily_growth", "germination_value", "germinates",
           "SPORE_L0", "SPORE_L1", "GEMMA_L0", "GEMMA_L1", "GERMINATION_WINDOW"]

#: Germination windows of eq 3.24 [days since the propagule was made] (paper 000 §3.6).
SPORE_L0, SPORE_L1 = 60.0, 365.0
#: (gemmae)
GEMMA_L0, GEMMA_L1 = -60.0, 60.0
#: both windows by propagule kind [days]
GERMINATION_WINDOW = {"spore": (SPORE_L0, SPORE_L1), "gemma": (GEMMA_L0, GEMMA_L1)}

_FOUR_LN2 = 4.0 * math.log(2.0)


def _check_window(x0, x1, n=None):
    """Reject scalar windows with x1 <= x0 or n <= 0 (arrays are not checked)."""
    def scalar(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool)
    if scalar(x0) and scalar(x1) and not x0 < x1:
        raise ParameterError("x0", x0, f"< x1 = {x1!r}", "the range needs x0 < x1")
    if n is not None and scalar(n) and not n > 0:
        raise ParameterError("n", n, "(0, 1] (table 3.7)", "the tolerance must be > 0")


def s(x, x0, x1):
    """Suitability of x for the range [x0, x1], eq (3.18) [-].

    ::

        s = exp{ -4 ln 2 / (x1 - x0)^2 * (x - (x1 + x0)/2)^2 }

    A Gaussian with its maximum 1 at the centre and s = 1/2 at x0 and x1 (the paper's "log" is the
    natural logarithm: only then is s(x0) = 1/2). x, x0, x1 in the unit of the factor.

    Parameters
    ----------
    x : float, array_like or drjit array
        Value of the growth factor, in the unit of the factor (e.g. [K], [-] or [W m-2]).
    x0, x1 : float, array_like or drjit array
        Lower and upper end of the range, in the unit of ``x``; x0 < x1.

    Returns
    -------
    numpy.float64, numpy.ndarray or drjit array
        Suitability s in (0, 1] [-], of the kind given (NumPy or Dr.Jit); NaN where an input is
        NaN.

    Raises
    ------
    ParameterError
        If scalar ``x0`` and ``x1`` do not satisfy x0 < x1 (arrays are not checked).
    """
    _check_window(x0, x1)
    x, x0, x1 = _prep(x, x0, x1)
    d = x - 0.5 * (x0 + x1)
    w = x1 - x0
    return _finish(_exp(-_FOUR_LN2 * d * d / (w * w)))


def fitness(x, x0, x1, n):
    """Fitness g of one growth factor, eq (3.19) [-].

    ::

        g = 1/2 + (s - 1/2)^n   if s > 1/2
        g = 1/2 - (1/2 - s)^n   otherwise,       s = s(x, x0, x1) of eq 3.18

    n in (0, 1] is the tolerance (n = 1: g = s). g = 1/2 at x0 and x1; g is symmetric about the
    centre and monotone on each side. As printed, g(centre) = 1/2 + (1/2)^n (1 for n = 1, 1.207 for
    n = 0.5) and g >= 1/2 - (1/2)^n.

    Parameters
    ----------
    x : float, array_like or drjit array
        Value of the growth factor, in the unit of the factor (e.g. [K], [-] or [W m-2]).
    x0, x1 : float, array_like or drjit array
        Lower and upper end of the range (table 3.7), in the unit of ``x``; x0 < x1.
    n : float, array_like or drjit array
        Tolerance in (0, 1] [-] (nT, nrh or nS of table 3.7).

    Returns
    -------
    numpy.float64, numpy.ndarray or drjit array
        Fitness g [-], in [1/2 - (1/2)^n, 1/2 + (1/2)^n] (see the module note), of the kind given.

    Raises
    ------
    ParameterError
        If scalar ``x0``, ``x1`` do not satisfy x0 < x1, or a scalar ``n`` is not > 0.
    """
    _check_window(x0, x1, n)
    sv, n = _prep(s(x, x0, x1), n)
    d = sv - 0.5
    p = _safe_power(_abs(d), n)
    return _finish(_where(d > 0.0, 0.5 + p, 0.5 - p))


def daily_fitness(species, Ts, rhs, S):
    """Daily environmental fitness G, eq (3.17) [-].

    ::

        G = g(Ts, T0, T1, nT) * g(rhs, rh0, rh1, nrh) * g(S, S0, S1, nS)

    Vectorised: one value per moss (or per spot).

    The one implementation of eq 3.17: the discrete run (parameters gathered per individual,
    ``moss.population.SpeciesTable``) and the relaxed model (differentiable parameters,
    ``tune.lifecycle``) both call it.

    Parameters
    ----------
    species : Species or str or mapping
        A :class:`Species`, a key of ``SPECIES``, or a mapping / object with the nine
        parameters ``T0, T1, nT, rh0, rh1, nrh, S0, S1, nS`` (numbers or arrays, e.g. one per
        individual or differentiable scalars).
    Ts : float, array_like or drjit array
        Surface temperature [K].
    rhs : float, array_like or drjit array
        Surface relative humidity [-].
    S : float, array_like or drjit array
        Daily-mean insolation [W m-2].

    Returns
    -------
    numpy.float64, numpy.ndarray or drjit array
        Daily fitness G [-], of the kind given.

    Raises
    ------
    ParameterError
        If ``species`` is a string that is not a key of ``SPECIES``.
    """
    if isinstance(species, str):
        species = get_species(species)
    if hasattr(species, "keys"):
        q = {k: species[k] for k in ("T0", "T1", "nT", "rh0", "rh1", "nrh", "S0", "S1", "nS")}
    else:
        q = {k: getattr(species, k) for k in ("T0", "T1", "nT", "rh0", "rh1", "nrh", "S0",
                                              "S1", "nS")}
    gT, grh, gS = _prep(fitness(Ts, q["T0"], q["T1"], q["nT"]),
                        fitness(rhs, q["rh0"], q["rh1"], q["nrh"]),
                        fitness(S, q["S0"], q["S1"], q["nS"]))
    return _finish(gT * grh * gS)


def daily_growth(species, G):
    """Daily growth D, eq (3.20): ``D = alpha_g (G - tau_g)`` [-] (negative = decline).

    The total growth since germination is ``G_moss = sum of D`` (eq 3.21); a moss dies when
    ``G_moss < tau_d`` while declining (D < 0).

    Parameters
    ----------
    species : Species or str
        A :class:`Species` or a key of ``SPECIES`` (gives alpha_g and tau_g [-]).
    G : float, array_like or drjit array
        Daily fitness of eq 3.17 [-].

    Returns
    -------
    numpy.float64, numpy.ndarray or drjit array
        Daily growth D [-] (negative = decline), of the kind given.

    Raises
    ------
    ParameterError
        If ``species`` is not a :class:`Species` or a key of ``SPECIES``.
    """
    sp = get_species(species)
    (G,) = _prep(G)
    return _finish(sp.alpha_g * (G - sp.tau_g))


def _window(kind):
    try:
        return GERMINATION_WINDOW[str(kind)]
    except KeyError:
        raise ParameterError("kind", kind, "'spore' or 'gemma'",
                             "name the propagule kind of eq 3.24") from None


def germination_value(G, L, kind):
    """Germination test value of eq (3.24): ``G * g(L, L0, L1, 1)`` [-].

    A propagule germinates when the value exceeds the species' ``tau_b`` (:func:`germinates`).

    Parameters
    ----------
    G : float, array_like or drjit array
        Daily fitness of eq 3.17 [-].
    L : float, array_like or drjit array
        Days since the propagule was made [days].
    kind : str
        ``"spore"`` (L0, L1 = 60, 365 [days]) or ``"gemma"`` (L0, L1 = -60, 60 [days]).

    Returns
    -------
    numpy.float64, numpy.ndarray or drjit array
        The test value [-], of the kind given.

    Raises
    ------
    ParameterError
        If ``kind`` is neither ``"spore"`` nor ``"gemma"``.
    """
    L0, L1 = _window(kind)
    G, gL = _prep(G, fitness(L, L0, L1, 1.0))
    return _finish(G * gL)


def germinates(species, G, L, kind):
    """Germination mask of eq (3.24): ``G * g(L, L0, L1, 1) > tau_b``.

    Parameters
    ----------
    species : Species or str
        A :class:`Species` or a key of ``SPECIES`` (gives tau_b [-]).
    G : float, array_like or drjit array
        Daily fitness of eq 3.17 [-].
    L : float, array_like or drjit array
        Days since the propagule was made [days].
    kind : str
        ``"spore"`` or ``"gemma"`` (the germination window of eq 3.24).

    Returns
    -------
    bool, numpy.ndarray of bool or drjit Bool array
        True where the propagule germinates.

    Raises
    ------
    ParameterError
        If ``species`` or ``kind`` is not known.
    """
    sp = get_species(species)
    return germination_value(G, L, kind) > sp.tau_b
