"""The Mitsuba BSDF ``veg_leaf``: a thin two-sided leaf, diffuse reflectance R(λ) + diffuse
transmittance T(λ).

Mitsuba 3 has no built-in diffuse transmitter (``twosided`` refuses transmissive BSDFs and the
C++ ``diffuse`` is one-sided), so this Python plugin models a leaf as a bi-Lambertian sheet:

    f(wi, wo) = R(λ)/π  if wi and wo lie on the same side of the blade,
                T(λ)/π  otherwise,                 (both sides alike)

Properties: ``reflectance`` and ``transmittance`` (spectral textures, e.g. ``regular`` spectra
from :func:`mitsuba_veg.foliage.leaf_spectra`, as :func:`mitsuba_veg.foliage.leaf_bsdf_dict`
builds them; a number is a flat spectrum). R + T <= 1 is checked at every wavelength when the
plugin is built (energy conservation).

Sampling picks reflection with probability p = <R>/(<R> + <T>) (means over the sample's
wavelengths), a cosine-weighted direction on the chosen side, and returns the weight R/p or
T/(1 - p): the expected weight is R + T, the leaf's albedo. For a spectrally flat leaf (or one
whose R/T ratio is the same at all of a sample's wavelengths) the weight is exactly R + T per
wavelength, so the photon pass's Russian roulette (continue with probability max weight) sees
the albedo R + T. The photon pass hands a back-face hit to the BSDF as it is (Mitsuba's
semantics); this one treats both sides alike.

Registered as ``veg_leaf`` when :mod:`mitsuba_veg.integrators` is imported (``import
mitsuba_veg`` does it).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_veg.errors import ParameterError

from .plugin_table import Parameter, with_parameter_table

__all__ = ["LeafBSDF", "PLUGIN_NAME"]

#: the name the BSDF is registered under
PLUGIN_NAME = "veg_leaf"


def _texture(props, name: str, default: float):
    """Property ``name`` as a texture (a number becomes a flat ``uniform`` spectrum)."""
    if name in props:
        v = props[name]
        if isinstance(v, (int, float)):
            return mi.load_dict({"type": "uniform", "value": float(v)})
        return v
    return mi.load_dict({"type": "uniform", "value": float(default)})


def _hmean(s):
    """Mean over the channels (wavelengths) of a spectrum."""
    n = dr.size_v(s)
    acc = s[0]
    for i in range(1, n):
        acc = acc + s[i]
    return acc * (1.0 / n)


@with_parameter_table
class LeafBSDF(mi.BSDF):
    """Mitsuba BSDF ``veg_leaf``: a thin two-sided leaf, diffuse reflectance R(lambda) and
    diffuse transmittance T(lambda) (module docstring).
    """

    #: the name the plugin is registered under, and its kind
    PLUGIN, PLUGIN_KIND = PLUGIN_NAME, "bsdf"
    #: every property the constructor reads (the docstring's table and the docs' plugin page)
    PARAMETERS = (
        Parameter("reflectance", "spectrum or float", "0.1",
                  "R [-], the same on both sides; a number is a flat spectrum."),
        Parameter("transmittance", "spectrum or float", "0.05",
                  "T [-]; R + T <= 1 at every wavelength (checked when the plugin is built)."),
    )

    #: its textures are inputs of a frozen function that reaches it (dr.freeze)
    DRJIT_STRUCT = {"reflectance": mi.Texture, "transmittance": mi.Texture}

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.reflectance = _texture(props, "reflectance", 0.1)
        self.transmittance = _texture(props, "transmittance", 0.05)
        self._check_energy()
        refl = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
        trans = mi.BSDFFlags.DiffuseTransmission | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
        self.m_components = [refl, trans]
        self.m_flags = refl | trans

    def _check_energy(self):
        wl = np.linspace(mi.MI_CIE_MIN, mi.MI_CIE_MAX, 941)
        n = len(wl) // 4 * 4
        si = dr.zeros(mi.SurfaceInteraction3f, n // 4)
        w = wl[:n].reshape(-1, 4)
        si.wavelengths = mi.Spectrum(*[mi.Float(w[:, k]) for k in range(4)])
        R = np.array(self.reflectance.eval(si))
        T = np.array(self.transmittance.eval(si))
        s = R + T
        if (R < 0).any() or (T < 0).any() or s.max() > 1.0 + 1e-5:
            raise ParameterError("veg_leaf reflectance + transmittance",
                                 f"max {s.max():.4f}, min R {R.min():.4f}, min T {T.min():.4f}",
                                 "R >= 0, T >= 0 and R + T <= 1 at every wavelength",
                                 "leaf spectra must conserve energy (use leaf_spectra())")

    # ---- helpers ----------------------------------------------------------------------------
    def _rt(self, si, active):
        R = self.reflectance.eval(si, active)
        T = self.transmittance.eval(si, active)
        return R, T

    def _p_reflect(self, ctx, R, T):
        has_r = ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0)
        has_t = ctx.is_enabled(mi.BSDFFlags.DiffuseTransmission, 1)
        r, t = _hmean(R), _hmean(T)
        p = dr.select(r + t > 0, r / dr.maximum(r + t, 1e-30), 0.5)
        if not has_t:
            p = dr.full(mi.Float, 1.0, dr.width(p))
        if not has_r:
            p = dr.zeros(mi.Float, dr.width(p))
        return p, has_r, has_t

    # ---- BSDF interface ---------------------------------------------------------------------
    def sample(self, ctx, si, sample1, sample2, active=True):
        """Sample reflection or transmission and a cosine-weighted direction on that side.

        Reflection is picked with probability p = <R>/(<R> + <T>) (means over the sample's
        wavelengths); the weight is R/p or T/(1 − p) (module docstring).

        Parameters
        ----------
        ctx : mi.BSDFContext
            Mitsuba's BSDF context (enabled components: 0 reflection, 1 transmission).
        si : mi.SurfaceInteraction3f
            The surface interaction (``wi`` in the local frame, wavelengths).
        sample1 : mi.Float
            Uniform sample [-] in [0, 1) that picks the component.
        sample2 : mi.Point2f
            Uniform 2-D sample [-] for the cosine-weighted direction.
        active : bool or mi.Bool
            Active lanes (default True).

        Returns
        -------
        bs : mi.BSDFSample3f
            Sampled direction ``wo`` (local frame), pdf [sr-1], eta = 1, sampled type and component.
        weight : mi.Spectrum
            BSDF value × ``|cos θ_o|`` / pdf [-] (R/p or T/(1 − p)); 0 where invalid.
        """
        cos_i = mi.Frame3f.cos_theta(si.wi)
        R, T = self._rt(si, active)
        p, has_r, has_t = self._p_reflect(ctx, R, T)
        reflect = sample1 < p
        wo = mi.warp.square_to_cosine_hemisphere(sample2)
        pdf_c = mi.warp.square_to_cosine_hemisphere_pdf(wo)
        # reflection: same side as wi; transmission: the other side
        side = dr.select(cos_i >= 0, 1.0, -1.0) * dr.select(reflect, 1.0, -1.0)
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = mi.Vector3f(wo.x, wo.y, wo.z * side)
        bs.pdf = pdf_c * dr.select(reflect, p, 1.0 - p)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(dr.select(reflect, mi.UInt32(+mi.BSDFFlags.DiffuseReflection),
                                              mi.UInt32(+mi.BSDFFlags.DiffuseTransmission)))
        bs.sampled_component = dr.select(reflect, mi.UInt32(0), mi.UInt32(1))
        weight = dr.select(reflect, R / dr.maximum(p, 1e-30), T / dr.maximum(1.0 - p, 1e-30))
        ok = active & (cos_i != 0) & (bs.pdf > 0) & (has_r | has_t)
        return bs, dr.select(ok, weight, 0.0)

    def eval(self, ctx, si, wo, active=True):
        """BSDF value times the cosine foreshortening: R/π or T/π times ``|cos θ_o|``.

        Parameters
        ----------
        ctx : mi.BSDFContext
            Mitsuba's BSDF context (enabled components: 0 reflection, 1 transmission).
        si : mi.SurfaceInteraction3f
            The surface interaction (``wi`` in the local frame, wavelengths).
        wo : mi.Vector3f
            Outgoing direction in the local frame.
        active : bool or mi.Bool
            Active lanes (default True).

        Returns
        -------
        mi.Spectrum
            f(wi, wo) ``|cos θ_o|`` [sr-1]: R/π on the side of ``wi``, T/π on the other; 0 for grazing
            ``wi`` or a disabled component.
        """
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        R, T = self._rt(si, active)
        same = cos_i * cos_o > 0
        has_r = ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0)
        has_t = ctx.is_enabled(mi.BSDFFlags.DiffuseTransmission, 1)
        f = dr.select(same, R if has_r else 0.0, T if has_t else 0.0)
        return dr.select(active & (cos_i != 0), f * (dr.abs(cos_o) * dr.inv_pi), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        """Density of :meth:`sample` for the direction ``wo``.

        Parameters
        ----------
        ctx : mi.BSDFContext
            Mitsuba's BSDF context.
        si : mi.SurfaceInteraction3f
            The surface interaction (``wi`` in the local frame, wavelengths).
        wo : mi.Vector3f
            Outgoing direction in the local frame.
        active : bool or mi.Bool
            Active lanes (default True).

        Returns
        -------
        mi.Float
            p ``|cos θ_o|`` / π (same side as ``wi``) or (1 − p) ``|cos θ_o|`` / π (other side) [sr-1].
        """
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        R, T = self._rt(si, active)
        p, _, _ = self._p_reflect(ctx, R, T)
        same = cos_i * cos_o > 0
        return dr.select(active & (cos_i != 0),
                         dr.select(same, p, 1.0 - p) * dr.abs(cos_o) * dr.inv_pi, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        """:meth:`eval` and :meth:`pdf` in one call.

        Parameters
        ----------
        ctx : mi.BSDFContext
            Mitsuba's BSDF context.
        si : mi.SurfaceInteraction3f
            The surface interaction.
        wo : mi.Vector3f
            Outgoing direction in the local frame.
        active : bool or mi.Bool
            Active lanes (default True).

        Returns
        -------
        value : mi.Spectrum
            f(wi, wo) ``|cos θ_o|`` [sr-1].
        pdf : mi.Float
            Sampling density of ``wo`` [sr-1].
        """
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def traverse(self, callback):
        """Expose ``reflectance`` and ``transmittance`` as differentiable scene parameters.

        Parameters
        ----------
        callback : mi.TraversalCallback
            Mitsuba's traversal callback (``mi.traverse``).
        """
        try:
            callback.put("reflectance", self.reflectance, mi.ParamFlags.Differentiable)
            callback.put("transmittance", self.transmittance, mi.ParamFlags.Differentiable)
        except Exception:  # pragma: no cover - older callback API
            pass

    def parameters_changed(self, keys=None):
        """Nothing to update: the textures are evaluated at every call.

        Parameters
        ----------
        keys : list of str, optional
            Names of the changed parameters (ignored).
        """
        pass

    def to_string(self):
        """Short description of the BSDF (Mitsuba's ``str()``).

        Returns
        -------
        str
            ``LeafBSDF[reflectance=..., transmittance=...]``.
        """
        return f"LeafBSDF[reflectance={self.reflectance}, transmittance={self.transmittance}]"


mi.register_bsdf(PLUGIN_NAME, lambda props: LeafBSDF(props))
