"""A run folder carries one run: SIGKILL at three moments resumes to the uninterrupted run,
a second writer is refused by the folder's lock, --fresh clears what an earlier run left, and
Ctrl-C ends with a checkpoint and a short message."""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
SMALL = ["light.photons=30000", "simulation.checkpoint_every=3", "simulation.frame_every=2"]
DAYS = 8
CLI = [sys.executable, "-c", "import sys; from mitsuba_veg.cli import main; "
       "sys.exit(main(sys.argv[1:]))"]

#: runs the command line in a child process, first wrapping one function so that the process
#: kills itself with SIGKILL at a chosen moment
DRIVER = textwrap.dedent('''
    import os, signal, sys
    import numpy as np
    import mitsuba_veg.daily.checkpoint as checkpoint
    import mitsuba_veg.daily.pipeline as pipeline
    import mitsuba_veg.outputs as outputs
    moment = sys.argv[1]

    def die():
        os.kill(os.getpid(), signal.SIGKILL)

    if moment == "between_checkpoints":
        step = pipeline.Simulation.step
        def patched(self):
            if self.day == 5:          # day 5 done, the last checkpoint holds day 3
                die()
            return step(self)
        pipeline.Simulation.step = patched
    elif moment == "checkpoint_write":
        save = checkpoint.save
        def patched(sim):
            if sim.day == 6:           # half of checkpoint.tmp.npz written, then killed
                (sim.out / "checkpoint.tmp.npz").write_bytes(b"PK\\x03\\x04" + b"\\0" * 500)
                die()
            return save(sim)
        checkpoint.save = patched
    elif moment == "map_write":
        write = outputs.DayFrames.write_day
        def patched(self, sim, rec):
            if rec["day"] == 4:        # a map half written
                self.dir.mkdir(parents=True, exist_ok=True)
                (self.dir / ".day_0004.tmp.png").write_bytes(b"\\x89PNG" + b"\\0" * 100)
                die()
            return write(self, sim, rec)
        outputs.DayFrames.write_day = patched
    from mitsuba_veg.cli import main
    sys.exit(main(sys.argv[2:]))
''')


def _cli(out, *extra, moment="none", tmp=None, check=True):
    driver = Path(tmp or out.parent) / "driver.py"
    driver.write_text(DRIVER)
    argv = ["run", str(SCEN), "--out", str(out), "--days", str(DAYS), "--quiet"]
    for s in SMALL:
        argv += ["--set", s]
    r = subprocess.run([sys.executable, str(driver), moment, *argv, *extra],
                       capture_output=True, text=True, timeout=600)
    if check:
        assert r.returncode == 0, r.stderr
    return r


def _state(out: Path):
    s = json.loads((out / "summary.json").read_text())
    recs = [{k: v for k, v in r.items() if k != "seconds"} for r in s["days_record"]]
    ck = np.load(out / "checkpoint.npz")
    arrays = {k: ck[k] for k in ("state", "species", "elem", "growth", "age", "pos", "O", "day")}
    maps = sorted(p.name for p in (out / "maps").iterdir())
    snaps = sorted(p.name for p in (out / "snapshots").iterdir())
    return recs, arrays, maps, snaps


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "run"
    _cli(out)
    return _state(out)


@pytest.mark.parametrize("moment", ["between_checkpoints",
                                    pytest.param("checkpoint_write", marks=pytest.mark.slow),
                                    pytest.param("map_write", marks=pytest.mark.slow)])
def test_sigkill_then_resume_equals_uninterrupted_run(tmp_path, reference, moment):
    out = tmp_path / "run"
    r = _cli(out, moment=moment, check=False)
    assert r.returncode == -signal.SIGKILL
    assert not (out / "summary.json").exists()
    assert (out / "checkpoint.npz").exists()          # the day-3 checkpoint survived
    _cli(out)                                          # the same command again resumes
    recs, arrays, maps, snaps = _state(out)
    ref_recs, ref_arrays, ref_maps, ref_snaps = reference
    assert recs == ref_recs
    for k, v in ref_arrays.items():
        assert np.array_equal(arrays[k], v), k
    assert maps == ref_maps and snaps == ref_snaps     # no half-written leftovers
    summary = json.loads((out / "summary.json").read_text())
    assert summary["resumed"]
    # the summary lists every map of the run, also those written before the kill
    assert sorted(Path(m).name for m in summary["files"]["maps"]) == ref_maps


