"""Smooth relaxations of the discrete moss events, with a temperature ``t`` (docs/tuning.md).

Every threshold of the discrete life cycle (paper 000 §3.6) is an indicator ``H(x) = [x > 0]``
of a quantity ``x`` in units of the fitness G (dimensionless, of order 0.1-1): death
``G_moss < tau_d`` while declining, germination ``G g(L) > tau_b``, the gemma staircase
``floor(G_moss / 0.5)``, spores ``G_moss >= 2`` while growing. The relaxed model replaces each
indicator by the logistic function

    H_t(x) = 1 / (1 + exp(-x / t)),        H_t(x) -> H(x) as t -> 0 (x != 0),

i.e. the probability that the event happens when the threshold carries logistic noise of scale
``t``; the relaxed model then evolves *expected* densities. ``t = 0`` selects the exact
indicators (no gradient), so the discrete rule is the ``t -> 0`` limit of every function here.

All functions take Dr.Jit arrays (any float type, with or without AD) and a temperature that is a
Python float or a width-1 Dr.Jit array (``dr.opaque``: changing it does not recompile kernels).
"""
from __future__ import annotations

import math

import drjit as dr

__all__ = ["heaviside", "soft_floor", "binomial_tail", "settle_fraction"]


def _is_zero(t) -> bool:
    return not dr.is_array_v(t) and float(t) == 0.0


def heaviside(x, t, strict: bool = True):
    """Relaxed indicator ``[x > 0]`` (``strict``) or ``[x >= 0]``: the logistic ``H_t(x)``.

    ``t = 0`` (a Python number) gives the exact indicator as 0/1 of the type of ``x``.
    Evaluated as ``(1 + tanh(x / 2t)) / 2``: no overflow for any ``x / t`` and a smooth
    derivative everywhere.

    Parameters
    ----------
    x : Dr.Jit float array
        The quantity whose sign is tested [-] (units of the fitness G).
    t : float or Dr.Jit float (width 1)
        Temperature of the relaxation [-] (same units as ``x``); 0 selects the exact indicator.
    strict : bool
        ``[x > 0]`` (True) or ``[x >= 0]`` (False); only matters at t = 0.

    Returns
    -------
    Dr.Jit float array
        ``H_t(x)`` in [0, 1], of the type of ``x``.
    """
    if _is_zero(t):
        m = (x > 0) if strict else (x >= 0)
        return dr.select(m, type(x)(1.0), type(x)(0.0))
    # 1 / (1 + exp(-x/t)) written with tanh: no overflow, smooth derivative at x = 0
    return 0.5 + 0.5 * dr.tanh((0.5 / t) * x if not dr.is_array_v(t) else x * (0.5 / t))


def soft_floor(x, t):
    """Relaxed staircase ``floor(x)`` for ``x >= 0``: ``sum_{k >= 1} H_t(x - k)``.

    Only the three steps nearest to ``x`` are evaluated (the others are 0 or 1 to within
    ``exp(-1/t)``, i.e. 2e-9 at t = 0.05); ``t = 0`` gives ``floor(x)`` exactly. Steps are at
    k = 1, 2, ... only, so ``soft_floor(0) ~ 0`` (no step sits at the origin).

    Parameters
    ----------
    x : Dr.Jit float array
        Values >= 0 [-].
    t : float or Dr.Jit float (width 1)
        Temperature of each step [-] (units of ``x``); 0: the exact ``floor``.

    Returns
    -------
    Dr.Jit float array
        The relaxed ``floor(x)`` [-].
    """
    n = dr.floor(x)
    if _is_zero(t):
        return n
    r = x - n  # in [0, 1): derivative 1 w.r.t. x (floor has derivative 0)
    out = dr.maximum(n - 2.0, 0.0)
    for j, dk in ((n - 1.0, 1.0), (n, 0.0), (n + 1.0, -1.0)):
        out += dr.select(j >= 1.0, heaviside(r + dk, t, strict=False), 0.0)
    return out


def binomial_tail(p, n: int, k: int):
    """P(X >= k) for X ~ Binomial(n, p), p in [0, 1] (a polynomial in p, differentiable).

    Used for the clump rule: a moss is *inside a clump* (no gemmae) when at least k of its
    neighbour cells hold moss; with neighbour cells occupied independently with the moss density
    p of its triangle, that probability is the binomial tail.

    Parameters
    ----------
    p : Dr.Jit float array
        Probability of each trial [-] (clipped to [0, 1]).
    n : int
        Number of trials.
    k : int
        Smallest number of successes counted.

    Returns
    -------
    Dr.Jit float array
        P(X >= k) [-], of the type of ``p``.
    """
    if k <= 0:
        return dr.full(type(p), 1.0, dr.width(p))
    if k > n:
        return dr.zeros(type(p), dr.width(p))
    p = dr.clip(p, 0.0, 1.0)
    q = 1.0 - p
    out = dr.zeros(type(p), dr.width(p))
    for j in range(k, n + 1):
        out += math.comb(n, j) * dr.power(p, j) * dr.power(q, n - j)
    return out


def settle_fraction(a):
    """``(1 - exp(-a)) / a`` for arrivals per spot ``a >= 0`` (1 at a = 0, stable near 0).

    ``a`` propagules landing uniformly on a triangle's spots (Poisson) leave ``1 - exp(-a)`` of
    its free spots taken; each arrival settles with probability ``free * (1 - e^-a) / a``.

    Parameters
    ----------
    a : Dr.Jit float array
        Arrivals per spot [-] (>= 0).

    Returns
    -------
    Dr.Jit float array
        ``(1 - exp(-a)) / a`` [-] (1 at a = 0).
    """
    small = a < 1e-4
    safe = dr.select(small, 1.0, a)
    return dr.select(small, 1.0 - 0.5 * a + a * a / 6.0, (1.0 - dr.exp(-safe)) / safe)
