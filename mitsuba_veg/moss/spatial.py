"""Spot grid: uniform moss-sized cells in hashed blocks (occupancy, neighbour counts).

Paper 000 (§3.8) keeps moss in a KD-tree to answer nearest-neighbour questions: is a spot already
taken, is a moss inside a dense clump (then it makes no gemmae), how dense is moss around a soil
element (m/M of eq 3.5). With every moss the same size (1 cm in the paper) a uniform grid whose
cell is one moss wide answers them in O(1) per moss:

- a cell holds at most one individual (moss or waiting propagule): the "spot";
- a moss is *inside a clump* when at least ``clump_neighbours`` of its 26 neighbour cells hold
  moss (8 = every in-plane neighbour of a moss lying on a flat surface);
- the density of a triangle is m/M with m the moss on it and M = area / cell² the most that fit
  (:func:`per_element_count`, :func:`max_per_element`).

Moss lives on surfaces, so almost every cell of a dense 3-D grid over the scene would stay empty
(the garden at 1.5 mm spots: 1.2 billion cells for 2 million possible spots). Cells are
therefore stored in blocks of 4 x 4 x 4, allocated when an individual first arrives in a block
and found through an open-addressing hash table (linear probing) of block keys: memory grows
with the surface that moss has reached, never with the scene's volume, and the spot size is
never coarsened. A cell holds ``slot + 1`` of its occupant (0 = free) with the top bit set when
the occupant is a moss, so a neighbour count reads 26 cells of at most 8 neighbouring blocks.

The grid follows the population through :meth:`SpotGrid.sync` (slots freed, propagules that
germinated) and :meth:`SpotGrid.insert` (newcomers); answers never depend on the order of
blocks or table entries, so resumed runs stay bit-identical.

The clump test is asked of every moss that passes a gemma step, 100,000s a day in a population
of a million, while only a few cells change from or to moss on most days. The grid therefore
keeps each moss's count of moss neighbours (``nb``, per slot) and updates it where cells change:
a cell that becomes moss adds one to its moss neighbours and counts its own; a moss cell that
empties subtracts one. :meth:`moss_neighbours` is then one gather per moss.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..arrays import Counters, opaque

__all__ = ["NEIGHBOURS", "SpotGrid", "per_element_count", "max_per_element"]

#: the 26 neighbour offsets of a cell (dx, dy, dz)
NEIGHBOURS = [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
              if (dx, dy, dz) != (0, 0, 0)]

_BITS = 21                      # bits per coordinate in a key
_OFFSET = 1 << (_BITS - 1)      # cell coordinates -2^20 .. 2^20 - 1
_USED = 1 << 63                 # marks a key (0 = empty table entry)
_GOLDEN = 0x9E3779B97F4A7C15    # Fibonacci hashing multiplier
_NONE64 = 0xFFFFFFFFFFFFFFFF
_NONE32 = 0xFFFFFFFF
_B = 4                          # cells per block edge
_B3 = _B ** 3
_MOSS_BIT = 1 << 31             # in a cell: the occupant is a moss
_NEW_BIT = 1 << 30              # ... that became one in the update under way
_SLOT_MASK = _NEW_BIT - 1       # slot + 1 (capacity < 2^30)
_PROPAGULE, _MOSS = 1, 2        # population states (population.py)


def _pack(a, b, c) -> mi.UInt64:
    f = lambda i: mi.UInt64(mi.UInt32(i))  # noqa: E731
    return f(a) | (f(b) << _BITS) | (f(c) << (2 * _BITS)) | mi.UInt64(_USED)


class SpotGrid:
    """Cubic cells of side ``cell`` [m]; cell (0, 0, 0) starts at ``bbox_min - 1.5 cell``.
    ``capacity``: the population's slots (``slot_cell`` keeps each slot's cell)."""

    #: cells per axis that a block key can address
    max_cells_per_axis = 2 * _OFFSET

    def __init__(self, bbox_min, bbox_max, cell: float, capacity: int):
        if not (cell > 0 and math.isfinite(cell)):
            raise ValueError("cell must be a positive length in metres")
        self.lo = np.asarray(bbox_min, float) - 1.5 * cell
        self.cell = self.requested_cell = float(cell)
        self.capacity = int(capacity)
        if not 0 < self.capacity < _NEW_BIT:
            raise ValueError(f"capacity {self.capacity}: a cell holds slot + 1 in 30 bits, so "
                             f"1 .. {_NEW_BIT - 1} slots")
        extent = (np.asarray(bbox_max, float) + 1.5 * cell - self.lo) / cell
        if np.any(extent >= 2 * _OFFSET):
            raise ValueError(f"the scene spans {extent.max():.3g} cells of {cell} m; at most "
                             f"{2 * _OFFSET} per axis fit a cell key (use a larger moss size)")
        self.bits = max(10, int(math.ceil(math.log2(max(self.capacity // 2, 512)))))
        self.tab_keys = dr.zeros(mi.UInt64, 1 << self.bits)
        self.tab_block = dr.zeros(mi.UInt32, 1 << self.bits)
        self._claim = dr.full(mi.UInt32, _NONE32, 1 << self.bits)
        self.n_blocks = 0
        self.block_cap = max(64, self.capacity // 8)
        self.pool = dr.zeros(mi.UInt32, self.block_cap * _B3)
        # per cell: the best claim of the newcomers being settled (``_NONE64``: none)
        self._cell_claim = dr.full(mi.UInt64, _NONE64, self.block_cap * _B3)
        self.block_key = dr.zeros(mi.UInt64, self.block_cap)
        # per block: block id + 1 of the 27 blocks around it (itself at 13; 0 = none)
        self.block_nbr = dr.zeros(mi.UInt32, self.block_cap * 27)
        self.slot_cell = dr.zeros(mi.UInt32, self.capacity)
        self._code = dr.zeros(mi.UInt32, self.capacity)  # state per slot at the last sync
        self.nb = dr.zeros(mi.UInt32, self.capacity)  # moss among the 26 neighbours (moss slots)
        self.rehashes = 0
        self._misses = Counters(1)  # lookups that found no block (cells())
        dr.make_opaque(self._cell_claim)
        dr.eval(self.tab_keys, self.tab_block, self._claim, self.pool, self.block_key,
                self.block_nbr, self.slot_cell, self._code, self.nb)

    @property
    def n_cells(self) -> int:
        """Cells allocated (in blocks of 64)."""
        return self.n_blocks * _B3

    # ---- keys -------------------------------------------------------------------------------
    def coords(self, p: mi.Point3f):
        """Integer cell coordinates of points ``p`` [m] (offset by 2^20: non-negative).

        Parameters
        ----------
        p : mi.Point3f
            Points [m].

        Returns
        -------
        list of mi.UInt32
            ``[ix, iy, iz]``: the cell index per axis plus 2^20 [cells], clamped to the addressable
            range 0 .. 2^21 - 1.
        """
        out = []
        for k, c in enumerate((p.x, p.y, p.z)):
            i = mi.Int32(dr.floor((c - float(self.lo[k])) * (1.0 / self.cell)))
            out.append(mi.UInt32(dr.clip(i, -_OFFSET, _OFFSET - 1) + _OFFSET))
        return out

    def key(self, p: mi.Point3f) -> mi.UInt64:
        """The cell key of points ``p`` (equal keys = same spot).

        Parameters
        ----------
        p : mi.Point3f
            Points [m].

        Returns
        -------
        mi.UInt64
            The packed cell coordinates (21 bits per axis, top bit set), one per point.
        """
        return _pack(*self.coords(p))

    index = key  # the spot of a point (callers compare spots)

    @staticmethod
    def _block_key(ix, iy, iz) -> mi.UInt64:
        return _pack(ix >> 2, iy >> 2, iz >> 2)

    @staticmethod
    def _local(ix, iy, iz) -> mi.UInt32:
        return (ix & 3) | ((iy & 3) << 2) | ((iz & 3) << 4)

    def _hash(self, key: mi.UInt64) -> mi.UInt32:
        return mi.UInt32((key * mi.UInt64(_GOLDEN)) >> (64 - self.bits))

    # ---- blocks -----------------------------------------------------------------------------
    def _find_block(self, bkeys: mi.UInt64, active) -> mi.UInt32:
        """Block + 1 of each block key (0 where the block does not exist)."""
        tab_keys, tab_block, mask = self.tab_keys, self.tab_block, (1 << self.bits) - 1

        def cond(pos, found, done):
            return ~done

        def body(pos, found, done):
            at = dr.gather(mi.UInt64, tab_keys, pos, ~done)
            hit = ~done & (at == bkeys)
            found = dr.select(hit, dr.gather(mi.UInt32, tab_block, pos, hit) + 1, found)
            done = done | hit | (at == 0)
            return dr.select(done, pos, (pos + 1) & mask), found, done

        n = dr.width(bkeys)
        _, found, _ = dr.while_loop((self._hash(bkeys), dr.zeros(mi.UInt32, n),
                                     ~(dr.full(mi.Bool, True, n) & active)), cond, body)
        return found

    #: most memory [B] that :meth:`reserve` may give the blocks of the surfaces at once
    reserve_bytes = 256 << 20
    #: memory per block [B]: its 64 cells (occupant, claim), key and 27 neighbour links, and two
    #: hash-table entries at the table's load of one half
    block_bytes = _B3 * (4 + 8) + 8 + 27 * 4 + 2 * (8 + 4 + 4)

    def reserve(self, p0, p1, p2, normals, lift: float = 1e-4) -> int:
        """Allocate, ahead of time, every block that the triangles ``p0 p1 p2`` reach.

        The blocks of a landing cell are otherwise allocated on the day a newcomer first
        reaches them: hash-table rounds of a dozen launches and reads on most days of a
        spreading population. Reserved here, a newcomer on these triangles always finds its
        block: the triangles are cut until no edge is longer than half a block, and every
        block that the box of a piece overlaps (lifted by up to ``lift`` along the normal, as
        landing points are, and widened by a twentieth of a cell against rounding) is
        allocated.
        Nothing that the grid answers depends on which blocks exist or on their order, so runs
        give the same numbers with and without it; a point off these triangles still gets its
        block on the day it is reached.

        Parameters
        ----------
        p0, p1, p2 : numpy.ndarray
            (n, 3) corners of the triangles [m] (the living surfaces).
        normals : numpy.ndarray
            (n, 3) unit normals [-].
        lift : float
            Offset of landing points along the normal [m] (``propagules.land``: 1e-4 m).

        Returns
        -------
        int
            Blocks allocated (0 when their estimated memory exceeds :attr:`reserve_bytes`:
            the blocks are then allocated as newcomers reach them).
        """
        a, b, c = (np.asarray(x, np.float64).reshape(-1, 3) for x in (p0, p1, p2))
        nrm = np.asarray(normals, np.float64).reshape(-1, 3)
        if len(a) == 0:
            return 0
        edge = _B * self.cell
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
        # a surface crossing blocks at an angle (or along a block boundary) meets up to about
        # four times its area in block faces
        if 4.0 * area / edge ** 2 * self.block_bytes > self.reserve_bytes:
            return 0
        piece = edge / 2
        boxes = []
        while len(a):
            longest = np.maximum(np.maximum(np.linalg.norm(b - a, axis=1),
                                            np.linalg.norm(c - b, axis=1)),
                                 np.linalg.norm(a - c, axis=1))
            d = np.flatnonzero(longest <= piece)
            if len(d):
                corners = np.stack([a[d], b[d], c[d]])
                corners = np.concatenate([corners, corners + lift * nrm[d]])
                boxes.append((corners.min(0), corners.max(0)))
            r = np.flatnonzero(longest > piece)
            a, b, c, nrm = a[r], b[r], c[r], nrm[r]
            ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
            # four triangles from the edge midpoints
            a, b, c = (np.concatenate(x) for x in ((a, ab, ca, ab), (ab, b, bc, bc),
                                                     (ca, bc, c, ca)))
            nrm = np.concatenate([nrm] * 4)
        lo = np.concatenate([x[0] for x in boxes])
        hi = np.concatenate([x[1] for x in boxes])

        def block(x, widen):
            # the block coordinate of :meth:`coords` (cell index + 2^20, clamped, // 4)
            i = np.floor((x - self.lo) / self.cell + widen)
            return (np.clip(i, -_OFFSET, _OFFSET - 1).astype(np.int64) + _OFFSET) >> 2
        b_lo, b_hi = block(lo, -0.05), block(hi, 0.05)
        # a piece is at most half a block long: with the lift and the widening its box is
        # shorter than a block (two blocks per axis at most) unless the lift is long
        per_axis = 2 if piece + lift + 0.1 * self.cell < edge else 3
        keys = []
        for d in np.ndindex(per_axis, per_axis, per_axis):
            # only the pieces whose box reaches that far (most lie in one block per axis);
            # a clamped offset would repeat a key of a smaller one
            bk = b_lo + np.array(d)
            bk = bk[np.all(bk <= b_hi, axis=1)].astype(np.uint64)
            keys.append(bk[:, 0] | (bk[:, 1] << np.uint64(_BITS))
                        | (bk[:, 2] << np.uint64(2 * _BITS)) | np.uint64(_USED))
        keys = np.unique(np.concatenate(keys))
        before = self.n_blocks
        have = np.asarray(self._find_block(mi.UInt64(keys), True)) > 0
        self._ensure_blocks(mi.UInt64(keys[~have]))
        return self.n_blocks - before

    def _ensure_blocks(self, bkeys: mi.UInt64) -> None:
        """Allocate the blocks of ``bkeys`` that do not exist yet (ids in order of claiming)."""
        n = dr.width(bkeys)
        if n == 0:
            return
        if self.n_blocks + n > (1 << self.bits) // 2:
            self._rehash(max(self.bits + 1, int(math.ceil(math.log2(2 * (self.n_blocks + n))))))
        self._place(bkeys)

    def _place(self, keys: mi.UInt64, ids: mi.UInt32 | None = None) -> None:
        """Enter ``keys`` into the table: with ``ids``, as those blocks (distinct keys); without,
        as new blocks where a key is not present yet. Rounds of one probe step: items with one
        key start at the same entry and move together; at an empty entry the lowest item claims
        it for its key, the others of that key then see it taken by their key and stop."""
        mask = (1 << self.bits) - 1
        first_new = self.n_blocks
        k, it, pos = keys, dr.arange(mi.UInt32, dr.width(keys)), self._hash(keys)
        dr.eval(k, pos)
        # every read of a table is evaluated before the table is written (a lazy read would
        # make Dr.Jit copy the whole table at the write)
        while True:
            at = dr.gather(mi.UInt64, self.tab_keys, pos)
            empty = at == 0
            found = at == k
            dr.eval(empty, found)
            del at
            # (Local: per-packet reduction then atomics; the default expands the table per
            # thread, three more launches a round)
            dr.scatter_reduce(dr.ReduceOp.Min, self._claim, it, pos, empty,
                              mode=dr.ReduceMode.Local)
            dr.eval(self._claim)
            win = empty & (dr.gather(mi.UInt32, self._claim, pos, empty) == it)
            dr.eval(win)
            dr.scatter(self._claim, mi.UInt32(_NONE32), pos, empty)
            w = dr.compress(win)
            m = dr.width(w)
            if m:
                wpos = dr.gather(mi.UInt32, pos, w)
                wkey = dr.gather(mi.UInt64, k, w)
                if ids is None:
                    self._grow(self.n_blocks + m)
                    wid = dr.arange(mi.UInt32, m) + opaque(mi.UInt32, self.n_blocks)
                    dr.scatter(self.block_key, wkey, wid)
                    self.n_blocks += m
                else:
                    wid = dr.gather(mi.UInt32, ids, dr.gather(mi.UInt32, it, w))
                dr.scatter(self.tab_keys, wkey, wpos)
                dr.scatter(self.tab_block, wid, wpos)
            dr.eval(self.tab_keys, self.tab_block, self.block_key, self._claim)
            on = ~found & ~win & (dr.gather(mi.UInt64, self.tab_keys, pos) != k)
            idx = dr.compress(on)
            if dr.width(idx) == 0:
                if self.n_blocks > first_new:
                    self._link(first_new, self.n_blocks)
                return
            k = dr.gather(mi.UInt64, k, idx)
            it = dr.gather(mi.UInt32, it, idx)
            pos = (dr.gather(mi.UInt32, pos, idx) + 1) & mask
            dr.eval(k, it, pos)

    def _grow(self, blocks: int) -> None:
        """Room for ``blocks`` blocks in the pool (doubling)."""
        if blocks <= self.block_cap:
            return
        cap = max(blocks, 2 * self.block_cap)
        pool = dr.zeros(mi.UInt32, cap * _B3)
        dr.scatter(pool, self.pool, dr.arange(mi.UInt32, self.block_cap * _B3))
        bk = dr.zeros(mi.UInt64, cap)
        dr.scatter(bk, self.block_key, dr.arange(mi.UInt32, self.block_cap))
        nbr = dr.zeros(mi.UInt32, cap * 27)
        dr.scatter(nbr, self.block_nbr, dr.arange(mi.UInt32, self.block_cap * 27))
        claim = dr.full(mi.UInt64, _NONE64, cap * _B3)   # (no claim is pending between calls)
        dr.make_opaque(claim)
        dr.eval(pool, bk, nbr)
        self.pool, self.block_key, self.block_nbr, self.block_cap = pool, bk, nbr, cap
        self._cell_claim = claim

    def _link(self, first: int, end: int) -> None:
        """Fill the neighbour-block table for the new blocks first .. end - 1 (and the back
        links of the blocks around them): 27 table lookups per new block, once."""
        # all 27 neighbours of all new blocks in one lookup: item i = block i // 27, offset i % 27
        j = dr.arange(mi.UInt32, (end - first) * 27)
        ids = j // 27 + opaque(mi.UInt32, first)
        o = j % 27
        bk = dr.gather(mi.UInt64, self.block_key, ids)
        m = (1 << _BITS) - 1
        d = (o // 9, (o // 3) % 3, o % 3)  # offset + 1 per axis
        # block coordinate + offset, modulo 2^21 (m = 2^21 - 1 stands for -1)
        c = [(mi.UInt32((bk >> (k * _BITS)) & m) + d[k] + m) & m for k in range(3)]
        f = self._find_block(_pack(*c), True)
        dr.eval(ids, o, f)
        dr.scatter(self.block_nbr, f, ids * 27 + o)
        dr.scatter(self.block_nbr, ids + 1, (f - 1) * 27 + (26 - o), f > 0)
        dr.eval(self.block_nbr)

    def _rehash(self, bits: int) -> None:
        """A table of 2^bits entries holding the existing blocks."""
        self.bits = bits
        size = 1 << bits
        self.tab_keys = dr.zeros(mi.UInt64, size)
        self.tab_block = dr.zeros(mi.UInt32, size)
        self._claim = dr.full(mi.UInt32, _NONE32, size)
        dr.eval(self.tab_keys, self.tab_block, self._claim)
        self.rehashes += 1
        if self.n_blocks:
            ids = dr.arange(mi.UInt32, self.n_blocks)
            self._place(dr.gather(mi.UInt64, self.block_key, ids), ids)

    def cells(self, p: mi.Point3f, active=True) -> mi.UInt32:
        """The pool cell of each active point, allocating the blocks that do not exist yet.

        One lookup kernel and a count read back; the blocks are placed (rounds of the hash
        table) only on the days a newcomer reaches a block no one has reached before.

        Parameters
        ----------
        p : mi.Point3f
            Points [m].
        active : mi.Bool or bool
            Which points (the others get an undefined cell).

        Returns
        -------
        mi.UInt32
            Pool cell per point (evaluated).
        """
        n = dr.width(p.x)
        active = dr.full(mi.Bool, True, n) & active
        ix, iy, iz = self.coords(p)
        bk = self._block_key(ix, iy, iz)
        found = self._find_block(bk, active)
        miss = active & (found == 0)
        cnt = self._misses.next(n)
        dr.scatter_add(cnt, mi.UInt32(1), mi.UInt32(0), miss, mode=dr.ReduceMode.Local)
        local = self._local(ix, iy, iz)
        cell = (found - 1) * _B3 + local
        # the cells in the lookup's kernel: right unless a block was missing
        dr.eval(bk, found, cnt, cell, local)
        if int(np.asarray(cnt)[0]):
            self._ensure_blocks(dr.gather(mi.UInt64, bk, dr.compress(miss)))
            cell = (self._find_block(bk, active) - 1) * _B3 + local
            dr.eval(cell)
        return cell

    def first_per_pool_cell(self, cell: mi.UInt32, rank: mi.UInt64, active=True) -> mi.Bool:
        """Among the active items, the one of lowest (distinct) ``rank`` in each pool cell.

        Every cell has a place in the claim array (the blocks exist, :meth:`cells`): one
        ``min`` per cell, then each item compares; no rounds, whatever the number of items.

        Parameters
        ----------
        cell : mi.UInt32
            Pool cell of each item (:meth:`cells`).
        rank : mi.UInt64
            Rank of each item; ranks must be distinct within a cell (lowest wins).
        active : mi.Bool or bool
            Which items take part.

        Returns
        -------
        mi.Bool
            True for the winning item of each cell.
        """
        n = dr.width(cell)
        active = dr.full(mi.Bool, True, n) & active
        dr.scatter_reduce(dr.ReduceOp.Min, self._cell_claim, rank, cell, active,
                          mode=dr.ReduceMode.Local)
        dr.eval(self._cell_claim)
        win = active & (dr.gather(mi.UInt64, self._cell_claim, cell, active) == rank)
        dr.eval(win)
        # the claims go (run with the next kernel that touches the array)
        dr.scatter(self._cell_claim, mi.UInt64(_NONE64), cell, active)
        return win

    def _cell(self, ix, iy, iz, active) -> tuple[mi.UInt32, mi.Bool]:
        """Pool index of cells (and whether their block exists)."""
        b = self._find_block(self._block_key(ix, iy, iz), active)
        ok = b > 0
        return (b - 1) * _B3 + self._local(ix, iy, iz), ok

    # ---- following the population -----------------------------------------------------------
    def insert(self, p: mi.Point3f, slots: mi.UInt32, state: mi.UInt32,
               cells: mi.UInt32 | None = None, newcomers_moss: bool = True) -> None:
        """Newcomers in ``slots`` occupy the cells of points ``p``.

        One per cell: the caller has resolved conflicts, see ``propagules.settle``. Call
        :meth:`sync` before the population frees or reuses slots.

        Parameters
        ----------
        p : mi.Point3f
            Positions of the newcomers [m].
        slots : mi.UInt32
            Their population slots (may be empty).
        state : mi.UInt32
            The population's state after adding them, per slot (read at ``slots``; every other
            slot as at the last :meth:`sync`).
        cells : mi.UInt32, optional
            Their pool cells when already known (:meth:`cells`, e.g. from settling).
        newcomers_moss : bool
            False when the caller knows every newcomer is a propagule (no moss-neighbour
            counts to update; the check costs two launches and a read-back).
        """
        if dr.width(slots):
            cell = self.cells(p) if cells is None else cells
            now = dr.gather(mi.UInt32, state, slots)
            moss = now == _MOSS
            v = (slots + 1) | dr.select(moss, mi.UInt32(_MOSS_BIT | _NEW_BIT), mi.UInt32(0))
            # the grid's copy of the state follows by k writes (a reference to the population's
            # array would make its next write in place copy the whole array first)
            dr.scatter(self._code, now, slots)
            dr.scatter(self.pool, v, cell)
            dr.scatter(self.slot_cell, cell, slots)
            if newcomers_moss:      # (newcomers are propagules but at the start)
                mcount = dr.zeros(mi.UInt32, 1)
                dr.scatter_add(mcount, mi.UInt32(1), mi.UInt32(0), moss,
                               mode=dr.ReduceMode.Local)
                dr.eval(self.pool, self.slot_cell, self._code, mcount)
                if int(np.asarray(mcount)[0]):
                    new = dr.gather(mi.UInt32, slots, dr.compress(moss))
                    nb_before = dr.gather(mi.UInt32, self.nb, new)
                    dr.eval(nb_before)
                    # the new moss's cells carry the "new" bit until they are counted
                    self._moss_counts_follow(new, True, True, nb_before,
                                             lambda s, v, m: (v & _NEW_BIT) != 0)
                    dr.scatter(self.pool, (new + 1) | _MOSS_BIT,
                               dr.gather(mi.UInt32, self.slot_cell, new))
                    dr.eval(self.pool)
        dr.eval(self.pool, self.slot_cell, self._code)

    def sync(self, state: mi.UInt32, changed: mi.Bool | None = None,
             was: mi.UInt32 | None = None) -> None:
        """Follow the population's changes since the last call.

        Freed slots empty their cell, propagules that germinated are marked as moss, and the moss
        neighbour counts are updated where cells changed.

        Parameters
        ----------
        state : mi.UInt32
            The population's current state per slot (0 free, 1 propagule, 2 moss).
        changed : mi.Bool, optional
            ``state != `` the grid's copy, already evaluated (the population's day computes it
            in its own kernel: ``live_day(changed_since=grid.state_copy)``).
        was : mi.UInt32, optional
            With ``changed``: the grid's copy of the state at the changed slots (any value
            elsewhere), an evaluated array of its own (``live_day`` writes it beside
            ``changed``). The grid's writes then share the kernel that reads the changes.
        """
        if changed is None:
            changed = self._code != state
            dr.eval(changed)  # (an array: the neighbour counts read it at neighbour slots)
            was = None
        # one pass over the slots finds the few that changed; the rest works on those
        sl = dr.compress(changed)
        if dr.width(sl):
            old = dr.gather(mi.UInt32, self._code if was is None else was, sl)
            now = dr.gather(mi.UInt32, state, sl)
            cell = dr.gather(mi.UInt32, self.slot_cell, sl)
            freed = (old != 0) & (now == 0)
            germ = (old == _PROPAGULE) & (now == _MOSS)
            moss_changed = ((old == _MOSS) & (now == 0)) | germ
            # a new moss's count before it is counted afresh (read before the counts change)
            nb_before = dr.gather(mi.UInt32, self.nb, sl, germ)
            if was is None:
                # no lazy read of the grid's copy stays behind to make its write copy it
                dr.eval(cell, freed, germ, now, moss_changed, nb_before)
            del old
            # one write per changed cell (a second write into the pool would be a kernel of
            # its own); a germinated propagule's cell holds a moss from now on
            dr.scatter(self.pool, dr.select(germ, (sl + 1) | _MOSS_BIT, mi.UInt32(0)), cell,
                       freed | germ)
            # the grid's own copy of the state, written where it changed (a reference to the
            # population's array would make its next write in place copy the whole array)
            dr.scatter(self._code, now, sl)
            dr.eval(self.pool, self._code, cell, germ, moss_changed, nb_before)
            # the moss neighbour counts, in the changed slots' width (a lane where the moss
            # did not change does nothing): no compress of those that did
            self._moss_counts_follow(
                sl, germ, moss_changed, nb_before,
                lambda s, v, m: dr.gather(mi.Bool, changed, s, m)
                & (dr.gather(mi.UInt32, state, s, m) == _MOSS))
        dr.eval(self.pool)

    def _moss_counts_follow(self, ev, grow, active, nb_before, is_new) -> None:
        """Update the moss-neighbour counts for slots ``ev`` (where ``active``) whose cell
        stopped holding a moss (``grow`` False) or started to (``grow`` True), in one kernel:
        moss that were moss before gain or lose one per changed neighbour; a new moss counts
        its moss neighbours afresh (new ones included). ``is_new(slots, cell values, mask)``:
        whether the moss of those slots (holding those cells; read only where ``mask``) are
        new; ``nb_before``: the new moss's counts before (their counts are summed to theirs
        minus it, so that both updates are additions into one array in one kernel). The
        counts do not depend on the order of ``ev``."""
        (ix, iy, iz), block = self._slot_coords(ev)
        step = dr.select(grow, mi.UInt32(1), mi.UInt32(_NONE32))  # +1 or -1 (mod 2^32)
        own = dr.zeros(mi.UInt32, dr.width(ev))
        for v, ok in self._neighbour_values(ix, iy, iz, active, block):
            moss = ok & ((v & _MOSS_BIT) != 0)
            slot = (v & _SLOT_MASK) - 1
            old = moss & ~is_new(slot, v, moss)
            # Direct (atomics): few writes into a large array; the default would expand the
            # array per thread and reduce it afterwards
            dr.scatter_add(self.nb, step, slot, old, mode=dr.ReduceMode.Direct)
            own += dr.select(moss & grow, mi.UInt32(1), mi.UInt32(0))
        dr.scatter_add(self.nb, own - nb_before, ev, active & grow, mode=dr.ReduceMode.Direct)
        dr.eval(self.nb)

    @property
    def state_copy(self) -> mi.UInt32:
        """The population's state per slot as the grid last saw it (:meth:`sync`,
        :meth:`insert`); read-only."""
        return self._code

    def rebuild(self, pos: mi.Point3f, state: mi.UInt32) -> None:
        """Empty every cell and insert all occupied slots (after loading a checkpoint).

        Parameters
        ----------
        pos : mi.Point3f
            Position of every slot [m] (width = capacity).
        state : mi.UInt32
            State of every slot (0 free, 1 propagule, 2 moss).
        """
        self.pool = dr.zeros(mi.UInt32, self.block_cap * _B3)
        self._code = dr.zeros(mi.UInt32, self.capacity)
        self.nb = dr.zeros(mi.UInt32, self.capacity)
        s = dr.compress(state != 0)
        self.insert(dr.gather(mi.Point3f, pos, s), s, state)

    def _slot_coords(self, slots: mi.UInt32):
        """Cell coordinates of the cells held by ``slots`` (from their block's key), and their
        block + 1."""
        cell = dr.gather(mi.UInt32, self.slot_cell, slots)
        bk = dr.gather(mi.UInt64, self.block_key, cell // _B3)
        local = cell % _B3
        m = (1 << _BITS) - 1
        return [(mi.UInt32((bk >> (k * _BITS)) & m) << 2) | ((local >> (2 * k)) & 3)
                for k in range(3)], cell // _B3 + 1

    # ---- reading ----------------------------------------------------------------------------
    def occupant(self, p: mi.Point3f, active=True) -> mi.UInt32:
        """Slot + 1 of the individual in the cell of each point (0 = the spot is free).

        Parameters
        ----------
        p : mi.Point3f
            Points [m].
        active : bool or mi.Bool, optional
            Which points to look up (default all); inactive ones give 0.

        Returns
        -------
        mi.UInt32
            Slot + 1 of the occupant, or 0, per point.
        """
        ix, iy, iz = self.coords(p)
        cell, ok = self._cell(ix, iy, iz, active)
        return dr.gather(mi.UInt32, self.pool, cell, ok & active) & _SLOT_MASK

    def moss_neighbours(self, slots: mi.UInt32) -> mi.UInt32:
        """Moss among the 26 neighbour cells of the moss in ``slots``.

        Kept up to date by :meth:`sync` and :meth:`insert`; equal to :meth:`neighbour_count` at
        their positions.

        Parameters
        ----------
        slots : mi.UInt32
            Slots of moss.

        Returns
        -------
        mi.UInt32
            Number of moss neighbours (0 .. 26), per slot.
        """
        return dr.gather(mi.UInt32, self.nb, slots)

    def neighbour_count(self, p: mi.Point3f, active=True, moss_only: bool = True) -> mi.UInt32:
        """Number of the 26 neighbour cells of each point that hold a moss or any individual.

        Read from the pool (not from the kept counts of :meth:`moss_neighbours`).

        Parameters
        ----------
        p : mi.Point3f
            Points [m].
        active : bool or mi.Bool, optional
            Which points to count for (default all); inactive ones give 0.
        moss_only : bool, optional
            Count only cells that hold a moss (default True); False counts any individual (moss or
            propagule).

        Returns
        -------
        mi.UInt32
            Neighbour count (0 .. 26), per point.
        """
        ix, iy, iz = self.coords(p)
        count = dr.zeros(mi.UInt32, dr.width(ix))
        for v, ok in self._neighbour_values(ix, iy, iz, active):
            hit = ok & (((v & _MOSS_BIT) != 0) if moss_only else (v != 0))
            count += dr.select(hit, mi.UInt32(1), mi.UInt32(0))
        return count

    def _neighbour_values(self, ix, iy, iz, active, own=None):
        """(cell value, block exists) of the 26 neighbour cells of cells (ix, iy, iz). The
        3 x 3 x 3 neighbourhood spans at most 2 x 2 x 2 blocks: each is found once (from the
        neighbour-block table when ``own``, the block + 1 of each cell, is given; else in the
        hash table), then the 26 cells are read from them."""
        n = dr.width(ix)
        active = dr.full(mi.Bool, True, n) & active
        w = lambda d: d % (1 << 32)  # noqa: E731  (-1 wraps: coordinates are unsigned)
        lo = [(c + w(-1)) >> 2 for c in (ix, iy, iz)]
        hi = [(c + 1) >> 2 for c in (ix, iy, iz)]
        base = [c >> 2 for c in (ix, iy, iz)]
        blocks = {}
        for cx in (0, 1):
            for cy in (0, 1):
                for cz in (0, 1):
                    need = active
                    b = []
                    for k, ck in enumerate((cx, cy, cz)):
                        b.append(hi[k] if ck else lo[k])
                        if ck:
                            need = need & (hi[k] != lo[k])
                    if own is None:
                        blocks[cx, cy, cz] = self._find_block(_pack(*b), need)
                    else:  # offsets -1 .. 1 per axis -> entry 0 .. 26 of the table
                        o = [b[k] + 1 - base[k] for k in range(3)]
                        at = (own - 1) * 27 + o[0] * 9 + o[1] * 3 + o[2]
                        blocks[cx, cy, cz] = dr.gather(mi.UInt32, self.block_nbr, at, need)
        for dx, dy, dz in NEIGHBOURS:
            j = [ix + w(dx), iy + w(dy), iz + w(dz)]
            up = [(j[k] >> 2) != lo[k] for k in range(3)]
            # the neighbour's block among the (up to) eight
            by_x = {}
            for cy in (0, 1):
                for cz in (0, 1):
                    by_x[cy, cz] = dr.select(up[0], blocks[1, cy, cz], blocks[0, cy, cz])
            by_y = {cz: dr.select(up[1], by_x[1, cz], by_x[0, cz]) for cz in (0, 1)}
            b = dr.select(up[2], by_y[1], by_y[0])
            ok = active & (b > 0)
            yield dr.gather(mi.UInt32, self.pool, (b - 1) * _B3 + self._local(*j), ok), ok

    @staticmethod
    def first_per_cell(keys: mi.UInt64, rank: mi.UInt64, active=True) -> mi.Bool:
        """Among the active items, the one of lowest (distinct) ``rank`` in each cell.

        Rounds of bucketing by a hash of the key (4 buckets per item): an item with the lowest rank
        of its bucket is the best of its cell (all items of a cell share a bucket); an item whose
        bucket went to its own cell lost; the rest (their bucket went to another cell) try again
        with another hash.

        Parameters
        ----------
        keys : mi.UInt64
            Cell key of each item (:meth:`key`).
        rank : mi.UInt64
            Rank of each item; ranks must be distinct within a cell (lowest wins).
        active : bool or mi.Bool, optional
            Which items take part (default all).

        Returns
        -------
        mi.Bool
            True for the winning item of each cell.
        """
        active = dr.full(mi.Bool, True, dr.width(keys)) & active  # a scalar True: all
        it = dr.compress(active)
        out = dr.zeros(mi.Bool, dr.width(keys))
        k = dr.gather(mi.UInt64, keys, it)
        r = dr.gather(mi.UInt64, rank, it)
        salt = 0
        while dr.width(it):
            bits = max(4, int(math.ceil(math.log2(4 * dr.width(it)))))
            mult = (_GOLDEN + 2 * salt * 0x632BE59BD9B4E019) % (1 << 64) | 1
            # opaque: the kernels do not depend on the round or the batch size
            b = mi.UInt32((k * opaque(mi.UInt64, mult)) >> opaque(mi.UInt64, 64 - bits))
            best = dr.full(mi.UInt64, _NONE64, 1 << bits)
            dr.scatter_reduce(dr.ReduceOp.Min, best, r, b, mode=dr.ReduceMode.Local)
            dr.eval(best, b)
            win = dr.gather(mi.UInt64, best, b) == r
            dr.eval(win)
            bk = dr.zeros(mi.UInt64, 1 << bits)
            dr.scatter(bk, k, b, win)
            dr.scatter(out, True, it, win)
            dr.eval(bk, out)
            rest = dr.compress(~win & (dr.gather(mi.UInt64, bk, b) != k))
            k = dr.gather(mi.UInt64, k, rest)
            r = dr.gather(mi.UInt64, r, rest)
            it = dr.gather(mi.UInt32, it, rest)
            dr.eval(k, r, it)
            salt += 1
        return out


def per_element_count(elem: mi.UInt32, active: mi.Bool, n_elements: int) -> mi.UInt32:
    """How many active individuals sit on each element (triangle): integer scatter-add.

    Parameters
    ----------
    elem : mi.UInt32
        Element index of each individual.
    active : mi.Bool
        Which individuals count (e.g. the moss mask).
    n_elements : int
        Number of elements.

    Returns
    -------
    mi.UInt32
        Count m per element (m of eq 3.5), width ``n_elements``.
    """
    counts = dr.zeros(mi.UInt32, n_elements)
    dr.scatter_add(counts, mi.UInt32(1), elem, active, mode=dr.ReduceMode.Local)
    return counts


def max_per_element(areas: np.ndarray, cell: float) -> np.ndarray:
    """M of eq 3.5: the most moss of footprint cell² that fit on each triangle (>= 1).

    Parameters
    ----------
    areas : numpy.ndarray
        Triangle areas [m2].
    cell : float
        Moss size (the spot grid's cell side) [m].

    Returns
    -------
    numpy.ndarray
        M = max(area / cell², 1) per triangle [-] (float64).
    """
    return np.maximum(np.asarray(areas, float) / (cell * cell), 1.0)

