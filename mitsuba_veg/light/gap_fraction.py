"""What a hemispherical photograph tells a forester: gap fractions in rings of zenith angle,
canopy openness, effective and clumping-corrected leaf area index, and site factors.

Every quantity weights the photograph's pixels by their solid angle
(:meth:`mitsuba_veg.light.fisheye.Lens.pixel_map`), so it does not depend on the lens's
projection.

- **Gap fraction** of a ring θ1 <= θ < θ2: the share of the ring's solid angle that is sky,
  P = Σ gap dΩ / Σ dΩ over the pixels whose centre lies in the ring. The LAI-2000/2200 plant
  canopy analyser reads five rings, 0-13°, 16-28°, 32-43°, 47-58° and 61-74°
  (:data:`LAI2000_RINGS`; Welles & Norman 1991, Agron. J. 83:818-825).
- **Canopy openness**: the share of the whole image's (the hemisphere's) solid angle that is
  sky (the definition of Gap Light Analyzer, Frazer et al. 1999).
- **Effective LAI** from Miller's (1967) integral L = 2 ∫0^{π/2} −ln P(θ) cos θ sin θ dθ,
  on rings: L_e = 2 Σ_i W_i (−ln P_i) cos θ_i with W_i ∝ ∫ sin θ dθ over ring i, normalised
  to 1 over the rings used (:func:`miller_lai`); the **LAI-2000 formula** is that sum with the
  instrument's published ring centres (7, 23, 38, 53, 68°), path lengths S_i = 1/cos θ_i
  (1.008, 1.087, 1.270, 1.662, 2.670) and weights W_i (0.034, 0.104, 0.160, 0.218, 0.484):
  L_e = 2 Σ W_i (−ln P_i) / S_i (:func:`lai2000_lai`; LAI-2000 manual, eq. 2-10). Both assume
  leaves placed at random (a Poisson canopy): under clumped foliage they read less than the
  true LAI (the effective LAI, Chen & Black 1992).
- **Clumping-corrected LAI** by Lang & Xiang (1986, Agric. For. Meteorol. 37:229-243):
  the logarithm is averaged over azimuth sectors of each ring before the sum,
  L_LX = 2 Σ_i W_i cos θ_i mean_k(−ln P_ik), instead of the logarithm of the ring's mean;
  by Jensen's inequality L_LX >= L_e, and the apparent clumping index is Ω = L_e / L_LX. A
  ring or sector without a single sky pixel has no logarithm: it is given the gap fraction of
  half its smallest pixel (the smallest gap the image could show) and counted as
  ``saturated``.
- **Site factors** (Anderson 1964; the "indirect/direct/total site factors" of
  hemispherical-photo software): the diffuse site factor is the share of the open's diffuse
  irradiance on a horizontal surface that reaches the point, Σ gap L(θ) cos θ dΩ / Σ L(θ)
  cos θ dΩ, for a uniform sky (L constant: the daily loop's sky) or the standard overcast sky
  (L ∝ 1 + 2 cos θ, Moon & Spencer 1942); the direct site factor is the share of the open's
  horizontal beam over sun positions k with weights w_k (DNI_k Δt): Σ w_k sin e_k gap(s_k) /
  Σ w_k sin e_k, gap(s_k) the pixel the sun is in; the total site factor weights the two by
  the open's beam and diffuse irradiation over the same time.
"""
from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, field

import numpy as np

from mitsuba_veg.errors import ParameterError, check_range

from .sunpath import sun_path

__all__ = ["LAI2000_RINGS", "LAI2000_CENTRES", "LAI2000_WEIGHTS", "LAI2000_PATHS", "SKIES",
           "rings_of_width", "parse_rings", "ring_gap_fractions", "openness",
           "diffuse_site_factor", "direct_site_factor", "total_site_factor", "miller_lai",
           "lai2000_lai", "lang_xiang_lai", "PhotoAnalysis", "analyse", "year_sun"]

