"""Autumn logical time τ per leaf from cumulative insolation (paper 003 §3.3), stages, leaf fall.

Paper 003: τ = f1(cumulative insolation) = f2(t, x, y, z); τ is mapped onto Ishikura's 7 stages.
The paper gives no f1. We use (parameters :class:`AutumnParams`):

    τ_raw,i(d) = ξ_i [ (1 − β) H_i(d) / H_full + β (d − d0 + 1) / D_full ]
    τ_i(d)     = clip(τ_raw,i(d), 0, 1),      stage = 1 + 6 τ

- H_i(d): insolation of leaf i summed from the onset day d0 (abscission layer formed: sugar is
  trapped in the leaf; the paper treats temperature and water as threshold conditions only)
  through day d [MJ m-2]; H_full: the insolation that takes a leaf from green to all red.
- β: the share of pure aging with time since onset (a shaded leaf still colours, later);
  β = 0 is the paper's pure insolation model.
- ξ_i: per-leaf log-normal rate factor (median 1, log-sd ``rate_sigma``): the paper's future
  work, the non-deterministic factors (abscission-layer growth, sugar export) that make one tree's
  leaves colour unevenly.
- Leaf fall (optional, the paper's other future work): leaf i falls on the first day its τ_raw
  reaches φ_i = ``fall_tau`` · exp(``fall_sigma`` · N(0, 1)).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import drjit as dr
import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

from .pigments import pigments_at_stage, stage_from_tau, vary_pigments


__all__ = ["AutumnParams", "AutumnState", "autumn_time", "tau_raw", "leaf_factors", "params_dict",
           "apply_to_tree"]

@dataclass(frozen=True)
class AutumnParams:
    """Parameters of the autumn logical time (paper 003 §3.3) and of leaf fall.

    Attributes
    ----------
    insolation_full : float
        H_full [MJ m-2]: cumulative insolation that turns a median leaf all red.
    time_weight : float
        β [-]: weight of ageing with time alone (shaded leaves still colour).
    days_full : float
        D_full [days]: days after the onset that turn a leaf all red by time alone.
    onset_day : int
        d0: day index of the insolation result at which colouring starts.
    rate_sigma : float
        Log-sd of the per-leaf rate factor ξ [-].
    pigment_sigma : float
        Log-sd of the per-leaf pigment variation [-].
    fall : bool
        Whether leaves fall when τ_raw reaches their threshold.
    fall_tau : float
        Median τ_raw at which a leaf falls [-].
    fall_sigma : float
        Log-sd of the per-leaf fall threshold [-].
    """

    insolation_full: float = 250.0   # H_full [MJ m-2]
    time_weight: float = 0.2         # β [-]
    days_full: float = 60.0          # D_full [days]
    onset_day: int = 0               # d0: day index of the insolation result
    rate_sigma: float = 0.15         # log-sd of ξ
    pigment_sigma: float = 0.1       # log-sd of per-leaf pigment variation
    fall: bool = False
    fall_tau: float = 1.25           # median τ_raw at which a leaf falls
    fall_sigma: float = 0.1

    def validate(self) -> "AutumnParams":
        """Check every field's range.

        Returns
        -------
        AutumnParams
            ``self``, unchanged, so that ``params = params.validate()`` reads naturally.

        Raises
        ------
        ParameterError
            When a field is out of range (e.g. ``insolation_full`` [MJ m-2] not in (0, 1e5],
            ``time_weight`` [-] not in [0, 1], ``days_full`` [days] not in (0, 1000]).
        """
        check_range("insolation_full", self.insolation_full, 0.0, 1e5, lo_open=True,
                    fix="cumulative insolation in MJ m-2 that turns a leaf all red (~100-1000)")
        check_range("time_weight", self.time_weight, 0.0, 1.0)
        check_range("days_full", self.days_full, 0.0, 1000.0, lo_open=True)
        check_range("onset_day", self.onset_day, 0, 100000)
        check_range("rate_sigma", self.rate_sigma, 0.0, 2.0)
        check_range("pigment_sigma", self.pigment_sigma, 0.0, 2.0)
        check_range("fall_tau", self.fall_tau, 0.0, 100.0, lo_open=True)
        check_range("fall_sigma", self.fall_sigma, 0.0, 2.0)
        return self


@dataclass
class AutumnState:
    """Per-leaf autumn state over the days of an insolation result."""

    tau_raw: np.ndarray      # (n, days) unclipped logical time
    rate: np.ndarray         # (n,) ξ
    fall_threshold: np.ndarray  # (n,) φ (inf without leaf fall)
    params: AutumnParams

    def tau(self, day: int = -1) -> np.ndarray:
        """τ ∈ [0, 1] per leaf at the end of ``day`` (default: the last day).

        Parameters
        ----------
        day : int
            Day index of the insolation result (default -1: the last day).

        Returns
        -------
        numpy.ndarray
            (n_leaves,) autumn logical time τ [-], τ_raw clipped to [0, 1].
        """
        return np.clip(self.tau_raw[:, day], 0.0, 1.0)

    def stage(self, day: int = -1) -> np.ndarray:
        """Continuous Ishikura stage (1..7) per leaf.

        Parameters
        ----------
        day : int
            Day index of the insolation result (default -1: the last day).

        Returns
        -------
        numpy.ndarray
            (n_leaves,) stage [-] in [1, 7], 1 + 6 τ.
        """
        return stage_from_tau(self.tau(day))

    def fallen(self, day: int = -1) -> np.ndarray:
        """Boolean per leaf: has it fallen by the end of ``day``?

        Parameters
        ----------
        day : int
            Day index of the insolation result (default -1: the last day).

        Returns
        -------
        numpy.ndarray
            (n_leaves,) bool: τ_raw has reached the leaf's fall threshold φ (always False without
            leaf fall).
        """
        return self.tau_raw[:, day] >= self.fall_threshold

    def fall_day(self) -> np.ndarray:
        """Day index on which each leaf fell (-1: still on the tree).

        Returns
        -------
        numpy.ndarray
            (n_leaves,) int: the first day index whose τ_raw reaches φ, or -1.
        """
        f = self.tau_raw >= self.fall_threshold[:, None]
        return np.where(f.any(axis=1), f.argmax(axis=1), -1)

    def pigments(self, day: int = -1, seed=0) -> dict:
        """Per-leaf pigment contents [µg cm-2] at ``day`` with per-leaf random variation.

        Contents of the leaf's stage (:func:`~mitsuba_veg.foliage.pigments.pigments_at_stage`), each
        multiplied by a log-normal factor of log-sd ``params.pigment_sigma``
        (:func:`~mitsuba_veg.foliage.pigments.vary_pigments`).

        Parameters
        ----------
        day : int
            Day index of the insolation result (default -1: the last day).
        seed : int or numpy.random.Generator
            Seed of the per-leaf variation (default 0).

        Returns
        -------
        dict
            ``{"Cab", "Car", "Anth"}``: (n_leaves,) chlorophyll a+b, carotenoid and anthocyanin
            contents [µg cm-2].
        """
        p = pigments_at_stage(self.stage(day))
        if self.params.pigment_sigma > 0:
            p = vary_pigments(p, np.random.default_rng(seed), self.params.pigment_sigma)
        return p


def autumn_time(daily_insolation, params: AutumnParams = AutumnParams(), seed=0) -> AutumnState:
    """τ per leaf and day from daily insolation (n_leaves, days) [MJ m-2] (module docstring).

    Draws the per-leaf rate factors ξ and fall thresholds φ (:func:`leaf_factors`), accumulates
    the insolation from ``params.onset_day`` on and evaluates τ_raw (:func:`tau_raw`) for every
    leaf and day.

    Parameters
    ----------
    daily_insolation : array_like or InsolationResult
        (n_leaves, days) insolation per day [MJ m-2] (finite, >= 0); or an
        :class:`~mitsuba_veg.foliage.insolation.InsolationResult` (its ``daily``).
    params : AutumnParams
        Model parameters (validated here; default ``AutumnParams()``).
    seed : int
        Seed of the per-leaf random factors (default 0).

    Returns
    -------
    AutumnState
        τ_raw (n_leaves, days) [-], rate factors ξ [-] and fall thresholds φ [-] per leaf.

    Raises
    ------
    ParameterError
        When the insolation is not 2-D, or is negative or not finite, or a parameter is out of
        range.
    """
    params = params.validate()
    daily = getattr(daily_insolation, "daily", daily_insolation)
    daily = np.asarray(daily, float)
    if daily.ndim != 2:
        raise ParameterError("daily_insolation", daily.shape, "(n_leaves, days)")
    if (daily < 0).any() or not np.isfinite(daily).all():
        raise ParameterError("daily_insolation", "negative or non-finite values",
                             "finite values >= 0 [MJ m-2]")
    n, nd = daily.shape
    rate, fall_thr = leaf_factors(n, params, seed)
    d = np.arange(nd)
    after = d >= params.onset_day
    H = np.cumsum(np.where(after[None, :], daily, 0.0), axis=1)
    t = np.where(after, d - params.onset_day + 1, 0).astype(float)
    raw = tau_raw(H, t[None, :], rate[:, None], params)
    return AutumnState(raw, rate, fall_thr, params)


def tau_raw(H, days_since_onset, rate, params: AutumnParams):
    """The unclipped logical time of the module docstring.

    τ_raw = ξ [(1 − β) H / H_full + β t / D_full], with β = ``params.time_weight``,
    H_full = ``params.insolation_full`` and D_full = ``params.days_full``. Arrays broadcast.

    Parameters
    ----------
    H : array_like
        Insolation summed since the onset [MJ m-2].
    days_since_onset : array_like
        Days t since the onset [days] (onset day = 1).
    rate : array_like
        Per-leaf rate factor ξ [-].
    params : AutumnParams
        Model parameters.

    Returns
    -------
    numpy.ndarray or drjit array
        τ_raw [-] (not clipped), the broadcast shape of the inputs (Dr.Jit arrays in, a Dr.Jit
        array out).
    """
    if dr.is_array_v(H):  # Dr.Jit arrays (the daily world's leaves on the device)
        return rate * ((1 - params.time_weight) * H / params.insolation_full
                       + params.time_weight * days_since_onset / params.days_full)
    return rate * ((1 - params.time_weight) * np.asarray(H, float) / params.insolation_full
                   + params.time_weight * np.asarray(days_since_onset, float)
                   / params.days_full)


def leaf_factors(n: int, params: AutumnParams, seed=0) -> tuple[np.ndarray, np.ndarray]:
    """Per-leaf rate factors ξ and fall thresholds φ, drawn as :func:`autumn_time` draws them.

    ξ = exp(``rate_sigma`` N(0, 1)); φ = ``fall_tau`` exp(``fall_sigma`` N(0, 1)) with leaf fall,
    inf without.

    Parameters
    ----------
    n : int
        Number of leaves.
    params : AutumnParams
        Model parameters (``rate_sigma``, ``fall``, ``fall_tau``, ``fall_sigma``).
    seed : int
        Random seed (default 0).

    Returns
    -------
    rate : numpy.ndarray
        (n,) rate factors ξ [-] (log-normal, median 1).
    fall_threshold : numpy.ndarray
        (n,) fall thresholds φ [-] on τ_raw (inf without leaf fall).
    """
    rng = np.random.default_rng(seed)
    rate = np.exp(params.rate_sigma * rng.standard_normal(n))
    fall_thr = (params.fall_tau * np.exp(params.fall_sigma * rng.standard_normal(n))
                if params.fall else np.full(n, np.inf))
    return rate, fall_thr


def params_dict(p: AutumnParams) -> dict:
    """The parameters as a plain dict (``dataclasses.asdict``).

    Parameters
    ----------
    p : AutumnParams
        Model parameters.

    Returns
    -------
    dict
        Field name -> value (units as in :class:`AutumnParams`).
    """
    return asdict(p)


def apply_to_tree(tree, state: AutumnState, day: int = -1, seed=0) -> None:
    """Store a day's autumn state in the tree's per-leaf attributes.

    Sets ``autumn_tau`` [-], ``autumn_stage`` [-] (1..7), ``fallen`` (bool) and the pigment
    contents ``cab``, ``car``, ``anth`` [µg cm-2] (with per-leaf variation) in ``leaves.attrs``.

    Parameters
    ----------
    tree : Tree or Leaves
        A :class:`~mitsuba_veg.trees.Tree` (its ``leaves``) or the Leaves themselves; modified in
        place.
    state : AutumnState
        Autumn state with one row per leaf.
    day : int
        Day index of the state (default -1: the last day).
    seed : int
        Seed of the per-leaf pigment variation (default 0).

    Raises
    ------
    ParameterError
        When the state does not have one row per leaf.
    """
    lv = tree.leaves if hasattr(tree, "leaves") else tree
    if len(lv) != state.tau_raw.shape[0]:
        raise ParameterError("state", state.tau_raw.shape[0], f"one row per leaf ({len(lv)})")
    lv.attrs["autumn_tau"] = state.tau(day)
    lv.attrs["autumn_stage"] = state.stage(day)
    lv.attrs["fallen"] = state.fallen(day)
    p = state.pigments(day, seed=seed)
    lv.attrs["cab"], lv.attrs["car"], lv.attrs["anth"] = p["Cab"], p["Car"], p["Anth"]
