"""The sky radiance model of the ``veg_sky`` emitter: relative radiance f(w) over the sky.

The emitter (:class:`mitsuba_veg.integrators.veg_sky.VegSky`) has separable radiance
L(w, lam) = S(lam) f(w), where ``f`` is a relative radiance distribution over the upper
hemisphere, zero below the horizon, normalised so that

    integral over the upper hemisphere of f(w) cos(theta) dw = pi,

hence the horizontal diffuse irradiance of the emitter is exactly pi * S(lambda) (= the SPCTRAL2
DHI when built by :func:`mitsuba_veg.light.daylight`). ``f`` has the Perez et al. (1993) form

    f ~ (1 + a exp(b / cos theta)) (1 + c exp(d gamma) + e cos^2 gamma)

(theta: zenith angle of w, gamma: angle between w and the sun) with coefficients from the Perez
all-weather model (sky clearness epsilon, brightness delta), or the CIE standard clear skies
(types 12 and 13, written in the same form), or a uniform sky (:func:`sky_coefficients`).

:func:`normalisation` gives the factor of f, :func:`sampling_table` the piecewise-constant table
of f over a latitude-longitude grid of the upper hemisphere (cells uniform in cos(theta) and
azimuth, so that the pdf is constant per cell in solid angle) from which the emitter
importance-samples directions.

Frame (project convention): +y up, +x east, +z south; the grid's azimuth is clockwise from north
(-z).
"""
from __future__ import annotations

import functools
import math

import numpy as np

from ..errors import ParameterError

__all__ = ["perez_coefficients", "cie_coefficients", "sky_coefficients", "relative_radiance",
           "normalisation", "sampling_table", "PEREZ_1993"]

#: Perez, Seals & Michalsky (1993), Solar Energy 50(3) 235-245, Table 1: for each of the 8 sky
#: clearness bins, the coefficients (x1, x2, x3, x4) of a, b, c, d, e with
#: x = x1 + x2 Z + delta (x3 + x4 Z)  (Z = solar zenith angle [rad]).
PEREZ_1993 = np.array([
    ((1.3525, -0.2576, -0.269, -1.4366),
     (-0.767, 0.0007, 1.2734, -0.1233),
     (2.8, 0.6004, 1.2375, 1),
     (1.8734, 0.6297, 0.9738, 0.2809),
     (0.0356, -0.1246, -0.5718, 0.9938)),
    ((-1.2219, -0.773, 1.4148, 1.1016),
     (-0.2054, 0.0367, -3.9128, 0.9156),
     (6.975, 0.1774, 6.4477, -0.1239),
     (-1.5798, -0.5081, -1.7812, 0.108),
     (0.2624, 0.0672, -0.219, -0.4285)),
    ((-1.1, -0.2515, 0.8952, 0.0156),
     (0.2782, -0.1812, -4.5, 1.1766),
     (24.7219, -13.0812, -37.7, 34.8438),
     (-5, 1.5218, 3.9229, -2.6204),
     (-0.0156, 0.1597, 0.4199, -0.5562)),
    ((-0.5484, -0.6654, -0.2672, 0.7117),
     (0.7234, -0.6219, -5.6812, 2.6297),
     (33.3389, -18.3, -62.25, 52.0781),
     (-3.5, 0.0016, 1.1477, 0.1062),
     (0.4659, -0.3296, -0.0876, -0.0329)),
    ((-0.6, -0.3566, -2.5, 2.325),
     (0.2937, 0.0496, -5.6812, 1.8415),
     (21, -4.7656, -21.5906, 7.2492),
     (-3.5, -0.1554, 1.4062, 0.3988),
     (0.0032, 0.0766, -0.0656, -0.1294)),
    ((-1.0156, -0.367, 1.0078, 1.4051),
     (0.2875, -0.5328, -3.85, 3.375),
     (14, -0.9999, -7.1406, 7.5469),
     (-3.4, -0.1078, -1.075, 1.5702),
     (-0.0672, 0.4016, 0.3017, -0.4844)),
    ((-1, 0.0211, 0.5025, -0.5119),
     (-0.3, 0.1922, 0.7023, -1.6317),
     (19, -5, 1.2438, -1.9094),
     (-4, 0.025, 0.3844, 0.2656),
     (1.0468, -0.3788, -2.4517, 1.4656)),
    ((-1.05, 0.0289, 0.426, 0.359),
     (-0.325, 0.1156, 0.7781, 0.0025),
     (31.0625, -14.5, -46.1148, 55.375),
     (-7.2312, 0.405, 13.35, 0.6234),
     (1.5, -0.6426, 1.8564, 0.5636)),
])
#: upper edges of the first 7 clearness bins (the 8th is open)
PEREZ_EPSILON_EDGES = (1.065, 1.23, 1.5, 1.95, 2.8, 4.5, 6.2)
#: range of the model's data (Perez 1993; clamped to it as in Radiance's gendaylit)
PEREZ_EPSILON_MAX = 12.01
PEREZ_DELTA_RANGE = (0.01, 0.6)

