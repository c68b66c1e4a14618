"""``mitsuba-veg grow TREE.toml --out DIR``: grow a tree (or a stand) and write mesh, metrics
and a picture.

TREE.toml (all keys optional; see ``scenes/trees/*.toml`` and docs/trees.md)::

    model = "growth"            # "growth" (paper 001), "branching" (no light) or "weber_penn"
    seed = 0
    generations = 10            # G
    positions = [[0.0, 0.0, 0.0]]   # tree bases [m]; [x, z] pairs stand on the terrain
    preset = "quaking_aspen"    # model = "weber_penn": a preset name (or [weber_penn] params)

    [growth]                    # GrowthParams fields; defaults = paper 001 table 3.1
    branch_angle = 60.0
    unit = 0.25                 # [m] per model unit

    [environment]               # obstacles [m]
    ground = { size = 60.0, y = 0.0, cells = 20 }
    slope = { angle = 25.0, size = 60.0, downhill = [1.0, 0.0], cells = 20 }
    boxes = [{ lo = [-4.0, 0.0, -15.0], hi = [-3.0, 20.0, 15.0], name = "wall" }]
    meshes = [{ file = "terrain.ply", light_factor = 1.0 }]

    [nongrowth]                 # optional: then deform the trees (paper 002)
    rules = ["death", "heliotropism"]
    voxel_size = 0.5

    [output]
    formats = ["ply", "glb"]    # mesh files (all trees in one mesh): ply, obj, glb, stl
    leaves = true               # leaf blades in the mesh
    picture = true

Writes into DIR: ``tree.<fmt>``, ``metrics.json`` (per tree + stand), ``picture.png``,
``summary.json`` (settings, timings per generation, sky rays, Mitsuba ray casts (obstacle
queries, or every cast of the ``mitsuba`` engine), versions, files).
"""
from __future__ import annotations

import time
import tomllib
from pathlib import Path

import numpy as np

from ..errors import ParameterError, unknown_field
from ..outputs import OutputFolder, atomic_write, write_json
from ..scenario import apply_overrides
from ..trees.environment import Environment
from ..trees.figures import picture
from ..trees.growth import GrowthParams, base_positions, branching, grow_forest
from ..trees.nongrowth import deform
from ..backend import versions
from .args import add_out, add_quiet, add_set, ranged
from .entry import standalone

__all__ = ["load_tree_toml", "build_environment", "run_grow", "report", "add_parser", "main"]

_TOP_KEYS = {"model", "seed", "generations", "positions", "position", "preset", "growth",
             "environment", "nongrowth", "output", "weber_penn", "name", "description"}
_MODELS = ("growth", "branching", "weber_penn")
_OUTPUT_KEYS = ("formats", "leaves", "picture")


def _unknown(field, value, known, source):
    """An unknown TREE.toml field, with the closest known names."""
    return unknown_field(field, value, known, source, "docs/trees.md")


_FORMATS = ("ply", "obj", "glb", "stl")