def test_second_writer_is_refused_by_the_lock(tmp_path):
    out = tmp_path / "run"
    first = subprocess.Popen([*CLI, "run", str(SCEN), "--out", str(out), "--days", "400",
                              "--quiet", "--set", "light.photons=20000"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        lock = out / ".mitsuba-veg.lock"
        t0 = time.time()
        while not (lock.exists() and lock.read_text().strip() == str(first.pid)):
            assert first.poll() is None, first.stderr.read()
            assert time.time() - t0 < 120
            time.sleep(0.2)
        second = subprocess.run([*CLI, "run", str(SCEN), "--out", str(out), "--days", "3",
                                 "--quiet", "--set", "light.seed=7"], capture_output=True,
                                text=True, timeout=300)
        assert second.returncode == 2
        lines = [ln for ln in second.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and "--out" in lines[0] and str(first.pid) in lines[0]
        assert first.poll() is None                     # the first run goes on
    finally:
        first.kill()
        first.wait()
    # the lock dies with its process: the folder can be used again (and resumes)
    r = subprocess.run([*CLI, "run", str(SCEN), "--out", str(out), "--days", "2", "--fresh",
                        "--quiet", "--set", "light.photons=20000"], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr


#: takes a folder's lock, then ends its main thread alone (as a SIGKILLed multi-threaded process
#: does first) while another thread keeps the process, and so the lock, for HOLD seconds
EXITING_HOLDER = textwrap.dedent("""
    import ctypes, os, sys, threading, time
    from mitsuba_veg.outputs import OutputFolder
    folder = OutputFolder(sys.argv[1], "run")   # held: the lock lives with the object
    hold = float(sys.argv[2])
    threading.Thread(target=lambda: (time.sleep(hold), os._exit(0))).start()
    print("locked", flush=True)
    ctypes.CDLL(None, use_errno=True).syscall(60 if os.uname().machine == "x86_64" else 93, 0)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and SYS_exit")
def test_a_folder_whose_holder_is_exiting_is_waited_for(tmp_path, monkeypatch):
    """A process killed while it holds a folder keeps the lock until its last thread has
    gone; a run started at once (a sweep resuming, a retried task) waits for that instead of
    failing, and a live holder is still refused at once."""
    from mitsuba_veg import outputs
    from mitsuba_veg.errors import ParameterError
    out = tmp_path / "run"
    holder = subprocess.Popen([sys.executable, "-c", EXITING_HOLDER, str(out), "3"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        t0 = time.monotonic()
        while Path(f"/proc/{holder.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
            assert time.monotonic() - t0 < 10, "the holder's main thread did not end"
            time.sleep(0.01)
        assert outputs._process_exiting(str(holder.pid))
        monkeypatch.setattr(outputs, "EXITING_GRACE_S", 0.2)
        with pytest.raises(ParameterError, match=f"process {holder.pid} holds it"):
            outputs.OutputFolder(out, "run")           # past the grace: refused, named
        monkeypatch.setattr(outputs, "EXITING_GRACE_S", 30.0)
        t0 = time.monotonic()
        folder = outputs.OutputFolder(out, "run")      # waits for the exiting holder
        waited = time.monotonic() - t0
        folder.release()
        assert 0.5 < waited < 10, waited
    finally:
        holder.kill()
        holder.wait()
    assert not outputs._process_exiting(str(os.getpid()))


def test_fresh_run_clears_what_an_earlier_run_left(tmp_path):
    """run --days 6, then --days 3 --fresh with another seed: maps, snapshots, the GIF and the
    animation's frame days hold the new run only; a render folder the package wrote goes, and
    the user's own files in the run folder stay."""
    import mitsuba_veg as mv
    from mitsuba_veg.atomic import atomic_write
    from mitsuba_veg.outputs import OutputFolder
    from mitsuba_veg.render.history import load_run
    out = tmp_path / "run"
    mv.run(SCEN, out=out, days=6, overrides=SMALL, progress=False)
    for sub in ("render", "animation"):      # as `render` and `animate` write them
        with OutputFolder(out / sub, "render" if sub == "render" else "animate"):
            with atomic_write(out / sub / "old.png") as tmp:
                tmp.write_bytes(b"old")
    (out / "animation" / "photo_2025.png").write_bytes(b"mine")   # the user's own files
    (out / "maps" / "site_plan.png").write_bytes(b"mine")
    (out / "notes.txt").write_text("mine")
    s = mv.run(SCEN, out=out, days=3, overrides=SMALL + ["light.seed=7"], resume=False,
               progress=False)
    assert s["days"] == 3 and not s["resumed"]
    assert sorted(p.name for p in (out / "maps").glob("day_*.png")) == \
        ["day_0001.png", "day_0002.png", "day_0003.png"]
    assert sorted(p.name for p in (out / "snapshots").glob("day_*.npz")) == \
        ["day_0001.npz", "day_0002.npz", "day_0003.npz"]
    assert not (out / "render").exists()
    assert sorted(p.name for p in (out / "animation").iterdir()
                  if not p.name.startswith(".")) == ["photo_2025.png"]
    assert (out / "animation" / "photo_2025.png").read_bytes() == b"mine"
    assert (out / "maps" / "site_plan.png").read_bytes() == b"mine"
    assert (out / "notes.txt").read_text() == "mine"
    from PIL import Image
    assert Image.open(out / "days.gif").n_frames == 3
    run = load_run(out)
    assert run.final_day == 3 and max(run.frame_days(count=10)) == 3
    assert all(run.frame(d).exact for d in run.frame_days(count=10))


@pytest.mark.slow
def test_ctrl_c_writes_a_checkpoint_and_says_how_to_resume(tmp_path):
    out = tmp_path / "run"
    p = subprocess.Popen([*CLI, "run", str(SCEN), "--out", str(out), "--days", "400",
                          "--quiet", "--set", "light.photons=20000", "--set",
                          "simulation.checkpoint_every=0"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while not (out / "maps" / "day_0010.png").exists():   # a few days have run
        assert p.poll() is None, p.stderr.read()
        assert time.time() - t0 < 300
        time.sleep(0.2)
    p.send_signal(signal.SIGINT)
    err = p.communicate(timeout=120)[1]
    assert p.returncode == 130
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err and "resume" in lines[0], err
    ck = np.load(out / "checkpoint.npz")
    assert int(ck["day"]) >= 10