#: CIE S 011/E:2003 standard general skies used here: type -> (a, b, c, d, e)
_CIE = {12: (-1.0, -0.32, 10.0, -3.0, 0.45),   # clear, low luminance turbidity
        13: (-1.0, -0.32, 16.0, -3.0, 0.30)}   # clear, polluted atmosphere


def perez_coefficients(epsilon: float, delta: float, sun_zenith: float):
    """Perez (1993) all-weather coefficients (a, b, c, d, e) of the sky radiance distribution.

    Each coefficient is ``x = x1 + x2 Z + delta (x3 + x4 Z)`` with (x1..x4) from
    :data:`PEREZ_1993` for the clearness bin of ``epsilon`` (the first bin has special forms of c
    and d). As in Radiance's gendaylit, epsilon is clamped to at most 12.01 and delta to
    [0.01, 0.6], and delta is raised to 0.2 for 1.065 < epsilon < 2.8 (no unphysical skies at low
    brightness).

    Parameters
    ----------
    epsilon : float
        Perez sky clearness [-], >= 1:
        ``((DHI + DNI)/DHI + 1.041 Z^3) / (1 + 1.041 Z^3)`` (Z in [rad]).
    delta : float
        Perez sky brightness [-], >= 0: ``DHI m / E0`` (m: air mass, E0: extraterrestrial
        irradiance).
    sun_zenith : float
        Solar zenith angle Z [rad].

    Returns
    -------
    tuple of float
        ``(a, b, c, d, e)`` of ``f = (1 + a exp(b / cos theta)) (1 + c exp(d gamma) +
        e cos^2 gamma)`` (theta, gamma in [rad]; f relative, unnormalised).

    Raises
    ------
    ParameterError
        If ``epsilon < 1`` or ``delta < 0`` (or either is NaN / infinite).
    """
    if not (epsilon >= 1.0) or not math.isfinite(epsilon):
        raise ParameterError("perez_epsilon", epsilon, "[1, inf)",
                             "sky clearness is ((DHI+DNI)/DHI + 1.041 Z^3)/(1 + 1.041 Z^3) >= 1")
    if not (delta >= 0.0) or not math.isfinite(delta):
        raise ParameterError("perez_delta", delta, "[0, inf)", "sky brightness DHI*m/E0 >= 0")
    # the model's validity range, as Radiance's gendaylit clamps it
    epsilon = min(float(epsilon), PEREZ_EPSILON_MAX)
    delta = min(max(float(delta), PEREZ_DELTA_RANGE[0]), PEREZ_DELTA_RANGE[1])
    k = int(np.searchsorted(PEREZ_EPSILON_EDGES, epsilon, side="right"))
    z = float(sun_zenith)
    if 1.065 < epsilon < 2.8:  # as Radiance's gendaylit: avoid unphysical skies at low delta
        delta = max(delta, 0.2)
    x = PEREZ_1993[k]
    a, b, c, d, e = (x[:, 0] + x[:, 1] * z + delta * (x[:, 2] + x[:, 3] * z)).tolist()
    if k == 0:  # first bin: special forms of c and d
        c = math.exp((delta * (x[2, 0] + x[2, 1] * z)) ** x[2, 2]) - x[2, 3]
        d = -math.exp(delta * (x[3, 0] + x[3, 1] * z)) + x[3, 2] + delta * x[3, 3]
    return tuple(float(v) for v in (a, b, c, d, e))


