"""Knots from dormant buds on Weber-Penn trees (paper 004, section 3.3).

A knot (コブ) is a stunted branch grown from a dormant bud. The generator in
:mod:`mitsuba_veg.trees.weber_penn` decides, bud by bud, whether a child of a branch becomes a
normal branch or a knot, and shapes knots and the branches that sprout from them with the
equations of this module. Every function works on scalars or NumPy arrays.

Random numbers: the paper writes ``X ± (XV × Random)`` with ``Random`` in [0, 1]; here the signed
draw ``xi = ±Random`` is passed in, uniform in [-1, 1], so ``X + XV * xi`` covers [X - XV, X + XV]
(the Weber & Penn convention for every ``V`` parameter).

Parameters (each may be given per level, like the Weber-Penn ``n...`` parameters):

- ``KnotRate``/``V`` - probability that a bud in the knot zone becomes a knot; held per parent
  branch and multiplied by ``1 - KnotRateDecay`` each time one of its buds becomes a knot.
- ``KnotPosition``/``V`` - start of the knot zone as a fraction 0..1 of the parent's length.
  Below ``BaseSize`` (trunk only) every bud between the knot position and ``BaseSize`` is a knot.
- ``Contraction``/``V`` - growth suppression, eq 3.1 (larger: shorter knots).
- ``Density``/``V`` - thickness, eq 3.2 (larger: thicker knots).
- ``DormancyBreak``/``V`` - dormancy value of the knots on one parent; it decreases by
  ``DormancyStep`` per branching level; when it reaches 0 the knot's dormant bud sprouts a
  normal branch (eqs 3.3-3.4), otherwise the bud forms another knot that inherits the value.
"""
from __future__ import annotations

import numpy as np

__all__ = ["knot_length", "knot_radius", "sprout_length", "sprout_radius", "expected_knots",
           "assign_knots", "dormancy_after", "sprouts"]


def knot_length(length_branch, offset, contraction, contraction_v=0.0, xi=0.0):
    """Eq 3.1: length of a knot from the length its branch would have had.

    ``length_knot = length_branch / (Contraction ± ContractionV·Random) · (1 − offset)``.
    Knots near the base of their parent are longer than knots near its tip.

    Parameters
    ----------
    length_branch : float or array_like
        Length the branch would have had (Weber-Penn) [m].
    offset : float or array_like
        Position of the knot on its parent as a fraction 0 (base) .. 1 (tip) [-].
    contraction : float or array_like
        ``Contraction``, growth suppression [-] (larger: shorter knots).
    contraction_v : float or array_like, optional
        ``ContractionV``, its variation [-] (default 0).
    xi : float or array_like, optional
        The signed random in [-1, 1] [-] (default 0: no variation).

    Returns
    -------
    float or numpy.ndarray
        Knot length [m] (broadcast shape of the inputs).
    """
    c = np.asarray(contraction, float) + np.asarray(contraction_v, float) * np.asarray(xi, float)
    return np.asarray(length_branch, float) / c * (1.0 - np.asarray(offset, float))


def knot_radius(radius_branch, density, density_v=0.0, xi=0.0):
    """Eq 3.2: radius of a knot, ``radius_knot = radius_branch · (Density ± DensityV·Random)``.

    The printed equation has no brackets (``radius_branch × Density ± (DensityV × Random)``);
    the text defines Density as a correction factor of the branch thickness and DensityV as its
    variation, so the variation multiplies the radius too (docs/deviations.md).

    Parameters
    ----------
    radius_branch : float or array_like
        Radius the branch would have had (Weber-Penn) [m].
    density : float or array_like
        ``Density``, thickness factor [-] (larger: thicker knots).
    density_v : float or array_like, optional
        ``DensityV``, its variation [-] (default 0).
    xi : float or array_like, optional
        The signed random in [-1, 1] [-] (default 0).

    Returns
    -------
    float or numpy.ndarray
        Knot radius [m].
    """
    d = np.asarray(density, float) + np.asarray(density_v, float) * np.asarray(xi, float)
    return np.asarray(radius_branch, float) * d


