"""Foliage: pigments and autumn colour (paper 003), leaf spectra, IFS maple leaves."""
