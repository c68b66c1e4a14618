"""Bad input over every command: exit code 2, one line naming the field, no traceback, and the
outputs already on disk byte-identical afterwards (table-driven, in-process, plus a few runs of
the installed console script)."""
import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg as mv
from mitsuba_veg.cli import main

ROOT = Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
SMALL = ["light.photons=30000", "simulation.checkpoint_every=3", "simulation.frame_every=2"]
SET = [x for s in SMALL for x in ("--set", s)]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A finished 4-day run, its copies with broken files, and bad input files."""
    tmp = tmp_path_factory.mktemp("bad_input")
    run = tmp / "run"
    mv.run(SCEN, out=run, days=4, overrides=SMALL, progress=False)
    (tmp / "a_file").write_text("not a folder\n")
    for name, content in (("ck_truncated", None), ("ck_empty", b""),
                          ("ck_garbage", b"\x89garbage" * 100)):
        d = tmp / name
        shutil.copytree(run, d)
        ck = d / "checkpoint.npz"
        ck.write_bytes(ck.read_bytes()[:300] if content is None else content)
    d = tmp / "summary_truncated"
    shutil.copytree(run, d)
    (d / "summary.json").write_text((run / "summary.json").read_text()[:200])
    scen = tmp / "scen_badpng"
    shutil.copytree(SCEN.parent, scen)
    (scen / "geology.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 40)
    (tmp / "binary.csv").write_bytes(bytes(range(256)) * 8)
    (tmp / "columns.csv").write_text("T,rh,Precip\n288,0.7,0\n288,0.7,0\n288,0.7,0\n"
                                     "288,0.7,0\n")
    (tmp / "bad.xml").write_text("<scene version='3.0.0'><shape type='nope'>\n")
    (tmp / "bad.toml").write_text("[light\nphotons = 3\n")
    np.save(tmp / "garbage.npy", np.array(["a", "b"]))
    (tmp / "truncated.npy").write_bytes(b"\x93NUMPY\x01\x00")
    (tmp / "flat.toml").write_text("model = 'branching'\ngenerations = 2\n"
                                   "positions = [[0.0, 0.0]]\n")
    (tmp / "tree.toml").write_text("model = 'branching'\ngenerations = 2\n")
    return tmp


def _digest(root: Path) -> dict:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != ".mitsuba-veg.lock"}


X = str(SCEN.parent / "scene.xml") if (SCEN.parent / "scene.xml").exists() else None
R = ["run", str(SCEN), "--quiet"]
I = ["irradiance", str(SCEN), "--quiet"]
T = ["tune", str(SCEN), "--target", "synthetic:S1=60", "--quiet", "--days", "2", "--species",
     "bryum_argenteum"]

#: (argv with {tmp} placeholders, text the one line must contain)
CASES = [
    # run: scenario fields (TOML and --set)
    (R + ["--set", "light.photonz=10", "--out", "{tmp}/o"], "light.photonz"),
    (R + ["--set", "light=5", "--out", "{tmp}/o"], "light = 5"),
    (R + ["--set", "regions.open=5", "--out", "{tmp}/o"], "regions.open"),
    (R + ["--set", "simulation.frame_every=often", "--out", "{tmp}/o"], "simulation.frame_every"),
    (R + ["--set", "climate.rain_days=10.5", "--out", "{tmp}/o"], "climate.rain_days"),
    (R + ["--set", "moss.initial_growth=nan", "--out", "{tmp}/o"], "moss.initial_growth"),
    (R + ["--set", "moss.priority=[1,2]", "--out", "{tmp}/o"], "moss.priority"),
    (R + ["--set", "light.photons=1000000000000000", "--out", "{tmp}/o"], "light.photons"),
    (R + ["--set", "light.photons=1e15", "--out", "{tmp}/o"], "light.photons"),
    (R + ["--set", "terrain.geology.roof='granite'", "--out", "{tmp}/o"], "terrain.geology.roof"),
    (R + ["--set", "mos.size=0.1", "--out", "{tmp}/o"], "moss"),
    (R + ["--set", "light.when='tomorrow'", "--out", "{tmp}/o"], "light.when"),
    (R + ["--set", "render.trees.preset=3", "--out", "{tmp}/o"], "render.trees.preset"),
    (R + ["--set", "light.photons", "--out", "{tmp}/o"], "--set"),
    (R + ["--set", "climate.csv='{tmp}/binary.csv'", "--out", "{tmp}/o"], "climate.csv"),
    (R + ["--set", "climate.csv='{tmp}/columns.csv'", "--out", "{tmp}/o"], "Precip"),
    (R + ["--set", "terrain.ground='grund'", "--out", "{tmp}/o"], "terrain.ground"),
    (R + ["--days", "0", "--out", "{tmp}/o"], "--days"),
    (R + SET + ["--days", "2", "--out", "{tmp}/run"], "--days"),           # resume, fewer days
    (R + SET + ["--days", "5", "--set", "light.seed=3", "--out", "{tmp}/run"], "checkpoint"),
    (R + SET + ["--days", "5", "--out", "{tmp}/ck_truncated"], "--fresh"),
    (R + SET + ["--days", "5", "--out", "{tmp}/ck_empty"], "--fresh"),
    (R + SET + ["--days", "5", "--out", "{tmp}/ck_garbage"], "--fresh"),
    (R + ["--out", "{tmp}/a_file"], "--out"),
    (R + ["--out", "/proc/mitsuba-veg-out"], "--out"),
    (["run", "{tmp}/scen_badpng/scenario.toml", "--quiet", "--days", "2", "--out", "{tmp}/o2"]
     + SET, "terrain.geology_texture"),
    (["run", "{tmp}/missing.toml", "--out", "{tmp}/o"], "scenario"),
    (["run", "{tmp}/bad.toml", "--out", "{tmp}/o"], "scenario"),
    # irradiance
    (["irradiance", "{tmp}/bad.xml", "--out", "{tmp}/o3"], "SCENE"),
    (["irradiance", "{tmp}/nothing.xml", "--out", "{tmp}/o3"], "SCENE"),
    (I + ["--photons", "0", "--out", "{tmp}/o3"], "--photons"),
    (I + ["--photons", "1e15", "--out", "{tmp}/o3"], "--photons"),
    (I + ["--when", "10am", "--out", "{tmp}/o3"], "--when"),
    (I + ["--photons", "1000", "--out", "{tmp}/run"], "--out"),            # a run's folder
    (I + ["--photons", "1000", "--out", "{tmp}/a_file"], "--out"),
    (I + ["--set", "light.photonz=1", "--out", "{tmp}/o3"], "light.photonz"),
    # light-study
    (["light-study", "{tmp}/bad.xml", "--when", "2026-06-01T12:00:00+09:00", "--out",
      "{tmp}/o4"], "--when"),
    (["light-study", "sphere-tree", "--leaves", "0", "--out", "{tmp}/o4"], "--leaves"),
    (["light-study", "sphere-tree", "--photons", "1000", "--leaves", "10", "--out",
      "/proc/mitsuba-veg-out"], "--out"),
    # render and animate
    (["render", "{tmp}/run", "--width", "0"], "--width"),
    (["render", "{tmp}/run", "--spp", "0"], "--spp"),
    (["render", "{tmp}/run", "--day", "99", "--quiet"], "day"),
    (["render", "{tmp}/summary_truncated", "--quiet"], "summary.json"),
    (["render", "{tmp}/o_none", "--quiet"], "RUN_DIR"),
    (["render", "{tmp}/run", "--out", "{tmp}/a_file", "--quiet"], "--out"),
    (["render", "{tmp}/run", "--when", "noon"], "--when"),
    (["animate", "{tmp}/run", "--fps", "0"], "--fps"),
    (["animate", "{tmp}/run", "--frames", "0"], "--frames"),
    (["animate", "{tmp}/run", "--every", "0"], "--every"),
    (["animate", "{tmp}/run", "--every", "-5"], "--every"),
    (["animate", "{tmp}/run", "--out", "{tmp}/run", "--quiet"], "--out"),
    (["animate", "{tmp}/run", "--out", "{tmp}/a_file", "--quiet"], "--out"),
    (["demo", "--out", "{tmp}/a_file", "--quiet"], "--out"),
    (["sweep", "{tmp}/missing_sweep.toml", "--out", "{tmp}/o7"], "sweep"),
    (["sweep", str(SCEN.parent / "sweep.toml"), "--workers", "0", "--out", "{tmp}/o7"],
     "--workers"),
    # grow
    (["grow", "{tmp}/flat.toml", "--out", "{tmp}/o5", "--quiet"], "positions"),
    (["grow", "{tmp}/tree.toml", "--set", "modell='x'", "--out", "{tmp}/o5"], "modell"),
    (["grow", "{tmp}/tree.toml", "--set", "growth.branch_anglez=3", "--out", "{tmp}/o5"],
     "growth.branch_anglez"),
    (["grow", "{tmp}/tree.toml", "--generations", "99", "--out", "{tmp}/o5"], "--generations"),
    (["grow", "{tmp}/tree.toml", "--out", "{tmp}/a_file", "--quiet"], "--out"),
    # tune
    (T + ["--lr", "nan", "--out", "{tmp}/o6"], "--lr"),
    (T + ["--lr", "-1", "--out", "{tmp}/o6"], "--lr"),
    (T + ["--temperature", "-1", "--out", "{tmp}/o6"], "temperature"),
    (T[:3] + ["{tmp}/garbage.npy", "--out", "{tmp}/o6"], "--target"),
    (T[:3] + ["{tmp}/truncated.npy", "--out", "{tmp}/o6"], "--target"),
    (T + ["--params", "S1", "--init", "Q=3", "--out", "{tmp}/o6"], "--init"),
    (T + ["--init", "S1=nan", "--out", "{tmp}/o6"], "--init"),
    (T + ["--light-every", "0", "--out", "{tmp}/o6"], "--light-every"),
    (T + ["--set", "light.photonz=1", "--out", "{tmp}/o6"], "light.photonz"),
    (T + ["--out", "{tmp}/run"], "--out"),
    # export-gltf
    (["export-gltf", "{tmp}/missing_run"], "RUN_DIR"),
    (["export-gltf", "{tmp}/run", "--day", "0"], "--day"),
    # hemiphoto
    (["hemiphoto", "{tmp}/run", "--at", "1,2,3", "--day", "1"], "--at"),
    (["hemiphoto", "{tmp}/run", "--at", "0.5,0.5"], "--day/--years"),
    (["hemiphoto", "{tmp}/run", "--at", "0.5,0.5", "--day", "99"], "--day"),
    (["hemiphoto", "{tmp}/run", "--at", "50,50", "--day", "1"], "--at"),
    (["hemiphoto", "{tmp}/run", "--at", "0.5,0.5", "--years", "--on", "13-45"], "--on"),
    (["hemiphoto", "{tmp}/run", "--at", "0.5,0.5", "--day", "1", "--size", "8"], "--size"),
    (["hemiphoto", "{tmp}/run", "--at", "0.5,0.5", "--day", "1", "--height", "0"], "--height"),
    (["hemiphoto", "{tmp}/o_none", "--at", "0.5,0.5", "--day", "1"], "RUN_DIR"),
    (["hemiphoto", "{tmp}/run", "--at", "0.5,0.5", "--day", "1", "--out", "{tmp}/a_file"],
     "--out"),
    # light-study of a run folder (under a world's trees): the run's scenario has no sensors
    (["light-study", "{tmp}/run", "--from", "2026-03-01", "--to", "2026-03-02", "--out",
      "{tmp}/o4"], "sensors"),
    # the command itself
    (["grwo", "x.toml"], "grwo"),
]


def _argv(case, tmp):
    return [a.replace("{tmp}", str(tmp)) for a in case]


def test_table_has_40_cases_over_every_command():
    assert len(CASES) >= 40
    cmds = {c[0][0] for c in CASES}
    assert {"run", "irradiance", "light-study", "render", "animate", "grow", "tune", "sweep",
            "demo", "export-gltf", "hemiphoto"} <= cmds


@pytest.mark.parametrize("argv, field", CASES, ids=[f"{i:02d}-{c[0][0]}-{c[1]}"
                                                    for i, c in enumerate(CASES)])
def test_bad_input_gives_one_line_exit_2_and_changes_nothing(world, capsys, argv, field):
    before = _digest(world)
    try:
        rc = main(_argv(argv, world))
    except SystemExit as e:   # argparse
        rc = e.code
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert len(lines) == 1, err
    assert "Traceback" not in err
    line = lines[0]
    assert field in line, line
    assert "allowed" in line or "invalid choice" in line, line
    assert "Fix" in line or "--help" in line or "did you mean" in line, line
    after = _digest(world)
    assert {k: v for k, v in after.items() if k in before} == before   # nothing changed


@pytest.mark.parametrize("argv, field", [
    (["run", str(SCEN), "--set", "light.photonz=10", "--out", "{tmp}/o"], "light.photonz"),
    (["render", "{tmp}/run", "--spp", "0"], "--spp"),
    (["irradiance", "{tmp}/bad.xml", "--out", "{tmp}/o3"], "SCENE"),
])
def test_console_script_exit_code_and_one_line(world, argv, field):
    exe = Path(sys.executable).parent / "mitsuba-veg"
    r = subprocess.run([str(exe), *_argv(argv, world)], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and field in lines[0] and "Traceback" not in r.stderr


def test_version_and_help_texts():
    exe = Path(sys.executable).parent / "mitsuba-veg"
    r = subprocess.run([str(exe), "--version"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == f"mitsuba-veg {mv.__version__}"
    from mitsuba_veg.cli import build_parser
    ap = build_parser()
    sub = next(a for a in ap._actions if a.__class__.__name__ == "_SubParsersAction")
    missing = []
    for name, p in sub.choices.items():
        for a in p._actions:
            if a.option_strings and a.dest != "help" and not (a.help or "").strip():
                missing.append(f"{name} {a.option_strings[0]}")
    assert not missing, missing


def test_render_warns_when_the_shipped_scenario_stands_in(world, tmp_path, caplog):
    """A run whose scenario file is gone: the render uses the shipped scenario of the same name
    and says so (it used to switch silently)."""
    import json as _json
    import logging
    from mitsuba_veg.render.history import load_run
    d = tmp_path / "run"
    shutil.copytree(world / "run", d)
    s = _json.loads((d / "summary.json").read_text())
    s["scenario"] = "/nonexistent/moss_garden/scenario.toml"
    (d / "summary.json").write_text(_json.dumps(s))
    with caplog.at_level(logging.WARNING, logger="mitsuba_veg"):
        run = load_run(d)
    assert run.scenario.path.name == "scenario.toml"
    assert any("is gone" in r.getMessage() and "--scenario" in r.getMessage()
               for r in caplog.records)


def test_a_plugins_own_error_reaches_the_user_without_mitsubas_traceback(tmp_path, capsys):
    """A bad property of the package's plugin in a user's XML: Mitsuba wraps the plugin's error
    in "failed to instantiate ... Traceback ..."; the command prints the plugin's own message
    on one line (where in the XML, which plugin, the field, the allowed values, the fix)."""
    from mitsuba_veg.errors import plugin_error
    xml = tmp_path / "bad_bands.xml"
    xml.write_text('<scene version="3.0.0">\n'
                   '  <integrator type="veg_photon_irradiance">'
                   '<string name="bands" value="par,purple"/></integrator>\n'
                   '  <emitter type="directional" id="sun">'
                   '<vector name="direction" value="0,-1,0"/></emitter>\n'
                   '  <shape type="rectangle" id="g"/>\n</scene>\n')
    assert main(["irradiance", str(xml), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "line 2" in err and "veg_photon_irradiance" in err
    assert "bands = 'par,purple' is invalid (allowed: comma-separated names of" in err
    assert plugin_error(RuntimeError("plain\n  message")) == "plain message"