def sprout_length(length_parent, contraction, variation, length_n, xi=0.0):
    """Eq 3.3: length of a branch sprouting from a knot.

    ``length_c = length_p · (Contraction ± V·Random) · LengthN``.
    The paper prints ``DensityV`` as ``V`` while its text names ContractionV; the caller passes
    whichever it uses (``SproutVariation`` option, docs/deviations.md). Multiplying by
    Contraction undoes the 1/Contraction of eq 3.1: the sprout grows "suddenly".

    Parameters
    ----------
    length_parent : float or array_like
        ``length_p``, the knot's length [m].
    contraction : float or array_like
        ``Contraction`` of the knot [-].
    variation : float or array_like
        ``V``, the variation of ``Contraction`` (ContractionV or DensityV) [-].
    length_n : float or array_like
        ``LengthN``, the Weber-Penn ``nLength`` of the sprouting branch's level [-].
    xi : float or array_like, optional
        The signed random in [-1, 1] [-] (default 0).

    Returns
    -------
    float or numpy.ndarray
        Length of the sprouted branch [m].
    """
    c = np.asarray(contraction, float) + np.asarray(variation, float) * np.asarray(xi, float)
    return np.asarray(length_parent, float) * c * np.asarray(length_n, float)


def sprout_radius(radius_parent, length_child, length_parent, density, density_v, ratio_power,
                  xi=0.0):
    """Eq 3.4: radius of a branch sprouting from a knot.

    ``radius_c = radius_p / (Density ± DensityV·Random) · (length_c/length_p)^RatioPower``.
    Dividing by Density undoes eq 3.2; the power law is Weber-Penn's child radius rule.

    Parameters
    ----------
    radius_parent : float or array_like
        ``radius_p``, the knot's radius [m].
    length_child : float or array_like
        ``length_c``, the sprouted branch's length (eq 3.3) [m].
    length_parent : float or array_like
        ``length_p``, the knot's length [m].
    density : float or array_like
        ``Density`` [-].
    density_v : float or array_like
        ``DensityV`` [-].
    ratio_power : float or array_like
        Weber-Penn ``RatioPower`` [-].
    xi : float or array_like, optional
        The signed random in [-1, 1] [-] (default 0).

    Returns
    -------
    float or numpy.ndarray
        Radius of the sprouted branch [m].
    """
    d = np.asarray(density, float) + np.asarray(density_v, float) * np.asarray(xi, float)
    ratio = np.asarray(length_child, float) / np.asarray(length_parent, float)
    return np.asarray(radius_parent, float) / d * ratio ** np.asarray(ratio_power, float)


def expected_knots(n_zone, rate, decay=0.0, max_factor=4.0):
    """Expected number of knots among the buds of one parent, computed in advance.

    The paper (§3.3.1, 発生率) folds the knot rate into the branch count so that knots do not
    thin out the branches: a parent that should carry ``n_zone`` normal branches in its knot zone
    gets ``n_zone + E`` buds there, where ``E`` is the expected number of knots. The rate starts
    at ``rate`` and is multiplied by ``1 - decay`` after each knot; ``E`` is the mean-field
    count: buds are added one at a time, each a knot with probability ``rate·(1-decay)^E_so_far``,
    until the expected normal buds reach ``n_zone`` (the last bud counts by the fraction needed).
    ``max_factor`` caps the buds at ``max_factor · n_zone`` (rate 1 without decay never ends).

    Example (tests): n_zone = 4, rate 0.5, decay 0.5 gives E = 1.6477.

    Parameters
    ----------
    n_zone : float or array_like
        Normal branches wanted in the knot zone of each parent [-] (may be fractional).
    rate : float or array_like
        Initial knot rate ``KnotRate``, a probability in [0, 1] [-].
    decay : float or array_like, optional
        ``KnotRateDecay``: the rate is multiplied by ``1 - decay`` after each knot [-]
        (default 0).
    max_factor : float, optional
        Cap on the buds, as a multiple of ``n_zone`` [-] (default 4).

    Returns
    -------
    float or numpy.ndarray
        Expected knot count ``E`` [-]: a float for scalar ``n_zone``, else an array of its shape.
    """
    scalar = np.ndim(n_zone) == 0
    n_zone = np.atleast_1d(np.asarray(n_zone, float))
    rate = np.broadcast_to(np.asarray(rate, float), n_zone.shape).astype(float)
    decay = np.broadcast_to(np.asarray(decay, float), n_zone.shape).astype(float)
    e = np.zeros_like(n_zone)
    normal = np.zeros_like(n_zone)
    buds = np.zeros_like(n_zone)
    cap = max_factor * n_zone
    active = (n_zone > 0) & (rate > 0)
    while active.any():
        p = rate[active] * (1.0 - decay[active]) ** e[active]
        need = n_zone[active] - normal[active]
        room = cap[active] - buds[active]
        step = np.minimum(1.0, np.minimum(need / np.maximum(1.0 - p, 1e-300), room))
        step = np.maximum(step, 0.0)
        e[active] += p * step
        normal[active] += (1.0 - p) * step
        buds[active] += step
        active = active & (normal < n_zone - 1e-12) & (buds < cap - 1e-12)
    return float(e[0]) if scalar else e