def cie_coefficients(sky_type: int = 12):
    """CIE standard sky ``sky_type`` (12 or 13) rewritten in the Perez form (a, b, c, d, e).

    CIE: phi(Z) f(chi) with f = 1 + c (exp(d chi) - exp(d pi/2)) + e cos^2 chi; dividing f by
    k = 1 - c exp(d pi/2) gives 1 + (c/k) exp(d chi) + (e/k) cos^2 chi (the scale is irrelevant
    after normalisation). Coefficients of CIE S 011/E:2003.

    Parameters
    ----------
    sky_type : int, optional
        12 (clear, low luminance turbidity; default) or 13 (clear, polluted atmosphere).

    Returns
    -------
    tuple of float
        ``(a, b, c, d, e)`` in the Perez form [-] (angles in [rad]).

    Raises
    ------
    ParameterError
        If ``sky_type`` is not 12 or 13.
    """
    if sky_type not in _CIE:
        raise ParameterError("cie sky type", sky_type, "12 (clear) or 13 (turbid)")
    a, b, c, d, e = _CIE[sky_type]
    k = 1.0 - c * math.exp(d * math.pi / 2)
    return (a, b, c / k, d, e / k)


def sky_coefficients(distribution: str, sun_zenith: float = 0.0, *, epsilon=None, delta=None,
                     custom=None):
    """Perez-form coefficients for a distribution name (see module docstring).

    Parameters
    ----------
    distribution : str
        ``"perez"``, ``"cie_clear"`` (CIE type 12), ``"cie_turbid"`` (type 13), ``"uniform"``
        (all zero) or ``"custom"``.
    sun_zenith : float, optional
        Solar zenith angle [rad] (used by ``"perez"`` only); default 0.
    epsilon : float, optional
        Perez sky clearness [-] (>= 1); required for ``"perez"``.
    delta : float, optional
        Perez sky brightness [-] (>= 0); required for ``"perez"``.
    custom : sequence of float, optional
        The five coefficients a, b, c, d, e for ``"custom"``.

    Returns
    -------
    tuple of float
        ``(a, b, c, d, e)`` [-].

    Raises
    ------
    ParameterError
        For an unknown distribution, ``"perez"`` without epsilon and delta, or ``"custom"``
        without five numbers.
    """
    if distribution == "perez":
        if epsilon is None or delta is None:
            raise ParameterError("perez_epsilon/perez_delta", (epsilon, delta), "two numbers",
                                 "give both (see daylight.perez_sky_parameters)")
        return perez_coefficients(float(epsilon), float(delta), sun_zenith)
    if distribution == "cie_clear":
        return cie_coefficients(12)
    if distribution == "cie_turbid":
        return cie_coefficients(13)
    if distribution == "uniform":
        return (0.0, 0.0, 0.0, 0.0, 0.0)
    if distribution == "custom":
        if custom is None or len(custom) != 5:
            raise ParameterError("a..e", custom, "five numbers", "give a, b, c, d and e")
        return tuple(float(v) for v in custom)
    raise ParameterError("distribution", distribution,
                         "'perez', 'cie_clear', 'cie_turbid', 'uniform', 'custom'")


def relative_radiance(cos_theta, cos_gamma, coeffs):
    """Unnormalised Perez-form radiance (numpy, float64); 0 at and below the horizon.

    ``max((1 + a exp(b / max(cos theta, 0.01))) (1 + c exp(d gamma) + e cos^2 gamma), 0)``.

    Parameters
    ----------
    cos_theta : float or array_like
        Cosine of the zenith angle of the direction [-].
    cos_gamma : float or array_like
        Cosine of the angle between the direction and the sun [-] (clipped to [-1, 1]).
    coeffs : sequence of float
        ``(a, b, c, d, e)`` of :func:`sky_coefficients`.

    Returns
    -------
    numpy.ndarray
        Relative radiance f [-] (broadcast shape of the inputs), >= 0.
    """
    a, b, c, d, e = coeffs
    ct = np.asarray(cos_theta, dtype=float)
    cg = np.clip(np.asarray(cos_gamma, dtype=float), -1.0, 1.0)
    grad = 1.0 + a * np.exp(b / np.maximum(ct, 0.01))
    ind = 1.0 + c * np.exp(d * np.arccos(cg)) + e * cg * cg
    return np.where(ct > 0.0, np.maximum(grad * ind, 0.0), 0.0)


def _direction(cos_t, phi):
    """Project frame direction from cos(zenith) and azimuth (clockwise from north = -z)."""
    s = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    return np.sin(phi) * s, cos_t, -np.cos(phi) * s


