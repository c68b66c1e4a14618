"""1/f ("pink") value noise in 3D, vectorised over points (NumPy).

Paper 000 gives the placement of its moss models 1/f noise so that the moss looks naturally
grown rather than dropped on a lattice. :func:`pink_noise` sums octaves of smooth value noise
(random values on an integer lattice, trilinear interpolation with a smoothstep fade) with
amplitude proportional to 1/frequency: the power spectrum falls as 1/f^2 per octave band, i.e.
the amplitude spectrum as 1/f, the classic "1/f noise" of procedural texturing.
"""
from __future__ import annotations

import numpy as np

__all__ = ["value_noise", "pink_noise", "pink_noise_image", "periodic_pink_noise_image"]

_MASK = np.uint64(0xFFFFFFFF)


def _hash(ix, iy, iz, seed):
    """Deterministic pseudo-random values in [-1, 1) for integer lattice points."""
    h = (ix.astype(np.uint64) * np.uint64(73856093)) \
        ^ (iy.astype(np.uint64) * np.uint64(19349663)) \
        ^ (iz.astype(np.uint64) * np.uint64(83492791)) ^ np.uint64(seed * 2654435761 & 0xFFFFFFFF)
    h &= _MASK
    h ^= h >> np.uint64(13)
    h = (h * np.uint64(1274126177)) & _MASK
    h ^= h >> np.uint64(16)
    return (h & np.uint64(0xFFFFFF)).astype(np.float64) / float(1 << 23) - 1.0


def value_noise(p, seed: int = 0) -> np.ndarray:
    """Smooth value noise in [-1, 1] at points ``p`` (n, 3), lattice spacing 1.

    Random values on the integer lattice, trilinear interpolation with a smoothstep fade.

    Parameters
    ----------
    p : array_like
        Points (n, 3), in lattice units [-] (spacing 1).
    seed : int, optional
        Seed of the lattice values (default 0).

    Returns
    -------
    numpy.ndarray
        Noise values (n,) in [-1, 1] [-], float64.
    """
    p = np.asarray(p, np.float64)
    i0 = np.floor(p).astype(np.int64)
    f = p - i0
    w = f * f * (3.0 - 2.0 * f)
    out = np.zeros(len(p))
    for dx in (0, 1):
        wx = w[:, 0] if dx else 1.0 - w[:, 0]
        for dy in (0, 1):
            wy = w[:, 1] if dy else 1.0 - w[:, 1]
            for dz in (0, 1):
                wz = w[:, 2] if dz else 1.0 - w[:, 2]
                out += wx * wy * wz * _hash(i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz, seed)
    return out


def pink_noise(p, scale: float = 0.1, octaves: int = 5, seed: int = 0) -> np.ndarray:
    """1/f noise at points ``p`` (n, 3) [m].

    Octaves of value noise with frequencies 2^k / ``scale`` and amplitudes 2^-k, normalised to a
    standard deviation of about 1/3 (values mostly in [-1, 1]).

    Parameters
    ----------
    p : array_like
        Points, reshaped to (n, 3) [m] (or any length unit: ``scale`` is in the same unit).
    scale : float, optional
        Wavelength of the lowest octave [m] (default 0.1).
    octaves : int, optional
        Number of octaves (default 5).
    seed : int, optional
        Seed (default 0); octave k uses ``seed + 101 k``.

    Returns
    -------
    numpy.ndarray
        Noise values (n,) [-], standard deviation about 1/3, float64.
    """
    p = np.asarray(p, np.float64).reshape(-1, 3)
    out = np.zeros(len(p))
    norm = 0.0
    for k in range(int(octaves)):
        f = (2.0 ** k) / float(scale)
        a = 2.0 ** -k
        out += a * value_noise(p * f + 17.31 * k, seed + 101 * k)
        norm += a * a
    # the octave sum has a standard deviation of ~0.42 * sqrt(norm); scale it to ~1/3
    return out / np.sqrt(norm) * (1.0 / 3.0) / 0.42


def pink_noise_image(shape, scale_px: float = 64.0, octaves: int = 6, seed: int = 0):
    """A 2D 1/f noise image (h, w) with values mostly in [-1, 1].

    Parameters
    ----------
    shape : tuple of int
        ``(h, w)`` [px].
    scale_px : float, optional
        Wavelength of the lowest octave [px] (default 64).
    octaves : int, optional
        Number of octaves (default 6).
    seed : int, optional
        Seed (default 0).

    Returns
    -------
    numpy.ndarray
        Noise image (h, w) [-], standard deviation about 1/3, float64.
    """
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    p = np.stack([xx.ravel() / scale_px, yy.ravel() / scale_px, np.zeros(h * w)], 1)
    return pink_noise(p, scale=1.0, octaves=octaves, seed=seed).reshape(h, w)


def periodic_pink_noise_image(shape, scale_px: float = 96.0, seed: int = 0) -> np.ndarray:
    """A 2D 1/f noise image that tiles without seams (h, w), values mostly in [-1, 1].

    White noise filtered in the Fourier domain: amplitude 1/f above the lowest wavelength
    ``scale_px`` (flat below it), then scaled to a standard deviation of 1/3. The inverse
    transform is periodic, so the image repeats seamlessly (a texture with ``wrap_mode`` repeat
    over a large surface shows no tile edges).

    Parameters
    ----------
    shape : tuple of int
        ``(h, w)`` [px].
    scale_px : float, optional
        Longest wavelength with 1/f amplitude [px] (default 96).
    seed : int, optional
        Seed (default 0).

    Returns
    -------
    numpy.ndarray
        Noise image (h, w) [-], standard deviation 1/3, float64.
    """
    h, w = shape
    rng = np.random.default_rng(seed)
    spec = np.fft.rfft2(rng.standard_normal((h, w)))
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    f = np.maximum(np.hypot(fx, fy), 1.0 / float(scale_px))
    img = np.fft.irfft2(spec / f, s=(h, w))
    img -= img.mean()
    return img / (3.0 * img.std())