def load_tree_toml(path, overrides=()) -> dict:
    """Read and check a TREE.toml (module docstring), with ``--set`` overrides applied.

    Checks the top-level and ``[output]`` keys, the positions (an [x, z] point needs an
    ``[environment]`` ground, slope or meshes), the model, ``generations`` (0..20), ``seed``
    (>= 0) and the mesh formats.

    Parameters
    ----------
    path : str or pathlib.Path
        The TREE.toml file.
    overrides : sequence of str, optional
        ``KEY=VALUE`` strings (dotted keys, TOML values); default none.

    Returns
    -------
    dict
        The file's data with the overrides applied.

    Raises
    ------
    ParameterError
        For a missing file, invalid TOML, an unknown key or a value out of range (naming the
        file).
    """
    path = Path(path)
    src = str(path)
    if not path.exists():
        raise ParameterError("TREE", src, "an existing .toml file", "check the path")
    try:
        # utf-8-sig: a byte-order mark (some editors write one) is not part of the TOML
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ParameterError("TREE", src, "valid TOML (UTF-8 text)", f"fix the syntax: {e}") \
            from None
    for item in overrides or ():
        top = str(item).split("=", 1)[0].strip().split(".")[0]
        if top not in _TOP_KEYS:
            raise _unknown(top, str(item).split("=", 1)[-1], _TOP_KEYS, f"{src} (--set)")
    data = apply_overrides(data, overrides, source=f"{src} (--set)")
    bad = [k for k in data if k not in _TOP_KEYS]
    if bad:
        raise _unknown(bad[0], data[bad[0]], _TOP_KEYS, src)
    oc = data.get("output", {})
    if not isinstance(oc, dict):
        raise ParameterError("output", oc, "a table with formats, leaves, picture", None, src)
    for k in oc:
        if k not in _OUTPUT_KEYS:
            raise _unknown(f"output.{k}", oc[k], {f"output.{o}" for o in _OUTPUT_KEYS}, src)
    if "positions" in data or "position" in data:
        pos = data.get("positions", [data.get("position")])
        env = data.get("environment") or {}
        flat = isinstance(pos, list) and len(pos) and isinstance(pos[0], (int, float))
        items = [pos] if flat else pos
        if not isinstance(items, list) or not items or any(
                not isinstance(it, list) or len(it) not in (2, 3) or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) for x in it)
                for it in items):
            raise ParameterError("positions", pos, "a list of [x, y, z] points, or [x, z] "
                                 "points with an [environment] ground or slope, in metres",
                                 "e.g. positions = [[0.0, 0.0, 0.0], [6.0, 0.0, 0.0]]", src)
        if any(len(it) == 2 for it in items) and not ({"ground", "slope", "meshes"} & set(env)):
            raise ParameterError("positions", pos, "[x, y, z] points (an [x, z] point stands on "
                                 "the terrain, and this file has no [environment] ground, slope "
                                 "or meshes)", "give the height: [x, y, z], or add "
                                 "[environment] ground = {}", src)
    model = data.get("model", "growth")
    if model not in _MODELS:
        raise ParameterError("model", model, f"one of {_MODELS}", source=src)
    g = data.get("generations", 10)
    if isinstance(g, bool) or not isinstance(g, int) or not 0 <= g <= 20:
        raise ParameterError("generations", g, "an integer in [0, 20]", "e.g. 10", src)
    s = data.get("seed", 0)
    if isinstance(s, bool) or not isinstance(s, int) or s < 0:
        raise ParameterError("seed", s, "an integer >= 0", source=src)
    fm = data.get("output", {}).get("formats", ["ply", "glb"])
    for f in fm if isinstance(fm, list) else [fm]:
        if f not in _FORMATS:
            raise ParameterError("output.formats", f, f"a list of {_FORMATS}", source=src)
    return data


def build_environment(cfg: dict, root: Path, source: str | None = None):
    """An Environment from an [environment] table (None when it is empty).

    Keys: ``ground`` (``size`` [m], default 60; ``y`` [m]; ``cells``), ``slope`` (``angle``
    [degrees], default 20; ``size`` [m]; ``cells``; ``downhill`` (x, z); ``y0`` [m]), ``boxes``
    (``lo``, ``hi`` [m], ``name``, ``max_edge`` [m], ``light_factor`` [-]) and ``meshes``
    (``file`` relative to the TOML, ``name``, ``light_factor`` [-], ``max_edge`` [m]).

    Parameters
    ----------
    cfg : dict
        The [environment] table.
    root : pathlib.Path
        Folder that mesh ``file`` paths are relative to (the TOML's folder).
    source : str, optional
        The TOML path, named in errors (default None).

    Returns
    -------
    mitsuba_veg.trees.environment.Environment or None
        The obstacles, or None for an empty table.

    Raises
    ------
    ParameterError
        For an unknown key, a missing value or mesh file, or a value out of range.
    """
    if not cfg:
        return None
    allowed = {"ground", "slope", "boxes", "meshes"}
    bad = [k for k in cfg if k not in allowed]
    if bad:
        raise ParameterError(f"environment.{bad[0]}", cfg[bad[0]], f"keys {sorted(allowed)}",
                             source=source)
    env = Environment()
    try:
        if "ground" in cfg:
            g = cfg["ground"] if isinstance(cfg["ground"], dict) else {}
            env.add_ground(g.get("size", 60.0), g.get("y", 0.0), g.get("cells", 20))
        if "slope" in cfg:
            s = cfg["slope"]
            env.add_slope(s.get("angle", 20.0), s.get("size", 60.0), s.get("cells", 20),
                          tuple(s.get("downhill", (1.0, 0.0))), s.get("y0", 0.0))
        for i, b in enumerate(cfg.get("boxes", [])):
            env.add_box(b["lo"], b["hi"], b.get("name", f"box{i}"), b.get("max_edge", 1.0),
                        b.get("light_factor", 1.0))
        for i, m in enumerate(cfg.get("meshes", [])):
            f = (root / m["file"]).resolve()
            if not f.exists():
                raise ParameterError(f"environment.meshes[{i}].file", m["file"],
                                     "an existing mesh file (relative to the TOML)",
                                     f"looked for {f}", source)
            import trimesh      # here: importing it costs every command most of a second

            tm = trimesh.load(f, force="mesh")
            env.add(tm, name=m.get("name", f.stem), light_factor=m.get("light_factor", 1.0),
                    max_edge=m.get("max_edge"))
    except KeyError as e:
        raise ParameterError(f"environment.{e.args[0]}", None, "a value", "add it", source) \
            from None
    except ParameterError as e:
        raise ParameterError(f"environment.{e.field}", e.value, e.allowed, e.fix, source) \
            from None
    return env


