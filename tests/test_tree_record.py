"""A world run's initial trees kept in its folder (mitsuba_veg.world.tree_record): written by
the run, read by the commands that draw its trees instead of re-growing them."""
import json
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg as mv
from mitsuba_veg.scenario import load_scenario
from mitsuba_veg.world import tree_record as tr
from mitsuba_veg.world.trees import WorldTree, scenario_trees

ROOT = Path(__file__).resolve().parent.parent
COURTYARD = ROOT / "scenes" / "courtyard" / "scenario.toml"
TREE_FIELDS = ("start", "end", "radius_start", "radius_end", "parent", "level", "alive", "kind")


@pytest.fixture(scope="module")
def courtyard_trees():
    """The courtyard's three trees: paper 001's growth tree, a Weber-Penn aspen and one
    adapted by paper 002's rules."""
    s = load_scenario(COURTYARD)
    return scenario_trees(s, s.load_scene(daylight=False))


def _same(a: WorldTree, b: WorldTree):
    assert (a.name, a.model, a.info) == (b.name, b.model, b.info)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.bark[0], b.bark[0])
    np.testing.assert_array_equal(a.bark[1], b.bark[1])
    np.testing.assert_array_equal(a.leaf_vertices, b.leaf_vertices)
    np.testing.assert_array_equal(a.leaf_area, b.leaf_area)
    if a.tree is None:
        assert b.tree is None
        return
    for f in TREE_FIELDS:
        np.testing.assert_array_equal(getattr(a.tree, f), getattr(b.tree, f))
    for f in ("position", "normal", "size", "segment", "up"):
        np.testing.assert_array_equal(getattr(a.tree.leaves, f), getattr(b.tree.leaves, f))
    assert sorted(a.tree.attrs) == sorted(b.tree.attrs)
    for k, v in a.tree.attrs.items():
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(v, b.tree.attrs[k])
        else:
            assert json.dumps(v, default=float) == json.dumps(b.tree.attrs[k], default=float), k
    wa, wb = getattr(a.tree, "weber_penn", None), getattr(b.tree, "weber_penn", None)
    assert (wa is None) == (wb is None)
    if wa is not None:
        assert wa.params == wb.params and (wa.seed, wa.knots, wa.scale_tree) == \
            (wb.seed, wb.knots, wb.scale_tree)


def test_the_record_gives_back_the_trees_as_built(courtyard_trees, tmp_path):
    """Growth, Weber-Penn, paper 002's adapted tree and a user's mesh tree: structure, leaves,
    attributes, generation record, and the wood and blades rebuilt from them, bit for bit."""
    mesh = WorldTree("mine", "mesh", np.array([1.0, 0.0, 2.0]),
                     (np.random.default_rng(0).random((8, 3)), np.array([[0, 1, 2], [2, 3, 4]])),
                     np.random.default_rng(1).random((5, 3, 3)), np.full(5, 0.01), None,
                     {"file": "tree.ply"})
    trees = [*courtyard_trees, mesh]
    path = tr.write_initial_trees(tmp_path, trees)
    assert path == tmp_path / tr.RECORD and path.is_file()
    assert not list(path.parent.glob(".*"))                 # no temporary file left
    back = tr.read_initial_trees(tmp_path)
    assert len(back) == len(trees)
    for a, b in zip(trees, back):
        _same(a, b)
    # plain arrays: numpy reads it without pickles
    with np.load(path, allow_pickle=False) as z:
        assert "record" in z.files


def test_what_the_record_cannot_hold_is_not_written(courtyard_trees, tmp_path, monkeypatch):
    """An object of a class outside the record's list, or more than MAX_BYTES of arrays: no
    file (readers re-grow the trees); a folder without the record, or with another format,
    reads as None; a record naming an unknown class is refused."""
    t = courtyard_trees[0]
    t.tree.attrs["foreign"] = object()
    try:
        assert tr.write_initial_trees(tmp_path / "a", [t]) is None
    finally:
        del t.tree.attrs["foreign"]
    assert not (tmp_path / "a" / tr.RECORD).exists()
    assert tr.read_initial_trees(tmp_path / "a") is None
    monkeypatch.setattr(tr, "MAX_BYTES", 1000)
    assert tr.write_initial_trees(tmp_path / "b", [t]) is None
    monkeypatch.undo()
    p = tr.write_initial_trees(tmp_path / "c", [t])
    with np.load(p) as z:
        d = dict(z)
    doc = json.loads(str(d["record"]))
    doc["format"] = tr.FORMAT + 1
    np.savez(p, **{**d, "record": np.array(json.dumps(doc))})
    assert tr.read_initial_trees(tmp_path / "c") is None
    doc["format"] = tr.FORMAT
    doc["trees"][0]["tree"]["__class__"] = "Popen"
    np.savez(p, **{**d, "record": np.array(json.dumps(doc))})
    with pytest.raises(ValueError, match="unknown class 'Popen'"):
        tr.read_initial_trees(tmp_path / "c")


def test_a_world_run_records_its_trees_and_the_render_draws_them(tmp_path, monkeypatch):
    """A world run writes trees/initial.npz; the render's trees come from it (re-growing is not
    called) and equal the trees re-grown from the scenario, as folders without the record
    get them."""
    import mitsuba_veg.render.world as rw
    from mitsuba_veg.render.history import load_run
    ov = ["light.photons=20000", "simulation.checkpoint_every=0", "moss.initial=50"]
    mv.run(COURTYARD, out=tmp_path / "run", days=1, overrides=ov, progress=False,
           frames=False)
    assert (tmp_path / "run" / tr.RECORD).is_file()
    recorded, _ = rw.world_trees(load_run(tmp_path / "run"))
    (tmp_path / "run" / tr.RECORD).unlink()
    regrown, _ = rw.world_trees(load_run(tmp_path / "run"))
    assert [t.name for t in recorded] == ["by_the_house", "aspen", "aspen_adapted"]
    for a, b in zip(recorded, regrown):
        for f in TREE_FIELDS:
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
        np.testing.assert_array_equal(a.leaves.position, b.leaves.position)
    # the record is what the render reads: with it back, re-growing is never called
    tr.write_initial_trees(tmp_path / "run", rw.initial_trees(load_run(tmp_path / "run")))

    def no_regrowth(*a, **k):
        raise AssertionError("re-grown")
    monkeypatch.setattr(rw, "world_scenario_trees", no_regrowth)
    drawn, _ = rw.world_trees(load_run(tmp_path / "run"))
    assert [len(t.leaves) for t in drawn] == [len(t.leaves) for t in recorded]
