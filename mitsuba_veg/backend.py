"""Choose and check the Mitsuba variant: the one place that imports Mitsuba for the package.

mitsuba-veg needs a *spectral* variant with automatic differentiation: bands such as red
(655-665 nm) and far-red (725-735 nm) are meaningless in RGB. On import the package selects
``cuda_ad_spectral`` when a CUDA device works and ``llvm_ad_spectral`` otherwise, unless the
user has already chosen a variant (then that choice is checked, never overridden).
"""
from __future__ import annotations

import os
import sys

import drjit as dr
import mitsuba as mi
import numpy

from .errors import VariantError

__all__ = ["SUPPORTED", "select_variant", "variant", "versions"]

#: the package version (also ``mitsuba_veg.__version__``)
__version__ = "0.1.0"

#: variants the package works with, in order of preference
SUPPORTED = ("cuda_ad_spectral", "llvm_ad_spectral")


def _cuda_works() -> bool:
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # pragma: no cover - depends on the machine
        return False


def select_variant(preferred: str | None = None) -> str:
    """Make sure a supported spectral variant is active and return its name.

    ``preferred`` (or the environment variable ``MITSUBA_VEG_VARIANT``) forces a variant when none
    is set yet. An already active variant is kept if supported; a non-spectral one raises
    :class:`VariantError` with the fix. Without a preference: ``cuda_ad_spectral`` when a CUDA
    device works, else ``llvm_ad_spectral``.

    Parameters
    ----------
    preferred : str, optional
        ``"cuda_ad_spectral"`` or ``"llvm_ad_spectral"``; default None (environment, then
        automatic).

    Returns
    -------
    str
        The active variant's name.

    Raises
    ------
    VariantError
        If the active or requested variant is not supported, or Dr.Jit has no LLVM backend.
    """
    current = mi.variant()
    if current is not None:
        if current not in SUPPORTED:
            raise VariantError(
                f"mitsuba-veg needs a spectral AD variant, but Mitsuba's active variant is "
                f"'{current}' (allowed: {', '.join(SUPPORTED)}). Fix: call "
                f"mi.set_variant('llvm_ad_spectral') (or 'cuda_ad_spectral' on a GPU) before "
                f"importing mitsuba_veg, or import mitsuba_veg first and let it choose.")
        return current
    preferred = preferred or os.environ.get("MITSUBA_VEG_VARIANT")
    if preferred:
        if preferred not in SUPPORTED:
            raise VariantError(
                f"MITSUBA_VEG_VARIANT='{preferred}' is not supported (allowed: "
                f"{', '.join(SUPPORTED)}). Fix: unset it or choose one of those.")
        mi.set_variant(preferred)
        return preferred
    if _cuda_works():
        try:
            mi.set_variant("cuda_ad_spectral")
            return "cuda_ad_spectral"
        except Exception:  # pragma: no cover - a broken CUDA set-up falls back to LLVM
            pass
    if not dr.has_backend(dr.JitBackend.LLVM):
        raise VariantError(
            "Dr.Jit found no LLVM backend: the llvm_ad_spectral variant needs a system libLLVM "
            ">= 16. Fix: `apt-get install -y libllvm19` (or run `make setup`), or point "
            "DRJIT_LIBLLVM_PATH at a libLLVM.so.")
    mi.set_variant("llvm_ad_spectral")
    return "llvm_ad_spectral"


def variant() -> str:
    """The active Mitsuba variant (after :func:`select_variant`).

    Returns
    -------
    str
        The variant name, e.g. ``"llvm_ad_spectral"``.
    """
    return mi.variant()


def versions() -> dict:
    """Versions of mitsuba-veg, Mitsuba, Dr.Jit, NumPy and Python and the active variant.

    Returns
    -------
    dict
        ``mitsuba_veg``, ``mitsuba``, ``drjit``, ``numpy``, ``variant``, ``python`` (for every
        ``summary.json``).
    """
    return {"mitsuba_veg": __version__, "mitsuba": mi.__version__, "drjit": dr.__version__,
            "numpy": numpy.__version__, "variant": mi.variant(),
            "python": sys.version.split()[0]}
