"""Barnsley's maple leaf drawn by the chaos game, with per-point aging (paper 003 §3.1, §4).

The leaf is the attractor of the IFS of 4 affine maps of the paper's table 2,

    w_i(x, y) = [a b; c d] (x, y) + (e, f)

drawn by the chaos game (random iteration): many independent chains run side by side (NumPy
arrays, one row per chain), each picks a map at random at every step; after a burn-in every
visited point lies on the attractor. Map probabilities default to ``|det|`` of each map (even point
density over the blade); the paper notes they change the look, not the shape.

Aging per point (paper §3.1: colouring starts at the margin and the tip, farthest from the main
veins, and moves inwards towards the petiole) is a weighted sum of

- the distance to the (fractal) vein skeleton: the three main veins from the petiole (the fixed
  point of w1, (0.5, 0.3)) to the lobe tips (fixed points of w2, w3, w4) and their images under
  the maps, ``vein_levels`` levels deep,
- the closeness to the blade margin (distance transform of the rasterised blade),
- the distance from the petiole (tip-ness),
- a fractal "address" term carried along the chaos game (z ← ρ z + (1 − ρ) c_i, i.e. a colour
  per map as the paper suggests), which gives the patchy, self-similar look,

rank-normalised to a uniform aging a ∈ [0, 1] (1 = ages first). A point turns dark green-red
when the leaf's stage passes S1(q) and red when it passes S2(q), q = 1 − a; S1, S2 are set so the
area fractions follow Ishikura's stage descriptions (the ``coloured`` and ``red`` columns of the
stage table): e.g. at stage 3 half of the blade is dark green-red, at stage 6 half is red.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

from .pigments import LeafTraits, StageTable, stage_from_tau, stage_table, state_pigments
from .spectra import leaf_spectra, spectrum_to_srgb

__all__ = ["MAPLE_IFS", "fixed_point", "chaos_game", "vein_segments", "MapleLeaf", "maple_leaf",
           "state_colours", "leaf_image"]

#: paper 003 table 2: rows w1..w4, columns a b c d e f
MAPLE_IFS = np.array([
    [0.8, 0.0, 0.0, 0.8, 0.1, 0.06],
    [0.5, 0.0, 0.0, 0.5, 0.25, 0.465],
    [0.355, -0.355, 0.355, 0.355, 0.266, 0.078],
    [0.355, 0.355, -0.355, 0.355, 0.378, 0.434],
])


def fixed_point(m) -> np.ndarray:
    """Fixed point of one affine map (a b c d e f).

    Solves w(x, y) = (x, y) for w(x, y) = [a b; c d] (x, y) + (e, f).

    Parameters
    ----------
    m : array_like
        The map's six coefficients a, b, c, d, e, f [-] (a row of :data:`MAPLE_IFS`).

    Returns
    -------
    numpy.ndarray
        (2,) fixed point (x, y) in the IFS's coordinates [-].
    """
    a, b, c, d, e, f = m
    return np.linalg.solve(np.array([[1 - a, -b], [-c, 1 - d]]), np.array([e, f]))


def _apply(m, p):
    return np.stack([m[0] * p[..., 0] + m[1] * p[..., 1] + m[4],
                     m[2] * p[..., 0] + m[3] * p[..., 1] + m[5]], -1)


def chaos_game(n_points: int = 200_000, *, maps=MAPLE_IFS, probabilities=None,
               chains: int = 8192, burn_in: int = 24, address_colour=(0.0, 1.0, 0.6, 0.6),
               address_memory: float = 0.5, seed=0):
    """Points of the IFS attractor by the vectorised chaos game.

    ``chains`` independent chains run side by side; each picks a map at random (``probabilities``)
    at every step and keeps its points after ``burn_in`` steps. The address value is the map
    colour ``address_colour[i]`` of the maps applied last, blended with memory
    ``address_memory`` (z ← ρ z + (1 − ρ) c_i): the paper's "colour per plotted point".

    Parameters
    ----------
    n_points : int
        Number of points returned (1 to 1e8; default 200 000).
    maps : array_like
        (k, 6) affine maps, rows a b c d e f [-] (default :data:`MAPLE_IFS`, paper 003 table 2).
    probabilities : array_like, optional
        (k,) non-negative map weights (normalised here); default ``|det|`` of each map (even point
        density over the blade).
    chains : int
        Chains run side by side (default 8192; at most ``n_points`` are used).
    burn_in : int
        Steps of each chain discarded before its points are kept (default 24).
    address_colour : sequence of float
        Colour value c_i [-] of each map (default (0, 1, 0.6, 0.6)).
    address_memory : float
        Memory ρ [-] of the address blend (default 0.5).
    seed : int
        Random seed (default 0).

    Returns
    -------
    points : numpy.ndarray
        (n_points, 2) points on the attractor in the IFS's unit square [-].
    address : numpy.ndarray
        (n_points,) address value [-] of each point.

    Raises
    ------
    ParameterError
        When ``maps`` is not (k, 6), ``probabilities`` is not k non-negative weights, or a count
        is out of range.
    """
    check_range("n_points", n_points, 1, 1e8)
    check_range("chains", chains, 1, 1e7)
    maps = np.asarray(maps, float)
    if maps.ndim != 2 or maps.shape[1] != 6:
        raise ParameterError("maps", maps.shape, "(k, 6) rows of a b c d e f")
    if probabilities is None:
        det = np.abs(maps[:, 0] * maps[:, 3] - maps[:, 1] * maps[:, 2])
        probabilities = det / det.sum()
    pr = np.asarray(probabilities, float)
    if pr.shape != (len(maps),) or (pr < 0).any() or pr.sum() <= 0:
        raise ParameterError("probabilities", probabilities, f"{len(maps)} non-negative weights")
    pr = pr / pr.sum()
    col = np.asarray(address_colour, float)
    rng = np.random.default_rng(seed)
    chains = int(min(chains, n_points))
    steps = burn_in + int(np.ceil(n_points / chains))
    p = rng.random((chains, 2))
    z = np.full(chains, 0.5)
    out_p, out_z = [], []
    cdf = np.cumsum(pr)
    for k in range(steps):
        i = np.minimum(np.searchsorted(cdf, rng.random(chains), side="right"), len(maps) - 1)
        m = maps[i]
        p = np.stack([m[:, 0] * p[:, 0] + m[:, 1] * p[:, 1] + m[:, 4],
                      m[:, 2] * p[:, 0] + m[:, 3] * p[:, 1] + m[:, 5]], 1)
        z = address_memory * z + (1.0 - address_memory) * col[i]
        if k >= burn_in:
            out_p.append(p)
            out_z.append(z)
    return np.concatenate(out_p)[:n_points], np.concatenate(out_z)[:n_points]


def vein_segments(levels: int = 2, maps=MAPLE_IFS) -> np.ndarray:
    """Vein skeleton (k, 2, 2): petiole -> lobe tips, and its images under the maps.

    The three main veins run from the petiole (the fixed point of w1) to the lobe tips (fixed
    points of w2, w3, w4); every level applies all maps to the previous level's segments.

    Parameters
    ----------
    levels : int
        Levels of images under the maps (default 2).
    maps : array_like
        (k, 6) affine maps a b c d e f [-] (default :data:`MAPLE_IFS`).

    Returns
    -------
    numpy.ndarray
        (n_segments, 2, 2) segment end points (x, y) in the IFS's coordinates [-].
    """
    maps = np.asarray(maps, float)
    base = fixed_point(maps[0])
    tips = [fixed_point(m) for m in maps[1:]]
    segs = np.array([[base, t] for t in tips])
    allsegs = [segs]
    cur = segs
    for _ in range(levels):
        cur = np.concatenate([_apply(m, cur) for m in maps])
        allsegs.append(cur)
    return np.concatenate(allsegs)


def _dist_to_segments(p, segs, chunk=65536):
    out = np.empty(len(p))
    a, b = segs[:, 0], segs[:, 1]
    ab = b - a
    L2 = np.maximum((ab ** 2).sum(1), 1e-30)
    for s in range(0, len(p), chunk):
        q = p[s:s + chunk, None, :]
        t = np.clip(((q - a) * ab).sum(-1) / L2, 0, 1)
        d = np.linalg.norm(q - (a + t[..., None] * ab), axis=-1)
        out[s:s + chunk] = d.min(1)
    return out


def _rank01(x):
    r = np.empty(len(x))
    r[np.argsort(x, kind="stable")] = np.arange(len(x))
    return r / max(len(x) - 1, 1)


@dataclass
class MapleLeaf:
    """A chaos-game maple leaf: points (n, 2) in the IFS's unit square and their aging."""

    points: np.ndarray
    aging: np.ndarray         # (n,) uniform in [0, 1], 1 = colours first
    base: np.ndarray          # petiole point (2,)
    components: dict          # the raw aging terms (vein distance, margin, tip, address)

    def fronts(self, table: StageTable | None = None):
        """Stages S1(q), S2(q) at which each point turns dark green-red / red.

        q = 1 − aging; S1 follows the stage table's ``coloured`` area fraction (stages 1..5), S2
        its ``red`` fraction (stages 5..7), each inverted at its first crossing (linear), starting
        half a stage before the first stage with coverage.

        Parameters
        ----------
        table : StageTable, optional
            Stage table (default: ``~mitsuba_veg.foliage.pigments.stage_table()``).

        Returns
        -------
        s1, s2 : numpy.ndarray
            (n,) stages [-] at which each point turns dark green-red and red.
        """
        tb = table or stage_table()
        q = 1.0 - self.aging
        # coloured fraction rises over stages 1..5, red over 5..7 (table columns)
        s1 = _inverse_front(q, tb.stage, tb.coloured)
        s2 = _inverse_front(q, tb.stage, tb.red)
        return s1, s2

    def state_weights(self, stage, width: float = 0.5, table: StageTable | None = None):
        """Per-point weights (n, 3) of the tissue states green / dark green-red / red.

        Weights at a leaf stage in [1, 7]; a point's change takes ``width`` stages (soft fronts
        ending at S1 and S2 of :meth:`fronts`).

        Parameters
        ----------
        stage : float
            Leaf stage [-] in [1, 7].
        width : float
            Stages over which a point changes state [-] (default 0.5).
        table : StageTable, optional
            Stage table (default: the shipped one).

        Returns
        -------
        numpy.ndarray
            (n, 3) weights [-] of green, dark green-red and red (they sum to 1).

        Raises
        ------
        ParameterError
            When ``stage`` is outside [1, 7].
        """
        check_range("stage", stage, 1.0, 7.0)
        s1, s2 = self.fronts(table)
        c = _ramp(stage, s1 - width, s1)   # dark green-red or red
        r = _ramp(stage, s2 - width, s2)   # red
        return np.stack([1.0 - c, c - r * c, r * c], 1)


