"""`mitsuba-veg render` / `animate` on a tiny real moss run (4 days, few photons)."""
import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg  # noqa: F401
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.render import film
from mitsuba_veg.cli.render import add_parsers, run_animate, run_render
from mitsuba_veg.render.history import load_run, run_with_snapshots

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenes" / "moss_garden" / "scenario.toml"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    run_with_snapshots(SCENARIO, out, days=4, every=2, progress=False,
                       overrides=["light.photons=20000", "moss.initial=400"])
    return out


def test_run_has_snapshots(run_dir):
    run = load_run(run_dir)
    assert run.final_day == 4
    assert [d for d, _ in run.snapshots] == [1, 2, 4]
    assert run.frame(2).exact and len(run.final_moss()) > 100


def test_run_render_writes_exr_png_and_rfr(run_dir, tmp_path):
    s = run_render(run_dir, tmp_path / "r", camera="overview", width=64, height=48, spp=4,
                   progress=False)
    f = s["files"]["overview"]
    ch = film.read_exr(f["exr"])
    assert {"R", "G", "B", "red_655_665", "far_red_725_735", "R_FR"} <= set(ch)
    assert ch["R"].shape == (48, 64) and np.all(np.isfinite(ch["G"]))
    from PIL import Image
    png = np.asarray(Image.open(f["png"]))
    assert png.shape == (48, 64, 3)
    assert 10 < png.mean() < 245                        # neither black nor blown out
    assert Path(f["rfr_png"]).exists()
    js = json.loads((tmp_path / "r" / "render.json").read_text())
    assert js["day"] == 4 and js["moss"] == s["moss"] > 100 and js["moss_exact"]
    assert 0.2 < js["cameras"]["overview"]["r_fr_median"] < 2.0
    with pytest.raises(ParameterError):
        run_render(run_dir, tmp_path / "x", day=99, width=16, height=16, spp=1, progress=False)


@pytest.mark.slow
def test_run_animate_writes_mp4_and_gif(run_dir, tmp_path):
    s = run_animate(run_dir, tmp_path / "a", width=48, height=32, spp=2, frames=3, fps=4,
                    progress=False)
    assert [r["day"] for r in s["frames"]] == [1, 2, 4] and s["exact"]
    from PIL import Image
    gif = Image.open(s["files"]["gif"])
    assert gif.n_frames == 3
    assert len(list((tmp_path / "a" / "frames").glob("frame_*.png"))) == 3
    if shutil.which("ffmpeg"):
        assert Path(s["files"]["mp4"]).stat().st_size > 1000
    else:
        assert s["files"]["mp4"] is None and "ffmpeg" in s["warning"]
    assert json.loads((tmp_path / "a" / "animate.json").read_text())["command"] == "animate"


def test_add_parsers():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd")
    add_parsers(sub)
    a = ap.parse_args(["render", "out/run", "--camera", "overview,shelter", "--spp", "8"])
    assert a.run_dir == "out/run" and a.spp == 8 and callable(a.func)
    a = ap.parse_args(["animate", "out/run", "--frames", "5", "--light", "daily"])
    assert a.frames == 5 and a.light == "daily"