#: the LAI-2000/2200's rings [deg] (Welles & Norman 1991)
LAI2000_RINGS = ((0.0, 13.0), (16.0, 28.0), (32.0, 43.0), (47.0, 58.0), (61.0, 74.0))
#: their centres [deg], weights W_i [-] and path lengths S_i = 1/cos θ_i [-] (LAI-2000 manual)
LAI2000_CENTRES = (7.0, 23.0, 38.0, 53.0, 68.0)
#: (the weights W_i)
LAI2000_WEIGHTS = (0.034, 0.104, 0.160, 0.218, 0.484)
#: (the path lengths S_i)
LAI2000_PATHS = (1.008, 1.087, 1.270, 1.662, 2.670)
#: sky radiance distributions of the diffuse site factor
SKIES = ("uniform", "soc")
#: default azimuth sectors of the Lang & Xiang average
SECTORS = 8


def rings_of_width(width_deg: float, theta_max_deg: float = 90.0) -> list[tuple[float, float]]:
    """Contiguous rings of one width from the zenith.

    Parameters
    ----------
    width_deg : float
        Ring width [deg], 0.5-90.
    theta_max_deg : float
        Last ring's outer edge [deg] (a shorter last ring where the width does not divide it).

    Returns
    -------
    list of (float, float)
        (inner, outer) zenith angles [deg].
    """
    check_range("ring width", width_deg, 0.5, 90.0, fix="degrees, e.g. 5 or 10")
    check_range("theta_max", theta_max_deg, width_deg, 90.0)
    edges = np.arange(0.0, theta_max_deg + 1e-9, width_deg)
    if edges[-1] < theta_max_deg - 1e-9:
        edges = np.append(edges, theta_max_deg)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:])]


def parse_rings(text: str) -> list[tuple[float, float]]:
    """Rings from text: ``"lai2000"``, a width (``"5"``: 5° rings to 90°, ``"10:75"``: 10° rings
    to 75°) or explicit ranges (``"0-13,16-28"``).

    Parameters
    ----------
    text : str
        The rings.

    Returns
    -------
    list of (float, float)
        (inner, outer) zenith angles [deg].
    """
    t = str(text).strip()
    if t.lower() == "lai2000":
        return list(LAI2000_RINGS)
    try:
        if "-" not in t:
            w, _, top = t.partition(":")
            return rings_of_width(float(w), float(top) if top else 90.0)
        out = []
        for part in t.split(","):
            a, b = part.split("-")
            lo, hi = float(a), float(b)
            if not (0.0 <= lo < hi <= 90.0):
                raise ValueError
            out.append((lo, hi))
        return out
    except (ValueError, ParameterError):
        raise ParameterError("rings", text, "lai2000, a ring width in degrees (5, or 10:75 "
                             "for 10-degree rings to 75 degrees) or ranges 0 <= lo < hi <= 90 "
                             "(0-13,16-28)", "e.g. --rings 5") from None


def _ring_masks(theta, rings):
    th = np.degrees(theta)
    return [(th >= lo) & (th < hi) for lo, hi in rings]


