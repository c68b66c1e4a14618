"""Array helpers shared by the package: one module for NumPy / Dr.Jit dispatch and for the few
device primitives the daily pipeline needs.

- **Backend dispatch** (:func:`is_dr`, :func:`float_type`, :func:`prep`, :func:`finish` and the
  NaN-keeping elementwise functions): a model written once runs on NumPy arrays (float64) and
  on Dr.Jit arrays of any backend (the result has the kind of the input), so the discrete
  daily run and the relaxed, differentiable model share one implementation of each equation
  (``soil.py``, ``moss/fitness_model.py``, ``foliage/autumn.py``).
- **Deterministic discrete sampling** (:class:`DiscreteSampler`): a probability table whose
  cumulative sums are formed on the host in float64 and searched on the device. Mitsuba's
  ``DiscreteDistribution`` forms them with Dr.Jit's prefix sum, which on CUDA is not bitwise
  repeatable (mitsuba3 issue 1938): the same seed then gave different sun directions.
- **Deterministic sums** (:class:`Tally`): many sums over segments (regions, trees, species)
  in a few kernels, exact to the last bit on every backend and in any thread order, by 64-bit
  fixed-point integer atomics (float atomics are not associative).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = ["is_dr", "float_type", "prep", "finish", "nan_keep", "exp", "abs_", "where",
           "maximum", "minimum", "power", "safe_power", "clip", "host_array", "opaque",
           "zero_index", "Pack", "host_scalar",
           "DiscreteSampler", "Tally"]


# --------------------------------------------------------------------------------------------
# Backend dispatch: NumPy or Dr.Jit, decided by the inputs
# --------------------------------------------------------------------------------------------
def is_dr(x) -> bool:
    """Whether ``x`` is a Dr.Jit array.

    Parameters
    ----------
    x : object
        Any value.

    Returns
    -------
    bool
        True for Dr.Jit arrays of any backend and type.
    """
    return dr.is_array_v(x)


def float_type(*xs):
    """The Dr.Jit floating-point array type among ``xs`` (the first Dr.Jit array found).

    Parameters
    ----------
    *xs : object
        Values; NumPy arrays and numbers are skipped.

    Returns
    -------
    type or None
        The type of the first Dr.Jit array (its float32 twin for an integer array), or None
        when no argument is a Dr.Jit array.
    """
    for x in xs:
        if is_dr(x):
            t = type(x)
            return t if dr.is_float_v(t) else dr.float32_array_t(t)
    return None


def prep(*xs) -> tuple:
    """Bring the inputs onto one backend.

    With any Dr.Jit input, NumPy arrays are converted to that Dr.Jit type and NumPy scalars to
    Python floats (Dr.Jit broadcasts them; a NumPy scalar on the left of a Dr.Jit array would
    turn the result into a NumPy array); otherwise everything becomes a float64 NumPy array.

    Parameters
    ----------
    *xs : object
        Numbers, NumPy arrays or Dr.Jit arrays.

    Returns
    -------
    tuple
        The inputs on one backend, in order.
    """
    t = float_type(*xs)
    if t is None:
        return tuple(np.asarray(x, dtype=np.float64) for x in xs)
    out = []
    for x in xs:
        if is_dr(x) or type(x) in (int, float):
            out.append(x)
        else:
            a = np.asarray(x, dtype=np.float64)
            out.append(float(a) if a.ndim == 0 else t(a.ravel()))
    return tuple(out)


def finish(x):
    """NumPy 0-d arrays become NumPy scalars; everything else is returned unchanged.

    Parameters
    ----------
    x : object
        A result.

    Returns
    -------
    object
        ``x[()]`` for a 0-d NumPy array, else ``x``.
    """
    if isinstance(x, np.ndarray) and x.ndim == 0:
        return x[()]
    return x


# Dr.Jit's transcendental functions do not reliably propagate NaN: on width-1 arrays, fused into
# a kernel with other work, exp2(10 * log2(NaN)) gave -1.1e10 (Float) or 2.2e307 (Float64), and
# power(NaN, Float(10)) gave -1.8e38 (Dr.Jit 1.5.0, LLVM). The NaN policy of the models is made
# explicit with a select.
def nan_keep(x, r):
    """``r`` where ``x`` is a number, ``x`` (NaN) where it is NaN (Dr.Jit arrays).

    Parameters
    ----------
    x : drjit array
        The operand whose NaN must survive.
    r : drjit array
        The result computed from it.

    Returns
    -------
    drjit array
        ``select(isnan(x), x, r)``.
    """
    return dr.select(dr.isnan(x), x, r)


def exp(x):
    """exp(x) on either backend, NaN in NaN out.

    Parameters
    ----------
    x : numpy.ndarray or drjit array
        Exponent [-].

    Returns
    -------
    numpy.ndarray or drjit array
        e^x [-].
    """
    return nan_keep(x, dr.exp(x)) if is_dr(x) else np.exp(x)


def abs_(x):
    """``|x|`` on either backend.

    Parameters
    ----------
    x : numpy.ndarray or drjit array
        Values.

    Returns
    -------
    numpy.ndarray or drjit array
        Absolute values.
    """
    return dr.abs(x) if is_dr(x) else np.abs(x)


def where(cond, a, b):
    """``a`` where ``cond`` else ``b``, on the backend of any Dr.Jit operand.

    Parameters
    ----------
    cond : array_like or drjit array
        Condition.
    a, b : array_like or drjit array
        The two choices.

    Returns
    -------
    numpy.ndarray or drjit array
        The selected values.
    """
    if is_dr(cond) or is_dr(a) or is_dr(b):
        return dr.select(cond, a, b)
    return np.where(cond, a, b)


def maximum(a, b):
    """max(a, b) that keeps a NaN in ``a`` (``a < b`` is False for NaN).

    Parameters
    ----------
    a, b : array_like or drjit array
        Operands.

    Returns
    -------
    numpy.ndarray or drjit array
        The larger value (NaN where ``a`` is NaN).
    """
    return where(a < b, b, a)


def minimum(a, b):
    """min(a, b) that keeps a NaN in ``a``.

    Parameters
    ----------
    a, b : array_like or drjit array
        Operands.

    Returns
    -------
    numpy.ndarray or drjit array
        The smaller value (NaN where ``a`` is NaN).
    """
    return where(a > b, b, a)


def clip(x, lo, hi):
    """``x`` clipped to [lo, hi], keeping NaN.

    Parameters
    ----------
    x : array_like or drjit array
        Values.
    lo, hi : float
        Bounds.

    Returns
    -------
    numpy.ndarray or drjit array
        Clipped values.
    """
    return minimum(maximum(x, lo), hi)


def power(x, y):
    """x**y for x >= 0 (or NaN); NaN in x or y gives NaN on both backends.

    Parameters
    ----------
    x : array_like or drjit array
        Base (>= 0).
    y : array_like or drjit array or float
        Exponent.

    Returns
    -------
    numpy.ndarray or drjit array
        x**y.
    """
    if is_dr(x) or is_dr(y):
        r = dr.power(x, y)
        if is_dr(y) or (isinstance(y, float) and math.isnan(y)):
            r = nan_keep(y, r)
        return nan_keep(x, r) if is_dr(x) else r
    return np.power(x, y)


def safe_power(base, expo):
    """``base**expo`` for ``base >= 0`` with a finite derivative at 0 (double ``where``).

    ``0**expo = 0``; NaN in ``base`` stays NaN. Negative bases must be clamped by the caller.

    Parameters
    ----------
    base : array_like or drjit array
        Base (>= 0).
    expo : array_like or drjit array or float
        Exponent (> 0).

    Returns
    -------
    numpy.ndarray or drjit array
        base**expo.
    """
    zero = base == 0
    safe = where(zero, 1.0, base)
    return where(zero, 0.0, power(safe, expo))


_NP_TYPES = {dr.VarType.UInt32: np.uint32, dr.VarType.Int32: np.int32,
             dr.VarType.UInt64: np.uint64, dr.VarType.Int64: np.int64,
             dr.VarType.Float32: np.float32, dr.VarType.Float64: np.float64,
             dr.VarType.Bool: np.bool_}


def host_array(t, values):
    """A Dr.Jit array of type ``t`` from host values, through a 64-byte aligned NumPy buffer.

    On the LLVM backend Dr.Jit maps NumPy memory instead of copying it, and a frozen function
    (``dr.freeze``) is recorded anew when an input's alignment differs from the last call's;
    NumPy's own buffers are aligned by chance. An aligned buffer keeps every day's inputs alike.

    Parameters
    ----------
    t : type
        Dr.Jit array type (``mi.Float``, ``mi.UInt32`` ...).
    values : array_like
        The values (flattened).

    Returns
    -------
    drjit array
        An evaluated array of the values.
    """
    v = np.ascontiguousarray(np.asarray(values, dtype=_NP_TYPES[dr.type_v(t)]).reshape(-1))
    a = aligned_empty(len(v), v.dtype)
    a[...] = v
    return t(a)


def aligned_empty(n: int, dtype) -> np.ndarray:
    """An uninitialised NumPy array of ``n`` values whose buffer starts on a 64-byte boundary.

    Filled by the caller and then handed to a Dr.Jit constructor, it is mapped (LLVM) without a
    copy and gives the kernels that read it the same code whatever the allocation
    (:func:`host_array`); the caller must not write to it afterwards.

    Parameters
    ----------
    n : int
        Number of values.
    dtype : numpy.dtype
        Their type.

    Returns
    -------
    numpy.ndarray
        (n,) array.
    """
    dt = np.dtype(dtype)
    buf = np.empty(int(n) * dt.itemsize + 64, np.uint8)
    off = (-buf.ctypes.data) % 64
    return buf[off:off + int(n) * dt.itemsize].view(dt)


def opaque(t, value):
    """A width-1 array of type ``t`` holding ``value`` that is a kernel *input*, not a literal.

    A Python number used in a kernel becomes a literal of its code: a value that changes
    every day (the day's weather, a photon count) would then compile a new kernel every day.
    Unlike ``dr.opaque`` (one memset launch per value), the value is copied from a host array,
    which on the LLVM backend launches nothing.

    Parameters
    ----------
    t : type
        Dr.Jit array type (``mi.Float``, ``mi.UInt32`` ...).
    value : number
        The value.

    Returns
    -------
    drjit array
        An evaluated width-1 array.
    """
    return host_array(t, [value])


_ZERO: dict = {}


def zero_index():
    """An evaluated UInt32 zero of the current variant (made once).

    ``zero_index() + j`` indexes a gather without being a literal: Dr.Jit performs a gather
    whose index is a literal at once (a copy launched per value), while one whose index is an
    expression is fused into the kernels that read it.

    Returns
    -------
    mi.UInt32
        A width-1 array holding 0.
    """
    key = mi.variant()
    if key not in _ZERO:
        _ZERO[key] = opaque(mi.UInt32, 0)
    return _ZERO[key]


class Counters:
    """``k`` integer counters for a kernel's atomics, zero at every use without a launch of
    their own: two sets used in turn, the kernel that adds into one set also zeroes the other
    (queued writes at the kernel's width) for the next use. A ``dr.zeros`` array would be a
    memset launch each time.

    Parameters
    ----------
    k : int
        Number of counters.
    t : type
        Their Dr.Jit array type (``mi.UInt32`` or ``mi.UInt64``).
    """

    def __init__(self, k: int, t=mi.UInt32):
        self.k, self.t = int(k), t
        self._sets = [dr.zeros(t, self.k) for _ in range(2)]
        dr.eval(self._sets)
        self._turn = 0

    def next(self, width: int):
        """The zeroed set for a kernel of ``width`` lanes (the call queues the zeroing of the
        other set: evaluate the kernel before the next call).

        Parameters
        ----------
        width : int
            The width of the kernel that adds into the counters.

        Returns
        -------
        mi.UInt32 or mi.UInt64
            ``k`` zeros, written in place by the caller's ``scatter_add``.
        """
        self._turn ^= 1
        now = self._sets[self._turn]
        if width >= self.k:
            lane = dr.arange(mi.UInt32, width)
            dr.scatter(self._sets[1 - self._turn], self.t(0), lane, lane < self.k)
        else:                       # (a narrow kernel: a launch of its own)
            self._sets[1 - self._turn] = dr.zeros(self.t, self.k)
            dr.eval(self._sets[1 - self._turn])
        return now


class Pack:
    """Several per-call numbers as kernel inputs from one host copy: ``pack[j]`` is value j,
    read inside the kernels that use it (a gather with a non-literal index).

    Parameters
    ----------
    t : type
        Dr.Jit array type.
    values : sequence of numbers
        The values.
    """

    def __init__(self, t, values):
        self.t = t
        self.arr = host_array(t, values)

    def __getitem__(self, j: int):
        return dr.gather(self.t, self.arr, zero_index() + int(j))

    def __len__(self) -> int:
        return dr.width(self.arr)


def host_scalar(x) -> float:
    """A Python float from a width-1 Dr.Jit array (reads it back) or a number.

    Parameters
    ----------
    x : drjit array or number
        A reduction result or a number.

    Returns
    -------
    float
        Its value.
    """
    return float(np.asarray(x, dtype=np.float64).ravel()[0])


# --------------------------------------------------------------------------------------------
# Deterministic discrete sampling
# --------------------------------------------------------------------------------------------
class DiscreteSampler:
    """A discrete distribution over ``n`` entries: cumulative sums on the host, search on the
    device.

    The cumulative sums are formed in float64 with NumPy and rounded to float32 once, so the
    table (and every sample drawn from it) is the same on every backend and in every process;
    :meth:`sample_reuse` matches Mitsuba's ``DiscreteDistribution.sample_reuse_pmf``.

    Parameters
    ----------
    weights : array_like
        (n,) non-negative weights (not all 0) [-]; normalised here.

    Attributes
    ----------
    pmf : numpy.ndarray
        (n,) probabilities (float64).
    cdf : mi.Float
        (n,) inclusive cumulative probabilities on the device (the last is 1).
    """

    #: its arrays are inputs of a frozen function that reaches it (dr.freeze)
    DRJIT_STRUCT = {"cdf": mi.Float, "pmf_dr": mi.Float}

    def __init__(self, weights):
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if w.size == 0 or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ValueError("DiscreteSampler: weights must be finite, >= 0 and not all 0 "
                             f"(got {w.size} values, sum {w.sum() if w.size else 0.0})")
        self.n = int(w.size)
        self.pmf = w / w.sum()
        c = np.cumsum(self.pmf)
        # 1 from the last entry with a weight on: entries of weight 0 are never drawn
        c[int(np.flatnonzero(self.pmf > 0)[-1]):] = 1.0
        self.cdf = host_array(mi.Float, c)
        self.pmf_dr = host_array(mi.Float, self.pmf)
        dr.eval(self.cdf, self.pmf_dr)

    def sample(self, u, active=True):
        """Entries drawn with probability pmf[i] from uniform numbers ``u``.

        Parameters
        ----------
        u : mi.Float
            Uniform samples in [0, 1).
        active : mi.Bool or bool
            Active lanes.

        Returns
        -------
        mi.UInt32
            The entry of each sample (the first i with u < cdf[i]).
        """
        cdf, n = self.cdf, self.n
        idx = dr.binary_search(0, n - 1,
                               lambda i: dr.gather(mi.Float, cdf, i, active) <= u)
        return dr.minimum(mi.UInt32(idx), n - 1)

    def sample_reuse(self, u, active=True):
        """An entry, the sample re-scaled to [0, 1) within it, and the entry's probability.

        Parameters
        ----------
        u : mi.Float
            Uniform samples in [0, 1).
        active : mi.Bool or bool
            Active lanes.

        Returns
        -------
        idx : mi.UInt32
            The entry.
        u_reused : mi.Float
            (u - cdf[idx - 1]) / pmf[idx], in [0, 1).
        pmf : mi.Float
            pmf[idx] [-].
        """
        idx = self.sample(u, active)
        hi = dr.gather(mi.Float, self.cdf, idx, active)
        p = dr.gather(mi.Float, self.pmf_dr, idx, active)
        lo = hi - p
        ur = dr.clip((u - lo) / dr.maximum(p, 1e-30), 0.0, float(np.nextafter(np.float32(1),
                                                                              np.float32(0))))
        return idx, ur, p


# --------------------------------------------------------------------------------------------
# Deterministic sums over segments
# --------------------------------------------------------------------------------------------
_FIX_TOTAL = float(2 ** 62)   # the largest sum a fixed-point column may reach


class Tally:
    """Sums of many quantities over segments, exact and repeatable on every backend, in one
    kernel per array width (two for a column without a bound) plus one read-back for all.

    Each quantity ``x`` (width n) is summed per segment ``s`` (a UInt32 per lane, or one
    segment for all). Float sums are 64-bit fixed-point integer atomics: each lane adds
    ``round(|x| * scale)`` with ``scale = 2^62 / (n b)``, ``b`` a bound on the column's values:
    no sum can exceed 2^62, integer addition is associative, so the result does not depend on
    the order of the atomics (a float ``scatter_add`` does, and Dr.Jit's CUDA float prefix sums
    do too). ``b`` is the ``bound`` given with the column (a host number: the scale is known
    before the kernel, which sums and checks in one pass) or else the column's largest value,
    found by a first kernel (an integer ``max`` of the float bits, which order like the values
    for x >= 0). A lane above its bound is not added; the column is then summed again with its
    largest value (two kernels more), so a bound only needs to hold in practice. The relative
    resolution of a sum is n b / 2^62 / sum (below 1e-10 for a million values whose sum is not
    1e-8 of n b). Signed quantities (``signed=True``) are summed as their positive and
    negative parts; counts (:meth:`count`) are exact integers.

    A column holding NaN or infinity sums to NaN; a negative value in an unsigned column too.

    Usage::

        t = Tally()
        t.add("S", S * area, mask=living, bound=1e5)      # one segment, |S area| <= 1e5
        t.add("par", par * area, segments=tree_of, n_segments=5)
        t.count("alive", pop.state == 2, segments=pop.species, n_segments=3)
        sums = t.evaluate()                               # {name: numpy (n_segments,)}

    Parameters
    ----------
    reuse : dict, optional
        A store of accumulators by size that the caller keeps from call to call (the same
        columns every day): the sums then start from an accumulator zeroed by the last
        evaluation's kernel (:class:`Counters`), not from a memset.
    """

    def __init__(self, reuse: dict | None = None):
        # (name, kind, values, segments, n_segments, mask, bound); kind "sum" or "count"
        self._cols: list[tuple] = []
        self._names: list[tuple[str, bool]] = []
        # the caller's store of accumulators by size (a daily record sums the same columns
        # every day: its accumulator is zeroed by the last evaluation's kernel, no memset)
        self._reuse = reuse

    def _check(self, name):
        if name in {n for n, _ in self._names}:
            raise ValueError(f"Tally: '{name}' added twice")

    def add(self, name: str, x, segments=None, n_segments: int = 1, mask=None,
            signed: bool = False, bound: float | None = None) -> None:
        """Queue the sum of ``x`` per segment.

        Parameters
        ----------
        name : str
            Key of the result.
        x : drjit float array
            Values (width n); non-negative unless ``signed``.
        segments : mi.UInt32, optional
            Segment of each lane, 0 .. n_segments - 1 (default: all in segment 0); lanes with
            a segment >= n_segments are skipped.
        n_segments : int
            Number of segments.
        mask : mi.Bool, optional
            Lanes that count (default: all).
        signed : bool
            ``x`` may be negative (summed as two non-negative parts).
        bound : float, optional
            A bound on ``|x|`` (> 0, finite): the column is summed in one kernel with the
            scale it gives (a lane above it makes the column be summed again, exactly, with
            its largest value). Without it a first kernel finds the largest value.
        """
        self._check(name)
        if bound is not None and not (math.isfinite(bound) and bound > 0):
            raise ValueError(f"Tally: bound of '{name}' is {bound!r}; it must be a positive "
                             "finite number (or None: the largest value is found first)")
        b = None if bound is None else float(bound)
        self._names.append((name, signed))
        if signed:
            # NaN in x: both parts lose it in max(); keep it in the positive part
            self._cols.append((name, "sum", dr.select(dr.isnan(x), x, dr.maximum(x, 0.0)),
                               segments, int(n_segments), mask, b))
            self._cols.append((name + "\0neg", "sum", dr.maximum(-x, 0.0), segments,
                               int(n_segments), mask, b))
        else:
            self._cols.append((name, "sum", x, segments, int(n_segments), mask, b))

    def count(self, name: str, x, segments=None, n_segments: int = 1, mask=None) -> None:
        """Queue an exact integer sum per segment.

        Parameters
        ----------
        name : str
            Key of the result.
        x : mi.Bool or mi.UInt32
            A mask (counts 1 where True) or non-negative integers (width n).
        segments : mi.UInt32, optional
            Segment of each lane (default: all in segment 0).
        n_segments : int
            Number of segments.
        mask : mi.Bool, optional
            Lanes that count (default: all).
        """
        self._check(name)
        self._names.append((name, False))
        self._cols.append((name, "count", x, segments, int(n_segments), mask, None))

    def evaluate(self) -> dict:
        """Compute every queued sum (a kernel per width, two where a column has no bound; one
        read-back).

        Returns
        -------
        dict
            ``{name: numpy.ndarray (n_segments,) float64}`` (counts are exact integers in
            float64; NaN for a float column that held NaN, infinity or, unsigned, a negative
            value).
        """
        if not self._cols:
            return {}
        cols, self._cols = self._cols, []
        raw = self._sums(cols)
        # columns with a lane above their bound: summed again with their largest value
        again = [i for i, c in enumerate(cols) if c[6] is not None and raw[i] is None]
        if again:
            redo = self._sums([cols[i][:6] + (None,) for i in again])
            for j, i in enumerate(again):
                raw[i] = redo[j]
        by_name = {c[0]: raw[i] for i, c in enumerate(cols)}
        out = {}
        for name, signed in self._names:
            out[name] = by_name[name] - by_name[name + "\0neg"] if signed else by_name[name]
        self._names = []
        return out

    def _sums(self, cols: list) -> list:
        """The sums of ``cols`` (one numpy array each; None for a bounded column with a lane
        above its bound)."""
        k_all = len(cols)
        unbounded = [i for i, c in enumerate(cols) if c[1] == "sum" and c[6] is None]
        top_bad = None
        if unbounded:
            # 1. per unbounded column: the largest value (bits of non-negative floats order
            #    like the values), and whether any value is negative, NaN or infinite
            #    (one array for both: one memset)
            top_bad = dr.zeros(mi.UInt32, 2 * k_all)
            for i in unbounded:
                _, _, x, seg, n_seg, mask, _ = cols[i]
                xf = mi.Float(x)
                xf = dr.select(xf == 0.0, 0.0, xf)  # -0.0 has the largest bit pattern
                m = self._lanes(x, seg, n_seg, mask)
                ok = (xf >= 0.0) & dr.isfinite(xf)  # False for NaN
                dr.scatter_reduce(dr.ReduceOp.Max, top_bad, dr.reinterpret_array(mi.UInt32, xf),
                                  mi.UInt32(i), m & ok, mode=dr.ReduceMode.Local)
                dr.scatter_reduce(dr.ReduceOp.Max, top_bad, mi.UInt32(1), mi.UInt32(k_all + i),
                                  m & ~ok, mode=dr.ReduceMode.Local)
            dr.eval(top_bad)
        # 2. fixed-point sums, and per bounded column two flag rows (a lane that is negative,
        #    NaN or infinite; a lane above the bound), in one array: one memset
        offsets, n_rows = [], 0
        for c in cols:
            offsets.append(n_rows)
            n_rows += c[4]
        flag_of, n_flags = {}, 0
        for i, c in enumerate(cols):
            if c[1] == "sum" and c[6] is not None:
                flag_of[i] = n_rows + n_flags
                n_flags += 2
        if self._reuse is None:
            acc = dr.zeros(mi.UInt64, n_rows + n_flags)
        else:
            pool = self._reuse.get(n_rows + n_flags)
            if pool is None:
                if len(self._reuse) >= 8:
                    self._reuse.pop(next(iter(self._reuse)))
                pool = self._reuse[n_rows + n_flags] = Counters(n_rows + n_flags, mi.UInt64)
            acc = pool.next(max(dr.width(c[2]) for c in cols))
        # the bounded columns' bounds and scales as kernel inputs, not literals (the same
        # kernels for every run and width; the array is kept while the numbers repeat)
        consts, at = [], {}
        for i, c in enumerate(cols):
            if i in flag_of:
                at[i] = len(consts)
                consts += [c[6], _FIX_TOTAL / (c[6] * dr.width(c[2]))]
        if consts:
            d_consts = self._constants(consts)
        for i, (_, kind, x, seg, n_seg, mask, bound) in enumerate(cols):
            n = dr.width(x)
            m = self._lanes(x, seg, n_seg, mask)
            s = dr.zeros(mi.UInt32, n) if seg is None else mi.UInt32(seg)
            if kind == "count":
                q = mi.UInt64(mi.UInt32(x)) if dr.is_mask_v(x) or not dr.is_float_v(x) \
                    else mi.UInt64(x)
            elif bound is None:
                # (an opaque index: a literal one would make Dr.Jit copy the value at once)
                xmax = mi.Float64(dr.reinterpret_array(
                    mi.Float, dr.gather(mi.UInt32, top_bad, zero_index() + i)))
                scale = dr.select(xmax > 0, _FIX_TOTAL / (xmax * n), 0.0)
                q = mi.UInt64(dr.round(dr.maximum(mi.Float64(x), 0.0) * scale))
            else:
                xf = mi.Float64(x)
                ok = (xf >= 0.0) & dr.isfinite(xf)  # False for NaN
                b = dr.gather(mi.Float64, d_consts, zero_index() + at[i])
                over = ok & (xf > b)
                one = mi.UInt64(1)
                dr.scatter_add(acc, one, mi.UInt32(flag_of[i]), m & ~ok,
                               mode=dr.ReduceMode.Local)
                dr.scatter_add(acc, one, mi.UInt32(flag_of[i] + 1), m & over,
                               mode=dr.ReduceMode.Local)
                m = m & ok & ~over
                scale = dr.gather(mi.Float64, d_consts, zero_index() + (at[i] + 1))
                q = mi.UInt64(dr.round(dr.maximum(xf, 0.0) * scale))
            dr.scatter_add(acc, q, s + offsets[i], m, mode=dr.ReduceMode.Local)
        dr.eval(acc)
        a_u = np.asarray(acc)
        a = a_u[:n_rows].astype(np.float64)
        if top_bad is not None:
            tb = np.asarray(top_bad)
            tops = tb[:k_all].view(np.float32).astype(np.float64)
        out = []
        for i, (_, kind, x, _, n_seg, _, bound) in enumerate(cols):
            v = a[offsets[i]:offsets[i] + n_seg]
            if kind == "count":
                out.append(v)
            elif bound is None:
                # the unit of column i: the inverse of the kernel's scale
                unit = tops[i] * dr.width(x) / _FIX_TOTAL if tops[i] > 0 else 0.0
                out.append(np.full(n_seg, np.nan) if tb[k_all + i] else v * unit)
            elif a_u[flag_of[i]]:
                out.append(np.full(n_seg, np.nan))
            elif a_u[flag_of[i] + 1]:
                out.append(None)
            else:
                out.append(v * (bound * dr.width(x) / _FIX_TOTAL))
        return out

    _CONSTANTS: dict = {}

    @classmethod
    def _constants(cls, values: list):
        """An evaluated Float64 array of ``values``, kept for the next calls with the same
        values (a day's record repeats its bounds: no host copy a day)."""
        key = (mi.variant(), tuple(values))
        arr = cls._CONSTANTS.get(key)
        if arr is None:
            if len(cls._CONSTANTS) >= 16:
                cls._CONSTANTS.pop(next(iter(cls._CONSTANTS)))
            arr = cls._CONSTANTS[key] = host_array(mi.Float64, values)
        return arr

    @staticmethod
    def _lanes(x, seg, n_seg, mask):
        n = dr.width(x)
        m = dr.full(mi.Bool, True, n) if mask is None else (mi.Bool(mask) &
                                                           dr.full(mi.Bool, True, n))
        if seg is not None:
            m &= mi.UInt32(seg) < n_seg
        return m
