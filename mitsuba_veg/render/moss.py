"""Moss for the render: one tuft model per living moss, merged into one mesh per species.

Input is the moss population of a run (positions, surface normals, species, total growth
G_moss; :func:`live_moss` reads them from a checkpoint or snapshot). Each moss becomes one of the
species' tuft models (:mod:`.tufts`), standing on its patch of the moss carpet
(:mod:`.carpet`, which draws the moss's cover), with

- a random rotation about the surface normal and a small random tilt (paper 000: "randomly
  rotated");
- its place: the centre of the moss's spot-grid cell (where its carpet patch lies) when the
  grid's origin is given, else the moss's own position, moved by 1/f-noise jitter in the
  tangent plane (paper 000: "1/f noise on the place"), amplitude ``jitter`` x the moss size;
- 1/f-noise modulation of its size and tone, so that neighbouring tufts vary together
  (patches) rather than independently;
- a scale from its growth: ``size * (0.45 + 0.5 (1 - exp(-G / 4)))`` (a young moss with G ~ 0
  is half-size, an established one with G >> 4 reaches 0.95 x ``size``: its footprint stays
  inside its cell, so the tufts add relief, not cover, to what the carpet draws).

Mitsuba 3.9.1 does not scale to one ``instance`` per tuft (../shared/MITSUBA_NOTES.md), so all
tufts of a species are merged into one triangle mesh (vectorised: one einsum per tuft variant).
Per-vertex ``tone`` (tuft model tone mixed with the tuft's own noise and growth) is attached as a
mesh attribute that blends the species' dark and light spectral reflectances.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ParameterError
from .carpet import cell_keys
from .noise import pink_noise
from .tufts import TUFT_SIZE, tuft_models

__all__ = ["MOSS_STATE", "MossSet", "live_moss", "growth_scale", "cell_centres", "TuftMesh",
           "place_tufts"]

#: population state of a living moss (:mod:`mitsuba_veg.moss.population`)
MOSS_STATE = 2  # mitsuba_veg.moss.population.MOSS


@dataclass
class MossSet:
    """Living moss: positions (n, 3) [m], unit normals (n, 3), species index (n,), growth
    G_moss (n,), and the species keys the indices refer to."""

    pos: np.ndarray
    nrm: np.ndarray
    species: np.ndarray
    growth: np.ndarray
    species_names: list = field(default_factory=list)

    def __post_init__(self):
        self.pos = np.asarray(self.pos, np.float64).reshape(-1, 3)
        n = len(self.pos)
        self.nrm = np.asarray(self.nrm, np.float64).reshape(n, 3)
        self.species = np.asarray(self.species, np.int64).reshape(n)
        self.growth = np.asarray(self.growth, np.float64).reshape(n)
        ln = np.linalg.norm(self.nrm, axis=1, keepdims=True)
        self.nrm = np.where(ln > 0, self.nrm / np.maximum(ln, 1e-30), [[0.0, 1.0, 0.0]])

    def __len__(self):
        return len(self.pos)

    def subset(self, mask) -> "MossSet":
        """The moss selected by ``mask``.

        Parameters
        ----------
        mask : numpy.ndarray
            Boolean mask (n,) or integer indices into the moss.

        Returns
        -------
        MossSet
            A new set with the selected moss (same species names).
        """
        return MossSet(self.pos[mask], self.nrm[mask], self.species[mask], self.growth[mask],
                       list(self.species_names))


def live_moss(arrays: dict, species_names) -> MossSet:
    """The living moss (state 2) of a population dict (checkpoint.npz or a snapshot).

    Parameters
    ----------
    arrays : dict
        ``pos`` (n, 3) [m], ``nrm`` (n, 3) [-], ``species`` (n,), ``growth`` (n,) G_moss [-],
        and, for a checkpoint, ``state`` (n,): then only slots with state 2 (moss) are kept; a
        snapshot (no ``state``) holds living moss only.
    species_names : list of str
        Species keys, indexed by the population's species id.

    Returns
    -------
    MossSet
        The living moss.
    """
    if "state" in arrays:
        m = np.asarray(arrays["state"]) == MOSS_STATE
        return MossSet(np.asarray(arrays["pos"])[m], np.asarray(arrays["nrm"])[m],
                       np.asarray(arrays["species"])[m], np.asarray(arrays["growth"])[m],
                       list(species_names))
    return MossSet(arrays["pos"], arrays["nrm"], arrays["species"], arrays["growth"],
                   list(species_names))


def growth_scale(growth) -> np.ndarray:
    """Tuft scale factor from total growth G_moss (see module docstring).

    ``0.45 + 0.5 (1 - exp(-G / 4))``, G clipped at 0: 0.45 for a young moss, up to 0.95.

    Parameters
    ----------
    growth : float or array_like
        Total growth G_moss (eq 3.21) [-].

    Returns
    -------
    numpy.ndarray
        Scale factor in [0.45, 0.95) [-], of the shape of ``growth``.
    """
    g = np.maximum(np.asarray(growth, np.float64), 0.0)
    return 0.45 + 0.5 * (1.0 - np.exp(-g / 4.0))


def cell_centres(pos, nrm, origin, size: float) -> np.ndarray:
    """The centre of each moss's cell seen along its dominant axis, on its tangent plane.

    Parameters
    ----------
    pos, nrm : array_like
        Moss positions [m] and unit normals [-], (n, 3).
    origin : array_like
        The spot grid's origin (3,) [m].
    size : float
        Cell side [m].

    Returns
    -------
    numpy.ndarray
        Points (n, 3) [m].
    """
    pos = np.asarray(pos, np.float64)
    nrm = np.asarray(nrm, np.float64)
    origin = np.asarray(origin, np.float64)
    d, ia, ib = cell_keys(pos, nrm, origin, size)
    a, b = (d + 1) % 3, (d + 2) % 3
    r = np.arange(len(pos))
    out = pos.copy()
    out[r, a] = origin[a] + (ia + 0.5) * size
    out[r, b] = origin[b] + (ib + 0.5) * size
    out[r, d] = pos[r, d] - (nrm[r, a] * (out[r, a] - pos[r, a]) +
                             nrm[r, b] * (out[r, b] - pos[r, b])) / nrm[r, d]
    return out


def _tangent_frames(n):
    a = np.where(np.abs(n[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(a, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    return t, b


@dataclass
class TuftMesh:
    """Merged tufts of one species: vertices (v, 3) float32, faces (f, 3) uint32, tone (v,)."""

    species: str
    vertices: np.ndarray
    faces: np.ndarray
    tone: np.ndarray
    count: int


def place_tufts(moss: MossSet, size: float = TUFT_SIZE, jitter: float = 0.12,
                tilt_deg: float = 12.0, seed: int = 0, variants: int | None = None,
                noise_scale: float = 0.08, origin=None, lift: float = 0.0) -> list[TuftMesh]:
    """Merge one tuft model per moss into one mesh per species (module docstring).

    A moss keeps its look from frame to frame when the seed and its position stay the same: every
    random draw is keyed on the position (quantised to 0.1 mm).

    Parameters
    ----------
    moss : MossSet
        The living moss.
    size : float, optional
        Tuft footprint [m] at scale 1 (the moss size of the run; default :data:`TUFT_SIZE`,
        0.01 m).
    jitter : float, optional
        1/f placement jitter amplitude as a fraction of ``size`` [-] (default 0.12).
    tilt_deg : float, optional
        Largest random tilt of the tuft axis from the surface normal [degrees] (default 12).
    seed : int, optional
        Makes rotations and variant choices reproducible (default 0).
    variants : int or None, optional
        Tuft models per species to choose from (default None: :data:`~.tufts.VARIANTS`).
    noise_scale : float, optional
        The 1/f noise's largest wavelength [m] (default 0.08; size and tone patches use twice
        that).
    origin : array_like, optional
        The spot grid's origin (3,) [m] (:func:`mitsuba_veg.render.carpet.grid_origin`): each
        tuft then stands at the centre of its moss's cell, on the moss's tangent plane; None: at
        the moss's position.
    lift : float, optional
        Height of the tufts' base above the surface [m] (default 0; the carpet's height when the
        tufts stand on it).

    Returns
    -------
    list of TuftMesh
        One merged mesh per species present (vertices [m], faces, per-vertex tone in [0, 1]),
        empty when there is no moss.

    Raises
    ------
    ParameterError
        If ``size`` is not a finite length > 0.
    """
    if size <= 0 or not np.isfinite(size):
        raise ParameterError("size", size, "> 0 [m]", "the moss size of the run, e.g. 0.01")
    out = []
    if len(moss) == 0:
        return out
    # per-tuft random numbers keyed on the (quantised) position: stable across frames
    q = np.round(moss.pos / 1e-4).astype(np.int64)
    key = (q[:, 0] * 73856093) ^ (q[:, 1] * 19349663) ^ (q[:, 2] * 83492791) ^ (seed * 2654435761)
    key = key.astype(np.uint64)

    def rnd(stream):
        h = (key + np.uint64((stream * 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFF)) & \
            np.uint64(0xFFFFFFFFFFFF)
        h ^= h >> np.uint64(17)
        h = (h * np.uint64(0xED5AD4BB)) & np.uint64(0xFFFFFFFFFFFF)
        h ^= h >> np.uint64(11)
        h = (h * np.uint64(0xAC4C1B51)) & np.uint64(0xFFFFFFFFFFFF)
        h ^= h >> np.uint64(15)
        return (h & np.uint64(0xFFFFFF)).astype(np.float64) / float(1 << 24)

    n = moss.nrm
    t, b = _tangent_frames(n)
    base = moss.pos if origin is None else cell_centres(moss.pos, n, origin, size)
    # 1/f jitter of placement, tangent to the surface
    jx = pink_noise(moss.pos, noise_scale, seed=seed + 1)
    jy = pink_noise(moss.pos, noise_scale, seed=seed + 2)
    pos = base + jitter * size * 2.0 * (jx[:, None] * t + jy[:, None] * b)
    patch = pink_noise(moss.pos, noise_scale * 2.0, seed=seed + 3)   # patches of size/tone
    scale = (size / TUFT_SIZE) * growth_scale(moss.growth) * (1.0 + 0.15 * patch) * \
        (0.9 + 0.2 * rnd(1))     # the models are ~TUFT_SIZE across, in metres
    # tilt the axis a little, rotate about it at random
    tilt = np.radians(tilt_deg) * np.sqrt(rnd(2))
    tphi = 2 * np.pi * rnd(3)
    axis = n * np.cos(tilt)[:, None] + np.sin(tilt)[:, None] * (
        np.cos(tphi)[:, None] * t + np.sin(tphi)[:, None] * b)
    ta, ba = _tangent_frames(axis)
    rot = 2 * np.pi * rnd(4)
    c, s = np.cos(rot)[:, None], np.sin(rot)[:, None]
    ex = c * ta + s * ba          # local x
    ez = -s * ta + c * ba         # local z
    tone_shift = 0.25 * patch + 0.15 * (rnd(5) - 0.5) - 0.2 * np.exp(-moss.growth / 3.0)
    # push the base a little into the surface so that tufts never float
    pos = pos + n * lift - axis * (0.05 * TUFT_SIZE * scale)[:, None]
    M = np.stack([ex, axis, ez], axis=1) * scale[:, None, None]     # rows: local axes in world
    names = moss.species_names
    for si in np.unique(moss.species):
        sel = np.nonzero(moss.species == si)[0]
        name = names[si] if si < len(names) else f"species{si}"
        models = tuft_models(name) if variants is None else tuft_models(name, variants)
        var = np.minimum((rnd(6)[sel] * len(models)).astype(np.int64), len(models) - 1)
        V, F, T = [], [], []
        nv = 0
        for k, model in enumerate(models):
            idx = sel[var == k]
            if len(idx) == 0:
                continue
            lv = model.vertices.astype(np.float64)
            w = np.einsum("vj,njk->nvk", lv, M[idx]) + pos[idx][:, None, :]
            V.append(w.reshape(-1, 3).astype(np.float32))
            f = model.faces[None, :, :].astype(np.int64) + \
                (nv + len(lv) * np.arange(len(idx)))[:, None, None]
            F.append(f.reshape(-1, 3))
            tone = np.clip(model.tone[None, :] * 0.75 + tone_shift[idx][:, None], 0.0, 1.0)
            T.append(tone.reshape(-1).astype(np.float32))
            nv += len(lv) * len(idx)
        out.append(TuftMesh(name, np.concatenate(V), np.concatenate(F).astype(np.uint32),
                            np.concatenate(T), len(sel)))
    return out
