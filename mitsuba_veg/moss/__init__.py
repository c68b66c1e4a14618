"""Moss of paper 000 (§3.3, §3.6): species parameters and the environmental fitness model.

- :mod:`.species`: :class:`Species` (table 3.7), the paper's species :data:`SPECIES` (table 4.2,
  shipped as ``mitsuba_veg/data/moss_species.toml``), :func:`load_species` for user files.
- :mod:`.fitness_model`: s (eq 3.18), g = :func:`fitness` (eq 3.19), daily fitness G (eq 3.17), daily
  growth D (eq 3.20), germination test (eq 3.24). Vectorised on NumPy and Dr.Jit arrays.
"""
from __future__ import annotations

from .species import Species, SPECIES, SPECIES_FILE, PARAMETER_FIELDS, load_species, get_species
from .fitness_model import (s, fitness, daily_fitness, daily_growth, germination_value, germinates,
                      SPORE_L0, SPORE_L1, GEMMA_L0, GEMMA_L1, GERMINATION_WINDOW)

__all__ = ["Species", "SPECIES", "SPECIES_FILE", "PARAMETER_FIELDS", "load_species", "get_species",
           "s", "fitness", "daily_fitness", "daily_growth", "germination_value", "germinates",
           "SPORE_L0", "SPORE_L1", "GEMMA_L0", "GEMMA_L1", "GERMINATION_WINDOW"]