def _weber_penn(data, seed, src):
    try:
        from ..trees import weber_penn
    except ImportError as e:
        raise ParameterError("model", "weber_penn", "a model available in this installation",
                             f"mitsuba_veg.trees.weber_penn is not available ({e}); use "
                             "model = 'growth'", src) from None
    wp = dict(data.get("weber_penn", {}))
    given = [k for k in ("preset", "weber_penn.preset", "weber_penn.params")
             if (data if k == "preset" else wp).get(k.split(".")[-1]) is not None]
    if len(given) > 1:
        raise ParameterError(" and ".join(given), "all given", "one of them",
                             "name a preset or give the parameters, once", src)
    what = data.get("preset") or wp.pop("preset", None) or wp.pop("params", None) \
        or "quaking_aspen"
    # every other key of [weber_penn] (flat parameter names or sections such as [weber_penn.knots])
    # overrides the preset's value; generate() refuses unknown names
    try:
        return weber_penn.generate(what, seed=seed, overrides=wp or None)
    except ParameterError as e:
        raise ParameterError(f"weber_penn.{e.field}", e.value, e.allowed, e.fix, src) from None


def run_grow(tree_toml_path, out_dir, overrides=(), progress: bool = True) -> dict:
    """Grow what TREE.toml describes; write mesh, metrics JSON, picture and summary.json.

    Files go into ``out_dir`` (module docstring); the trees are optionally deformed by the
    ``[nongrowth]`` rules (paper 002).

    Parameters
    ----------
    tree_toml_path : str or pathlib.Path
        The TREE.toml file.
    out_dir : str or pathlib.Path
        Output folder (created; refused if another process is writing it).
    overrides : sequence of str, optional
        ``KEY=VALUE`` overrides of the file (default none).
    progress : bool, optional
        Show a progress bar over generations (default True).

    Returns
    -------
    dict
        The summary written to ``summary.json``: settings, ``history`` per generation,
        ``timings_s`` [s], ``rays``, ``ray_casts``, stand ``metrics`` (heights [m], counts),
        ``files`` and ``versions``.

    Raises
    ------
    ParameterError
        For an invalid TREE.toml or option (naming the file).
    """

    t_start = time.perf_counter()
    path = Path(tree_toml_path)
    src = str(path)
    data = load_tree_toml(path, overrides)
    out = Path(out_dir)
    folder = OutputFolder(out, "grow", info={"tree_file": src})
    model = data.get("model", "growth")
    seed = int(data.get("seed", 0))
    gens = int(data.get("generations", 10))
    positions = data.get("positions", [data.get("position", [0.0, 0.0, 0.0])])
    env = build_environment(data.get("environment", {}), path.parent, src)
    params = GrowthParams.from_dict(data.get("growth", {}), src)
    history: list = []
    t0 = time.perf_counter()
    try:
        trees = _make_trees(model, data, positions, params, gens, env, seed, src, progress,
                            history)
    except ParameterError as e:
        if e.source:
            raise
        raise ParameterError(e.field, e.value, e.allowed, e.fix, src) from None
    t_model = time.perf_counter() - t0
    ng_stats = None
    if data.get("nongrowth"):
        ng = dict(data["nongrowth"])
        try:
            res = deform(trees, env, **ng)
        except TypeError as e:
            raise ParameterError("nongrowth", sorted(ng), "arguments of "
                                 "mitsuba_veg.trees.nongrowth.deform", str(e), src) from None
        except ParameterError as e:
            raise ParameterError(f"nongrowth.{e.field}", e.value, e.allowed, e.fix, src) \
                from None
        trees, ng_stats = res.trees, res.stats
    # outputs
    oc = data.get("output", {})
    formats = oc.get("formats", ["ply", "glb"])
    files = {"mesh": []}
    mesh = _stand_mesh(trees, leaves=bool(oc.get("leaves", True)))
    for fmt in formats:
        f = out / f"tree.{fmt}"
        with atomic_write(f, out / f"tree.tmp.{fmt}") as tmp:
            mesh.export(str(tmp))
        files["mesh"].append(str(f))
    metrics = {"trees": [t.metrics() for t in trees], "stand": _stand_metrics(trees)}
    write_json(out / "metrics.json", metrics)
    files["metrics"] = str(out / "metrics.json")
    if oc.get("picture", True):
        files["picture"] = picture(trees, out / "picture.png", env=env,
                                   title=f"{path.stem}: {model}, {len(trees)} tree(s)")
    vers = versions()
    summary = {
        "command": "grow", "tree_file": src, "model": model, "seed": seed,
        "generations": gens, "positions": positions,
        "params": params.to_dict() if model != "weber_penn" else data.get("weber_penn", {}),
        "environment": data.get("environment", {}),
        "nongrowth": ng_stats, "history": history,
        "timings_s": {"model": t_model, "total": time.perf_counter() - t_start},
        "rays": int(sum(h["rays"] for h in history)),
        "ray_casts": int(sum(h["casts"] for h in history)),
        "metrics": metrics["stand"], "files": files, "versions": vers,
    }
    write_json(out / "summary.json", summary)
    files["summary"] = str(out / "summary.json")
    folder.release()
    return summary


