"""Hemispherical photographs in a world: a run's ``[[hemiphotos]]`` taken on their days (and the
same photograph from the run folder afterwards), and light studies under the world's trees in
their leaf state on each date (docs/hemiphoto.md)."""
import csv
import shutil
from pathlib import Path

import pytest

import mitsuba_veg as mv
from mitsuba_veg.errors import ParameterError

ROOT = Path(__file__).resolve().parent.parent
COURTYARD = ROOT / "scenes" / "courtyard"

TREE = """
[[trees]]
name = "oak"
model = "weber_penn"
preset = "quaking_aspen"
position = [0.0, 0.0, 0.0]
height = 4.0
seed = 3

[[sensors]]
name = "under_crown"
size = 0.3
position = [0.8, 0.3, 0.0]

[[sensors]]
name = "open"
size = 0.3
position = [2.5, 0.3, 2.5]
"""


def _world(tmp, start, extra="", phenology=""):
    d = tmp / "scen"
    shutil.copytree(COURTYARD, d)
    text = (d / "scenario.toml").read_text()
    text = text[:text.index("# ---- the trees of the world")]
    text = text.replace('start_date = "2026-03-01"', f'start_date = "{start}"')
    (d / "scenario.toml").write_text(text + TREE + extra + "\n[phenology]\n" + phenology)
    return d / "scenario.toml"


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_a_run_takes_its_hemiphotos_and_the_run_folder_gives_the_same(tmp_path):
    """A world run with ``[[hemiphotos]]`` writes the photograph of its day (PNG, tidy CSV, a
    row of series.csv) under the tree: vegetation in the LAI-2000 rings, a true LAI and PAI in
    the view cone; ``hemiphoto RUN_DIR`` of that day (from the run's snapshot) gives the same
    gap fractions and truth; a bad ``on`` is refused before day 1."""
    photos = """
[[hemiphotos]]
name = "crown"
at = [0.6, 0.3]
height = 0.5
on = ["07-02"]
size = 256
"""
    scen = _world(tmp_path, "2026-07-01", photos)
    ov = ["light.photons=100000", "simulation.frame_every=1", "moss.initial=20"]
    mv.run(scen, out=tmp_path / "run", days=2, overrides=ov, progress=False)
    folder = tmp_path / "run" / "hemiphotos"
    assert (folder / "crown_2026-07-02.png").is_file()
    rows = _rows(folder / "series.csv")
    assert [(r["date"], r["photo"]) for r in rows] == [("2026-07-02", "crown")]
    r = rows[0]
    assert float(r["lai_true"]) > 0.3 and float(r["pai_true"]) > float(r["lai_true"])
    assert 0.0 < float(r["gap_0_13"]) < 1.0 and float(r["lai_lai2000"]) > 0.1
    table = _rows(folder / "crown_2026-07-02.csv")
    assert {t["quantity"] for t in table} >= {"gap_fraction_lai2000", "gap_fraction",
                                              "lai_lai2000", "lai_true", "site_factor_total"}
    from mitsuba_veg.canopy_photo import run_hemiphoto
    s = run_hemiphoto(tmp_path / "run", tmp_path / "post", at=[(0.6, 0.3)], day=2,
                      height=0.5, size=256)
    p = s["photographs"][0]
    for k in ("gap_0_13", "gap_16_28", "gap_61_74", "openness", "lai_true", "pai_true",
              "site_factor_diffuse"):
        assert p[k] == pytest.approx(float(r[k]), rel=1e-5), k
    bad = _world(tmp_path / "b", "2026-07-01", photos.replace('"07-02"', '"7/2"'))
    with pytest.raises(ParameterError, match=r"hemiphotos\[0\]\.on"):
        mv.run(bad, out=tmp_path / "bad", days=1, overrides=ov, progress=False)


@pytest.mark.slow
def test_light_study_follows_the_leaves_out(tmp_path):
    """A light study of a world scenario over leaf-out (leaf_out_days = 2 from day 95): the
    world's loop is run to each date, and the sensor under the crown loses a fifth of its
    daily light from the bare day to the leafy one while the open sensor keeps it; the days
    are traced in as many leaf states as they have; photographs at the point sensors on the
    first day. Measured: 47.7 -> 30.7 mol m-2 d-1 under the crown, open 49.5 -> 49.0."""
    from mitsuba_veg.canopy_photo import run_world_sensor_study
    scen = _world(tmp_path, "2026-04-02", phenology="leaf_out_doy = 95\nleaf_out_days = 2\n")
    s = run_world_sensor_study(scen, tmp_path / "ls", start="2026-04-03", end="2026-04-07",
                               step="daily", photons=100_000, heatmap_every=0,
                               overrides=["light.photons=100000", "moss.initial=20"],
                               photo_size=256)
    dli = {(r["date"], r["sensor"]): float(r["dli_mol_m2_d"])
           for r in _rows(tmp_path / "ls" / "dli.csv")}
    assert dli[("2026-04-07", "under_crown")] < 0.8 * dli[("2026-04-03", "under_crown")]
    assert dli[("2026-04-07", "open")] == pytest.approx(dli[("2026-04-03", "open")], rel=0.1)
    assert len(s["world"]["segments"]) >= 3
    names = {r["photo"] for r in s["hemiphotos"]}
    assert names == {"under_crown", "open"}
    assert (tmp_path / "ls" / "hemiphotos" / "under_crown_2026-04-03.png").is_file()
    # the library function alone still refuses trees it would leave out
    from mitsuba_veg.foliage.light_series import run_sensor_study
    with pytest.raises(ParameterError, match="trees.*light-study"):
        run_sensor_study(scen, tmp_path / "ls2", start="2026-04-03", end="2026-04-03")
