"""Fingerprints of the files a run reads, so that a resume never mixes inputs.

A run reads more than its scenario TOML: the Mitsuba scene XML and every file it references
(meshes, textures, included XML), the weather CSV (``climate.csv``), the species file
(``species_file``), the geology texture (``terrain.geology_texture``) and the meshes of its
``[[trees]]`` (``file``, ``leaves_file``). :func:`input_hashes` gives the SHA-256 of each, keyed
by its path relative to the scenario's folder; :func:`check_same_inputs` compares two such
records and :func:`check_resume` two checkpoint fingerprints, raising one
:class:`~mitsuba_veg.errors.ParameterError` that names the file (or scenario field) that
changed and the fix (``--fresh``).

The hashes of a scenario are taken once, when the run reads its scene
(:meth:`mitsuba_veg.scenario.Scenario.load_scene` calls :func:`input_hashes`), and kept on the
scenario object, so a file edited while the run goes on is seen at the resume. A file's hash
is cached by its size, modification time and inode (a file is read once per process while it
does not change).
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from .errors import ParameterError

__all__ = ["FILE_FIELDS", "TREE_FILE_FIELDS", "MISSING", "file_sha256", "scene_references",
           "input_files", "input_hashes", "changed_input", "check_same_inputs",
           "same_run_scenario", "check_resume", "ply_problem", "check_scene_files"]

#: scenario fields naming files the run reads (``trees`` entries: ``file``, ``leaves_file``)
FILE_FIELDS = ("scene.file", "climate.csv", "species_file", "terrain.geology_texture")
#: fields of a ``[[trees]]`` entry that name files (hashed for a resume)
TREE_FILE_FIELDS = ("file", "leaves_file")
#: the hash recorded for a referenced file that does not exist
MISSING = "missing"

_CACHE: dict = {}
_VAR = re.compile(r"\$(\w+)")


def file_sha256(path) -> str:
    """SHA-256 of a file's content (cached while its size, mtime and inode stay the same).

    Parameters
    ----------
    path : str or pathlib.Path
        The file.

    Returns
    -------
    str
        The hex digest, or :data:`MISSING` when the file does not exist or cannot be read.
    """
    p = Path(path)
    try:
        st = p.stat()
    except OSError:
        return MISSING
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns, st.st_ino)
    if key not in _CACHE:
        h = hashlib.sha256()
        try:
            with open(p, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
        except OSError:
            return MISSING
        _CACHE[key] = h.hexdigest()
    return _CACHE[key]


def scene_references(xml_path) -> list[Path]:
    """The files a Mitsuba XML scene references, recursively through ``<include>``.

    Every ``filename`` (``<string name="filename" value=...>`` of meshes, bitmaps, ...) and
    every ``<include filename=...>``, with ``$name`` replaced by the scene's ``<default>``
    values, resolved against the XML's folder and its ``<path>`` entries.

    Parameters
    ----------
    xml_path : str or pathlib.Path
        The scene file.

    Returns
    -------
    list of pathlib.Path
        The referenced files (absolute; those that do not exist are included as the path
        they would have), in document order, without duplicates; an XML that does not parse
        references nothing (its load fails with Mitsuba's message).
    """
    out: list[Path] = []
    seen = set()

    def walk(path: Path):
        if path in seen:
            return
        seen.add(path)
        try:
            root = ET.parse(path).getroot()
        except (ET.ParseError, OSError):
            return
        defaults = {e.get("name"): e.get("value", "") for e in root.iter("default")}
        dirs = [path.parent] + [path.parent / _sub(e.get("value", ""), defaults)
                                for e in root.iter("path")]

        def resolve(name: str) -> Path:
            name = _sub(name, defaults)
            cands = [Path(name)] if Path(name).is_absolute() else [d / name for d in dirs]
            return next((c for c in cands if c.exists()), cands[0]).resolve()

        for e in root.iter():
            name = None
            if e.tag == "include":
                name = e.get("filename")
            elif e.get("name") == "filename" and e.get("value"):
                name = e.get("value")
            if not name:
                continue
            q = resolve(name)
            if q not in out:
                out.append(q)
            if e.tag == "include" and q.suffix.lower() == ".xml":
                walk(q)

    walk(Path(xml_path).resolve())
    return out


def _sub(text: str, defaults: dict) -> str:
    return _VAR.sub(lambda m: defaults.get(m.group(1), m.group(0)), text or "")


def input_files(scn) -> dict:
    """The files a run of a scenario reads, by the name the fingerprint gives them.

    Parameters
    ----------
    scn : mitsuba_veg.scenario.Scenario
        The loaded scenario.

    Returns
    -------
    dict of str to pathlib.Path
        Name (the path relative to the scenario's folder, POSIX-style; absolute when outside
        it) -> the file.
    """
    root = Path(scn.path).resolve().parent
    files: dict = {}

    def add(p: Path):
        p = Path(os.path.abspath(p))
        try:
            name = Path(os.path.relpath(p, root)).as_posix()
        except ValueError:          # another drive
            name = p.as_posix()
        files.setdefault(name, p)

    for f in FILE_FIELDS:
        v = scn.get(f)
        if v:
            p = (root / str(v)).resolve()
            add(p)
            if f == "scene.file":
                for q in scene_references(p):
                    add(q)
    trees = scn.get("trees") or []
    for t in [trees] if isinstance(trees, dict) else trees:
        for f in TREE_FILE_FIELDS:
            if isinstance(t, dict) and t.get(f):
                add((root / str(t[f])).resolve())
    return files


def input_hashes(scn) -> dict:
    """SHA-256 of every file a run of the scenario reads (:func:`input_files`).

    Computed once per scenario object (the first call: when the run loads its scene) and kept
    on it, so that later calls give what the run read.

    Parameters
    ----------
    scn : mitsuba_veg.scenario.Scenario
        The scenario whose run is fingerprinted.

    Returns
    -------
    dict of str to str
        Relative path -> hex digest (:data:`MISSING` for a file that does not exist).
    """
    cached = getattr(scn, "_input_hashes", None)
    if cached is None:
        cached = {k: file_sha256(p) for k, p in sorted(input_files(scn).items())}
        try:
            scn._input_hashes = cached
        except AttributeError:
            pass
    return dict(cached)


def changed_input(recorded: dict, current: dict) -> tuple[str, str] | None:
    """The first difference between two :func:`input_hashes` records.

    Parameters
    ----------
    recorded, current : dict of str to str
        The hashes then and now.

    Returns
    -------
    tuple of str or None
        (the file's name, what differs in words, e.g. ``"scene.xml has changed since: its
        content differs"``, ``"meshes/a.ply is missing now"``, ``"wall.ply is read now and
        was not then"``); None when they are the same.
    """
    for name in sorted(set(recorded) | set(current)):
        a, b = recorded.get(name), current.get(name)
        if a == b:
            continue
        if a is None:
            return name, f"{name} is read now and was not then"
        if b is None:
            return name, f"{name} was read then and is not now"
        if b == MISSING:
            return name, f"{name} is missing now"
        if a == MISSING:
            return name, f"{name} was missing then and exists now"
        return name, f"{name} has changed since: its content differs"
    return None


def check_same_inputs(recorded: dict, current: dict, what: str, value, fix: str,
                      source: str | None = None) -> None:
    """Refuse when two :func:`input_hashes` records differ, naming the file.

    Parameters
    ----------
    recorded, current : dict of str to str
        The hashes then (e.g. in a checkpoint) and now.
    what : str
        The field of the message (e.g. ``"checkpoint"``).
    value : object
        Its value (e.g. the checkpoint's path).
    fix : str
        How to go on; ``{file}`` is replaced by the file's name.
    source : str, optional
        The file the check is about, for the message; default None.

    Raises
    ------
    ParameterError
        Naming the first file that differs.
    """
    d = changed_input(recorded, current)
    if d is not None:
        raise ParameterError(what, value, "the input files it was computed from, unchanged; "
                             f"{d[1]}", fix.replace("{file}", d[0]), source)


def _first_difference(a, b, prefix: str = ""):
    """The dotted name and the two values of the first difference between nested dicts."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{prefix}{k}.")
        return None
    return prefix.rstrip("."), a, b


def same_run_scenario(recorded: str, scn) -> str | None:
    """Whether a scenario is the one a run was made from, by the run's checkpoint fingerprint.

    Compares what the render draws: the settings but ``[simulation]``, ``[render]`` (the
    render's own), ``[light]`` and ``[climate]`` (how the run was lit and watered, not what it
    looks like: a run made with ``--set light.photons=...`` renders with its own file) and,
    when the checkpoint recorded them, the input files but the weather CSV.

    Parameters
    ----------
    recorded : str
        The checkpoint's fingerprint (JSON).
    scn : mitsuba_veg.scenario.Scenario
        The scenario to compare.

    Returns
    -------
    str or None
        What differs in words (e.g. ``"light.seed is 0 in the run and 3 here"``), or None when
        nothing does (or the fingerprint cannot be read).
    """
    try:
        old = json.loads(recorded)
        settings = dict(old["scenario"])
    except (ValueError, KeyError, TypeError):
        return None
    skip = ("simulation", "render", "light", "climate")
    diff = _first_difference({k: v for k, v in settings.items() if k not in skip},
                             json.loads(json.dumps({k: v for k, v in scn.data.items()
                                                    if k not in skip}, default=str)))
    if diff is not None:
        name, a, b = diff
        return f"{name} is {a!r} in the run and {b!r} here"
    if isinstance(old.get("inputs"), dict):
        weather = [(settings.get("climate") or {}).get("csv"), scn.get("climate.csv")]
        strip = {Path(str(w)).as_posix() for w in weather if w}
        d = changed_input({k: v for k, v in old["inputs"].items() if k not in strip},
                          {k: v for k, v in input_hashes(scn).items() if k not in strip})
        if d is not None:
            return d[1] + " (then: the run; now: this scenario)"
    return None


def check_resume(recorded: str, current: str, checkpoint) -> None:
    """Refuse to resume a checkpoint whose run read other settings or files than this one.

    ``recorded`` and ``current`` are the JSON fingerprints of the checkpoint and of this run
    (``scenario``: the settings, ``start``: the start date, ``inputs``: :func:`input_hashes`).
    A checkpoint written before input fingerprints existed (no ``inputs``) is resumed when its
    settings match, with a warning that its files could not be compared.

    Parameters
    ----------
    recorded : str
        The checkpoint's fingerprint (JSON).
    current : str
        This run's fingerprint (JSON).
    checkpoint : str or pathlib.Path
        The checkpoint file, for the message.

    Raises
    ------
    ParameterError
        Naming the scenario field or the file that differs, with the fix (``--fresh``).
    """
    fix = ("restore {file} as it was, or run again with --fresh to start over (or choose "
           "another --out folder)")
    if recorded == current:
        return
    try:
        old, new = json.loads(recorded), json.loads(current)
    except ValueError:
        old, new = None, None
    if not isinstance(old, dict) or not isinstance(new, dict):
        raise ParameterError("checkpoint", str(checkpoint), "a checkpoint of the same scenario",
                             "use --fresh (or another --out folder) to start afresh")
    diff = _first_difference({k: old.get(k) for k in ("scenario", "start")},
                             {k: new.get(k) for k in ("scenario", "start")})
    if diff is not None:
        name, a, b = diff
        name = name.removeprefix("scenario.")
        raise ParameterError("checkpoint", str(checkpoint), "a checkpoint of the same scenario "
                             f"({name} was {a!r} then, {b!r} now)",
                             "use --fresh (or another --out folder) to start afresh")
    if "inputs" not in old:
        logging.getLogger("mitsuba_veg").warning(
            "%s was written before mitsuba-veg recorded the input files of a run: the scene, "
            "meshes and weather it read cannot be compared with today's (use --fresh to be "
            "sure)", checkpoint)
        return
    check_same_inputs(old.get("inputs") or {}, new.get("inputs") or {}, "checkpoint",
                      str(checkpoint), fix)


#: bytes of the PLY property types
_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2,
              "int16": 2, "uint16": 2, "int": 4, "uint": 4, "int32": 4, "uint32": 4,
              "float": 4, "float32": 4, "double": 8, "float64": 8}


def ply_problem(path) -> str | None:
    """What is wrong with a PLY mesh file, from its header and size (None: nothing found).

    Finds an empty file, a file that is not PLY, a header without ``end_header`` and a body
    shorter than its header declares (a truncated file: binary bodies by size, with at least
    three indices per face list; ASCII bodies by their lines).

    Parameters
    ----------
    path : str or pathlib.Path
        The mesh file to check.

    Returns
    -------
    str or None
        The problem in words (e.g. ``"is empty (0 bytes)"``), or None.
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        with open(p, "rb") as f:
            head = f.read(1 << 16)
    except OSError as e:
        return f"cannot be read ({e.strerror})"
    if size == 0:
        return "is empty (0 bytes)"
    if not head.startswith(b"ply"):
        return "is not a PLY file (it does not start with 'ply')"
    end = head.find(b"end_header")
    if end < 0:
        return "has no complete PLY header (no end_header)"
    nl = head.find(b"\n", end)
    body_start = nl + 1 if nl >= 0 else len(head)
    fmt, elements = None, []
    for line in head[:end].decode("ascii", "replace").splitlines():
        w = line.split()
        if not w:
            continue
        if w[0] == "format" and len(w) > 1:
            fmt = w[1]
        elif w[0] == "element" and len(w) == 3 and w[2].isdigit():
            elements.append([w[1], int(w[2]), 0, 0])     # name, count, fixed bytes, list bytes
        elif w[0] == "property" and elements:
            if len(w) >= 5 and w[1] == "list":
                elements[-1][3] += _PLY_SIZES.get(w[2], 1) + 3 * _PLY_SIZES.get(w[3], 4)
            elif len(w) >= 3:
                elements[-1][2] += _PLY_SIZES.get(w[1], 4)
    declared = ", ".join(f"{n:,d} {name}" for name, n, _, _ in elements) + " elements"
    if fmt == "ascii":
        with open(p, "rb") as f:
            f.seek(body_start)
            lines = sum(1 for ln in f if ln.strip())
        need = sum(n for _, n, _, _ in elements)
        if lines < need:
            return (f"is truncated: its header declares {declared} ({need:,d} lines of data), "
                    f"the file holds {lines:,d}")
        return None
    need = sum(n * (a + b) for _, n, a, b in elements)
    have = size - body_start
    if have < need:
        return (f"is truncated: its header declares {declared}, which take at least "
                f"{need:,d} bytes, and the file holds {have:,d} after its header")
    return None


def check_scene_files(xml_path, field: str = "scene.file", source: str | None = None) -> None:
    """Refuse a scene whose referenced files are missing, empty or truncated, naming the file
    and what is wrong (before Mitsuba loads it and blames the XML).

    Parameters
    ----------
    xml_path : str or pathlib.Path
        The scene file.
    field : str, optional
        The field or argument that named the scene (default ``"scene.file"``).
    source : str, optional
        The scenario file, for messages; default None.

    Raises
    ------
    ParameterError
        For the first referenced file (mesh, texture, included XML) that is missing, empty or,
        for a PLY mesh, truncated or not PLY.
    """
    xml = Path(xml_path)
    for ref in scene_references(xml):
        try:
            name = Path(os.path.relpath(ref, xml.resolve().parent)).as_posix()
        except ValueError:
            name = str(ref)
        if not ref.exists():
            problem = "does not exist"
        elif ref.is_dir():
            problem = "is a folder"
        elif ref.suffix.lower() == ".ply":
            problem = ply_problem(ref)
        else:
            problem = "is empty (0 bytes)" if ref.stat().st_size == 0 else None
        if problem is not None:
            raise ParameterError(field, str(xml), f"a scene whose files are complete ({name}, "
                                 f"which {xml.name} references, {problem})",
                                 f"restore or re-export {name}, or fix its filename in "
                                 f"{xml.name}", source)
