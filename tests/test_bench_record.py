"""benchmarks/_record.py writes each headline figure with its unit, machine, variant and date."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture()
def record(tmp_path, monkeypatch):
    monkeypatch.setenv("MITSUBA_VEG_BENCH_RESULTS", str(tmp_path))
    spec = importlib.util.spec_from_file_location("_record", ROOT / "benchmarks" / "_record.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_recorder_writes_figures_machine_and_variant(record, tmp_path):
    import mitsuba_veg  # noqa: F401  (sets the variant the record names)
    import mitsuba as mi

    rec = record.Recorder("demo_case", command="python benchmarks/x.py --n 3", notes="a note")
    rec.add("ratio", 0.51, "ratio", "a ratio").add("t", 2, "s", "a time")
    path = rec.write()
    assert path == tmp_path / "demo_case.json"
    doc = json.loads(path.read_text())
    assert doc["source"] == "measured" and doc["variant"] == mi.variant()
    assert doc["command"] == "python benchmarks/x.py --n 3" and doc["notes"] == "a note"
    assert [f["key"] for f in doc["figures"]] == ["ratio", "t"]
    assert doc["figures"][0] == {"key": "ratio", "label": "a ratio", "value": 0.51,
                                 "unit": "ratio"}
    cpuinfo = Path("/proc/cpuinfo").read_text()
    assert doc["machine"]["cores"] == cpuinfo.count("processor\t:")
    assert doc["machine"]["cpu"] in cpuinfo
    assert doc["machine"]["gpu"] is None or mi.variant().startswith("cuda")
    assert len(doc["date"]) == 10 and doc["versions"]["mitsuba"] == mi.__version__
    assert record.load_results(tmp_path)["demo_case"] == doc


def test_recorded_earlier_keeps_the_stated_machine(record, tmp_path):
    m = {"cpu": "unknown", "cores": None, "gpu": "NVIDIA H200", "system": "Linux"}
    path = record.write_recorded("gpu_case", "python benchmarks/y.py",
                                 [("wall", 338.0, "s", "ten years")], m,
                                 "cuda_ad_spectral", "2026-11-27", notes="from the docs")
    doc = json.loads(path.read_text())
    assert doc["source"] == "recorded earlier" and doc["machine"] == m
    assert doc["date"] == "2026-11-27" and doc["variant"] == "cuda_ad_spectral"
    assert doc["load_average"] is None


def test_recorder_refuses_bad_names_and_repeats(record):
    with pytest.raises(ValueError, match="letters"):
        record.Recorder("../x")
    rec = record.Recorder("ok")
    rec.add("a", 1.0, "s", "x")
    with pytest.raises(ValueError, match="twice"):
        rec.add("a", 2.0, "s", "y")
    with pytest.raises(ValueError, match="no figures"):
        record.Recorder("empty").write()
