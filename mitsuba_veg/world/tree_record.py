"""The trees a world run starts with, kept in its folder: ``trees/initial.npz``.

A world run builds its ``[[trees]]`` and ``[stand]`` from the scenario when it starts (paper 001's
growth in the scene's light, Weber-Penn generation, paper 002's deformation: about a second for
the courtyard's three trees, minutes for a stand). Every later command that draws the run's
trees (``render``, ``animate``, ``hemiphoto``) needs them as the run had them. Re-growing them
costs that time again in every command, and draws different trees if the package's models
changed since the run. So the run writes them once, and readers take them from the folder
(falling back to re-growing for folders without the file).

The file holds plain arrays only (read with ``allow_pickle=False``): each tree's branch structure,
leaves and attributes as arrays, everything else as one JSON document that names the arrays.
The classes a record may hold are listed (:data:`CLASSES`); anything else is refused when the
record is written, and the run goes on without it. Wood and leaf blades are not stored: they are
rebuilt from the structure, as when the tree was built. A record larger than
:data:`MAX_BYTES` is not written (a hectare's hundreds of megabytes of leaves would cost more to
write and read than to rebuild the trees from the scenario's seeds).
"""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from ..atomic import atomic_write
from ..trees.structure import Leaves, Tree
from ..trees.weber_penn import WeberPennInfo, WeberPennParams
from .trees import WorldTree, world_tree

__all__ = ["RECORD", "FORMAT", "MAX_BYTES", "CLASSES", "write_initial_trees",
           "read_initial_trees"]

#: the file in a run folder
RECORD = "trees/initial.npz"
#: the record's format; a reader refuses (and re-grows) another
FORMAT = 1
#: the largest record written [bytes of arrays]
MAX_BYTES = 256 * 2 ** 20
#: the classes a record holds, by the name it stores
CLASSES = {"Tree": Tree, "Leaves": Leaves, "WeberPennInfo": WeberPennInfo,
           "WeberPennParams": WeberPennParams}


class _Unrecordable(TypeError):
    """A value the record cannot hold."""


def _encode(x, arrays: dict):
    """``x`` as JSON-able data; its arrays go into ``arrays`` under the names it keeps."""
    if isinstance(x, np.ndarray):
        if x.dtype == object:
            raise _Unrecordable("an object array")
        key = f"a{len(arrays)}"
        arrays[key] = x
        return {"__array__": key}
    if isinstance(x, np.generic):
        return x.item()
    if x is None or isinstance(x, (bool, int, float, str)):
        return x
    if isinstance(x, (list, tuple)):
        items = [_encode(v, arrays) for v in x]
        return items if isinstance(x, list) else {"__tuple__": items}
    if isinstance(x, dict):
        return {"__dict__": [[_encode(k, arrays), _encode(v, arrays)] for k, v in x.items()]}
    name = type(x).__name__
    if CLASSES.get(name) is type(x):
        # the instance's own attributes: a Weber-Penn tree carries ``weber_penn`` beside its
        # fields
        return {"__class__": name, "state": {k: _encode(v, arrays) for k, v in vars(x).items()}}
    raise _Unrecordable(f"a {type(x).__module__}.{name}")


def _decode(x, arrays):
    if isinstance(x, list):
        return [_decode(v, arrays) for v in x]
    if not isinstance(x, dict):
        return x
    if "__array__" in x:
        return np.asarray(arrays[x["__array__"]])
    if "__tuple__" in x:
        return tuple(_decode(v, arrays) for v in x["__tuple__"])
    if "__dict__" in x:
        return {_decode(k, arrays): _decode(v, arrays) for k, v in x["__dict__"]}
    if "__class__" in x:
        cls = CLASSES.get(x["__class__"])
        if cls is None:
            raise ValueError(f"unknown class {x['__class__']!r}")
        obj = cls.__new__(cls)
        obj.__dict__.update({k: _decode(v, arrays) for k, v in x["state"].items()})
        return obj
    raise ValueError(f"malformed record entry {sorted(x)!r}")


def _world_tree_entry(wt: WorldTree, arrays: dict) -> dict:
    entry = {"name": wt.name, "model": wt.model, "position": _encode(wt.position, arrays),
             "info": _encode(wt.info, arrays)}
    if wt.tree is not None:
        entry["tree"] = _encode(wt.tree, arrays)
    else:                           # a user's mesh: its wood and leaf triangles as they are
        entry["mesh"] = _encode((wt.bark, wt.leaf_vertices, wt.leaf_area), arrays)
    return entry


def write_initial_trees(run_dir, trees: list[WorldTree]) -> Path | None:
    """Write a world run's initial trees into its folder (:data:`RECORD`), atomically.

    Parameters
    ----------
    run_dir : path-like
        The run folder.
    trees : list of WorldTree
        The trees as the run built them.

    Returns
    -------
    pathlib.Path or None
        The file, or None where no record was written: the trees hold a value the record
        cannot (a class outside :data:`CLASSES`), or their arrays exceed :data:`MAX_BYTES`
        (logged; readers then re-grow the trees from the scenario).
    """
    arrays: dict = {}
    try:
        doc = {"format": FORMAT, "trees": [_world_tree_entry(wt, arrays) for wt in trees]}
    except _Unrecordable as e:
        logging.getLogger("mitsuba_veg").info("initial trees not recorded: they hold %s", e)
        return None
    size = sum(a.nbytes for a in arrays.values())
    if size > MAX_BYTES:
        logging.getLogger("mitsuba_veg").info(
            "initial trees not recorded: %.0f MB of arrays (the record's limit is %.0f MB); "
            "readers re-grow them from the scenario", size / 2 ** 20, MAX_BYTES / 2 ** 20)
        return None
    path = Path(run_dir) / RECORD
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, path.with_name(".initial.tmp.npz")) as tmp:
        # uncompressed: a command reads it in milliseconds (the courtyard's is ~5 MB)
        np.savez(tmp, record=np.array(json.dumps(doc)), **arrays)
    return path


def read_initial_trees(run_dir) -> list[WorldTree] | None:
    """A world run's initial trees from its folder (:func:`write_initial_trees`).

    Parameters
    ----------
    run_dir : path-like
        The run folder.

    Returns
    -------
    list of WorldTree or None
        The trees (wood and leaf blades rebuilt from their structure), or None where the folder
        has no record or one of another format (the caller re-grows them).

    Raises
    ------
    ValueError
        If the record names a class outside :data:`CLASSES` or is malformed.
    """
    path = Path(run_dir) / RECORD
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as z:
        arrays = dict(z)
    doc = json.loads(str(arrays.pop("record")))
    if doc.get("format") != FORMAT:
        return None
    out = []
    for e in doc["trees"]:
        pos = _decode(e["position"], arrays)
        info = _decode(e["info"], arrays)
        if "tree" in e:
            out.append(world_tree(e["name"], e["model"], _decode(e["tree"], arrays), pos, info))
        else:
            bark, verts, area = _decode(e["mesh"], arrays)
            out.append(WorldTree(e["name"], e["model"], pos, bark, verts, area, None, info))
    return out
