"""A day of a run as glTF binary (.glb): terrain coloured by its moss cover, the trees as they
stood that day (wood, and the leaves on the tree in their autumn stage's colour).

:func:`export_day` reads a run folder (``mitsuba-veg run``): its scenario's meshes, the moss
per terrain triangle from the day's snapshot (``moss_counts``; cover = min(count x moss size² /
triangle area, 1), paper 000's covered area), the trees of that day
(:func:`mitsuba_veg.render.world.world_trees`: grown ones from ``trees/<year>.npz``) in the
snapshot's leaf state, and writes them with :class:`mitsuba_veg.export_gltf.GltfWorld` (linear
sRGB vertex colours; leaves by the stage's PROSPECT-D colour). ``mitsuba-veg export-gltf`` is
its command.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ParameterError, check_range
from ..foliage.pigments import N_STAGES
from ..outputs import OutputFolder
from ..meshes import triangle_geometry
from ..trees.structure import leaf_quads
from .history import _read_snapshot, load_run
from .world import WorldLeaves, world_trees

__all__ = ["BARK_RGB", "export_day"]

#: colour of the wood (linear sRGB)
BARK_RGB = (0.12, 0.08, 0.05)


def _terrain(run, counts):
    """[(id, vertices, faces, cover per face)] of the scenario's meshes, in the run's order."""
    scene = run.scenario.load_scene(daylight=False)
    out, start = [], 0
    cell2 = float(run.moss_size) ** 2
    for sh in scene.shapes():
        if not (sh.is_mesh() and sh.face_count() > 0):
            continue
        v = np.asarray(sh.vertex_positions_buffer(), float).reshape(-1, 3)
        f = np.asarray(sh.faces_buffer(), np.int64).reshape(-1, 3)
        area = triangle_geometry(v, f)[0]
        c = np.zeros(len(f))
        if counts is not None and start + len(f) <= len(counts):
            c = np.minimum(counts[start:start + len(f)] * cell2 / np.maximum(area, 1e-30), 1.0)
        out.append((sh.id(), v, f, c))
        start += len(f)
    return out


def export_day(run_dir, day: int | None = None, path=None, scenario=None) -> dict:
    """Write a run's day as ``.glb`` (module docstring).

    Parameters
    ----------
    run_dir : path-like
        A run folder.
    day : int, optional
        Simulated day (1-based); default the last with a snapshot.
    path : path-like, optional
        The ``.glb`` file, which must not exist yet (default ``RUN_DIR/gltf/day_NNNN.glb``:
        a folder claimed and marked as a ``gltf`` result, where a later export of the day
        replaces the earlier one).
    scenario : path-like, optional
        The run's scenario (default: the one its summary names).

    Returns
    -------
    dict
        ``path``, ``day``, ``date``, the meshes written and their triangles, the moss cover
        [m2] and the leaves on the trees.

    Raises
    ------
    ParameterError
        Without a snapshot on or before ``day`` (the moss and leaves of a day come from
        snapshots: run with frames), for a day outside the run, or if ``path`` exists.
    """
    run = load_run(run_dir, scenario)
    last = run.snapshots[-1][0] if run.snapshots else 0
    if not last:
        raise ParameterError("RUN_DIR", str(run_dir), "a run with snapshots (frames)",
                             "run it again without --no-frames to write them")
    day = last if day is None else int(day)
    check_range("day", day, 1, last, fix=f"a day of the run's snapshots (1-{last})")
    snap = [p for d, p in run.snapshots if d <= day]
    if not snap:
        raise ParameterError("day", day, f">= {run.snapshots[0][0]} (the first snapshot)")
    z = _read_snapshot(snap[-1])
    counts = np.asarray(z["moss_counts"], float) if "moss_counts" in z else None
    date = run.date(day)
    from ..export_gltf import GltfWorld     # (trimesh: imported only for an export)

    w = GltfWorld()
    info = {"day": day, "date": date.isoformat(), "meshes": [], "moss_cover_m2": 0.0,
            "leaves_on_trees": 0}
    for sid, v, f, cover in _terrain(run, counts):
        w.add_terrain(sid, v, f, cover)
        info["meshes"].append({"name": sid, "triangles": int(len(f))})
        info["moss_cover_m2"] += float((cover * triangle_geometry(v, f)[0]).sum())
    trees, offsets = world_trees(run, day)
    if trees:
        WorldLeaves(run, trees, offsets).apply(date)
    for k, t in enumerate(trees):
        name = t.name if t.name not in {m["name"] for m in info["meshes"]} else f"tree{k}"
        bark = t.to_mesh(leaves=False)
        bv, bf = (bark if isinstance(bark, tuple) else (bark.vertices, bark.faces))
        w.add_mesh(f"{name}.wood", np.asarray(bv, float), np.asarray(bf, np.int64),
                   colour=BARK_RGB)
        info["meshes"].append({"name": f"{name}.wood", "triangles": int(len(bf))})
        lv = t.leaves
        on = ~np.asarray(lv.attrs.get("fallen", np.zeros(len(lv), bool)), bool)
        if len(lv) and on.any():
            sel = lv.subset(on)
            tau = np.asarray(sel.attrs.get("autumn_tau", np.zeros(len(sel))), float)
            stages = 1.0 + (N_STAGES - 1) * np.clip(tau, 0.0, 1.0)
            qv, qf = leaf_quads(sel)
            w.add_leaves(f"{name}.leaves", qv, qf, stages,
                         face_leaf=np.repeat(np.arange(len(sel)), 2))
            info["meshes"].append({"name": f"{name}.leaves", "triangles": int(len(qf))})
            info["leaves_on_trees"] += int(len(sel))
    if path is None:
        # the run's own gltf/ folder, claimed and marked like a render's: a later export
        # replaces what an earlier one wrote there, never a file of the user's
        path = Path(run_dir) / "gltf" / f"day_{day:04d}.glb"
        with OutputFolder(path.parent, "gltf", info={"run": str(run.dir)}, reads=run.dir):
            info["path"] = str(w.export(path))
        return info
    path = Path(path)
    if path.exists():
        raise ParameterError("--out", str(path), "a file that does not exist yet",
                             "choose another file name, or remove this one yourself")
    path.parent.mkdir(parents=True, exist_ok=True)
    info["path"] = str(w.export(path))
    return info