def assign_knots(row, in_zone, forced, rate, decay, u):
    """Decide bud by bud which buds become knots (vectorised over parents).

    A zone bud becomes a knot when ``u < rate[row]``; after each such knot the parent's rate is
    multiplied by ``1 - decay``. Forced buds are knots whatever their draw and leave the rate
    unchanged.

    Parameters
    ----------
    row : array_like
        (m,) int parent index of each bud, buds of one parent contiguous and in order from its
        base to its tip.
    in_zone : array_like
        (m,) bool: the bud lies in the knot zone.
    forced : array_like
        (m,) bool: the bud lies between the knot position and ``BaseSize`` (always a knot, rate
        unchanged).
    rate : array_like
        (n,) initial knot rate per parent [-].
    decay : float or array_like
        (n,) decay of the rate per knot [-].
    u : array_like
        (m,) uniform draws in [0, 1) [-].

    Returns
    -------
    is_knot : numpy.ndarray
        (m,) bool, True for buds that become knots.
    rate_used : numpy.ndarray
        (m,) float, the parent's rate at the time the bud was decided [-] (NaN outside the zone
        and for forced buds).
    """
    row = np.asarray(row, np.int64)
    m = len(row)
    is_knot = np.asarray(forced, bool).copy()
    rate_used = np.full(m, np.nan)
    if m == 0:
        return is_knot, rate_used
    cur = np.array(rate, float, copy=True)
    dec = np.broadcast_to(np.asarray(decay, float), cur.shape)
    # rank of each bud within its parent (buds of a parent are contiguous and ordered)
    start = np.r_[0, np.nonzero(np.diff(row))[0] + 1]
    rank = np.arange(m) - np.repeat(start, np.diff(np.r_[start, m]))
    cand = np.asarray(in_zone, bool) & ~is_knot
    u = np.asarray(u, float)
    for j in range(int(rank.max()) + 1):
        sel = np.nonzero((rank == j) & cand)[0]
        if not len(sel):
            continue
        r = row[sel]
        rate_used[sel] = cur[r]
        k = u[sel] < cur[r]
        is_knot[sel[k]] = True
        cur[r[k]] *= 1.0 - dec[r[k]]
    return is_knot, rate_used


def dormancy_after(value, step=1.0):
    """Dormancy-break value one branching level later (it decreases by ``step`` per level).

    Parameters
    ----------
    value : float or array_like
        Dormancy-break value (``DormancyBreak``) [-].
    step : float, optional
        ``DormancyStep``, decrease per branching level [-] (default 1).

    Returns
    -------
    numpy.ndarray or numpy.float64
        ``value - step`` [-] (a NumPy scalar for a scalar ``value``).
    """
    return np.asarray(value, float) - step


def sprouts(value, step=1.0):
    """True where a knot with dormancy ``value`` sprouts at the next level (value reaches 0).

    Parameters
    ----------
    value : float or array_like
        Dormancy-break value [-].
    step : float, optional
        ``DormancyStep``, decrease per branching level [-] (default 1).

    Returns
    -------
    numpy.ndarray or ``numpy.bool_``
        True where ``value - step <= 0`` (a NumPy scalar for a scalar ``value``).
    """
    return dormancy_after(value, step) <= 0.0