def ring_gap_fractions(gap, theta, weight, rings, azimuth=None, sectors: int = 1):
    """Gap fraction of each ring (and of its azimuth sectors).

    Parameters
    ----------
    gap : numpy.ndarray
        (h, w) bool: sky pixels.
    theta : numpy.ndarray
        (h, w) zenith angle of each pixel [rad].
    weight : numpy.ndarray
        (h, w) solid angle of each pixel [sr] (0 outside the image).
    rings : sequence of (float, float)
        (inner, outer) zenith angles [deg].
    azimuth : numpy.ndarray, optional
        (h, w) azimuth [rad] (needed for ``sectors`` > 1).
    sectors : int
        Equal azimuth sectors from north, clockwise.

    Returns
    -------
    fraction : numpy.ndarray
        (rings, sectors) gap fraction [-] (NaN where a sector holds no pixel).
    smallest : numpy.ndarray
        (rings, sectors) solid-angle share of the sector's smallest pixel [-].
    """
    check_range("sectors", sectors, 1, 360)
    g = np.asarray(gap, bool)
    w = np.asarray(weight, float)
    if sectors > 1:
        if azimuth is None:
            raise ParameterError("azimuth", None, "the pixels' azimuths for sectors > 1")
        sec = np.minimum((np.asarray(azimuth) / (2 * np.pi) * sectors).astype(np.int64),
                         sectors - 1)
    else:
        sec = np.zeros(g.shape, np.int64)
    frac = np.full((len(rings), sectors), np.nan)
    small = np.full((len(rings), sectors), np.nan)
    for i, m in enumerate(_ring_masks(theta, rings)):
        m = m & (w > 0)
        s, ww, gg = sec[m], w[m], g[m]
        tot = np.bincount(s, ww, sectors)
        sky = np.bincount(s, ww * gg, sectors)
        mn = np.full(sectors, np.inf)
        np.minimum.at(mn, s, ww)
        ok = tot > 0
        frac[i, ok] = sky[ok] / tot[ok]
        small[i, ok] = mn[ok] / tot[ok]
    return frac, small


def openness(gap, weight) -> float:
    """Canopy openness: the sky's share of the image's solid angle.

    Parameters
    ----------
    gap : numpy.ndarray
        (h, w) bool sky pixels.
    weight : numpy.ndarray
        (h, w) pixel solid angles [sr].

    Returns
    -------
    float
        Openness [-].
    """
    w = np.asarray(weight, float)
    return float(np.sum(w * np.asarray(gap, bool)) / np.sum(w))


def _sky_radiance(theta, sky: str):
    if sky not in SKIES:
        raise ParameterError("sky", sky, ", ".join(SKIES), "uniform: the daily loop's sky; "
                             "soc: the standard overcast sky")
    c = np.cos(theta)
    return np.ones_like(c) if sky == "uniform" else (1.0 + 2.0 * c) / 3.0


def diffuse_site_factor(gap, theta, weight, sky: str = "uniform",
                        theta_max_deg: float = 90.0) -> float:
    """The share of the open's diffuse horizontal irradiance that reaches the point.

    Σ gap L cos θ dΩ / Σ L cos θ dΩ (module docstring). The denominator is the open's
    horizontal irradiance over the same pixels (its analytic value differs by the disc edge's
    pixels only).

    Parameters
    ----------
    gap, theta, weight : numpy.ndarray
        (h, w) sky pixels (bool), zenith angles [rad], solid angles [sr].
    sky : str
        ``"uniform"`` or ``"soc"`` (standard overcast, L ∝ 1 + 2 cos θ).
    theta_max_deg : float
        Pixels beyond this zenith angle [deg] count as blocked (default 90: none).

    Returns
    -------
    float
        The diffuse (indirect) site factor [-].
    """
    w = np.asarray(weight, float) * _sky_radiance(theta, sky) * np.cos(theta)
    inside = np.degrees(theta) < theta_max_deg
    return float(np.sum(w * (np.asarray(gap, bool) & inside)) / np.sum(w))


def direct_site_factor(gap, lens, azimuth, elevation, weights) -> float:
    """The share of the open's horizontal beam, over sun positions, that reaches the point.

    Parameters
    ----------
    gap : numpy.ndarray
        (size, size) bool sky pixels of a photograph taken with ``lens``.
    lens : Lens
        The photograph's lens (:class:`mitsuba_veg.light.fisheye.Lens`).
    azimuth, elevation : array_like
        Sun positions [deg] (azimuth clockwise from north).
    weights : array_like
        Their beam weights (DNI Δt, any unit); positions at or below the horizon are left out.

    Returns
    -------
    float
        The direct site factor [-] (NaN without a sun above the horizon).
    """
    el = np.asarray(elevation, float)
    w = np.asarray(weights, float) * np.maximum(np.sin(np.radians(el)), 0.0)
    up = (el > 0) & (w > 0)
    if not up.any():
        return float("nan")
    row, col = lens.pixel_of(np.radians(90.0 - el[up]), np.radians(np.asarray(azimuth)[up]))
    seen = (row >= 0) & np.asarray(gap, bool)[np.maximum(row, 0), np.maximum(col, 0)]
    return float(np.sum(w[up] * seen) / np.sum(w[up]))


