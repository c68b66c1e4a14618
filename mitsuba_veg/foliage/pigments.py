"""Pigments of a maple leaf through Ishikura's 7 autumn stages (paper 003 §3.1, table 1, fig. 2).

The shipped table ``mitsuba_veg/data/foliage_ishikura_stages.csv`` (with its sources in the
header) gives leaf-mean chlorophyll a+b, carotenoid and anthocyanin contents [µg cm-2] per stage,
and the area fractions of the blade that are dark green-red / red. Autumn logical time τ ∈ [0, 1]
maps linearly onto the stages, ``stage = 1 + 6 τ``; contents are interpolated linearly in the
stage. Structure, water and dry matter stay constant (:class:`LeafTraits`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import drjit as dr
import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

__all__ = ["TABLE_FILE", "N_STAGES", "STATES", "StageTable", "stage_table", "LeafTraits",
           "stage_from_tau", "tau_from_stage", "pigments_at_stage", "pigments_at_tau",
           "state_pigments", "vary_pigments"]

#: the pigment table per stage (Ishikura's seven stages, reconstructed)
TABLE_FILE = Path(__file__).resolve().parent.parent / "data" / "foliage_ishikura_stages.csv"
#: number of autumn stages (Ishikura)
N_STAGES = 7
#: names of the three tissue states drawn on a leaf (stage 1, stage 5, stage 7 contents)
STATES = ("green", "dark_green_red", "red")


@dataclass(frozen=True)
class StageTable:
    """The pigment table of the seven autumn stages (``data/foliage_ishikura_stages.csv``).

    Attributes
    ----------
    stage : numpy.ndarray
        Stages 1..7.
    coloured : numpy.ndarray
        Area fraction of the blade that is dark green-red or red [-].
    red : numpy.ndarray
        Area fraction that is red [-].
    cab, car, anth : numpy.ndarray
        Chlorophyll a+b, carotenoid and anthocyanin contents [µg cm-2].
    source : str
        Where the table comes from.
    """

    stage: np.ndarray      # 1..7
    coloured: np.ndarray   # area fraction dark green-red or red
    red: np.ndarray        # area fraction red
    cab: np.ndarray        # [µg cm-2]
    car: np.ndarray
    anth: np.ndarray
    source: str


@lru_cache(maxsize=4)
def stage_table(path: str | None = None) -> StageTable:
    """The stage pigment table (default: the shipped Ishikura reconstruction).

    Reads a CSV with comment lines (``#``, the sources) and the columns ``stage, coloured, red,
    cab_ug_cm2, car_ug_cm2, anth_ug_cm2`` for stages 1..7 in order (cached).

    Parameters
    ----------
    path : str, optional
        CSV file; default :data:`TABLE_FILE` (``mitsuba_veg/data/foliage_ishikura_stages.csv``).

    Returns
    -------
    StageTable
        Stages [-], area fractions coloured / red [-], contents Cab, Car, Anth [µg cm-2] and the
        source text.

    Raises
    ------
    ParameterError
        When the file is missing, its columns or rows differ from the above, or a content is
        negative.
    """
    p = Path(path) if path else TABLE_FILE
    if not p.exists():
        raise ParameterError("stage table", str(p), "an existing CSV file",
                             "use the shipped mitsuba_veg/data/foliage_ishikura_stages.csv")
    lines = p.read_text().splitlines()
    source = "\n".join(ln[1:].strip() for ln in lines if ln.startswith("#"))
    rows = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
    header = [h.strip() for h in rows[0].split(",")]
    need = ["stage", "coloured", "red", "cab_ug_cm2", "car_ug_cm2", "anth_ug_cm2"]
    if header != need:
        raise ParameterError("stage table columns", header, ", ".join(need), source=str(p))
    data = np.array([[float(v) for v in r.split(",")] for r in rows[1:]])
    if data.shape[0] != N_STAGES or not np.allclose(data[:, 0], np.arange(1, 8)):
        raise ParameterError("stage table rows", data[:, 0].tolist(), "stages 1..7 in order",
                             source=str(p))
    if (data[:, 3:] < 0).any():
        raise ParameterError("stage table contents", "negative", ">= 0", source=str(p))
    return StageTable(data[:, 0], data[:, 1], data[:, 2], data[:, 3], data[:, 4], data[:, 5],
                      source)


@dataclass(frozen=True)
class LeafTraits:
    """Leaf properties that do not change with autumn colour (PROSPECT-D inputs).

    Defaults: a thin maple leaf: N = 1.4 layers, water Cw = 0.012 cm, dry matter Cm = 0.0045
    g cm-2 (leaf mass per area 45 g m-2), no brown pigments.
    """

    N: float = 1.4
    Cw: float = 0.012      # [cm]
    Cm: float = 0.0045     # [g cm-2]
    Cbrown: float = 0.0    # [-]


def stage_from_tau(tau):
    """Ishikura stage (continuous, 1..7) from autumn logical time τ (clipped to [0, 1]).

    stage = 1 + 6 clip(τ, 0, 1).

    Parameters
    ----------
    tau : float or array_like
        Autumn logical time τ [-].

    Returns
    -------
    numpy.ndarray or drjit array
        Stage [-] in [1, 7], the shape of ``tau`` (0-d for a number; a Dr.Jit array for one).

    Raises
    ------
    ParameterError
        When ``tau`` holds NaN.
    """
    if dr.is_array_v(tau):   # Dr.Jit arrays (the daily world's leaves): no NaN check on host
        return 1.0 + 6.0 * dr.clip(tau, 0.0, 1.0)
    t = np.asarray(tau, dtype=np.float64)
    if np.isnan(t).any():
        raise ParameterError("tau", "NaN", "numbers (autumn logical time, 0..1)")
    return 1.0 + 6.0 * np.clip(t, 0.0, 1.0)


def tau_from_stage(stage):
    """Inverse of :func:`stage_from_tau` for stages in [1, 7].

    Parameters
    ----------
    stage : float or array_like
        Ishikura stage [-].

    Returns
    -------
    numpy.ndarray
        τ = (stage − 1) / 6 [-], clipped to [0, 1].
    """
    s = np.asarray(stage, dtype=np.float64)
    return np.clip((s - 1.0) / 6.0, 0.0, 1.0)


def pigments_at_stage(stage, table: StageTable | None = None) -> dict:
    """Leaf-mean pigment contents [µg cm-2] at continuous stage(s) in [1, 7] (linear in stage).

    Parameters
    ----------
    stage : float or array_like
        Ishikura stage(s) [-] in [1, 7].
    table : StageTable, optional
        Stage table (default: ``stage_table()``).

    Returns
    -------
    dict
        ``{"Cab": ..., "Car": ..., "Anth": ...}``: chlorophyll a+b, carotenoid and anthocyanin
        contents [µg cm-2] with the shape of ``stage``.

    Raises
    ------
    ParameterError
        When a stage is NaN or outside [1, 7].
    """
    tb = table or stage_table()
    s = np.asarray(stage, dtype=np.float64)
    if np.isnan(s).any() or (s < 1).any() or (s > 7).any():
        raise ParameterError("stage", float(np.nanmin(s)) if (s < 1).any() else float(np.nanmax(s)),
                             "[1, 7] (Ishikura's stages)", "use stage_from_tau(tau)")
    return {"Cab": np.interp(s, tb.stage, tb.cab), "Car": np.interp(s, tb.stage, tb.car),
            "Anth": np.interp(s, tb.stage, tb.anth)}


def pigments_at_tau(tau, table: StageTable | None = None) -> dict:
    """Leaf-mean pigment contents [µg cm-2] at autumn logical time τ ∈ [0, 1].

    Parameters
    ----------
    tau : float or array_like
        Autumn logical time τ [-] (clipped to [0, 1]).
    table : StageTable, optional
        Stage table (default: ``stage_table()``).

    Returns
    -------
    dict
        ``{"Cab", "Car", "Anth"}`` [µg cm-2] with the shape of ``tau``
        (:func:`pigments_at_stage`).
    """
    return pigments_at_stage(stage_from_tau(tau), table)


def state_pigments(table: StageTable | None = None) -> dict:
    """Contents of the three tissue states drawn on a leaf.

    Green (stage 1), dark green-red (stage 5) and red (stage 7).

    Parameters
    ----------
    table : StageTable, optional
        Stage table (default: ``stage_table()``).

    Returns
    -------
    dict
        ``{state: {"Cab", "Car", "Anth"}}`` for the states of :data:`STATES`: contents
        [µg cm-2] (float).
    """
    tb = table or stage_table()
    return {name: {"Cab": float(tb.cab[i]), "Car": float(tb.car[i]), "Anth": float(tb.anth[i])}
            for name, i in zip(STATES, (0, 4, 6))}


def vary_pigments(pigments: dict, rng, sigma: float = 0.1) -> dict:
    """Per-leaf random variation (paper 003 §6's non-deterministic factors).

    Each content is multiplied by an independent log-normal factor with median 1 and log-sd
    ``sigma``.

    Parameters
    ----------
    pigments : dict
        Contents [µg cm-2] (e.g. ``{"Cab", "Car", "Anth"}``), numbers or arrays.
    rng : int or numpy.random.Generator
        Seed or generator (passed to ``numpy.random.default_rng``).
    sigma : float
        Log-sd of the factors [-] in [0, 2] (default 0.1).

    Returns
    -------
    dict
        The same keys, varied contents [µg cm-2] (float arrays of the input shapes).
    """
    check_range("sigma", sigma, 0.0, 2.0)
    rng = np.random.default_rng(rng)
    return {k: np.asarray(v, float) * np.exp(sigma * rng.standard_normal(np.shape(v)))
            for k, v in pigments.items()}