def normalisation(sun, coeffs, n_theta=768):
    """The factor that makes the sky's relative radiance integrate to pi against cos(theta).

    pi / (integral over the upper hemisphere of f cos(theta) dw), by the midpoint rule in theta
    and phi.

    Parameters
    ----------
    sun : array_like
        (3,) unit vector towards the sun (scene frame, +y up).
    coeffs : sequence of float
        ``(a, b, c, d, e)`` of :func:`sky_coefficients`.
    n_theta : int, optional
        Midpoint cells over 0-90 deg zenith (4 x as many in azimuth); default 768.

    Returns
    -------
    float
        The factor [-] by which :func:`relative_radiance` is multiplied.

    Raises
    ------
    ParameterError
        If the radiance is zero everywhere above the horizon.
    """
    # the same sky is set up again and again (every scene a world rebuilds): remembered
    return _normalisation(tuple(float(v) for v in np.asarray(sun, float).reshape(-1)),
                          tuple(float(c) for c in coeffs), int(n_theta))


@functools.lru_cache(maxsize=256)
def _normalisation(sun, coeffs, n_theta):
    th = (np.arange(n_theta) + 0.5) * (0.5 * math.pi / n_theta)
    ph = (np.arange(4 * n_theta) + 0.5) * (2 * math.pi / (4 * n_theta))
    ct, st = np.cos(th)[:, None], np.sin(th)[:, None]
    x, y, z = _direction(ct, ph[None, :])
    rad = relative_radiance(ct, x * sun[0] + y * sun[1] + z * sun[2], coeffs)
    cell = (0.5 * math.pi / n_theta) * (2 * math.pi / (4 * n_theta))
    integral = float(np.sum(rad * ct * st)) * cell
    if not integral > 0.0:
        raise ParameterError("sky distribution", coeffs, "a radiance > 0 somewhere above the "
                             "horizon", "check the Perez/CIE coefficients")
    return math.pi / integral


def sampling_table(sun, coeffs, norm, rows, sub=3):
    """The piecewise-constant sampling table of the sky over the upper hemisphere (float64).

    ``rows`` rows over 0-90 deg zenith, uniform in cos(theta), and 4 x ``rows`` columns in
    azimuth (clockwise from north); each cell holds the mean of the normalised f over
    ``sub`` x ``sub`` samples, floored at 1e-3 of the mean so that every cell can be drawn.

    Parameters
    ----------
    sun : array_like
        (3,) unit vector towards the sun (scene frame, +y up).
    coeffs : sequence of float
        ``(a, b, c, d, e)`` of :func:`sky_coefficients`.
    norm : float
        The factor of :func:`normalisation` [-].
    rows : int
        Rows of the table.
    sub : int, optional
        Samples per cell and axis; default 3.

    Returns
    -------
    cos_edges : numpy.ndarray
        (rows + 1,) cos(theta) at the row edges, from 1 (zenith) to 0 (horizon) [-].
    pdf : numpy.ndarray
        (rows * 4 rows,) density per cell in solid angle [sr-1], row-major.
    pmf : numpy.ndarray
        (rows * 4 rows,) probability of each cell [-] (sums to 1).
    """
    cols = 4 * rows
    th_e = np.linspace(0.0, 0.5 * math.pi, rows + 1)
    cos_e = np.cos(th_e)
    cos_e[-1] = 0.0
    # sub-samples uniform in cos(theta) and phi inside each cell (the in-cell sampling density)
    u = (np.arange(sub) + 0.5) / sub
    ct = (cos_e[:-1, None] + (cos_e[1:, None] - cos_e[:-1, None]) * u[None, :]).reshape(-1)
    ph = ((np.arange(cols)[:, None] + u[None, :]) * (2 * math.pi / cols)).reshape(-1)
    x, y, z = _direction(ct[:, None], ph[None, :])
    f = norm * relative_radiance(ct[:, None], x * sun[0] + y * sun[1] + z * sun[2], coeffs)
    fbar = f.reshape(rows, sub, cols, sub).mean(axis=(1, 3))
    fbar = np.maximum(fbar, 1e-3 * float(fbar.mean()))   # keep every cell samplable
    omega = ((cos_e[:-1] - cos_e[1:]) * (2 * math.pi / cols))[:, None]
    pdf = fbar / float(np.sum(fbar * omega))              # per-cell pdf in solid angle
    pmf = pdf * omega
    return cos_e, pdf.reshape(-1), pmf.reshape(-1)