def total_site_factor(direct: float, diffuse: float, beam: float, sky: float) -> float:
    """The total site factor: the two site factors weighted by the open's irradiation.

    Parameters
    ----------
    direct, diffuse : float
        Direct and diffuse site factors [-].
    beam, sky : float
        The open's horizontal beam and diffuse irradiation over the same period (any one unit,
        e.g. MJ m-2).

    Returns
    -------
    float
        (direct beam + diffuse sky) / (beam + sky) [-].
    """
    if beam + sky <= 0:
        return float("nan")
    return float((direct * beam + diffuse * sky) / (beam + sky))


def _log_gap(p, small, floor):
    """−ln P with a saturated (all-vegetation) value replaced by half its smallest pixel."""
    p = np.asarray(p, float)
    sat = p <= 0
    q = np.where(sat, 0.5 * np.asarray(small, float) if floor is None else floor, p)
    return -np.log(q), sat


def miller_lai(fractions, rings, smallest=None) -> tuple[float, int]:
    """Effective LAI from Miller's integral on rings (module docstring).

    Parameters
    ----------
    fractions : array_like
        (rings,) gap fraction of each ring [-].
    rings : sequence of (float, float)
        Their (inner, outer) zenith angles [deg].
    smallest : array_like, optional
        (rings,) share of each ring's smallest pixel (for rings without a gap).

    Returns
    -------
    lai : float
        L_e [m2 m-2] = 2 Σ W_i (−ln P_i) cos θ_i, W_i ∝ cos θ_lo − cos θ_hi (normalised),
        θ_i the ring's middle.
    saturated : int
        Rings without a single sky pixel.
    """
    r = np.radians(np.asarray(rings, float))
    w = np.cos(r[:, 0]) - np.cos(r[:, 1])
    w = w / w.sum()
    c = np.cos(r.mean(axis=1))
    small = np.full(len(r), np.nan) if smallest is None else np.asarray(smallest, float)
    lg, sat = _log_gap(fractions, small, None)
    return float(2.0 * np.sum(w * lg * c)), int(sat.sum())


def lai2000_lai(fractions, smallest=None) -> tuple[float, int]:
    """Effective LAI by the LAI-2000 formula from its five rings' gap fractions.

    Parameters
    ----------
    fractions : array_like
        (5,) gap fraction of the rings :data:`LAI2000_RINGS` [-].
    smallest : array_like, optional
        (5,) share of each ring's smallest pixel (for rings without a gap).

    Returns
    -------
    lai : float
        L_e = 2 Σ W_i (−ln P_i) / S_i [m2 m-2] (published W_i and S_i).
    saturated : int
        Rings without a single sky pixel.
    """
    f = np.asarray(fractions, float)
    if f.shape != (5,):
        raise ParameterError("fractions", f.shape, "the five LAI-2000 rings")
    small = np.full(5, np.nan) if smallest is None else np.asarray(smallest, float)
    lg, sat = _log_gap(f, small, None)
    return float(2.0 * np.sum(np.asarray(LAI2000_WEIGHTS) * lg / np.asarray(LAI2000_PATHS))), \
        int(sat.sum())


