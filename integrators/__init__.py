"""Mitsuba integrator plugins of mitsuba-veg (installed as ``mitsuba_veg.integrators``).

Importing this package registers every plugin with Mitsuba; ``import mitsuba_veg`` does it.
"""
from __future__ import annotations

import mitsuba as mi

from .photon_irradiance import (BANDS, KERNEL_MODES, PhotonIrradianceIntegrator,
                                PhotonIrradianceResult, PhotonPathRecord)

mi.register_integrator("veg_photon_irradiance", lambda props: PhotonIrradianceIntegrator(props))

__all__ = ["PhotonIrradianceIntegrator", "PhotonIrradianceResult", "PhotonPathRecord", "BANDS",
           "KERNEL_MODES"]
