"""Replay of recorded photon paths: the flux as a polynomial in the albedos, differentiable.

The photon pass (paper 000 §3.4) continues a photon at a hit with probability q = albedo
(Russian roulette): unbiased, but a step function of the albedo whose derivative is zero almost
everywhere. In the kernel's "weights" mode every photon goes on (cosine-weighted, about the side
it hit) up to ``max_depth`` hits and carries the product of the albedos it met as a weight:

    P_0 = s_e w_0,        P_{k+1} = P_k a(e_k, side_k),        flux(e) += P_k  for every hit k on e

with ``w_0`` the photon's initial power [W] (the emitter's own emission: same aim and
stratification), ``s_e`` a strength factor per emitter, ``a(e, side)`` the albedo of element e
on the side that was hit and ``e_k`` the element of the k-th hit. Both estimators have the same
expectation (Russian roulette keeps P a / q with probability q). The directions do not depend on
the albedos, so :meth:`PhotonIrradianceIntegrator.trace_paths` traces the geometry once (element
and side of each hit, :class:`PhotonPathRecord`) and :func:`replay` evaluates the polynomial
with Dr.Jit gathers and scatter-adds: differentiable in reverse and forward mode with respect to
the albedos and the strengths (and, through ``w_0``, the emitters' parameters), and exactly the
derivative of the Monte-Carlo estimate (common random numbers: a finite difference of two
replays is noise-free).

The albedos a(e, side) are either given per element (one array: it reflects on the side that
was hit, like the pass's per-element ``reflectance`` overrides) or per element and side (a
``(front, back)`` pair). :func:`bsdf_albedo` takes them from the scene's BSDFs as the weights
mode does: a(e, side) = pi f(n, n) / cos, the BSDF evaluated for light arriving and leaving
along the normal on the side that was hit, averaged over the band. For a Lambertian BSDF
(``diffuse``, ``twosided`` diffuse, ``veg_leaf``) this is its reflectance (0 on the back of a
one-sided ``diffuse``: Mitsuba's semantics); another BSDF is replayed as the Lambertian of that
albedo, and the replay's band-mean albedo is exact for reflectances flat within the band.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import ParameterError, SceneError

from .photon_result import PhotonPathRecord
from .scene_index import _children, _reg_id, _spatially_varying

__all__ = ["replay", "replay_slots", "irradiance", "albedo_array", "bsdf_albedo", "SIDES",
           "COMPONENTS"]

_INVALID = 0xFFFFFFFF
#: sides a replay records: front (against the geometric normal), back, or both
SIDES = ("front", "back", "both")
#: components a replay records: direct (first hit), indirect (later hits), or both
COMPONENTS = ("direct", "indirect", "both")
#: wavelengths [nm] per band at which :func:`bsdf_albedo` averages a BSDF (16 x 4 = 64)
_ALBEDO_LANES = 16


def _f64():
    return dr.float64_array_t(mi.Float)


def _float_type(albedo):
    a = albedo[0] if isinstance(albedo, tuple) else albedo
    return type(a) if dr.is_array_v(a) else _f64()


def replay(record: PhotonPathRecord, albedo, strength=1.0, side: str = "front",
           component: str = "both", w0=None):
    """Flux per element [W] of the recorded paths for given albedos (module docstring).

    Parameters
    ----------
    record : PhotonPathRecord
        Paths from :meth:`PhotonIrradianceIntegrator.trace_paths`.
    albedo : Float64 or tuple of Float64
        Albedo of every element [-] (width ``record.n_elements``; it reflects on the side that
        was hit), or a ``(front, back)`` pair of such arrays. May carry gradients.
    strength : float or Float64
        Emitter strength factor s_e [-] (a number or a width-1 array, may carry gradients).
    side : str
        ``"front"``, ``"back"`` or ``"both"``: the hits recorded.
    component : str
        ``"direct"`` (first hits), ``"indirect"`` (later hits) or ``"both"``.
    w0 : Float, optional
        Initial power per photon [W] to use instead of ``record.w0`` (e.g. one attached to the
        emitter's parameters).

    Returns
    -------
    Float64
        Flux per element [W] (the band power of the record), same float type as ``albedo``.
    """
    if side not in SIDES:
        raise ParameterError("side", side, "'front', 'back' or 'both'")
    if component not in COMPONENTS:
        raise ParameterError("component", component, "'direct', 'indirect' or 'both'")
    F = _float_type(albedo)
    n = record.n_elements
    slots = replay_slots(record, albedo, strength, w0)
    e4 = dr.arange(mi.UInt32, n) * 4
    sides = {"front": (0,), "back": (1,), "both": (0, 1)}[side]
    comps = {"direct": (0,), "indirect": (1,), "both": (0, 1)}[component]
    flux = dr.zeros(F, n)
    for c in comps:
        for sd in sides:
            flux = flux + dr.gather(F, slots, e4 + (c * 2 + sd))
    return flux


def replay_slots(record: PhotonPathRecord, albedo, strength=1.0, w0=None):
    """The replay's flux per element, component and side in one pass over the paths:
    ``out[4 e + 2 c + s]`` [W] with c = 0 direct (first hits), 1 indirect, s = 0 front, 1 back
    (module docstring; :func:`replay` sums the ones asked for).

    Parameters
    ----------
    record : PhotonPathRecord
        Paths from :meth:`PhotonIrradianceIntegrator.trace_paths`.
    albedo : Float64 or tuple of Float64
        As for :func:`replay`.
    strength : float or Float64
        Emitter strength factor [-].
    w0 : Float, optional
        As for :func:`replay`.

    Returns
    -------
    Float64
        (4 x elements) flux [W], the float type of ``albedo``.
    """
    F = _float_type(albedo)
    pair = albedo if isinstance(albedo, tuple) else (albedo, albedo)
    if len(pair) != 2:
        raise ParameterError("albedo", f"a tuple of {len(pair)}", "one array or (front, back)")
    for a in pair:
        if dr.width(a) != record.n_elements:
            raise ParameterError("albedo", f"width {dr.width(a)}",
                                 f"one albedo per element ({record.n_elements})")
    a_front, a_back = (F(a) for a in pair)
    out = dr.zeros(F, 4 * record.n_elements)
    beta = F(record.w0 if w0 is None else w0) * strength
    for k, (e, front) in enumerate(zip(record.elem, record.front)):
        valid = e != _INVALID
        slot = e * 4 + (2 if k > 0 else 0) + dr.select(front, 0, 1)
        dr.scatter_add(out, beta, slot, valid)
        a = dr.select(front, dr.gather(F, a_front, e, valid), dr.gather(F, a_back, e, valid))
        beta = beta * a
    return out


def irradiance(record: PhotonPathRecord, albedo, strength=1.0, side: str = "front",
               component: str = "both", w0=None):
    """Irradiance per element [W m-2] = :func:`replay` / element area.

    Parameters
    ----------
    record : PhotonPathRecord
        Paths from :meth:`PhotonIrradianceIntegrator.trace_paths`.
    albedo : Float64 or tuple of Float64
        As for :func:`replay`.
    strength : float or Float64
        Emitter strength factor [-].
    side : str
        ``"front"``, ``"back"`` or ``"both"``.
    component : str
        ``"direct"``, ``"indirect"`` or ``"both"``.
    w0 : Float, optional
        As for :func:`replay`.

    Returns
    -------
    Float64
        Irradiance per element [W m-2].
    """
    F = _float_type(albedo)
    inv_area = F(1.0 / np.maximum(np.asarray(record.areas, float), 1e-30))
    return replay(record, albedo, strength, side, component, w0) * inv_area


def albedo_array(n_elements: int, base, overrides: dict | None = None,
                 slices: dict | None = None, dtype=None):
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
    F = dtype or _f64()
    a = F(np.broadcast_to(np.asarray(base, float), (n_elements,)).copy())
    if overrides:
        ids = dr.arange(mi.UInt32, n_elements)
        for sid, v in overrides.items():
            if slices is None or sid not in slices:
                raise SceneError(f"albedo override for unknown shape '{sid}'")
            sl = slices[sid]
            m = (ids >= sl.start) & (ids < sl.stop)
            a = dr.select(m, v, a)
    return a


def element_bsdfs(scene: mi.Scene, index) -> list:
    """The BSDF of every element's shape as ``[(slice of elements, BSDF)]``.

    Top-level shapes in ``scene.shapes()`` order; an instance's elements per mesh of its group
    (``index.sub_slices``).

    Parameters
    ----------
    scene : mi.Scene
        The scene of ``index``.
    index : SceneIndex
        Its element index.

    Returns
    -------
    list
        ``[(slice, mi.BSDF or None)]`` covering every element.
    """
    out = []
    groups = {name: obj for name, obj in _children(scene).items()
              if isinstance(obj, mi.Shape) and obj.class_name().startswith("ShapeGroup")}
    # a group's meshes by their traversal names (the keys of ``index.sub_slices``)
    members = {g: {n: s for n, s in _children(obj).items() if isinstance(s, mi.Shape)}
               for g, obj in groups.items()}
    for sid, sh in zip(index.shape_ids, scene.shapes()):
        if sid in index.instances:
            inner = members.get(index.instances[sid], {})
            for key, sl in index.sub_slices.items():
                inst, _, mesh = key.partition("/")
                if inst == sid:
                    m = inner.get(mesh)
                    out.append((sl, m.bsdf() if m is not None else None))
        else:
            out.append((index.shape_slice(sid), sh.bsdf()))
    return out


def bsdf_albedo(scene: mi.Scene, index, band, dtype=None):
    """Per-element albedo on the front and the back side from the scene's BSDFs, band mean.

    a(e, side) = pi f(n, n) / cos for light arriving and leaving along the normal on that side
    (module docstring), averaged over 64 wavelengths evenly spread over the band. Evaluated
    with Dr.Jit AD enabled: the result is attached to the BSDFs' parameters where they carry
    gradients (``mi.traverse`` + ``dr.enable_grad`` + ``params.update()``).

    Parameters
    ----------
    scene : mi.Scene
        The scene of ``index``.
    index : SceneIndex
        Its element index.
    band : tuple of float
        (min_nm, max_nm) [nm].
    dtype : type, optional
        The Dr.Jit float type of the result (default ``mi.Float``).

    Returns
    -------
    tuple
        (front, back): albedo per element [-], each of width ``index.n_elements``.

    Raises
    ------
    SceneError
        When a BSDF varies over its surface (a texture): one albedo per element would need the
        texture at every element, which this replay does not evaluate.
    """
    F = dtype or mi.Float
    lo, hi = float(band[0]), float(band[1])
    n = _ALBEDO_LANES
    # each element's BSDF as a slot of a small table (host, one pass over the shapes); slot 0:
    # no BSDF (albedo 0)
    slot = np.zeros(index.n_elements, np.uint32)
    bsdfs: dict = {}
    for sl, b in element_bsdfs(scene, index):
        if b is not None:
            slot[sl] = bsdfs.setdefault(_reg_id(b), (len(bsdfs) + 1, b))[0]
    table = {1.0: [F(0.0)], -1.0: [F(0.0)]}
    i = dr.arange(mi.Float, n)
    wl = [lo + (hi - lo) * (i * 4 + j + 0.5) / (4 * n) for j in range(4)]
    with dr.resume_grad():
        for _, b in bsdfs.values():
            if _spatially_varying(b):
                raise SceneError(f"BSDF '{b.id() or b.class_name()}' varies over its surface "
                                 "(a texture): the differentiable replay takes one albedo per "
                                 "shape; use a uniform reflectance for the parameter studied")
            for z in (1.0, -1.0):
                si = dr.zeros(mi.SurfaceInteraction3f, n)
                si.n = mi.Normal3f(0, 0, 1)
                si.sh_frame = mi.Frame3f(si.n)
                si.wi = mi.Vector3f(0, 0, z)
                si.wavelengths = mi.Spectrum(*wl)
                f = b.eval(mi.BSDFContext(), si, mi.Vector3f(0, 0, z), mi.Bool(True))
                v = mi.Spectrum(f) * dr.pi          # pi f cos / cos (cos = 1)
                table[z].append(F(dr.mean(v[0] + v[1] + v[2] + v[3]) * 0.25))
        # one differentiable gather per side from the (BSDFs + 1)-entry tables
        idx = mi.UInt32(slot)
        front = dr.gather(F, dr.concat(table[1.0]), idx)
        back = dr.gather(F, dr.concat(table[-1.0]), idx)
    return front, back
