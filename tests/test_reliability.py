"""Issue 27: nothing the user owns is lost, a resume never mixes inputs, and the silent or
misleading cases of the audit end in one line (exit code 2) or do the right thing.

Each test is one case of docs/reliability.md (which also names the cases tested elsewhere:
tests/test_run_folders.py, tests/test_sweep.py, tests/test_sensors.py). A case passes only when
the package refuses with one line naming the field or file, or behaves correctly, and leaves
the user's files byte-identical.
"""
import hashlib
import json
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg as mv
from mitsuba_veg.cli import main
from mitsuba_veg.errors import ParameterError

ROOT = Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
SMALL = ["light.photons=20000", "simulation.checkpoint_every=1", "simulation.frame_every=1"]
SET = [x for s in SMALL for x in ("--set", s)]


def _run(capsys, argv):
    """``mitsuba-veg ARGV`` in this process: (exit code, the non-empty lines of stderr)."""
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as e:      # argparse
        rc = e.code
    err = capsys.readouterr().err
    return rc, [ln for ln in err.splitlines() if ln.strip()]


def _refused(capsys, argv, *words):
    """Exit code 2, one line, no traceback, naming every one of ``words``."""
    rc, lines = _run(capsys, argv)
    assert rc == 2 and len(lines) == 1, lines
    assert "Traceback" not in lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def _digest(root: Path) -> dict:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


WEATHER = "T,rh,P\n" + "".join(f"{288 + i % 3},0.7,{i % 2}\n" for i in range(40))


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A scenario that reads a weather CSV and a species file besides its scene, and a
    2-day run of it with a checkpoint."""
    tmp = tmp_path_factory.mktemp("reliability")
    scen = tmp / "scen"
    shutil.copytree(SCEN.parent, scen)
    (scen / "weather.csv").write_text(WEATHER)
    shutil.copy(ROOT / "mitsuba_veg" / "data" / "moss_species.toml", scen / "species.toml")
    toml = (scen / "scenario.toml").read_text()
    toml = 'species_file = "species.toml"\n' + toml.replace(
        "[climate]", '[climate]\ncsv = "weather.csv"', 1)
    (scen / "scenario.toml").write_text(toml)
    run = tmp / "run"
    mv.run(scen / "scenario.toml", out=run, days=2, overrides=SMALL, progress=False)
    return tmp


def _copies(base, tmp_path):
    scen, run = tmp_path / "scen", tmp_path / "run"
    shutil.copytree(base / "scen", scen)
    shutil.copytree(base / "run", run)
    return scen, run


# ---- data loss ------------------------------------------------------------------------------
def test_foreign_folder_is_refused_and_left_as_it_is(tmp_path, capsys):
    """`run --out results` where results/ holds the user's own maps/ and render/: refused
    (it is not an output folder), nothing deleted."""
    out = tmp_path / "results"
    (out / "maps").mkdir(parents=True)
    (out / "render").mkdir()
    (out / "maps" / "site_plan.png").write_bytes(b"mine")
    (out / "render" / "photo_2025.png").write_bytes(b"mine too")
    (out / "summary.txt").write_text("notes")
    before = _digest(out)
    _refused(capsys, ["run", SCEN, "--out", out, "--days", "1", "--quiet", *SET],
             "--out", "not written by it")
    assert _digest(out) == before and sorted(p.name for p in out.iterdir()) == \
        ["maps", "render", "summary.txt"]


def test_empty_out_is_refused(tmp_path, capsys, monkeypatch):
    """`--out ""` (an unset $OUTDIR) is refused by every command and by the library: the
    working folder's summary.json and maps stay."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "summary.json").write_text("{}")
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "day_0001.png").write_bytes(b"mine")
    before = _digest(tmp_path)
    for argv in (["run", SCEN, "--out", "", "--quiet"],
                 ["irradiance", SCEN, "--out", "", "--quiet"],
                 ["render", tmp_path, "--out", ""]):
        _refused(capsys, argv, "--out", "empty")
    with pytest.raises(ParameterError, match="--out = '' is invalid"):
        mv.run(SCEN, out="", days=1, overrides=SMALL, progress=False)
    assert _digest(tmp_path) == before


