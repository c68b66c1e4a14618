"""Uniform cell grid over the scene: occupancy, neighbour counts and per-triangle moss density.

Paper 000 (§3.8) keeps moss in a KD-tree to answer nearest-neighbour questions: is a spot already
taken, is a moss inside a dense clump (then it makes no gemmae), how dense is moss around a soil
element (m/M of eq 3.5). With every moss the same size (1 cm in the paper) a uniform grid whose
cell is one moss wide answers all three in O(1) per moss, vectorised with Dr.Jit gathers and
scatters (no tree to rebuild each day):

- a cell holds at most one individual (moss or waiting propagule): the "spot";
- a moss is *inside a clump* when at least ``clump_neighbours`` of its 26 neighbour cells hold
  moss (8 = every in-plane neighbour of a moss lying on a flat surface);
- the density of a triangle is m/M with m the moss on it and M = area / cell² the most that fit.

The grid is dense (one UInt32 per cell) up to ``max_cells``; beyond that the cell is enlarged
(coarser spots) and a warning is recorded.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

NEIGHBOURS = [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
              if (dx, dy, dz) != (0, 0, 0)]


class CellGrid:
    """Dense grid of cubic cells of side ``cell`` [m] covering ``bbox_min..bbox_max`` [m]."""

    def __init__(self, bbox_min, bbox_max, cell: float, max_cells: int = 64_000_000):
        lo = np.asarray(bbox_min, float) - 1.5 * cell
        hi = np.asarray(bbox_max, float) + 1.5 * cell
        self.requested_cell = float(cell)
        dims = np.ceil((hi - lo) / cell).astype(np.int64)
        while int(np.prod(dims)) > max_cells:
            cell *= 1.25
            dims = np.ceil((hi - lo) / cell).astype(np.int64)
        self.cell = float(cell)
        self.lo = lo
        self.dims = dims
        self.n_cells = int(np.prod(dims))

    def coords(self, p: mi.Point3f):
        """Integer cell coordinates (clamped into the grid) of points ``p``."""
        out = []
        for k, c in enumerate((p.x, p.y, p.z)):
            i = mi.Int32(dr.floor((c - float(self.lo[k])) * (1.0 / self.cell)))
            out.append(dr.clip(i, 0, int(self.dims[k]) - 1))
        return out

    def index(self, p: mi.Point3f) -> mi.UInt32:
        ix, iy, iz = self.coords(p)
        return self._linear(ix, iy, iz)

    def _linear(self, ix, iy, iz) -> mi.UInt32:
        nx, ny = int(self.dims[0]), int(self.dims[1])
        return mi.UInt32(ix) + nx * (mi.UInt32(iy) + ny * mi.UInt32(iz))

    def _persistent(self, name: str, fill: int) -> mi.UInt32:
        """A grid kept between calls (allocated and filled once): clearing a dense grid every
        day would cost more than everything else; instead the cells written last time are reset."""
        grid = getattr(self, f"_{name}", None)
        if grid is None:
            grid = dr.full(mi.UInt32, fill, self.n_cells)
            dr.eval(grid)
            setattr(self, f"_{name}", grid)
            setattr(self, f"_{name}_last", None)
        last = getattr(self, f"_{name}_last")
        if last is not None:
            dr.scatter(grid, mi.UInt32(fill), last[0], last[1])
        return grid

    def occupancy(self, p: mi.Point3f, slot: mi.UInt32, active: mi.Bool,
                  name: str = "occupancy") -> mi.UInt32:
        """Grid of ``slot + 1`` at the cells of the active points (0 = empty). Callers keep at
        most one individual per cell, so the scatter has no conflicts. ``name`` selects one of
        the persistent grids: the returned grid is valid until the next call with that name."""
        grid = self._persistent(name, 0)
        cells = self.index(p)
        dr.scatter(grid, slot + 1, cells, active)
        dr.eval(grid, cells, active)
        setattr(self, f"_{name}_last", (cells, active))
        return grid

    def reduce_min(self, key: mi.UInt32, cells: mi.UInt32, active: mi.Bool) -> mi.UInt32:
        """Per cell, the smallest ``key`` of the active entries (0xFFFFFFFF where none); the grid
        is valid until the next call."""
        grid = self._persistent("min", 0xFFFFFFFF)
        dr.scatter_reduce(dr.ReduceOp.Min, grid, key, cells, active)
        dr.eval(grid, cells, active)
        self._min_last = (cells, active)
        return grid

    def neighbour_count(self, flags: mi.UInt32, p: mi.Point3f, active: mi.Bool,
                        state: mi.UInt32 | None = None, wanted: int = 0) -> mi.UInt32:
        """Number of the 26 neighbour cells of each point whose ``flags`` entry is non-zero
        (with ``state``: whose occupant, slot = entry - 1, has ``state == wanted``)."""
        ix, iy, iz = self.coords(p)
        count = dr.zeros(mi.UInt32, dr.width(p.x))
        for dx, dy, dz in NEIGHBOURS:
            jx, jy, jz = ix + dx, iy + dy, iz + dz
            inside = (jx >= 0) & (jy >= 0) & (jz >= 0) & (jx < int(self.dims[0])) & \
                (jy < int(self.dims[1])) & (jz < int(self.dims[2]))
            v = dr.gather(mi.UInt32, flags, self._linear(jx, jy, jz), active & inside)
            hit = v > 0
            if state is not None:
                hit &= dr.gather(mi.UInt32, state, v - 1, hit) == wanted
            count += dr.select(hit, mi.UInt32(1), mi.UInt32(0))
        return count


def per_element_count(elem: mi.UInt32, active: mi.Bool, n_elements: int) -> mi.UInt32:
    """How many active individuals sit on each element (triangle): integer scatter-add."""
    counts = dr.zeros(mi.UInt32, n_elements)
    dr.scatter_add(counts, mi.UInt32(1), elem, active)
    return counts


def max_per_element(areas: np.ndarray, cell: float) -> np.ndarray:
    """M of eq 3.5: the most moss of footprint cell² that fit on each triangle (>= 1)."""
    return np.maximum(np.asarray(areas, float) / (cell * cell), 1.0)


def suggested_cell(moss_size: float) -> float:
    """A cell as wide as one moss [m]."""
    if not (moss_size > 0 and math.isfinite(moss_size)):
        raise ValueError("moss size must be a positive length in metres")
    return float(moss_size)
