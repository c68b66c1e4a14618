"""`mitsuba-veg sweep` on a real Dask LocalCluster of 2 worker processes (small runs)."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed", reason="the 'distributed' extra is not installed")
import pandas as pd  # noqa: E402
from distributed import Client, LocalCluster  # noqa: E402

import mitsuba_veg as mv  # noqa: E402
from mitsuba_veg.errors import DependencyError, ParameterError  # noqa: E402
from mitsuba_veg.sweeps import load_sweep  # noqa: E402
from mitsuba_veg.sweeps.table import comparable  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
SMALL = ["light.photons=30000", "simulation.checkpoint_every=3", "simulation.frame_every=10"]


def write_sweep(path: Path, days: int, axes: str, seeds="[0, 1]", frames=False,
                extra: str = "") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"""
[sweep]
scenario = "{SCEN}"
days = {days}
seeds = {seeds}
set = {json.dumps(SMALL)}
frames = {"true" if frames else "false"}
{extra}
[axes]
{axes}
""")
    return path


AXES_2X2 = """
"climate.temperature" = [288.15, 293.15]
"moss.species" = [["bryum_argenteum"], ["polytrichum"]]
"""


def strip(records):
    return [{k: v for k, v in r.items() if k != "seconds"} for r in records]


@pytest.fixture(scope="module")
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as c:
        yield c


@pytest.mark.slow
def test_sweep_equals_the_same_runs_made_one_by_one(tmp_path, client):
    days = 6
    f = write_sweep(tmp_path / "s.toml", days, AXES_2X2, frames=True)
    df = mv.sweep(f, tmp_path / "out", client=client, progress=False)
    sw = load_sweep(f)
    assert len(sw.runs) == 8
    assert list(df.columns[:7]) == ["run", "index", "status", "error", "climate.temperature",
                                    "moss.species", "light.seed"]
    assert len(df) == 8 * days and set(df["status"]) == {"done"}
    assert {"day", "date", "moss_alive", "covered_area_m2", "mean_S_W_m2", "mean_Ts_K",
            "regions.under_roof.covered_area_m2", "events.germinated",
            "alive.Bryum argenteum"} <= set(df.columns)
    # bit-identical to the same runs made one by one in this process
    for r in sw.runs:
        one = mv.run(SCEN, out=tmp_path / "one" / r.run_id, days=days, overrides=r.overrides,
                     progress=False, frames=False)
        folder = tmp_path / "out" / "runs" / r.run_id
        in_sweep = json.loads((folder / "summary.json").read_text())
        assert strip(in_sweep["days_record"]) == strip(one["days_record"]), r.values
        rows = df[df["run"] == r.run_id].sort_values("day")
        assert rows["covered_area_m2"].tolist() == [x["covered_area_m2"]
                                                     for x in one["days_record"]]
        assert rows["moss_alive"].tolist() == [x["moss_alive"] for x in one["days_record"]]
        assert (rows["climate.temperature"] == r.values["climate.temperature"]).all()
        assert (folder / "checkpoint.npz").exists() and (folder / "maps").is_dir()
    # the files: Parquet and CSV hold the table; the plots
    out = tmp_path / "out"
    back = pd.read_parquet(out / "sweep.parquet")
    pd.testing.assert_frame_equal(back, df, check_dtype=False)
    assert len(pd.read_csv(out / "sweep.csv")) == len(df)
    assert (out / "plots" / "cover_by_day.png").exists()
    assert (out / "plots" / "final_vs_climate_temperature.png").exists()
    m = json.loads((out / "sweep.json").read_text())
    assert m["counts"] == {"done": 8, "skipped": 0, "failed": 0}
    assert {r["drjit_threads"] for r in m["runs"]} == {1}      # 2 cores / 2 workers
    # again into the same folder: nothing to run, the same table
    again = mv.sweep(f, out, client=client, progress=False, plots=False)
    assert set(again["status"]) == {"skipped"}
    pd.testing.assert_frame_equal(comparable(again), comparable(df))


def _checkpoint_day(run: Path) -> int:
    """The day of a run folder's checkpoint; -1 without a readable one."""
    try:
        with np.load(run / "checkpoint.npz") as d:
            return int(d["day"])
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return -1


