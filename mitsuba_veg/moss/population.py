"""The moss population: fixed-capacity Dr.Jit arrays and the daily life cycle (paper 000 §3.6).

Every individual is a slot of a structure of arrays of ``capacity`` entries (16,384 in the paper;
1,000,000 and more work the same way):

    state    0 free, 1 propagule (a gemma or spore waiting to germinate), 2 moss
    species  index into the run's species list
    kind     0 gemma, 1 spore (what the individual came from)
    elem     global element (triangle) index in the photon pass's SceneIndex
    pos, nrm position [m] on the surface and the surface's unit normal
    growth   G_moss, total growth since germination (eq 3.21) [-]
    age      L, days since the propagule was made (eq 3.24) [day]
    gemmae   how many multiples of 0.5 of G_moss have already produced a gemma

The day's order is the paper's (§3.3): 1 germination, 2 growth and death, 3 gemmae, 4 spores.
Each step is a handful of whole-array Dr.Jit operations; no Python loop runs per moss.
Free slots are reused: new individuals take the lowest free slots (``dr.compress``).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..arrays import Counters, host_array, opaque
from .fitness_model import GEMMA_L0, GEMMA_L1, SPORE_L0, SPORE_L1, daily_fitness, fitness
from .spatial import per_element_count
from .species import Species

__all__ = ["GEMMA_STEP", "SPORE_THRESHOLD", "DayEvents", "SlotQueue", "concat_u32", "SpeciesTable",
           "MossPopulation"]

FREE, PROPAGULE, MOSS = 0, 1, 2
GEMMA, SPORE = 0, 1
#: G_moss step that releases one gemma (paper 000 §3.6: "every +0.5")
GEMMA_STEP = 0.5
#: G_moss from which a growing moss releases spores (paper 000 §3.6)
SPORE_THRESHOLD = 2.0
_MINUS_ONE = 0xFFFFFFFF   # -1 in a UInt32 sum (mod 2^32)

_FIELDS = ("state", "species", "kind", "elem", "growth", "age", "gemmae")
#: counts of a day's life cycle (germinated, died, expired, gemma and spore parents, negative
#: G_moss, free slots)
_N_COUNTS = 7


@dataclass
class DayEvents:
    """Counts of what happened in one day (Python ints, for the run's summary)."""

    germinated: int = 0
    died: int = 0
    expired: int = 0
    gemma_parents: int = 0
    spore_parents: int = 0


class SlotQueue:
    """The slots where ``mask`` is set, in slot order, handed out on demand.

    ``take(m)`` returns the next m of them, compressing only a window of slots large enough
    for them (sized from the mask's density): a day that needs the first few thousand of
    300,000 parents does not list them all. Taking everything is one ``dr.compress``."""

    def __init__(self, mask: mi.Bool, count: int):
        self.mask, self.count = mask, int(count)
        self.size = dr.width(mask)
        self.cursor = 0             # slots [0, cursor) have been listed
        self.listed = 0             # set slots among them
        self.buf = mi.UInt32()      # listed, not yet taken

    @property
    def left(self) -> int:
        """Set slots not yet taken."""
        return self.count - self.listed + dr.width(self.buf)

    def take(self, m: int) -> mi.UInt32:
        """The next ``m`` set slots of the mask, in slot order.

        Parameters
        ----------
        m : int
            How many slots to take (capped at :attr:`left`).

        Returns
        -------
        mi.UInt32
            Up to ``m`` slot indices (fewer when fewer are left), evaluated.
        """
        m = min(int(m), self.left)
        while dr.width(self.buf) < m:
            need = m - dr.width(self.buf)
            rest = self.size - self.cursor
            unlisted = self.count - self.listed
            window = rest if 2 * need >= unlisted else \
                min(rest, int(need * rest / unlisted * 1.25) + 1024)
            if window == self.size:
                idx = dr.compress(self.mask)
            else:
                at = dr.arange(mi.UInt32, window) + opaque(mi.UInt32, self.cursor)
                idx = dr.gather(mi.UInt32, at, dr.compress(dr.gather(mi.Bool, self.mask, at)))
            self.cursor += window
            self.listed += dr.width(idx)
            self.buf = concat_u32(self.buf, idx)
        out = self.buf
        if dr.width(out) > m:
            out = dr.gather(mi.UInt32, self.buf, dr.arange(mi.UInt32, m))
            self.buf = dr.gather(mi.UInt32, self.buf, dr.arange(mi.UInt32, dr.width(self.buf) - m)
                                 + opaque(mi.UInt32, m))
        else:
            self.buf = mi.UInt32()
        dr.eval(out, self.buf)
        return out


def concat_u32(a: mi.UInt32, b: mi.UInt32) -> mi.UInt32:
    """a followed by b (UInt32 arrays).

    Parameters
    ----------
    a, b : mi.UInt32
        The arrays (either may be empty).

    Returns
    -------
    mi.UInt32
        The concatenation, of width ``width(a) + width(b)`` (``a`` or ``b`` itself when the other
        is empty).
    """
    na, nb = dr.width(a), dr.width(b)
    if na == 0 or nb == 0:
        return b if na == 0 else a
    out = dr.zeros(mi.UInt32, na + nb)
    dr.scatter(out, a, dr.arange(mi.UInt32, na))
    dr.scatter(out, b, dr.arange(mi.UInt32, nb) + opaque(mi.UInt32, na))
    return out


class SpeciesTable:
    """Per-species parameters as small Dr.Jit arrays, gathered per individual."""

    NAMES = ("T0", "T1", "nT", "rh0", "rh1", "nrh", "S0", "S1", "nS", "alpha_g", "tau_g",
             "tau_b", "tau_d")

    def __init__(self, species: list[Species], priority=None):
        self.species = list(species)
        self.names = [getattr(s, "name", f"species{i}") for i, s in enumerate(self.species)]
        for n in self.NAMES:
            setattr(self, n, mi.Float([float(getattr(s, n)) for s in self.species]))
        pr = priority if priority is not None else [0.0] * len(self.species)
        self.priority = mi.Float([float(p) for p in pr])
        # dense rank of each species' priority, 0 for the highest: an exact integer key for
        # ordering newcomers of one cell, whatever the priorities' magnitude
        levels = sorted({float(p) for p in pr}, reverse=True)
        self.priority_rank = mi.UInt32([levels.index(float(p)) for p in pr])

    def get(self, name: str, idx: mi.UInt32) -> mi.Float:
        """Parameter ``name`` of the species ``idx`` (one gather).

        Parameters
        ----------
        name : str
            One of :attr:`NAMES` (table 3.7: T0, T1 [K]; rh0, rh1 [-]; S0, S1 [W m-2]; the others
            [-]).
        idx : mi.UInt32
            Species index of each individual.

        Returns
        -------
        mi.Float
            The parameter per individual, in its unit.
        """
        return dr.gather(mi.Float, getattr(self, name), idx)

    def fitness(self, idx: mi.UInt32, Ts, rhs, S) -> mi.Float:
        """Daily fitness G of eq 3.17 for individuals of species ``idx``.

        Parameters
        ----------
        idx : mi.UInt32
            Species index of each individual.
        Ts : mi.Float
            Surface temperature [K], one per individual.
        rhs : mi.Float
            Surface relative humidity [-], one per individual.
        S : mi.Float
            Daily-mean insolation [W m-2], one per individual.

        Returns
        -------
        mi.Float
            Daily fitness G [-], one per individual.
        """
        p = {k: self.get(k, idx) for k in ("T0", "T1", "nT", "rh0", "rh1", "nrh", "S0", "S1",
                                              "nS")}
        return daily_fitness(p, Ts, rhs, S)

    def fitness_table(self, Ts, rhs, S) -> mi.Float:
        """G of eq 3.17 for every (element, species) pair.

        Element-major (index ``elem * n_species + species``). G depends only on the spot's
        environment and the species, so it is evaluated once per triangle and species, not once per
        moss.

        Parameters
        ----------
        Ts : mi.Float
            Surface temperature per element [K].
        rhs : mi.Float
            Surface relative humidity per element [-].
        S : mi.Float
            Daily-mean insolation per element [W m-2].

        Returns
        -------
        mi.Float
            Daily fitness G [-], of width ``n_elements * n_species``.
        """
        n_sp = len(self.species)
        n_el = dr.width(Ts)
        e = dr.arange(mi.UInt32, n_el * n_sp) // n_sp
        sp = dr.arange(mi.UInt32, n_el * n_sp) % n_sp
        return self.fitness(sp, dr.gather(mi.Float, Ts, e), dr.gather(mi.Float, rhs, e),
                            dr.gather(mi.Float, S, e))


class MossPopulation:
    """Structure of arrays of ``capacity`` slots (see module docstring).

    Parameters
    ----------
    capacity : int
        Number of slots.
    species : SpeciesTable
        The species.
    n_elements : int, optional
        Number of elements the individuals live on (``elem`` below it): the moss per element
        is then kept up to date by every change of the population (:attr:`per_element`).
    """

    def __init__(self, capacity: int, species: SpeciesTable, n_elements: int | None = None):
        self.capacity = int(capacity)
        self.table = species
        c = self.capacity
        #: number of elements counted in :attr:`per_element` (None: not kept)
        self.n_elements = None if n_elements is None else int(n_elements)
        #: live moss per element (m of eq 3.5), kept by the writes that change it: +1 where
        #: a propagule germinates or a moss is added, -1 where a moss dies or is removed (no
        #: count of the whole population each day); None without ``n_elements``
        self.per_element = None
        if self.n_elements is not None:
            self.per_element = dr.zeros(mi.UInt32, self.n_elements)
            dr.eval(self.per_element)
        # the day's event counters (zero every day without a launch of their own)
        self._counters = Counters(_N_COUNTS)
        self.state = dr.zeros(mi.UInt32, c)
        self._free = None       # (state variable, its evaluated FREE mask) from live_day
        self.species = dr.zeros(mi.UInt32, c)
        self.kind = dr.zeros(mi.UInt32, c)
        self.elem = dr.zeros(mi.UInt32, c)
        self.pos = dr.zeros(mi.Point3f, c)
        self.nrm = dr.zeros(mi.Vector3f, c)
        self.growth = dr.zeros(mi.Float, c)
        self.age = dr.zeros(mi.Float, c)
        self.gemmae = dr.zeros(mi.UInt32, c)
        self.overflow = 0  # individuals that found no free slot, over the whole run
        self.free_after_add = -1  # free slots left by the last add (-1: none yet)
        # occupants with G_moss < 0 at the end of the last day (-1: not known yet); with equal
        # species priorities, none means no newcomer can evict anyone
        self.negative_growth = -1

    # ---- bookkeeping ------------------------------------------------------------------------
    @property
    def moss(self) -> mi.Bool:
        """Mask over the slots: True where the slot holds a moss (state 2)."""
        return self.state == MOSS

    def count(self, state=MOSS) -> int:
        """Number of slots in a state.

        Parameters
        ----------
        state : int, optional
            ``FREE`` (0), ``PROPAGULE`` (1) or ``MOSS`` (2, the default).

        Returns
        -------
        int
            How many slots are in ``state``.
        """
        return int(dr.count(self.state == state)[0]) if dr.width(self.state) else 0

    def count_by_species(self, state=MOSS) -> list[int]:
        """Number of slots in a state, per species.

        Parameters
        ----------
        state : int, optional
            ``FREE`` (0), ``PROPAGULE`` (1) or ``MOSS`` (2, the default).

        Returns
        -------
        list of int
            One count per species of the table, in its order.
        """
        n = len(self.table.species)
        counts = dr.zeros(mi.UInt32, n)
        dr.scatter_add(counts, mi.UInt32(1), self.species, self.state == state,
                       mode=dr.ReduceMode.Local)
        return [int(v) for v in np.asarray(counts)]

    def to_numpy(self) -> dict:
        """All state as NumPy arrays (checkpoints, outputs).

        Returns
        -------
        dict
            Copies of ``state``, ``species``, ``kind``, ``elem``, ``growth`` [-], ``age`` [days],
            ``gemmae`` (each of shape (capacity,)), ``pos`` [m] and ``nrm`` [-] (capacity, 3), and
            ``overflow`` (0-d array).
        """
        # copies: a NumPy view would follow the in-place writes of later days
        d = {k: np.array(getattr(self, k)) for k in _FIELDS}
        d["pos"] = np.stack([np.asarray(c) for c in (self.pos.x, self.pos.y, self.pos.z)], 1)
        d["nrm"] = np.stack([np.asarray(c) for c in (self.nrm.x, self.nrm.y, self.nrm.z)], 1)
        d["overflow"] = np.array(self.overflow)
        return d

    def load_numpy(self, d: dict) -> None:
        """Restore the state written by :meth:`to_numpy` (a checkpoint).

        Parameters
        ----------
        d : dict
            Arrays as returned by :meth:`to_numpy`.

        Raises
        ------
        ValueError
            If the checkpoint's capacity differs from this population's.
        """
        if len(d["state"]) != self.capacity:
            raise ValueError(f"checkpoint capacity {len(d['state'])} != run capacity "
                             f"{self.capacity}")
        for k in _FIELDS:
            t = mi.Float if k in ("growth", "age") else mi.UInt32
            setattr(self, k, host_array(t, d[k]))
        self.pos = mi.Point3f(*[host_array(mi.Float, d["pos"][:, k]) for k in range(3)])
        self.nrm = mi.Vector3f(*[host_array(mi.Float, d["nrm"][:, k]) for k in range(3)])
        self.overflow = int(d["overflow"])
        self.negative_growth = -1
        self._free = None
        if self.n_elements is not None:
            self.per_element = per_element_count(self.elem, self.state == MOSS, self.n_elements)
            dr.eval(self.per_element)

    # ---- adding individuals -----------------------------------------------------------------
    def add(self, state, species, kind, elem, pos, nrm, growth) -> mi.UInt32:
        """Put new individuals (Dr.Jit arrays of equal width n) into the lowest free slots.

        Individuals beyond the free capacity are dropped and counted in ``overflow``. A moss placed
        with some growth starts with its gemma counter past the thresholds it has already reached.
        Each argument is a Dr.Jit array of width n or a scalar (the same for all).

        Parameters
        ----------
        state : int or mi.UInt32
            ``PROPAGULE`` (1) or ``MOSS`` (2).
        species : int or mi.UInt32
            Species index into the table.
        kind : int or mi.UInt32
            ``GEMMA`` (0) or ``SPORE`` (1).
        elem : mi.UInt32
            Global element (triangle) index; its width gives n.
        pos : mi.Point3f
            Positions on the surface [m].
        nrm : mi.Vector3f
            Unit surface normals [-].
        growth : float or mi.Float
            Initial G_moss [-] (0 for a propagule).

        Returns
        -------
        mi.UInt32
            The slots used (width = number placed).
        """
        n = dr.width(elem)
        if n == 0:
            return mi.UInt32()
        # the free slots: from the mask the day's life cycle evaluated while the state is
        # still the one it wrote (any write gives the state array a new variable), else anew
        mask = self._free[1] if self._free is not None and \
            self._free[0] == self.state.index else self.state == FREE
        self._free = None
        free = dr.compress(mask)
        k = min(n, dr.width(free))
        self.overflow += n - k
        self.free_after_add = dr.width(free) - k
        if k == 0:
            return mi.UInt32()
        src = dr.arange(mi.UInt32, k)
        slots = dr.gather(mi.UInt32, free, src)

        def col(value, t):
            return dr.gather(t, value, src) if dr.is_array_v(value) else t(value)

        vals = {"state": col(state, mi.UInt32), "species": col(species, mi.UInt32),
                "kind": col(kind, mi.UInt32), "elem": col(elem, mi.UInt32),
                "growth": col(growth, mi.Float), "age": mi.Float(0.0)}
        # a moss placed with some growth has already passed its gemma thresholds
        vals["gemmae"] = mi.UInt32(dr.floor(dr.maximum(vals["growth"], 0.0) / GEMMA_STEP))
        p = mi.Point3f(*[col(pos[c], mi.Float) for c in range(3)])
        q = mi.Vector3f(*[col(nrm[c], mi.Float) for c in range(3)])
        # in place, in one kernel with the gathers: k writes instead of rewriting every array
        # (Dr.Jit copies an array first if anything else still refers to it)
        for name, v in vals.items():
            dr.scatter(getattr(self, name), v, slots)
        dr.scatter(self.pos, p, slots)
        dr.scatter(self.nrm, q, slots)
        self._count_moss(vals["elem"], vals["state"] == MOSS, mi.UInt32(1))
        dr.eval(slots, self.state, self.species, self.kind, self.elem, self.growth, self.age,
                self.gemmae, self.pos, self.nrm, self.per_element)
        return slots

    def _count_moss(self, elem, active, step) -> None:
        """Add ``step`` (1, or 2^32 - 1 for -1) to :attr:`per_element` at ``elem`` where
        ``active`` (queued: it runs in the kernel that evaluates the change)."""
        if self.per_element is not None:
            # Direct (atomics): few writes into a large array; integer sums in any order
            dr.scatter_add(self.per_element, step, elem, active & (elem < self.n_elements),
                           mode=dr.ReduceMode.Direct)

    def remove(self, slots: mi.UInt32) -> None:
        """Free ``slots`` (written in place).

        Parameters
        ----------
        slots : mi.UInt32
            The slots to free (may be empty).
        """
        if dr.width(slots):
            self._free = None
            if self.per_element is not None:
                # the removed moss leave their elements (read before the write: a lazy read
                # of the state would make its write in place copy it)
                was = dr.gather(mi.UInt32, self.state, slots) == MOSS
                elem = dr.gather(mi.UInt32, self.elem, slots)
                dr.eval(was, elem)
                self._count_moss(elem, was, mi.UInt32(_MINUS_ONE))
            dr.scatter(self.state, mi.UInt32(FREE), slots)
            dr.eval(self.state, self.per_element)

    # ---- the daily life cycle ---------------------------------------------------------------
    def live_day(self, S, Ts, rhs, interior: mi.Bool | None = None, table=None,
                 changed_since=None):
        """Steps 1-2 of the day (germination, growth and death) and the parents of step 3-4.

        Propagules age by one day and germinate by eq 3.24 (or are freed past their window); moss
        grow by eqs 3.20-3.21 and die when G_moss < tau_d while declining; the gemma parents (one
        gemma per +0.5 of G_moss) and spore parents (G_moss >= 2.0 and growing) are returned.

        Parameters
        ----------
        S : mi.Float
            Daily-mean insolation per element (over all elements) [W m-2].
        Ts : mi.Float
            Surface temperature per element [K].
        rhs : mi.Float
            Surface relative humidity per element [-].
        interior : mi.Bool or None, optional
            Per-slot mask of moss inside a dense clump (no gemmae), or None (default) to return the
            gemma *candidates* (the caller then drops those inside a clump, testing only them).
        table : list of mi.Float, optional
            G per element for these S, Ts, rhs, one evaluated array per species (the values
            of :meth:`SpeciesTable.fitness_table`, e.g. from the kernel that computed the
            soil): otherwise the table is computed here, in a kernel of its own.
        changed_since : mi.UInt32, optional
            A state per slot to compare with: the mask of the slots whose state differs from
            it at the end of the day's steps is evaluated in the same kernel and kept in
            :attr:`changed`, and its values there in :attr:`changed_from` (None without it).

        Returns
        -------
        gemma : mi.Bool
            Per slot: gemma parents (or candidates when ``interior`` is None).
        spores : mi.Bool
            Per slot: spore parents.
        events : DayEvents
            Counts of the day's germinations, deaths, expiries and parents.
        """
        t = self.table
        alive = self.state != FREE
        n_sp = len(t.species)
        if table is None:
            G = dr.gather(mi.Float, t.fitness_table(Ts, rhs, S), self.elem * n_sp + self.species,
                          alive)
        else:
            # one masked gather per species: each slot reads its own species' column
            G = dr.zeros(mi.Float, dr.width(self.state))
            for k, col in enumerate(table):
                mine = alive & (self.species == k)
                G = dr.select(mine, dr.gather(mi.Float, col, self.elem, mine), G)
        # 1. germination (eq 3.24): G g(L, L0, L1, 1) > tau_b
        prop = self.state == PROPAGULE
        self.age = dr.select(prop, self.age + 1.0, self.age)
        spore = self.kind == SPORE
        L0 = dr.select(spore, SPORE_L0, GEMMA_L0)
        L1 = dr.select(spore, SPORE_L1, GEMMA_L1)
        germ = prop & (G * fitness(self.age, L0, L1, 1.0) > t.get("tau_b", self.species))
        # a propagule past its window can no longer germinate: its slot is freed
        expired = prop & ~germ & (self.age > L1)
        self.state = dr.select(germ, mi.UInt32(MOSS), self.state)
        self.growth = dr.select(germ, 0.0, self.growth)
        self.gemmae = dr.select(germ, mi.UInt32(0), self.gemmae)
        self.state = dr.select(expired, mi.UInt32(FREE), self.state)
        # 2. growth (eqs 3.20-3.21) and death: G_moss < tau_d while declining
        moss = self.state == MOSS
        D = t.get("alpha_g", self.species) * (G - t.get("tau_g", self.species))
        growth = dr.select(moss, self.growth + D, self.growth)
        died = moss & (growth < t.get("tau_d", self.species)) & (D < 0)
        self.growth = growth
        self.state = dr.select(died, mi.UInt32(FREE), self.state)
        live = moss & ~died
        # 3. gemmae: one per +0.5 of G_moss, only from the surface of a clump (eq 3.22)
        steps = mi.UInt32(dr.floor(dr.maximum(growth, 0.0) / GEMMA_STEP))
        gemma = live & (steps > self.gemmae)
        if interior is not None:
            gemma &= ~interior
        # inside a clump the counter moves on without a gemma (the paper: they grow, no gemmae)
        self.gemmae = dr.select(live & (steps > self.gemmae), steps, self.gemmae)
        # 4. spores: G_moss >= 2.0 and growing (eq 3.23)
        spores = live & (growth >= SPORE_THRESHOLD) & (D > 0)
        negative = (self.state != FREE) & (self.growth < 0.0)
        free = self.state == FREE
        # the day's counts in the same kernel as the state (integer atomics, packet-reduced):
        # one launch and one read-back instead of a reduction per count
        counts = self._counters.next(self.capacity)
        for k, m in enumerate((germ, died, expired, gemma, spores, negative, free)):
            dr.scatter_add(counts, mi.UInt32(1), mi.UInt32(k), m, mode=dr.ReduceMode.Local)
        # germinated: +1 moss on their element, died: -1
        self._count_moss(self.elem, germ | died,
                         dr.select(germ, mi.UInt32(1), mi.UInt32(_MINUS_ONE)))
        changed = was = None
        if changed_since is not None:
            changed = self.state != changed_since
            # the compared state where it changed, an array of its own: the grid's writes into
            # its copy can then share the kernel that reads the old values
            was = dr.select(changed, changed_since, mi.UInt32(0))
        dr.eval(self.state, self.growth, self.gemmae, self.age, gemma, spores, counts, free,
                *([] if changed is None else [changed, was]),
                *([] if self.per_element is None else [self.per_element]))
        # (the free mask serves the day's first :meth:`add` while the state is unchanged)
        self._free = (self.state.index, free)
        c = [int(v) for v in np.asarray(counts)]
        ev = DayEvents(germinated=c[0], died=c[1], expired=c[2], gemma_parents=c[3],
                       spore_parents=c[4])
        #: the slots whose state differs from ``changed_since`` (or None)
        self.changed = changed
        #: ``changed_since`` at those slots, 0 elsewhere (or None)
        self.changed_from = was
        self.negative_growth = c[5]
        #: free slots at the end of the day's steps 1-2
        self.free_slots = c[6]
        return gemma, spores, ev