def _inverse_front(q, stages, frac):
    """Stage at which the covered area fraction reaches q (first crossing, linear)."""
    f = np.maximum.accumulate(np.asarray(frac, float))
    s = np.asarray(stages, float)
    # strictly increasing part for interpolation; before it starts: the first stage with f > 0
    keep = np.concatenate([[True], np.diff(f) > 0])
    fs, ss = f[keep], s[keep]
    # the front starts half a stage before the first stage with coverage
    i0 = int(np.argmax(fs > 0))
    fs = np.concatenate([[0.0], fs[i0:]])
    ss = np.concatenate([[ss[i0] - 0.5], ss[i0:]])
    return np.interp(q, fs, ss)


def _ramp(x, lo, hi):
    return np.clip((x - lo) / np.maximum(hi - lo, 1e-9), 0.0, 1.0)


def maple_leaf(n_points: int = 200_000, *, seed=0, vein_levels: int = 2, weights=None,
               raster: int = 256, probabilities=None) -> MapleLeaf:
    """A Barnsley maple leaf with per-point aging (see module docstring).

    The aging is the weighted sum of the vein-distance, margin, tip and address terms (each
    normalised to [0, 1]), rank-normalised to a uniform a ∈ [0, 1] (1 = colours first).

    Parameters
    ----------
    n_points : int
        Chaos-game points (default 200 000).
    seed : int
        Random seed of the chaos game (default 0).
    vein_levels : int
        Levels of the fractal vein skeleton (:func:`vein_segments`, default 2).
    weights : dict, optional
        Weights of the aging terms [-], default ``{"vein": 0.35, "margin": 0.3, "tip": 0.2,
        "address": 0.15}``; the keys given replace those defaults.
    raster : int
        Raster size [pixels] of the blade mask for the margin's distance transform (default 256).
    probabilities : array_like, optional
        Map probabilities of :func:`chaos_game` (default ``|det|``).

    Returns
    -------
    MapleLeaf
        Points (n, 2) [-] in the IFS's unit square, aging (n,) [-], petiole point and the raw
        aging terms.

    Raises
    ------
    ParameterError
        When ``weights`` has an unknown key.
    """
    from scipy import ndimage

    w = {"vein": 0.35, "margin": 0.3, "tip": 0.2, "address": 0.15}
    if weights:
        unknown = set(weights) - set(w)
        if unknown:
            raise ParameterError("weights", sorted(unknown), f"keys among {sorted(w)}")
        w.update(weights)
    pts, addr = chaos_game(n_points, seed=seed, probabilities=probabilities)
    base = fixed_point(MAPLE_IFS[0])
    d_vein = _dist_to_segments(pts, vein_segments(vein_levels))
    # margin: distance transform of the rasterised blade (closed to fill the dust gaps)
    lo, hi = pts.min(0), pts.max(0)
    scale = (raster - 1) / (hi - lo).max()
    ij = np.clip(((pts - lo) * scale).astype(int), 0, raster - 1)
    mask = np.zeros((raster, raster), bool)
    mask[ij[:, 1], ij[:, 0]] = True
    mask = ndimage.binary_closing(mask, iterations=2)
    mask = ndimage.binary_fill_holes(mask)
    edt = ndimage.distance_transform_edt(mask)
    d_margin = edt[ij[:, 1], ij[:, 0]] / scale
    r_tip = np.linalg.norm(pts - base, axis=1)
    comp = {"vein": d_vein / max(d_vein.max(), 1e-12),
            "margin": 1.0 - d_margin / max(d_margin.max(), 1e-12),
            "tip": r_tip / r_tip.max(), "address": addr}
    raw = sum(w[k] * comp[k] for k in w)
    return MapleLeaf(pts, _rank01(raw), base, comp)