@pytest.mark.parametrize("kill", ["group", pytest.param("parent", marks=pytest.mark.slow)])
def test_sweep_killed_midway_resumes_to_the_same_table(tmp_path, client, kill):
    """SIGKILL of the sweep with its cluster (``group``), or of the sweep's process alone
    (``parent``: its orphaned workers may still hold a run folder when the resumed sweep's task
    for that run arrives): run again at once, the table is the uninterrupted one."""
    days = 24
    axes = '"climate.temperature" = [288.15, 293.15]'
    f = write_sweep(tmp_path / "s.toml", days, axes)          # 4 runs
    ref = mv.sweep(f, tmp_path / "ref", client=client, progress=False, plots=False)
    out = tmp_path / "killed"
    code = ("import mitsuba_veg as mv; "
            f"mv.sweep({str(f)!r}, {str(out)!r}, workers=2, progress=False, plots=False, "
            "dashboard_address=':0')")
    p = subprocess.Popen([sys.executable, "-c", code], start_new_session=True,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 150:
            runs = list((out / "runs").glob("run-*")) if (out / "runs").is_dir() else []
            done = [r for r in runs if (r / "summary.json").exists()]
            # a run with at least 9 of its days still to go when it is killed (a run near its
            # end could finish between this check and the kill: then nothing would resume)
            partial = [r for r in runs if not (r / "summary.json").exists()
                       and 0 <= _checkpoint_day(r) <= days - 9]
            if done and partial:
                break
            assert p.poll() is None, "the sweep ended before it could be killed"
            time.sleep(0.05)
        else:
            pytest.fail("no run finished within 150 s")
    finally:
        if kill == "group":
            os.killpg(p.pid, signal.SIGKILL)   # the sweep, its scheduler and its workers
        else:
            os.kill(p.pid, signal.SIGKILL)     # the sweep's process alone
        p.wait()
    assert not (out / "sweep.parquet").exists()
    assert any(not (r / "summary.json").exists() and _checkpoint_day(r) >= 0
               for r in (out / "runs").glob("run-*")), "no run was left part-way"
    try:
        df = mv.sweep(f, out, client=client, progress=False, plots=False)
    finally:
        try:
            os.killpg(p.pid, signal.SIGKILL)   # the orphans of a killed parent, if any left
        except ProcessLookupError:
            pass
    m = json.loads((out / "sweep.json").read_text())
    statuses = {r["status"] for r in m["runs"]}
    seen = [(r["run"], r["status"], r["resumed"], r["error"]) for r in m["runs"]]
    assert "skipped" in statuses and "done" in statuses, seen
    assert any(r["resumed"] for r in m["runs"] if r["status"] == "done"), seen
    pd.testing.assert_frame_equal(comparable(df), comparable(ref))


def test_failing_run_is_reported_not_fatal(tmp_path, client):
    """A run that fails where only the run can tell (a shape id the scene lacks) is a failed
    row with its error; the other runs go on."""
    f = write_sweep(tmp_path / "s.toml", 3, '"terrain.ground" = ["ground", "grund"]',
                    seeds="[0]")
    df = mv.sweep(f, tmp_path / "out", client=client, progress=False)
    bad = df[df["terrain.ground"] == "grund"]
    good = df[df["terrain.ground"] == "ground"]
    assert len(bad) == 1 and bad["status"].item() == "failed"
    assert "terrain.ground = 'grund'" in bad["error"].item()
    assert bad["day"].isna().all()
    assert len(good) == 3 and set(good["status"]) == {"done"}
    m = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert m["counts"] == {"done": 1, "skipped": 0, "failed": 1}
    folder = tmp_path / "out" / "runs" / bad["run"].item()
    assert "ParameterError" in json.loads((folder / "error.json").read_text())["error"]
    # the CLI says which run failed (on stderr too, with --quiet) and exits 1
    from mitsuba_veg.cli import main
    import contextlib
    import io
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["sweep", str(f), "--out", str(tmp_path / "out"), "--quiet", "--no-plots",
                     "--scheduler", client.scheduler.address]) == 1
    assert "1 of 2 runs failed" in err.getvalue() and "grund" in err.getvalue()


