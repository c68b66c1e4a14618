"""``mitsuba-veg grow``: run_grow writes mesh, metrics, picture and summary; TREE.toml errors
name file and field; the shipped scenes/trees/*.toml are valid; the Weber-Penn hook."""
import argparse
import json
import sys
from pathlib import Path

import pytest

import mitsuba_veg  # noqa: F401  (variant)
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.cli.grow import add_parser, build_environment, load_tree_toml, run_grow
from mitsuba_veg.trees.growth import GrowthParams

ROOT = Path(__file__).resolve().parents[1]
SMALL = """
model = "growth"
seed = 1
generations = 5
positions = [[-2.0, 0.0, 0.0], [2.0, 0.0]]
[growth]
branch_angle = 50.0
[environment]
ground = { size = 30.0, cells = 10 }
boxes = [{ lo = [-8.0, 0.0, -5.0], hi = [-7.0, 6.0, 5.0] }]
"""


def _toml(tmp_path, text, name="t.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_run_grow_writes_everything(tmp_path):
    s = run_grow(_toml(tmp_path, SMALL), tmp_path / "out", ["growth.phototropism=0.6"],
                 progress=False)
    out = tmp_path / "out"
    for f in ("tree.ply", "tree.glb", "metrics.json", "picture.png", "summary.json"):
        assert (out / f).stat().st_size > 0, f
    m = json.loads((out / "metrics.json").read_text())
    assert len(m["trees"]) == 2 and m["stand"]["trees"] == 2
    for k in ("height", "crown_centroid", "crown_radius", "live_branches", "dead_branches",
              "leaves"):
        assert k in m["trees"][0]
    summ = json.loads((out / "summary.json").read_text())
    assert summ["params"]["branch_angle"] == 50.0 and summ["params"]["phototropism"] == 0.6
    assert len(summ["history"]) == 6 and summ["rays"] > 0
    assert s["files"]["picture"].endswith("picture.png")
    import trimesh
    mesh = trimesh.load(out / "tree.ply", force="mesh")
    assert len(mesh.faces) > 100


@pytest.mark.parametrize("override,field", [("growth.branch_angle=200", "growth.branch_angle"),
                                            ("growth.brnch=1", "growth.brnch"),
                                            ("colour=1", "colour"),
                                            ("generations=-2", "generations"),
                                            ("model='oak'", "model"),
                                            ("output.formats=['fbx']", "output.formats"),
                                            ("positions=[[1, 2, 3, 4]]", "positions"),
                                            ("nongrowth.shading=2.0", "nongrowth.shading")])
def test_bad_values_name_file_and_field(tmp_path, override, field):
    p = _toml(tmp_path, SMALL)
    with pytest.raises(ParameterError) as e:
        run_grow(p, tmp_path / "o", [override], progress=False)
    assert field in str(e.value) and "t.toml" in str(e.value)


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ParameterError, match="existing"):
        load_tree_toml(tmp_path / "nope.toml")
    with pytest.raises(ParameterError, match="valid TOML"):
        load_tree_toml(_toml(tmp_path, "model = ", "bad.toml"))


def test_shipped_tree_files_are_valid():
    files = sorted((ROOT / "scenes" / "trees").glob("*.toml"))
    assert len(files) >= 6
    for f in files:
        d = load_tree_toml(f)
        GrowthParams.from_dict(d.get("growth", {}), str(f))
        build_environment(d.get("environment", {}), f.parent, str(f))


def test_nongrowth_section(tmp_path):
    s = run_grow(ROOT / "scenes" / "trees" / "stand_5x5_nongrowth.toml", tmp_path,
                 ["generations=4", "output.formats=['ply']"], progress=False)
    assert [st["rule"] for st in s["nongrowth"]] == ["death", "heliotropism"]
    assert (tmp_path / "tree.ply").exists() and not (tmp_path / "tree.glb").exists()


def test_weber_penn_model(tmp_path, monkeypatch):
    p = _toml(tmp_path, 'model = "weber_penn"\npreset = "quaking_aspen"\n')
    try:
        import mitsuba_veg.trees.weber_penn  # noqa: F401
        have = True
    except ImportError:
        have = False
    if have:
        s = run_grow(p, tmp_path / "wp", progress=False)
        assert s["metrics"]["live_branches"] > 10
    monkeypatch.setitem(sys.modules, "mitsuba_veg.trees.weber_penn", None)
    monkeypatch.delattr(mitsuba_veg.trees, "weber_penn", raising=False)
    with pytest.raises(ParameterError, match="weber_penn"):
        run_grow(p, tmp_path / "wp2", progress=False)


def test_weber_penn_table_overrides_and_conflicts(tmp_path):
    """Keys of [weber_penn] besides preset/params override the preset; nothing is dropped."""
    from mitsuba_veg.cli.grow import _weber_penn
    plain = _weber_penn({"preset": "quaking_aspen"}, 0, "t")
    short = _weber_penn({"weber_penn": {"preset": "quaking_aspen", "Scale": 5.0}}, 0, "t")
    ys = lambda t: float(max(t.end[:, 1].max(), t.start[:, 1].max()))     # tree height [m]
    assert ys(short) < 0.8 * ys(plain)              # quaking aspen's Scale is 13 m
    with pytest.raises(ParameterError, match=r"weber_penn\.bogus"):
        _weber_penn({"weber_penn": {"bogus": 1}}, 0, "t")
    with pytest.raises(ParameterError, match="preset and weber_penn.preset"):
        _weber_penn({"preset": "quaking_aspen", "weber_penn": {"preset": "quaking_aspen"}}, 0,
                    "t")


def test_add_parser():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd")
    add_parser(sub)
    a = ap.parse_args(["grow", "x.toml", "--out", "d", "--set", "seed=3", "--generations", "4"])
    assert a.tree == "x.toml" and a.out == "d" and a.set == ["seed=3"] and a.generations == 4
    assert callable(a.func)