def state_colours(exposure: float = 2.2, traits=None, table=None) -> np.ndarray:
    """sRGB (3, 3) of the three tissue states (green, dark green-red, red).

    PROSPECT-D reflectance of each state's pigments
    (:func:`~mitsuba_veg.foliage.pigments.state_pigments`) under D65, times ``exposure``.

    Parameters
    ----------
    exposure : float
        Factor on XYZ before encoding [-] (default 2.2).
    traits : LeafTraits, optional
        Leaf structure, water and dry matter (default ``LeafTraits()``).
    table : StageTable, optional
        Stage table (default: the shipped one).

    Returns
    -------
    numpy.ndarray
        (3, 3) encoded sRGB [-] in [0, 1], one row per state.
    """
    sp = state_pigments(table)
    traits = traits or LeafTraits()
    out = []
    for name in ("green", "dark_green_red", "red"):
        p = sp[name]
        s = leaf_spectra(Cab=p["Cab"], Car=p["Car"], Anth=p["Anth"], traits=traits)
        out.append(spectrum_to_srgb(s.wavelength, s.reflectance, exposure))
    return np.array(out)


def leaf_image(leaf: MapleLeaf, stage=None, tau=None, size: int = 256, colours=None,
               background=(1.0, 1.0, 1.0)) -> np.ndarray:
    """RGB image (size, size, 3) of the leaf at a stage (or τ).

    Every chaos-game point gets the colour of its tissue state mix
    (:meth:`MapleLeaf.state_weights`); pixels average their points; empty pixels show the
    background.

    Parameters
    ----------
    leaf : MapleLeaf
        The leaf (:func:`maple_leaf`).
    stage : float, optional
        Leaf stage [-] in [1, 7]; give it or ``tau``.
    tau : float, optional
        Autumn logical time [-] in [0, 1] (stage = 1 + 6 τ).
    size : int
        Image side [pixels] (default 256).
    colours : array_like, optional
        (3, 3) sRGB [-] of the three states (default ``state_colours()``).
    background : sequence of float
        sRGB [-] of empty pixels (default white).

    Returns
    -------
    numpy.ndarray
        (size, size, 3) encoded sRGB [-], row 0 at the top.

    Raises
    ------
    ParameterError
        Unless exactly one of ``stage`` and ``tau`` is given.
    """
    if (stage is None) == (tau is None):
        raise ParameterError("stage/tau", (stage, tau), "exactly one of them")
    if tau is not None:
        stage = float(stage_from_tau(tau))
    cols = state_colours() if colours is None else np.asarray(colours, float)
    wts = leaf.state_weights(stage)
    rgb = wts @ cols
    lo, hi = leaf.points.min(0), leaf.points.max(0)
    span = (hi - lo).max() * 1.04
    c0 = (lo + hi) / 2 - span / 2
    ij = np.clip(((leaf.points - c0) / span * size).astype(int), 0, size - 1)
    flat = (size - 1 - ij[:, 1]) * size + ij[:, 0]
    cnt = np.bincount(flat, minlength=size * size).astype(float)
    img = np.stack([np.bincount(flat, rgb[:, k], minlength=size * size) for k in range(3)], 1)
    bg = np.asarray(background, float)
    img = np.where(cnt[:, None] > 0, img / np.maximum(cnt[:, None], 1), bg)
    return img.reshape(size, size, 3)
