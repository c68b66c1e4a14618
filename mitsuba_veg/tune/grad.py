"""Gradients of a loss of the relaxed model's run w.r.t. named parameters, through many days.

:func:`value_and_grad` back-propagates a loss of the final state through every day with Dr.Jit
AD. Two modes:

- ``mode="adjoint"`` (default): a *day-by-day* reverse pass with checkpoints. The forward pass
  runs without AD and keeps the state every ``checkpoint_every`` days; the reverse pass takes the
  segments last-first, re-runs a segment without AD to get its daily states, and then, for each
  day from the last, re-runs that one day with AD from its stored start state and back-propagates
  ``sum_k <state_out_k, adjoint_k>`` (a scalar whose gradient is exactly the vector-Jacobian
  product), which gives the adjoint of the day's start state and adds the day's share to the
  parameter gradients. Memory: days / K + K states and one day's AD graph; time: about two
  forward passes plus the per-day backward passes. Every day's backward kernels have the same
  shape, so Dr.Jit compiles them once and reuses them (cache hits).
- ``mode="graph"``: one AD graph over all days and one ``dr.backward``. Simple, but its memory
  grows with the days and its backward kernels are fused differently for every run length
  (a new LLVM compilation for most of them): on the moss garden 15 days took 20-50 s against
  0.2-0.8 s for the adjoint mode (docs/tuning.md).

The light (photon replays, differentiable w.r.t. albedo and emitter strengths) is computed once
and enters every day as a leaf; its accumulated gradient is back-propagated into the albedo and
strength parameters at the end.

:func:`finite_difference` gives central differences of the same loss for checks.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from .smooth import RunResult, SmoothMossModel

__all__ = ["value_and_grad", "finite_difference", "GradResult", "loss_value"]


@dataclass
class GradResult:
    """A loss and its gradient through many days (:func:`value_and_grad`).

    Attributes
    ----------
    loss : float
        The loss.
    grad : dict
        d loss / d value, by parameter name.
    seconds : float
        Wall time [s].
    stats : dict
        Timings and counts (checkpoints, days).
    result : RunResult or None
        The forward run.
    """

    loss: float
    grad: dict                  # name -> d loss / d value
    seconds: float = 0.0
    stats: dict = field(default_factory=dict)
    result: RunResult | None = None


def _leaves(params: dict, T) -> dict:
    out = {}
    for k, v in params.items():
        x = T(float(v))
        dr.make_opaque(x)
        dr.enable_grad(x)
        out[k] = x
    return out


def _scalar(x) -> float:
    return float(np.asarray(dr.detach(x)).ravel()[0])


def _opaque_adjoint(arrays) -> list:
    """The gradients of ``arrays``, each a distinct evaluated array of full width.

    A state array that did not influence the loss gets a *literal* zero gradient; fed into the
    next (earlier) day as a constant it would change that day's kernels, and which slots are
    zero moves with the shift registers: a new compilation every day. Materialised, every day's
    reverse kernels are the same.
    """
    out = []
    for a in arrays:
        g = dr.grad(a)
        if dr.width(g) != dr.width(a):
            g = g + dr.zeros(type(a), dr.width(a))
        out.append(g)
    dr.make_opaque(out)
    return out


def loss_value(model: SmoothMossModel, params: dict, loss_fn, days: int | None = None) -> float:
    """The loss without gradients (for finite differences and line searches).

    Parameters
    ----------
    model : SmoothMossModel
        The relaxed model.
    params : dict
        ``{name: value}``.
    loss_fn : callable
        ``loss_fn(result: RunResult, model)`` -> width-1 Dr.Jit float.
    days : int, optional
        Days to run [d] (default: the model's).

    Returns
    -------
    float
        The loss.
    """
    with dr.suspend_grad():
        out = model.run({k: float(v) for k, v in params.items()}, days=days)
        return _scalar(loss_fn(out, model))


def value_and_grad(model: SmoothMossModel, params: dict, loss_fn, days: int | None = None,
                   checkpoint_every: int | None = None, mode: str = "adjoint") -> GradResult:
    """Loss and its gradient w.r.t. every entry of ``params``.

    Parameters
    ----------
    model : SmoothMossModel
        The relaxed model.
    params : dict
        ``{name: value}`` of the parameters to differentiate.
    loss_fn : callable
        ``loss_fn(result: RunResult, model)`` -> width-1 Float64, differentiable in
        ``result.cover``, ``result.moss_density`` and ``result.state`` (the final state;
        ``result.history`` is empty).
    days : int, optional
        Days to run [d] (default: the model's).
    checkpoint_every : int, optional
        Days between stored states in the adjoint mode (default sqrt(days)).
    mode : {"adjoint", "graph"}
        Day-by-day reverse pass with checkpoints, or one AD graph over all days (module
        docstring).

    Returns
    -------
    GradResult
        The loss, ``{name: d loss / d value}``, time, memory statistics and the forward
        result.
    """
    t0 = time.perf_counter()
    leaves = _leaves(params, model.T)
    days = model.days if days is None else int(days)
    if mode == "graph":
        out = model.run(leaves, days=days)
        loss = loss_fn(out, model)
        dr.sync_thread()   # the forward's launched kernels in its time (the rest stays lazy)
        t1 = time.perf_counter()
        dr.backward(loss)
        g = {k: _scalar(dr.grad(v)) for k, v in leaves.items()}
        return GradResult(_scalar(loss), g, time.perf_counter() - t0,
                          {"mode": "graph", "forward_s": t1 - t0,
                           "backward_s": time.perf_counter() - t1}, out)
    if mode != "adjoint":
        raise ValueError(f"mode must be 'adjoint' or 'graph', not {mode!r}")

    K = int(checkpoint_every) if checkpoint_every else max(int(round(days ** 0.5)), 1)
    P = model.resolve(leaves)
    sun_ad, sky_ad = model.light(P)
    # the light enters every day as a leaf; its gradient accumulates over the days
    sun_l = [dr.detach(f) for f in sun_ad]
    sky_l = dr.detach(sky_ad)
    for f_ad, f in zip(list(sun_ad) + [sky_ad], sun_l + [sky_l]):
        if dr.grad_enabled(f_ad):  # only when albedo or emitter strengths are parameters
            dr.enable_grad(f)
    light = (sun_l, sky_l)

    t1 = time.perf_counter()
    checkpoints = []
    with dr.suspend_grad():
        Pf = model.resolve(params)
        st = model.initial_state()
        while st.day < days:
            if (st.day % K) == 0:
                checkpoints.append(st.detached())
            st = model.step(st, Pf, light)
        final = st.detached()
    dr.sync_thread()       # the days' kernels run on Dr.Jit's threads after their launch
    t_fwd = time.perf_counter() - t1

    arrays = final.arrays()
    for a in arrays:
        dr.enable_grad(a)
    fin = final.with_arrays(arrays)
    out = RunResult(fin, model.cover(fin), model.moss_density(fin))
    loss = loss_fn(out, model)
    dr.backward(loss)
    adj = _opaque_adjoint(arrays)
    loss_v = _scalar(loss)

    t2 = time.perf_counter()
    peak_states = 0
    for cp in reversed(checkpoints):
        end = min(cp.day + K, days)
        states = [cp]
        with dr.suspend_grad():
            s = cp
            while s.day < end - 1:
                s = model.step(s, Pf, light).detached()
                states.append(s)
        peak_states = max(peak_states, len(states))
        for sd in reversed(states):
            arr_in = [dr.detach(a) for a in sd.arrays()]
            for a in arr_in:
                dr.enable_grad(a)
            s_out = model.step(sd.with_arrays(arr_in), model.resolve(leaves), light)
            sur = None
            for a, g in zip(s_out.arrays(), adj):
                if dr.grad_enabled(a):
                    term = dr.sum(a * g)
                    sur = term if sur is None else sur + term
            if sur is not None:
                dr.backward(sur)
            adj = _opaque_adjoint(arr_in)
            # evaluate the accumulated gradients of the leaves too: left lazy they grow into
            # an expression over all days (huge, ever-different kernels)
            dr.eval([dr.grad(v) for v in leaves.values()],
                    [dr.grad(f) for f in sun_l + [sky_l] if dr.grad_enabled(f)])
        del states
    # back into the light's own parameters (albedo, strengths)
    sur = None
    for f_ad, f_l in zip(list(sun_ad) + [sky_ad], sun_l + [sky_l]):
        if dr.grad_enabled(f_ad) and dr.grad_enabled(f_l):
            term = dr.sum(f_ad * dr.grad(f_l))
            sur = term if sur is None else sur + term
    if sur is not None:
        dr.backward(sur)
    g = {k: _scalar(dr.grad(v)) for k, v in leaves.items()}
    state_bytes = final.nbytes()
    stats = {"mode": "adjoint", "checkpoint_every": K, "checkpoints": len(checkpoints),
             "forward_s": t_fwd, "backward_s": time.perf_counter() - t2,
             "state_bytes": state_bytes,
             "stored_state_bytes": state_bytes * (len(checkpoints) + peak_states)}
    return GradResult(loss_v, g, time.perf_counter() - t0, stats, out)


def finite_difference(model: SmoothMossModel, params: dict, loss_fn, name: str, h: float,
                      days: int | None = None) -> float:
    """Central difference ``(L(p + h) - L(p - h)) / 2h`` of the loss in parameter ``name``.

    Parameters
    ----------
    model : SmoothMossModel
        The relaxed model.
    params : dict
        ``{name: value}`` at which to differentiate.
    loss_fn : callable
        ``loss_fn(result: RunResult, model)`` -> width-1 Dr.Jit float.
    name : str
        The parameter.
    h : float
        Half step, in the parameter's unit.
    days : int, optional
        Days to run [d] (default: the model's).

    Returns
    -------
    float
        The difference quotient (loss per unit of the parameter).
    """
    up = dict(params)
    dn = dict(params)
    up[name] = float(params[name]) + h
    dn[name] = float(params[name]) - h
    return (loss_value(model, up, loss_fn, days) - loss_value(model, dn, loss_fn, days)) / (2 * h)