def lang_xiang_lai(fractions, smallest, rings=LAI2000_RINGS, weights=None,
                   cosines=None) -> tuple[float, int]:
    """Clumping-corrected LAI of Lang & Xiang (1986): the logarithm averaged over sectors.

    Parameters
    ----------
    fractions : array_like
        (rings, sectors) gap fractions [-] (NaN sectors are left out).
    smallest : array_like
        (rings, sectors) share of each sector's smallest pixel.
    rings : sequence of (float, float)
        The rings [deg] (default the LAI-2000's, with its published weights and path lengths).
    weights, cosines : array_like, optional
        W_i and cos θ_i (default: the LAI-2000's for its rings, else as :func:`miller_lai`).

    Returns
    -------
    lai : float
        L_LX = 2 Σ W_i cos θ_i mean_k(−ln P_ik) [m2 m-2].
    saturated : int
        Sectors without a single sky pixel.
    """
    f = np.asarray(fractions, float)
    rings = [tuple(map(float, r)) for r in rings]
    if weights is None or cosines is None:
        if rings == [tuple(map(float, r)) for r in LAI2000_RINGS]:
            weights = np.asarray(LAI2000_WEIGHTS)
            cosines = 1.0 / np.asarray(LAI2000_PATHS)
        else:
            r = np.radians(np.asarray(rings, float))
            weights = np.cos(r[:, 0]) - np.cos(r[:, 1])
            weights = weights / weights.sum()
            cosines = np.cos(r.mean(axis=1))
    lg, sat = _log_gap(f, smallest, None)
    ok = np.isfinite(f)
    mean = np.nansum(np.where(ok, lg, 0.0), axis=1) / np.maximum(ok.sum(axis=1), 1)
    return float(2.0 * np.sum(np.asarray(weights) * np.asarray(cosines) * mean)), \
        int((sat & ok).sum())


@dataclass
class PhotoAnalysis:
    """Everything :func:`analyse` reads from one photograph.

    Attributes
    ----------
    rings : list of (float, float)
        The extra rings asked for [deg] (besides the LAI-2000's).
    lai2000_gaps, ring_gaps : numpy.ndarray
        Gap fractions [-] of the LAI-2000 rings and of ``rings``.
    values : dict
        Scalars: ``openness``, ``lai_lai2000`` (effective, LAI-2000 formula),
        ``lai_miller`` (effective, Miller on ``rings`` within ``miller_max_deg``),
        ``lai_lang_xiang`` (clumping-corrected, LAI-2000 rings, ``sectors`` sectors),
        ``clumping_index`` (L_e / L_LX), ``site_factor_diffuse`` (uniform sky),
        ``site_factor_diffuse_soc``, and with sun positions ``site_factor_direct`` and
        ``site_factor_total``; the counts ``saturated_rings`` and ``saturated_sectors``.
    """

    rings: list
    lai2000_gaps: np.ndarray
    ring_gaps: np.ndarray
    values: dict = field(default_factory=dict)

    def rows(self) -> list[tuple]:
        """The analysis as tidy rows.

        Returns
        -------
        list of tuple
            (quantity, ring_lo_deg, ring_hi_deg, value, unit); rings NaN for whole-image
            quantities.
        """
        out = []
        for (lo, hi), p in zip(LAI2000_RINGS, self.lai2000_gaps):
            out.append(("gap_fraction_lai2000", lo, hi, float(p), "-"))
        for (lo, hi), p in zip(self.rings, self.ring_gaps):
            out.append(("gap_fraction", lo, hi, float(p), "-"))
        units = {"openness": "-", "lai_lai2000": "m2 m-2", "lai_miller": "m2 m-2",
                 "lai_lang_xiang": "m2 m-2", "clumping_index": "-"}
        for k, v in self.values.items():
            out.append((k, math.nan, math.nan, float(v),
                        units.get(k, "count" if k.startswith("saturated") else "-")))
        return out