def test_bad_axis_value_is_refused_before_anything_starts(tmp_path):
    """A value the scenario refuses, in any combination, ends the sweep before the cluster
    starts: one line naming the field, the value and the run, exit code 2, nothing written."""
    f = write_sweep(tmp_path / "s.toml", 3, '"climate.humidity" = [0.5, 7.0]', seeds="[0]")
    with pytest.raises(ParameterError, match=r"the run with climate\.humidity=7\.0.*"
                       r"climate\.humidity = 7\.0 is invalid"):
        load_sweep(f)
    g = write_sweep(tmp_path / "t.toml", 3, '"moss.species" = [["bryum_argenteum"], '
                    '["bryum_argentum"]]', seeds="[0]")
    with pytest.raises(ParameterError, match=r"moss\.species = 'bryum_argentum'"):
        load_sweep(g)
    r = subprocess.run([sys.executable, "-m", "mitsuba_veg.cli", "sweep", str(f), "--out",
                        str(tmp_path / "o"), "--quiet"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "climate.humidity = 7.0" in lines[0], r.stderr
    assert not (tmp_path / "o").exists()


def test_edited_input_file_gives_new_run_ids(tmp_path):
    """The run ids hash the content of the files a run reads: an edited scene (or weather, or
    mesh) file makes new runs instead of taking the old ones as finished."""
    import shutil
    scen = tmp_path / "scen"
    shutil.copytree(SCEN.parent, scen)
    f = write_sweep(tmp_path / "s.toml", 3, '"climate.temperature" = [288.15]', seeds="[0]")
    f.write_text(f.read_text().replace(str(SCEN), str(scen / "scenario.toml")))
    before = [r.run_id for r in load_sweep(f).runs]
    assert [r.run_id for r in load_sweep(f).runs] == before          # stable
    xml = scen / "scene.xml"
    xml.write_text(xml.read_text().replace('value="0.35"', 'value="0.9"', 1))
    after = [r.run_id for r in load_sweep(f).runs]
    assert after != before
    (scen / "wall.ply").write_bytes((scen / "wall.ply").read_bytes() + b"\n")
    assert [r.run_id for r in load_sweep(f).runs] != after


def test_worker_lost_midrun_is_retried_and_resumes(tmp_path, client):
    days = 30
    f = write_sweep(tmp_path / "s.toml", days, '"climate.temperature" = [288.15]')  # 2 runs
    ref = [mv.run(SCEN, out=tmp_path / "one" / r.run_id, days=days, overrides=r.overrides,
                  progress=False, frames=False) for r in load_sweep(f).runs]
    out = tmp_path / "out"
    box = {}
    th = threading.Thread(target=lambda: box.setdefault(
        "df", mv.sweep(f, out, client=client, progress=False, plots=False)))
    th.start()
    killed = None
    t0 = time.monotonic()
    while killed is None and time.monotonic() - t0 < 120 and th.is_alive():
        for r in (out / "runs").glob("run-*") if (out / "runs").is_dir() else []:
            # at least 9 days to go: the run cannot finish before the kill lands
            if not (r / "summary.json").exists() and 0 <= _checkpoint_day(r) <= days - 9:
                for addr, keys in client.processing().items():
                    if any(r.name in str(k) for k in keys):
                        pid = client.run(os.getpid, workers=[addr])[addr]
                        os.kill(pid, signal.SIGKILL)
                        killed = r.name
                        break
            if killed:
                break
        time.sleep(0.05)
    th.join(300)
    assert killed, "no run was caught mid-way"
    df = box["df"]
    m = json.loads((out / "sweep.json").read_text())
    run = [x for x in m["runs"] if x["run"] == killed][0]
    assert run["status"] == "done" and run["resumed"]
    for r, one in zip(load_sweep(f).runs, ref):
        rows = df[df["run"] == r.run_id].sort_values("day")
        assert rows["covered_area_m2"].tolist() == [x["covered_area_m2"]
                                                     for x in one["days_record"]]
        got = json.loads((out / "runs" / r.run_id / "summary.json").read_text())
        assert strip(got["days_record"]) == strip(one["days_record"])
    client.wait_for_workers(2, timeout=60)


# ---- the sweep file: validated before any run (no cluster needed) -------------------------------
def test_sweep_file_unknown_keys_and_fields_are_refused(tmp_path):
    f = write_sweep(tmp_path / "a.toml", 3, AXES_2X2, extra="sedes = [1]")
    with pytest.raises(ParameterError, match=r"a\.toml: sweep\.sedes = \[1\].*'sweep\.seeds'"):
        load_sweep(f)
    f = write_sweep(tmp_path / "b.toml", 3, '"climate.temprature" = [288.0]')
    with pytest.raises(ParameterError,
                       match=r"b\.toml: axes\.climate\.temprature .*'climate\.temperature'"):
        load_sweep(f)
    (tmp_path / "c.toml").write_text(f'[sweep]\nscenario = "{SCEN}"\n[axis]\n"x" = [1]\n')
    with pytest.raises(ParameterError, match=r"c\.toml: axis .*'axes'"):
        load_sweep(tmp_path / "c.toml")
    # the CLI: one line on stderr, exit code 2, before any cluster starts
    r = subprocess.run([sys.executable, "-m", "mitsuba_veg.cli", "sweep", str(f), "--out",
                        str(tmp_path / "o")], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "climate.temprature" in r.stderr
    assert not (tmp_path / "o").exists()


def test_sweep_file_ranges_seeds_and_run_folders(tmp_path):
    f = write_sweep(tmp_path / "s.toml", 3, """
"climate.humidity" = {start = 0.6, stop = 0.8, num = 3}
moss.initial = {start = 100, stop = 300, step = 100}
""", seeds="{start = 4, stop = 5, step = 1}")
    sw = load_sweep(f)
    assert sw.axes == {"climate.humidity": [0.6, 0.7, 0.8], "moss.initial": [100, 200, 300],
                       "light.seed": [4, 5]}
    assert len(sw.runs) == 18 and len({r.run_id for r in sw.runs}) == 18
    assert sw.runs[1].overrides[-3:] == ["climate.humidity=0.6", "moss.initial=100",
                                         "light.seed=5"]
    # a run keeps its folder when the sweep grows
    g = write_sweep(tmp_path / "t.toml", 3, """
"climate.humidity" = [0.5, 0.6, 0.7, 0.8]
moss.initial = [100, 200, 300]
""", seeds="[4, 5, 6]")
    ids = {r.run_id for r in load_sweep(g).runs}
    assert {r.run_id for r in sw.runs} <= ids
    with pytest.raises(ParameterError, match=r"axes\.climate\.humidity\.num"):
        load_sweep(write_sweep(tmp_path / "u.toml", 3,
                               '"climate.humidity" = {start = 0.6, stop = 0.8, num = 0}'))


def test_package_import_leaves_dask_out_and_missing_extra_says_how(monkeypatch):
    r = subprocess.run([sys.executable, "-c", "import sys, mitsuba_veg as mv; "
                        "print(callable(mv.sweep), sorted(m for m in ('dask', 'distributed', "
                        "'pandas', 'pyarrow') if m in sys.modules))"],
                       capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "True []"
    from mitsuba_veg.sweeps.cluster import require_distributed
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(DependencyError, match=r"pip install 'mitsuba-veg\[distributed\]'"):
        require_distributed()


@pytest.mark.slow
def test_animation_frames_as_dask_tasks_match_the_sequential_ones(tmp_path, client):
    import numpy as np
    from PIL import Image

    from mitsuba_veg.sweeps.frames import run_animate
    from mitsuba_veg.render.history import run_with_snapshots
    run_with_snapshots(SCEN, tmp_path / "run", days=4, every=2, progress=False,
                       overrides=["light.photons=20000", "moss.initial=400"])
    kw = dict(width=64, height=48, spp=4, frames=3, progress=False)
    seq = run_animate(tmp_path / "run", tmp_path / "seq", **kw)
    dsk = run_animate(tmp_path / "run", tmp_path / "dask", client=client, **kw)
    assert [f["day"] for f in dsk["frames"]] == [f["day"] for f in seq["frames"]] == [1, 2, 4]
    assert dsk["dask"]["workers"] == 2 and Path(dsk["files"]["gif"]).exists()
    for k in range(3):
        a, b = (np.asarray(Image.open(tmp_path / d / "frames" / f"frame_{k:04d}.png"))
                for d in ("seq", "dask"))
        assert np.array_equal(a, b), k     # same exposure (from the last frame), same pixels