def test_a_file_the_package_did_not_write_is_never_overwritten(tmp_path):
    """In a run folder, a file of the user's own under an output's name is not replaced."""
    from mitsuba_veg.outputs import OutputFolder, write_json
    with OutputFolder(tmp_path / "run", "run"):
        write_json(tmp_path / "run" / "summary.json", {"mine": False})     # the package's
        write_json(tmp_path / "run" / "summary.json", {"mine": False})     # again: fine
        (tmp_path / "run" / "run.json").write_text("the user's")
        with pytest.raises(ParameterError, match="run.json exists and was not written"):
            write_json(tmp_path / "run" / "run.json", {})
    assert (tmp_path / "run" / "run.json").read_text() == "the user's"
    assert not list((tmp_path / "run").glob("*.tmp"))


def test_a_run_folder_from_before_manifests_keeps_the_users_files(tmp_path):
    """A run folder written before the manifest existed: a new run clears its outputs by
    name (maps/day_NNNN.png, snapshots, checkpoint, summary) and keeps everything else."""
    from mitsuba_veg.outputs import MARKER, RUN_OUTPUTS, clear_outputs
    run = tmp_path / "run"
    mv.run(SCEN, out=run, days=2, overrides=SMALL, progress=False)
    meta = json.loads((run / MARKER).read_text())
    del meta["files"]
    (run / MARKER).write_text(json.dumps(meta))
    (run / "maps" / "site_plan.png").write_bytes(b"mine")
    (run / "snapshots" / "notes.txt").write_text("mine")
    clear_outputs(run, RUN_OUTPUTS)
    assert sorted(p.relative_to(run).as_posix() for p in run.rglob("*")
                  if p.is_file() and not p.name.startswith(".")) == \
        ["maps/site_plan.png", "snapshots/notes.txt"]


#: `render RUN` with its scene build slowed down: it holds RUN (read) and RUN/render (write)
SLOW_RENDER = textwrap.dedent("""
    import sys, time
    import mitsuba_veg.render.still as still
    real = still._render_cameras
    def slow(*a, **k):
        print("rendering", flush=True)
        time.sleep(float(sys.argv[1]))
        return real(*a, **k)
    still._render_cameras = slow
    from mitsuba_veg.cli import main
    sys.exit(main(sys.argv[2:]))
""")