def analyse(photo, rings=None, sun=None, sectors: int = SECTORS,
            miller_max_deg: float = 75.0) -> PhotoAnalysis:
    """Gap fractions, openness, LAI and site factors of a binary photograph.

    Parameters
    ----------
    photo : GapImage
        The photograph (:func:`mitsuba_veg.light.fisheye.gap_image`).
    rings : sequence of (float, float), optional
        Rings [deg] besides the LAI-2000's (default 5° rings to 90°, :func:`rings_of_width`).
    sun : tuple of array_like, optional
        (azimuth [deg], elevation [deg], weight) of sun positions over the period of the
        direct site factor, and the open's (beam, diffuse) irradiation of the total as a 4th
        and 5th item (e.g. a year's clear-sky sun paths, :func:`year_sun`).
    sectors : int
        Azimuth sectors of the Lang & Xiang average.
    miller_max_deg : float
        Miller's integral over the rings within this zenith angle [deg] (deep canopies give
        no gaps near the horizon).

    Returns
    -------
    PhotoAnalysis
        The gaps and values.
    """
    m = photo.pixel_map()
    theta, w, az = m["theta"], m["solid_angle"], m["azimuth"]
    rings = rings_of_width(5.0) if rings is None else [tuple(map(float, r)) for r in rings]
    g = photo.gap
    lf, ls = ring_gap_fractions(g, theta, w, LAI2000_RINGS)
    rf, rs = ring_gap_fractions(g, theta, w, rings)
    sf, ss = ring_gap_fractions(g, theta, w, LAI2000_RINGS, az, sectors)
    v = {"openness": openness(g, w)}
    v["lai_lai2000"], sat5 = lai2000_lai(lf[:, 0], ls[:, 0])
    use = [i for i, (lo, hi) in enumerate(rings) if hi <= miller_max_deg + 1e-9]
    if use:
        v["lai_miller"], satm = miller_lai(rf[use, 0], [rings[i] for i in use], rs[use, 0])
    else:
        satm = 0
        v["lai_miller"] = math.nan
    v["lai_lang_xiang"], satx = lang_xiang_lai(sf, ss)
    v["clumping_index"] = v["lai_lai2000"] / v["lai_lang_xiang"] if v["lai_lang_xiang"] > 0 \
        else math.nan
    v["site_factor_diffuse"] = diffuse_site_factor(g, theta, w, "uniform")
    v["site_factor_diffuse_soc"] = diffuse_site_factor(g, theta, w, "soc")
    if sun is not None:
        sa, se, sw = sun[:3]
        v["site_factor_direct"] = direct_site_factor(g, photo.lens, sa, se, sw)
        if len(sun) >= 5:
            v["site_factor_total"] = total_site_factor(v["site_factor_direct"],
                                                       v["site_factor_diffuse"], sun[3], sun[4])
    v["saturated_rings"] = float(sat5 + satm)
    v["saturated_sectors"] = float(satx)
    return PhotoAnalysis(rings, lf[:, 0], rf[:, 0], v)


def year_sun(latitude: float, longitude: float, year: int, step_minutes: float = 10.0):
    """A year's clear-sky sun: positions and the open's beam and diffuse irradiation.

    Sun positions every ``step_minutes`` (NREL SPA) with SPCTRAL2 broadband DNI and DHI
    (:func:`mitsuba_veg.light.sunpath.sun_path`, the package's sun paths).

    Parameters
    ----------
    latitude, longitude : float
        The site [deg].
    year : int
        The calendar year.
    step_minutes : float
        Time step [min].

    Returns
    -------
    tuple
        (azimuth [deg], elevation [deg], DNI Δt weights [J m-2], the open's horizontal beam
        irradiation [MJ m-2], its diffuse irradiation [MJ m-2]) of the year's daytime steps.
    """
    days = (_dt.date(year + 1, 1, 1) - _dt.date(year, 1, 1)).days
    p = sun_path(latitude, longitude, start=_dt.date(year, 1, 1), days=days,
                 step_hours=step_minutes / 60.0, intensity="clear_sky")
    dt = step_minutes * 60.0
    beam = float(np.sum(p.dni * np.sin(np.radians(p.elevation)))) * dt / 1e6
    diffuse = float(np.sum(p.dhi)) * dt / 1e6
    return p.azimuth, p.elevation, p.dni * dt, beam, diffuse