def _make_trees(model, data, positions, params, gens, env, seed, src, progress, history):
    if model == "growth":
        return grow_forest(positions, params, gens, env, seed, progress=progress,
                           history=history)
    pos = base_positions(positions, env)
    if model == "branching":
        return [branching(params, gens, p, seed) for p in pos]
    base = _weber_penn(data, seed, src)
    return [base.translated(p - base.start[0]) if len(base) else base for p in pos]


def _stand_metrics(trees) -> dict:
    ms = [t.metrics() for t in trees]
    return {"trees": len(trees), "height_max": max(m["height"] for m in ms),
            "live_branches": sum(m["live_branches"] for m in ms),
            "dead_branches": sum(m["dead_branches"] for m in ms),
            "leaves": sum(m["leaves"] for m in ms),
            "leaf_spheres": sum(m.get("leaf_spheres", 0) for m in ms)}


def _stand_mesh(trees, leaves=True):
    parts = []
    for t in trees:
        m = t.to_mesh(leaves=leaves)
        part = m.metadata.get("part", np.zeros(len(m.faces), np.int8))
        col = np.where(part[:, None] == 1, [[46, 139, 62, 255]], [[90, 58, 26, 255]])
        m.visual.face_colors = col.astype(np.uint8)
        parts.append(m)
    import trimesh.util

    return trimesh.util.concatenate(parts) if len(parts) > 1 else parts[0]


def report(s: dict) -> None:
    """Print what run_grow did (one screen).

    Parameters
    ----------
    s : dict
        The summary returned by :func:`run_grow`.
    """
    st = s["metrics"]
    what = s["model"] if s["model"] == "weber_penn" else f"{s['model']}, G = {s['generations']}"
    print(f"grew {st['trees']} tree(s) ({what}) in "
          f"{s['timings_s']['model']:.2f} s: {st['live_branches']} live / {st['dead_branches']} "
          f"dead branches, {st['leaf_spheres']} leaf spheres, max height {st['height_max']:.2f} m")
    if s["rays"]:
        eng = sorted({h.get("engine") for h in s["history"] if h.get("engine")})
        print(f"  light: {s['rays']:,d} sky rays (sphere counting: {', '.join(eng)}), "
              f"{s['ray_casts']:,d} Mitsuba ray casts")
    print("wrote:")
    for f in s["files"]["mesh"]:
        print(f"  {f}")
    for k in ("metrics", "picture", "summary"):
        if k in s["files"]:
            print(f"  {s['files'][k]}")


def _cmd_grow(a) -> int:
    overrides = list(a.set or ())
    if a.seed is not None:
        overrides.append(f"seed={a.seed}")
    if a.generations is not None:
        overrides.append(f"generations={a.generations}")
    s = run_grow(a.tree, a.out, overrides, progress=not a.quiet)
    report(s)
    return 0


def add_parser(subparsers):
    """Add the ``grow`` command to an argparse sub-parser set (``mitsuba-veg grow``).

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command registry of the ``mitsuba-veg`` parser (``add_subparsers()``).

    Returns
    -------
    argparse.ArgumentParser
        The ``grow`` parser.
    """
    p = subparsers.add_parser("grow", help="grow trees from light (paper 001/002) or make a "
                              "Weber-Penn tree: mesh, metrics, picture")
    p.add_argument("tree", help="TREE.toml (see scenes/trees/)")
    add_out(p, "out/grow", "tree meshes, metrics.json, picture.png and summary.json")
    p.add_argument("--seed", type=ranged(int, 0, 2**31 - 1),
                   help="random seed (default: the file's seed, else 0)")
    p.add_argument("--generations", type=ranged(int, 0, 20, "generations"),
                   help="growth generations G (default: the file's, else 10)")
    add_set(p, "TREE.toml", "growth.branch_angle=45")
    add_quiet(p)
    p.set_defaults(func=_cmd_grow)
    return p


def main(argv=None) -> int:
    """Run ``mitsuba-veg grow`` on its own (``python -m mitsuba_veg.cli.grow TREE.toml``).

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``grow`` (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit code.
    """
    return standalone("grow", add_parser, argv)


if __name__ == "__main__":
    raise SystemExit(main())
