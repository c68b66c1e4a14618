"""A differentiable photon pass: weights instead of Russian roulette, replayed with Dr.Jit AD.

The photon pass of ``integrators/photon_irradiance.py`` (paper 000 §3.4) continues a photon at a
hit with probability q = albedo (Russian roulette). That is unbiased but a step function of the
albedo: its derivative is zero almost everywhere. Here every photon always continues (diffusely,
cosine-weighted about the side it hit, as in the integrator) up to ``max_depth`` hits and
carries the product of the albedos it met as a *weight*:

    P_0 = s_e w_0 / N,        P_{k+1} = P_k a(e_k),        flux(e) += P_k   for every hit k on e,

with ``w_0`` the emitter's sample weight (the integrator's own emission: same aim and
stratification), ``s_e`` a strength factor per emitter, ``a(e)`` the albedo of triangle e
(grey, Lambertian, the same on both sides) and ``e_k`` the triangle of the k-th hit. Both
estimators have the same expectation (the integrator's RR keeps P a/q with probability q).

Because the directions do not depend on the albedo (cosine sampling), the geometry of every path
is traced once (:func:`trace_paths`: triangle and side of each hit, no AD) by the integrator's
own photon kernel in its "weights" mode (``PhotonIrradianceIntegrator.trace_paths``: one
kernel for the plain and the differentiable pass; this module has no transport loop) and
the flux is a polynomial in the albedos that :func:`replay` evaluates with Dr.Jit gathers and
scatter-adds: differentiable in reverse and forward mode w.r.t. per-triangle albedo and emitter
strength, and exactly the derivative of the Monte-Carlo estimate (common random numbers: a
finite difference of two replays is noise-free). Re-tracing with the same seed gives the same
paths.

Front/back: as in the integrator, a hit is *front* when the ray arrives against the geometric
normal; the moss model uses front irradiance only. The albedos a(e) stand in for the scene's
BSDFs like the integrator's per-triangle ``reflectance`` overrides do, and like them reflect on
the side that was hit (two-sided; a plain ``diffuse`` BSDF of the scene is one-sided in the
integrator's own pass).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, SceneError
from ..integrators.photon_irradiance import PhotonIrradianceIntegrator, SceneIndex

__all__ = ["PhotonPaths", "trace_paths", "replay", "irradiance"]

_INVALID = 0xFFFFFFFF


def _f64():
    return dr.float64_array_t(mi.Float)


@dataclass
class PhotonPaths:
    """Recorded geometry of a photon pass of one emitter (see module docstring).

    ``elem[k]`` (UInt32, width = photons) is the element of the k-th hit (0xFFFFFFFF: none),
    ``front[k]`` whether it hit the front side; ``w0`` the initial power per photon [W] for a
    unit strength (already divided by the photon count and multiplied by the band width).
    """

    emitter: str
    photons: int
    max_depth: int
    band: tuple
    w0: object                 # Float64 (photons)
    elem: list = field(default_factory=list)
    front: list = field(default_factory=list)
    n_elements: int = 0
    areas: np.ndarray | None = None
    seconds: float = 0.0
    rays: int = 0

    @property
    def nbytes(self) -> int:
        """Memory of the recorded paths [bytes] (w0 and, per depth, element and side).

        Returns
        -------
        int
            Bytes.
        """
        return self.photons * (8 + len(self.elem) * 5)


def trace_paths(scene: mi.Scene, emitter, photons: int, index=None, max_depth: int = 8,
                seed: int = 0, band=(360.0, 830.0)) -> PhotonPaths:
    """Trace ``photons`` paths from one emitter and record the hit elements (no AD).

    The integrator's own kernel in its "weights" mode
    (:meth:`~mitsuba_veg.integrators.photon_irradiance.PhotonIrradianceIntegrator.trace_paths`):
    the same emission, intersection and element tables as the plain pass; every photon goes on
    (cosine-weighted, two-sided) up to ``max_depth`` hits, and the element and side of each
    hit are recorded, so that :func:`replay` gives the flux for any albedos (module docstring).

    Parameters
    ----------
    scene : mi.Scene
        The scene (loaded with ``optimize=False``).
    emitter : mi.Emitter or str or int
        An emitter of ``scene``: the object, its id or its index.
    photons : int
        Photons to trace, 16 .. 2^26.
    index : SceneIndex, optional
        The :class:`~mitsuba_veg.integrators.photon_irradiance.SceneIndex` of the scene (built
        if None).
    max_depth : int
        Hits per photon, 1 .. 64.
    seed : int
        Random seed (same seed, same paths).
    band : tuple of float
        (min_nm, max_nm) [nm]: the photon power is the emitter's spectral power integrated over
        the band (four stratified wavelengths per photon, as the integrator does), so that
        :func:`replay` gives band flux [W] and :func:`irradiance` band irradiance [W m-2].

    Returns
    -------
    PhotonPaths
        The recorded paths: ``w0`` [W] per photon (Float64), ``elem`` and ``front`` per depth,
        ``rays`` (ray casts made), ``seconds`` (wall time [s]).
    """
    # validation (photons, max_depth, band, emitter) and tracing are the integrator's
    index = SceneIndex.build(scene) if index is None else index
    rec = PhotonIrradianceIntegrator().trace_paths(scene, emitter, photons, seed=seed,
                                                   max_depth=max_depth, band=band, index=index)
    return PhotonPaths(emitter=rec.emitter, photons=rec.photons, max_depth=rec.max_depth,
                       band=rec.band, w0=_f64()(rec.w0), elem=rec.elem, front=rec.front,
                       n_elements=index.n_elements, areas=np.asarray(index.areas, float),
                       seconds=rec.seconds, rays=rec.rays)


def replay(paths: PhotonPaths, albedo, strength=1.0, side: str = "front"):
    """Flux per element [W] of the recorded paths for per-element albedos.

    P_0 = s_e w_0, flux(e_k) += P_k, P_{k+1} = P_k a(e_k) (module docstring), evaluated with
    Dr.Jit gathers and scatter-adds: differentiable with Dr.Jit AD in both modes.

    Parameters
    ----------
    paths : PhotonPaths
        Paths from :func:`trace_paths`.
    albedo : Float64
        Albedo of every element [-], width ``paths.n_elements`` (may carry gradients).
    strength : float or Float64
        Emitter strength factor s_e [-] (a number or a width-1 array, may carry gradients).
    side : str
        ``"front"``, ``"back"`` or ``"both"``: the hits recorded.

    Returns
    -------
    Float64
        Flux per element [W] (band power, see :func:`trace_paths`).
    """
    F64 = type(albedo) if dr.is_array_v(albedo) else _f64()
    if side not in ("front", "back", "both"):
        raise ParameterError("side", side, "'front', 'back' or 'both'")
    if dr.width(albedo) != paths.n_elements:
        raise ParameterError("albedo", f"width {dr.width(albedo)}",
                             f"one albedo per element ({paths.n_elements})")
    flux = dr.zeros(F64, paths.n_elements)
    beta = F64(paths.w0) * strength
    for e, front in zip(paths.elem, paths.front):
        valid = e != _INVALID
        rec = valid if side == "both" else (valid & front if side == "front" else valid & ~front)
        dr.scatter_add(flux, beta, e, rec)
        beta = beta * dr.gather(F64, albedo, e, valid)
    return flux


def irradiance(paths: PhotonPaths, albedo, strength=1.0, side: str = "front"):
    """Irradiance per element [W m-2] = :func:`replay` / element area.

    Parameters
    ----------
    paths : PhotonPaths
        Paths from :func:`trace_paths`.
    albedo : Float64
        Albedo of every element [-], width ``paths.n_elements`` (may carry gradients).
    strength : float or Float64
        Emitter strength factor [-].
    side : str
        ``"front"``, ``"back"`` or ``"both"``.

    Returns
    -------
    Float64
        Irradiance per element [W m-2].
    """
    F64 = type(albedo) if dr.is_array_v(albedo) else _f64()
    inv_area = F64(1.0 / np.maximum(paths.areas, 1e-30))
    return replay(paths, albedo, strength, side) * inv_area


def albedo_array(n_elements: int, base, overrides: dict | None = None, slices: dict | None = None,
                 dtype=None):
    """Per-element albedo: ``base`` with ``{shape_id: value}`` overrides.

    Parameters
    ----------
    n_elements : int
        Elements of the scene index.
    base : float or array_like
        Albedo of every element [-] (a number or one value per element).
    overrides : dict, optional
        ``{shape_id: value}`` albedo [-] of a shape's elements (values may be Dr.Jit scalars
        with gradients).
    slices : dict, optional
        ``{shape_id: slice}`` of the elements of each overridden shape (required with
        ``overrides``).
    dtype : type, optional
        The Dr.Jit float type (default Float64).

    Returns
    -------
    Float64
        Albedo per element [-].
    """
    F64 = dtype or _f64()
    a = F64(np.broadcast_to(np.asarray(base, float), (n_elements,)).copy())
    if overrides:
        ids = dr.arange(mi.UInt32, n_elements)
        for sid, v in overrides.items():
            if slices is None or sid not in slices:
                raise SceneError(f"albedo override for unknown shape '{sid}'")
            sl = slices[sid]
            m = (ids >= sl.start) & (ids < sl.stop)
            a = dr.select(m, v, a)
    return a
