"""The validation page script (benchmarks/validation_page.py) runs every light reference with
--quick and writes a page in which every reference row is present, with a finite error below the
test suite's tolerance, and the photon-pass throughput ratio on this machine."""
import json
import math
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "benchmarks" / "validation_page.py"

#: every reference the page must carry: key -> title on the page
ROWS = {"plane": "Analytic plane", "energy_bookkeeping": "Energy bookkeeping",
        "energy_flux": "Energy from the recorded flux",
        "path": "Mitsuba path tracer + irradiancemeter",
        "beer_lambert": "Beer–Lambert through a leaf cloud", "spctral2_par": "SPCTRAL2 PAR",
        "spa_example_zenith": "NREL SPA worked example: zenith",
        "spa_example_azimuth": "NREL SPA worked example: azimuth",
        "spa_pvlib_elevation": "pvlib SPA: elevation", "spa_pvlib_azimuth": "pvlib SPA: azimuth",
        "prospect_d": "PROSPECT-D vs prosail"}


def test_quick_page_has_every_reference_within_tolerance(tmp_path):
    page, js = tmp_path / "validation.md", tmp_path / "validation.json"
    p = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--out", str(page), "--json",
                        str(js)], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-3000:]
    text = page.read_text()
    res = json.loads(js.read_text())
    rows = {r["key"]: r for r in res["rows"]}
    assert set(ROWS) <= set(rows), set(ROWS) - set(rows)
    for key, title in ROWS.items():
        r = rows[key]
        assert math.isfinite(r["error"]) and r["error"] >= 0, r
        assert r["tolerance"] is not None and r["error"] < r["tolerance"], r
        assert r["passed"] is True
        assert r["test"].startswith("tests/") and (ROOT / r["test"].split("::")[0]).exists()
        line = [ln for ln in text.splitlines() if ln.startswith(f"| {title} |")]
        assert len(line) == 1, title
        assert line[0].rstrip().endswith("| yes |") and r["test"] in line[0]
    # throughput: measured in the same run, ratio to Mitsuba's raw ray casts
    for key in ("throughput_full", "throughput_preliminary"):
        assert math.isfinite(rows[key]["error"]) and rows[key]["error"] > 0
    assert "## Photon-pass throughput on this machine" in text
    # the page says how it was made, on what machine, with which versions
    assert "benchmarks/validation_page.py" in text and "--quick" in text
    m, v = res["machine"], res["versions"]
    assert m["logical_cores"] >= 1 and m["cpu"] in text
    assert v["variant"] in text and f"mitsuba {v['mitsuba']}" in text
