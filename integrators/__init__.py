"""The Mitsuba plugins of mitsuba-veg (installed as ``mitsuba_veg.integrators``), one module per
plugin family:

- ``veg_photon_irradiance`` (integrator): :mod:`.photon_irradiance` (the plugin), with its
  kernel :mod:`.photon_kernel`, element index :mod:`.scene_index`, result :mod:`.photon_result`,
  differentiable replay :mod:`.photon_replay` and bands :mod:`.bands`;
- ``veg_sky`` (emitter): :mod:`.veg_sky` (:class:`VegSky`, :func:`attach_scene`);
- ``veg_sun_path`` and ``veg_sun_steps`` (emitters): :mod:`.veg_sun` (:class:`VegSunPath`,
  :class:`VegSunSteps`, their base :class:`DeltaSun`);
- ``veg_leaf`` (BSDF): :mod:`.veg_leaf` (:class:`LeafBSDF`);
- ``veg_fisheye`` (sensor): :mod:`.veg_fisheye` (:class:`VegFisheye`, a hemispherical canopy
  camera).

Each module registers its plugins at its end; importing this package registers every plugin
with Mitsuba (``import mitsuba_veg`` does it).
"""
from __future__ import annotations

from .photon_irradiance import (BANDS, KERNEL_MODES, PhotonIrradianceIntegrator,
                                PhotonIrradianceResult, PhotonPathRecord)
from .veg_fisheye import VegFisheye
from .veg_leaf import LeafBSDF
from .veg_sky import VegSky, attach_scene
from .veg_sun import DeltaSun, VegSunPath, VegSunSteps

__all__ = ["PhotonIrradianceIntegrator", "PhotonIrradianceResult", "PhotonPathRecord", "BANDS",
           "KERNEL_MODES", "VegSky", "attach_scene", "DeltaSun", "VegSunPath", "VegSunSteps",
           "LeafBSDF", "VegFisheye"]