@pytest.mark.slow
def test_fresh_is_refused_while_render_reads_the_run(base, tmp_path, capsys):
    """`run RUN --fresh` while `render RUN` renders: refused with one line naming the render's
    process; the render's files and the run's stay, and the render ends well."""
    run = tmp_path / "run"
    shutil.copytree(base / "run", run)
    before = _digest(run)
    p = subprocess.Popen([sys.executable, "-c", SLOW_RENDER, "20", "render", str(run),
                          "--width", "32", "--height", "24", "--spp", "1", "--camera",
                          "overview", "--quiet"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "rendering", p.stderr.read()
        line = _refused(capsys, ["run", base / "scen" / "scenario.toml", "--out", run,
                                 "--fresh", "--days", "2", "--quiet", *SET],
                        "--out", f"process {p.pid}", "nothing was deleted")
        assert "render" in line
        assert {k: v for k, v in _digest(run).items() if k in before} == before
    finally:
        out, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    r = json.loads((run / "render" / "render.json").read_text())
    assert all(Path(f).exists() for cam in r["files"].values() for f in cam.values())
    # once the render has ended, --fresh may clear the run and the render it made
    rc, lines = _run(capsys, ["run", base / "scen" / "scenario.toml", "--out", run, "--fresh",
                              "--days", "1", "--quiet", *SET])
    assert rc == 0, lines
    assert not (run / "render").exists()


# ---- silent resumes on changed inputs ----------------------------------------------------------
def _edit_text(path: Path, old: str, new: str):
    t = path.read_text()
    assert old in t
    path.write_text(t.replace(old, new, 1))


def _flip_vertex_byte(ply: Path):
    b = bytearray(ply.read_bytes())
    i = b.index(b"end_header\n") + len(b"end_header\n") + 4     # inside the first vertex
    b[i] ^= 0x01
    ply.write_bytes(bytes(b))


@pytest.mark.parametrize("case, edit, named", [
    ("scene_xml", lambda s: _edit_text(s / "scene.xml", 'value="0.35"', 'value="0.9"'),
     "scene.xml"),
    ("mesh_replaced", lambda s: _flip_vertex_byte(s / "ground.ply"), "ground.ply"),
    ("weather_csv", lambda s: _edit_text(s / "weather.csv", "288,0.7,0", "299,0.7,0"),
     "weather.csv"),
    ("species_file", lambda s: _edit_text(s / "species.toml", "S1 = 60.0", "S1 = 61.0"),
     "species.toml"),
    ("geology_texture", lambda s: (s / "geology.png").write_bytes(
        (s / "geology.png").read_bytes() + b"\0"), "geology.png"),
    ("toml_setting", lambda s: _edit_text(s / "scenario.toml", "seed = 0", "seed = 5"),
     "light.seed"),
])
def test_resume_with_a_changed_input_is_refused(base, tmp_path, capsys, case, edit, named):
    """A resume after an input of the run changed names the file (or field) and --fresh; the
    run folder stays as it was."""
    scen, run = _copies(base, tmp_path)
    edit(scen)
    before = _digest(run)
    line = _refused(capsys, ["run", scen / "scenario.toml", "--out", run, "--days", "3",
                             "--quiet", *SET], "checkpoint", named)
    assert "--fresh" in line
    assert {k: v for k, v in _digest(run).items() if k in before} == before


def test_the_same_toml_in_another_scenario_folder(base, tmp_path, capsys):
    """The same TOML copied into another folder whose mesh differs is refused; a byte-identical
    copy of the whole scenario resumes (the check compares content, not places)."""
    scen, run = _copies(base, tmp_path)
    other = tmp_path / "other"
    shutil.copytree(scen, other)
    _flip_vertex_byte(other / "wall.ply")
    _refused(capsys, ["run", other / "scenario.toml", "--out", run, "--days", "3", "--quiet",
                      *SET], "checkpoint", "wall.ply")
    same = tmp_path / "same"
    shutil.copytree(scen, same)
    rc, lines = _run(capsys, ["run", same / "scenario.toml", "--out", run, "--days", "3",
                              "--quiet", *SET])
    assert rc == 0, lines
    assert json.loads((run / "summary.json").read_text())["resumed"]


def test_resume_compares_the_inputs_the_checkpoint_recorded(base):
    """The checkpoint holds the hashes of every file the run read (scene, its meshes and
    texture, weather, species)."""
    ck = np.load(base / "run" / "checkpoint.npz")
    inputs = json.loads(str(ck["fingerprint"]))["inputs"]
    assert set(inputs) == {"scene.xml", "ground.ply", "roof.ply", "wall.ply", "weather.csv",
                           "species.toml", "geology.png"}
    assert all(len(h) == 64 for h in inputs.values())


def test_a_checkpoint_without_input_hashes_resumes_with_a_warning(base, tmp_path, caplog):
    """A checkpoint written before input fingerprints: its settings are compared, its files
    cannot be; the resume says so."""
    import logging
    from mitsuba_veg.inputs import check_resume
    ck = np.load(base / "run" / "checkpoint.npz")
    fp = json.loads(str(ck["fingerprint"]))
    old = json.dumps({k: v for k, v in fp.items() if k != "inputs"})
    with caplog.at_level(logging.WARNING, logger="mitsuba_veg"):
        check_resume(old, json.dumps(fp), "ck.npz")
    assert any("cannot be compared" in r.getMessage() for r in caplog.records)
    fp2 = json.loads(json.dumps(fp))
    fp2["scenario"]["light"]["seed"] = 9
    with pytest.raises(ParameterError, match=r"light\.seed was 0 then, 9 now"):
        check_resume(old, json.dumps(fp2), "ck.npz")


# ---- lost rows in resumed sweeps -----------------------------------------------------------------
HOLDER = textwrap.dedent("""
    import sys, time
    from mitsuba_veg.outputs import OutputFolder
    f = OutputFolder(sys.argv[1], "run")
    print("locked", flush=True)
    time.sleep(float(sys.argv[2]))
""")


def _spec(out, days=2, **kw):
    return {"run_id": "run-x", "index": 0, "scenario": str(SCEN), "overrides": SMALL,
            "out": str(out), "days": days, "frames": False, "values": {}, **kw}


def test_a_sweep_task_waits_for_a_holder_and_never_counts_a_short_run_as_done(tmp_path,
                                                                               monkeypatch):
    """A run folder held by another process (a killed sweep's worker going away): the task
    waits and runs; a folder that stays held comes back as busy (the sweep submits it again);
    a run that returns fewer days than asked is failed, not done."""
    from mitsuba_veg.sweeps import runner
    out = tmp_path / "run"
    h = subprocess.Popen([sys.executable, "-c", HOLDER, str(out), "3"], stdout=subprocess.PIPE,
                         text=True)
    assert h.stdout.readline().strip() == "locked"
    busy = runner.run_task(_spec(out, lock_wait=0.2))
    assert busy["status"] == "busy" and f"process {h.pid}" in busy["error"]
    t0 = time.monotonic()
    res = runner.run_task(_spec(out))
    assert res["status"] == "done" and len(res["records"]) == 2, res["error"]
    assert time.monotonic() - t0 > 1.0              # it waited for the holder
    h.wait()
    real = runner.run

    def short(*a, **k):           # a run that comes back with a day missing
        s = real(*a, **k)
        s["days_record"] = s["days_record"][:-1]
        return s
    monkeypatch.setattr(runner, "run", short)
    res = runner.run_task(_spec(tmp_path / "run2"))
    assert res["status"] == "failed" and "recorded 1 of its 2 days" in res["error"]


# ---- silent or misleading ----------------------------------------------------------------------
def test_irradiance_of_an_xml_checks_every_set(tmp_path, capsys):
    """`irradiance scene.xml --set light.photonz=5` is refused (it was ignored); the light
    fields apply; other fields need a scenario."""
    xml = SCEN.parent / "scene.xml"
    _refused(capsys, ["irradiance", xml, "--set", "light.photonz=5", "--out", tmp_path / "a"],
             "light.photonz", "light.photons")
    _refused(capsys, ["irradiance", xml, "--set", "moss.size=0.1", "--out", tmp_path / "a"],
             "moss.size", "scenario")
    _refused(capsys, ["irradiance", xml, "--set", "light.photons=0", "--out", tmp_path / "a"],
             "light.photons")
    rc, lines = _run(capsys, ["irradiance", xml, "--set", "light.photons=700", "--set",
                              "light.seed=3", "--out", tmp_path / "b", "--quiet"])
    assert rc == 0, lines
    s = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert s["settings"]["photons"] == 700 and s["settings"]["seed"] == 3


def test_render_with_another_scenario_is_refused(base, tmp_path, capsys):
    """`render RUN --scenario OTHER` draws another scene over the run: refused naming what
    differs; the run's own scenario (a copy elsewhere) is accepted by the check."""
    from mitsuba_veg.render.history import load_run
    other = tmp_path / "other.toml"
    other.write_text((base / "scen" / "scenario.toml").read_text().replace(
        "initial = 200", "initial = 300"))
    shutil.copy(base / "scen" / "weather.csv", tmp_path)
    shutil.copy(base / "scen" / "species.toml", tmp_path)
    for f in ("scene.xml", "ground.ply", "roof.ply", "wall.ply", "geology.png"):
        shutil.copy(base / "scen" / f, tmp_path)
    _refused(capsys, ["render", base / "run", "--scenario", other, "--out", tmp_path / "r",
                      "--quiet"], "--scenario", "moss.initial")
    assert not (tmp_path / "r").exists()
    same = tmp_path / "scenario.toml"
    shutil.copy(base / "scen" / "scenario.toml", same)
    assert load_run(base / "run", same).scenario.path == same   # the run's own: accepted
    _flip_vertex_byte(tmp_path / "ground.ply")
    with pytest.raises(ParameterError, match=r"--scenario.*ground\.ply has changed"):
        load_run(base / "run", same)


@pytest.mark.parametrize("text, words", [
    ("T,rh,P,T\n288,0.7,0,290\n", ("columns", "T appears 2 times")),
    ("T,rh,P\n288,0.7,0\n288,0.7,0,5\n", ("row 3", "3 cells")),
    ("T,rh,P,day_of_year\n288,0.7,0,60.7\n", ("day_of_year", "60.7", "whole day")),
])
def test_weather_csv_refuses_what_it_used_to_read_silently(tmp_path, capsys, text, words):
    """A repeated column (the second used to win), an extra cell (dropped), a fractional day
    of the year (truncated): one line naming the row or column."""
    (tmp_path / "w.csv").write_text(text)
    _refused(capsys, ["run", SCEN, "--set", f"climate.csv='{tmp_path / 'w.csv'}'", "--days",
                      "1", "--out", tmp_path / "o", "--quiet"], "w.csv", *words)
    assert not (tmp_path / "o").exists()


def test_scenario_values_that_ran_silently(tmp_path, capsys):
    """A region with min > max (0 m² for ever), a species listed twice, a typo in a
    [[render.trees]] override (refused only later by the render): refused by `run` before
    anything is written."""
    o = tmp_path / "o"
    _refused(capsys, ["run", SCEN, "--set", "regions.open.min=[1.0, -0.2, 0.2]", "--set",
                      "regions.open.max=[-1.0, 0.5, 1.0]", "--out", o, "--quiet"],
             "regions.open.min", "in x")
    _refused(capsys, ["run", SCEN, "--set", 'moss.species=["polytrichum", "polytrichum"]',
                      "--set", "moss.priority=[1, 2]", "--out", o, "--quiet"],
             "moss.species", "polytrichum is listed more than once")
    toml = SCEN.read_text().replace("LeafScale = 0.45", "LeafScal = 0.45")
    (tmp_path / "typo.toml").write_text(toml.replace('file = "scene.xml"',
                                                     f'file = "{SCEN.parent / "scene.xml"}"')
                                        .replace('"geology.png"',
                                                 f'"{SCEN.parent / "geology.png"}"'))
    _refused(capsys, ["run", tmp_path / "typo.toml", "--days", "1", "--out", o, "--quiet",
                      *SET], "render.trees.overrides.LeafScal", "did you mean 'LeafScale'")
    assert not o.exists()


def test_set_keys_and_top_level_fields_keep_their_names(tmp_path, capsys):
    """`--set =1` and `--set light..photons=5` name the whole item; a top-level `seed = 3`
    suggests light.seed (it suggested 'scene')."""
    o = tmp_path / "o"
    _refused(capsys, ["run", SCEN, "--set", "=1", "--out", o], "'=1'")
    _refused(capsys, ["run", SCEN, "--set", "light..photons=5", "--out", o],
             "'light..photons=5'")
    (tmp_path / "s.toml").write_text("seed = 3\n" + SCEN.read_text())
    line = _refused(capsys, ["run", tmp_path / "s.toml", "--out", o], "seed = 3")
    assert "did you mean 'light.seed'" in line


def test_when_without_an_offset_is_the_sites_local_time(tmp_path, capsys):
    """`irradiance --when 2026-06-21T10:00:00` (no offset) was read as UTC (night in Japan):
    it is the site's local time (longitude 139 E: +09:00), as the render does."""
    from mitsuba_veg.scenario import load_scenario, site_time
    rc, lines = _run(capsys, ["irradiance", SCEN, "--when", "2026-06-21T10:00:00", "--photons",
                              "1000", "--out", tmp_path / "i", "--quiet"])
    assert rc == 0, lines
    assert json.loads((tmp_path / "i" / "summary.json").read_text())["when"] == \
        "2026-06-21T10:00:00+09:00"
    s = load_scenario(SCEN, ["site.timezone=1.5", "light.when='2026-06-21T10:00:00'"])
    assert s.get("light.when") == "2026-06-21T10:00:00+01:30"
    assert site_time("2026-06-21T10:00:00Z", {}) == "2026-06-21T10:00:00Z"


def test_a_corrupt_snapshot_is_one_line(base, tmp_path, capsys):
    """`render RUN` with a corrupt snapshot: one line naming the file (was: internal error:
    BadZipFile)."""
    run = tmp_path / "run"
    shutil.copytree(base / "run", run)
    snap = run / "snapshots" / "day_0002.npz"
    snap.write_bytes(b"PK\x03\x04" + b"\0" * 64)
    _refused(capsys, ["render", run, "--width", "32", "--height", "24", "--spp", "1",
                      "--quiet"], "snapshot", "day_0002.npz", "BadZipFile")


@pytest.mark.parametrize("damage, words", [
    ("empty", ("wall.ply", "is empty (0 bytes)")),
    ("truncated", ("wall.ply", "is truncated", "1,424 face")),
    ("missing", ("wall.ply", "does not exist")),
    ("not_ply", ("wall.ply", "is not a PLY file")),
])
def test_a_broken_mesh_is_named(tmp_path, capsys, damage, words):
    """A truncated, empty or missing PLY blamed the XML ("correct the XML") or said "No such
    file" for an empty one: the line names the mesh and what is wrong with it."""
    scen = tmp_path / "scen"
    shutil.copytree(SCEN.parent, scen)
    ply = scen / "wall.ply"
    data = ply.read_bytes()
    if damage == "empty":
        ply.write_bytes(b"")
    elif damage == "truncated":
        ply.write_bytes(data[:3000])
    elif damage == "missing":
        ply.unlink()
    else:
        ply.write_bytes(b"solid wall\n" + data)
    for cmd in (["run", scen / "scenario.toml", "--days", "1"],
                ["irradiance", scen / "scene.xml", "--photons", "100"]):
        _refused(capsys, [*cmd, "--out", tmp_path / "o", "--quiet"], *words)
    # `run` claims its folder first: nothing but its marker and lock is written
    assert not [p for p in (tmp_path / "o").rglob("*") if not p.name.startswith(".mitsuba")]


def test_resuming_into_a_read_only_folder_is_refused_before_any_day(base, tmp_path, capsys):
    """A run folder that cannot be written: refused at once (it simulated every day and then
    failed writing the checkpoint)."""
    run = tmp_path / "run"
    shutil.copytree(base / "run", run)
    before = _digest(run)
    if os.geteuid() == 0:     # root writes anywhere but into an immutable folder
        r = subprocess.run(["chattr", "+i", str(run)], capture_output=True)
        if r.returncode != 0:
            pytest.skip("chattr +i is not available here: root cannot make a folder read-only")
        undo = ["chattr", "-i", str(run)]
    else:
        run.chmod(0o555)
        undo = ["chmod", "755", str(run)]
    try:
        t0 = time.monotonic()
        _refused(capsys, ["run", base / "scen" / "scenario.toml", "--out", run, "--days", "30",
                          "--quiet", *SET], "--out", "writable", "before any work")
        assert time.monotonic() - t0 < 60
    finally:
        subprocess.run(undo, check=True)
    assert _digest(run) == before


def test_a_lock_held_by_another_program_names_it(base, tmp_path, capsys):
    """The folder's lock held by a program that is not mitsuba-veg (here `flock`): the line
    names that process, not the last mitsuba-veg writer's pid written in the lock file."""
    run = tmp_path / "run"
    shutil.copytree(base / "run", run)
    lock = run / ".mitsuba-veg.lock"
    lock.write_text("999999")                      # a dead writer's pid
    p = subprocess.Popen(["flock", str(lock), "sleep", "60"]) if shutil.which("flock") else \
        subprocess.Popen([sys.executable, "-c", "import fcntl, sys, time; f = open(sys.argv[1]"
                          ", 'a'); fcntl.flock(f, fcntl.LOCK_EX); time.sleep(60)", str(lock)])
    try:
        from mitsuba_veg.outputs import lock_holders
        t0 = time.monotonic()
        while p.pid not in lock_holders(lock):
            assert time.monotonic() - t0 < 20
            time.sleep(0.05)
        line = _refused(capsys, ["run", base / "scen" / "scenario.toml", "--out", run,
                                 "--days", "3", "--quiet", *SET], f"process {p.pid}")
        assert "999999" not in line
    finally:
        p.kill()
        p.wait()


def test_tune_says_which_parameters_and_refuses_repeats(tmp_path, capsys):
    """`tune` of the three-species garden with its default --params S1,T1 failed after the
    set-up: refused at once naming the species; --params S1,S1 and an infinite target value
    refused too."""
    t = ["tune", SCEN, "--target", "synthetic:S1=60", "--days", "2", "--out", tmp_path / "t",
         "--quiet"]
    line = _refused(capsys, t, "--params", "(the default)", "bryum_argenteum.S1",
                    "--species bryum_argenteum")
    _refused(capsys, t + ["--species", "bryum_argenteum", "--params", "S1,S1"], "--params",
             "S1 is named twice")
    target = np.full(10, 0.2)
    target[3] = np.inf
    np.save(tmp_path / "inf.npy", target)
    _refused(capsys, ["tune", SCEN, "--target", tmp_path / "inf.npy", "--species",
                      "bryum_argenteum", "--out", tmp_path / "t"], "--target", "1 infinite")
    assert "polytrichum" in line and not (tmp_path / "t").exists()


@pytest.mark.slow
def test_tune_target_nan_on_every_living_triangle_is_refused(tmp_path, capsys):
    """A .npy target whose finite values are all on triangles moss cannot live on: the fit
    would see no data (its gradient 0, the start returned as fitted); refused."""
    from mitsuba_veg.scenario import load_scenario
    scene = load_scenario(SCEN).load_scene()
    n = sum(s.face_count() for s in scene.shapes())
    target = np.full(n, np.nan)
    np.save(tmp_path / "nan.npy", target)
    target[0] = 0.1
    np.save(tmp_path / "one.npy", target)   # triangle 0 of the ground: a living one
    _refused(capsys, ["tune", SCEN, "--target", tmp_path / "nan.npy", "--species",
                      "bryum_argenteum", "--out", tmp_path / "t"], "--target",
             "at least one finite")
    rc, lines = _run(capsys, ["tune", SCEN, "--target", tmp_path / "one.npy", "--species",
                              "bryum_argenteum", "--params", "S1", "--days", "2", "--steps",
                              "1", "--photons", "20000", "--out", tmp_path / "t2", "--quiet"])
    assert rc == 0 and any("are NaN and left out of the fit" in ln for ln in lines), lines


# ---- virtual sensors ----------------------------------------------------------------------------
def test_sensors_at_one_place_are_refused_or_independent():
    """A spherical and a hemispherical sensor at one place shared their photons (the sphere
    read a quarter or half of its value): refused with one line; domes facing opposite ways,
    and a square inside a sphere, are independent and allowed."""
    S = mv.light.sensors
    with pytest.raises(ParameterError, match=r"sensors = 'ball and dome'.*do not coincide"):
        S.point("ball", (0, 0.5, 0), kind="spherical") + \
            S.point("dome", (0, 0.5, 0), kind="hemispherical")
    with pytest.raises(ParameterError, match="spacing >= its sensors' size"):
        S.grid("g", (0, 0, 0), (1, 0, 0), (0, 0, 1), spacing=0.05, size=0.1)
    with pytest.raises(ParameterError, match="'up and down'"):
        S.point("up", (0, 0.5, 0)) + S.point("down", (0, 0.5, 0), normal=(0, -1, 0))
    ok = S.point("sky", (0, 0.5, 0), kind="hemispherical") + \
        S.point("ground", (0, 0.5, 0), normal=(0, -1, 0), kind="hemispherical") + \
        S.point("flat", (0, 0.5, 0)) + S.point("big", (0, 0.5, 0), kind="spherical", size=0.3)
    assert len(ok) == 4 and ok.overlap() is None
    assert len(S.grid("g", (0, 0, 0), (1, 0, 0), (0, 0, 1), spacing=0.1, size=0.1)) == 100


def test_shapes_without_ids_are_refused(tmp_path, capsys):
    """Mitsuba's XML writer writes shapes with ``name=`` and no ``id=``: every shape would load
    with the id '' and share one name (one row, one map file written over and over). Refused
    with one line naming the shapes and the fix; no result written (the output folder is
    claimed before the scene loads: at most its marker is there)."""
    import mitsuba as mi
    xml = tmp_path / "cbox.xml"
    mi.parser.write_file(mi.parser.parse_dict(mi.parser.ParserConfig(mi.variant()),
                                              mi.cornell_box()), str(xml))
    assert 'id="' not in "".join(ln for ln in xml.read_text().splitlines() if "<shape" in ln)
    _refused(capsys, ["irradiance", xml, "--set", "light.photons=1000", "--out", tmp_path / "o"],
             "no id", "id=")
    left = sorted(p.name for p in (tmp_path / "o").rglob("*")) if (tmp_path / "o").exists() \
        else []
    assert all(n.startswith(".mitsuba-veg") for n in left), left
