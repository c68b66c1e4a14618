"""Checkpoints of a run: the whole state in one ``checkpoint.npz`` (written atomically),
resumed only by a run of the same scenario. A killed run resumes from the last checkpoint and
reproduces the uninterrupted run exactly.

The state is read back from the device only here, every ``checkpoint_every`` days: the soil
water, the moss population (the spot grid is rebuilt from it), the leaves' phenology and the
canopy's blades, the sensor readings so far, the history and the timings; in a world whose
trees grow from their light, the year's leaf-light sums, the growth log and the growth trees
as they are now (a resumed run rebuilds its light scene with them).
"""
from __future__ import annotations

import json
import zipfile
from collections import Counter

import mitsuba as mi
import numpy as np

from ..arrays import host_array
from ..errors import ParameterError
from ..inputs import check_resume, input_hashes
from ..light import sensors as sensors_mod
from ..outputs import atomic_write
from ..parallel import map_on_cores
from ..world.trees import age_tree, tree_from_state, tree_state, with_alive


__all__ = ["fingerprint", "save", "load"]

def fingerprint(sim) -> str:
    """What must match for a checkpoint to be resumed: the settings of the run and the
    content of every file it reads (:func:`mitsuba_veg.inputs.input_hashes`).

    Parameters
    ----------
    sim : Simulation
        The run.

    Returns
    -------
    str
        A JSON string of the scenario (but its ``simulation`` section), the start date and
        the input files' hashes.
    """
    keep = {k: v for k, v in sim.scn.data.items() if k != "simulation"}
    return json.dumps({"scenario": keep, "start": sim.start.isoformat(),
                       "inputs": input_hashes(sim.scn)}, sort_keys=True, default=str)


def save(sim) -> None:
    """Write the whole state of ``sim`` atomically to its ``checkpoint.npz``.

    Parameters
    ----------
    sim : Simulation
        The run (set up).
    """
    st = sim.state
    d = st.moss.pop.to_numpy()
    if st.year is not None:
        d.update(st.year.to_numpy())
        for i in sim.pipeline.growth.trees:
            d.update(tree_state(sim.site.trees[i], f"growth_trees/{i}"))
        for i in sim.pipeline.growth.adapting:   # paper 002's dead subtrees so far
            d[f"adapted_trees/{i}"] = np.asarray(sim.site.trees[i].tree.alive, bool)
        d["growth_log"] = np.array(json.dumps(st.growth_log))
        d["floor_log"] = np.array(json.dumps(st.floor_log))
    if st.leaves is not None:
        d.update(st.leaves.to_numpy())
        d.update(sim.site.canopy.state())
    if sim.sensors is not None:
        n = len(sim.sensors)
        d["sensor_days"] = (np.stack(st.sensor_days) if st.sensor_days else
                            np.zeros((0, n, len(sensors_mod.QUANTITIES),
                                      len(sensors_mod.COMPONENTS))))
    d.update({"day": np.array(st.day), "O": np.asarray(st.O, np.float64),
              "history": np.array(json.dumps(st.history)),
              "timings": np.array(json.dumps(sim.timings)),
              "fingerprint": np.array(fingerprint(sim))})
    with atomic_write(sim.checkpoint_path, sim.out / "checkpoint.tmp.npz") as tmp:
        np.savez_compressed(tmp, **d)


def load(sim) -> bool:
    """Resume ``sim`` (set up) from its checkpoint if there is one.

    Parameters
    ----------
    sim : Simulation
        The run.

    Returns
    -------
    bool
        Whether a checkpoint was loaded.

    Raises
    ------
    ParameterError
        The checkpoint cannot be read, belongs to another scenario, or holds more days than
        this run has.
    """
    p = sim.checkpoint_path
    if not p.exists():
        return False
    try:
        d = dict(np.load(p, allow_pickle=False))
        fp, day = str(d["fingerprint"]), int(d["day"])
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
        raise ParameterError("checkpoint", str(p), "a complete checkpoint written by "
                             "mitsuba-veg run", f"it cannot be read ({type(e).__name__}); "
                             "run again with --fresh to start over") from None
    check_resume(fp, fingerprint(sim), p)  # names the field or file that changed
    growth_log = json.loads(str(d["growth_log"])) if "growth_log" in d else []
    if growth_log and sim.pipeline.growth is not None:
        # the trees grew before the checkpoint: the light scene of the trees as they are now
        trees = list(sim.site.trees)
        try:
            for i in sim.pipeline.growth.trees:
                trees[i] = tree_from_state(d, f"growth_trees/{i}")
            adapting, ageing = set(sim.pipeline.growth.adapting), set(sim.pipeline.growth.ageing)
            # (read before the threads: a missing entry raises here)
            alive = {i: d[f"adapted_trees/{i}"] for i in sorted(adapting)}
            # the years each Weber-Penn tree aged: its rows of the log, counted once
            aged = Counter(r.get("tree") for r in growth_log
                           if r.get("model") == "weber_penn" and "age" in r)

            def wp_tree(i):      # one Weber-Penn tree as it is now (on the machine's cores)
                t = trees[i]
                if i in adapting:                   # without the subtrees that died
                    t = with_alive(t, alive[i])
                if i in ageing and aged[t.name]:    # as many years older as it aged
                    t = age_tree(t, aged[t.name])
                return t

            wp_idx = sorted(adapting | ageing)
            for i, t in zip(wp_idx, map_on_cores(wp_tree, wp_idx)):
                trees[i] = t
        except (KeyError, ValueError) as e:
            raise ParameterError("checkpoint", str(p), "a checkpoint of the same world",
                                 f"use --fresh ({e})") from None
        sim._rebuild(trees)
    if day > sim.days:
        raise ParameterError("--days", sim.days, f">= {day}: the checkpoint in "
                             f"{sim.out} already holds day {day}",
                             f"pass --days {day} or more to resume, or --fresh to start "
                             "over with fewer days")
    st = sim.state
    try:
        st.moss.pop.load_numpy(d)
        if st.leaves is not None:
            st.leaves.load_numpy(d)
            sim.site.canopy.load_state(d, sim.pipeline.scene_params)
        if sim.sensors is not None:
            st.sensor_days = list(np.asarray(d["sensor_days"]))
        if st.year is not None:
            st.year.load_numpy(d)
            st.growth_log = growth_log
            st.floor_log = json.loads(str(d["floor_log"])) if "floor_log" in d else []
        O = np.asarray(d["O"], np.float64)
        if O.shape != (sim.site.n_terrain,):
            raise ValueError(f"O: {O.shape} != ({sim.site.n_terrain},)")
    except (KeyError, ValueError) as e:
        raise ParameterError("checkpoint", str(p), "a checkpoint of the same world",
                             f"use --fresh ({e})") from None
    st.moss.grid.rebuild(st.moss.pop.pos, st.moss.pop.state)
    st.day = day
    st.O = host_array(mi.Float64, O)
    st.history = json.loads(str(d["history"]))
    sim.timings.update(json.loads(str(d["timings"])))
    return True
