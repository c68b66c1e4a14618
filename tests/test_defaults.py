"""One table of the light pass's defaults and ranges (``mitsuba_veg.defaults.LIGHT``): the
scenario schema, the command line, the Python API and the plugin's properties agree with it,
and no other module writes a photon, seed or depth bound of its own."""
import re
from pathlib import Path

import pytest

import mitsuba_veg as mv  # noqa: F401  (selects the variant, registers the plugins)
import mitsuba as mi
from mitsuba_veg.cli.command import build_parser
from mitsuba_veg.defaults import LIGHT, MAX_PHOTONS, range_text
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.integrators.photon_irradiance import PhotonIrradianceIntegrator
from mitsuba_veg.light.photon import integrator
from mitsuba_veg.scenario import field_spec, light_overrides

ROOT = Path(__file__).resolve().parent.parent
RANGED = ("photons", "max_depth", "seed")


def test_scenario_schema_reads_the_table():
    for name in RANGED:
        f = field_spec(f"light.{name}")
        assert (f.lo, f.hi) == (LIGHT[name].lo, LIGHT[name].hi), name
    assert MAX_PHOTONS == LIGHT["photons"].hi == 10**9
    # a value one past the bound is refused by the scenario's --set with that bound named
    with pytest.raises(ParameterError, match=r"\[1, 1e\+09\]"):
        light_overrides([f"light.photons={MAX_PHOTONS + 1}"])
    assert light_overrides([f"light.photons={MAX_PHOTONS}"]) == {"photons": MAX_PHOTONS}


def test_plugin_and_api_defaults_and_bounds_are_the_tables():
    plugin = mi.load_dict({"type": "veg_photon_irradiance"})
    api = integrator()
    for obj in (plugin, api):
        for name in ("photons", "max_depth", "seed", "indirect", "batch"):
            assert getattr(obj, name) == LIGHT[name].default, name
    for name in RANGED:
        s = LIGHT[name]
        with pytest.raises(ParameterError, match=name):
            integrator(**{name: s.hi + 1})
        with pytest.raises(ParameterError, match=name):
            integrator(**{name: s.lo - 1})
        # the plugin refuses the same values (wrapped by Mitsuba's loader)
        with pytest.raises(Exception, match=name):
            mi.load_dict({"type": "veg_photon_irradiance", name: s.hi + 1})
    with pytest.raises(ParameterError, match="batch"):
        integrator(batch=LIGHT["batch"].lo - 1)


def test_plugin_parameter_table_states_the_tables_defaults():
    doc = PhotonIrradianceIntegrator.__doc__
    for name in ("photons", "max_depth", "seed", "batch"):
        m = re.search(rf"\* - {name}\n\s+- \w+\n\s+- (\S+)", doc)
        assert m is not None, name
        assert int(m.group(1)) == LIGHT[name].default, name
    assert "1 - 1e9" in doc and range_text("photons") == "1 .. 1e9"


def test_command_line_takes_the_tables_ranges():
    ap = build_parser()
    ok = ap.parse_args(["irradiance", "scene.xml", "--photons", str(MAX_PHOTONS),
                        "--max-depth", "1000", "--seed", str(2**31 - 1)])
    assert (ok.photons, ok.max_depth, ok.seed) == (MAX_PHOTONS, 1000, 2**31 - 1)
    for opt, bad in (("--photons", MAX_PHOTONS + 1), ("--max-depth", 1001), ("--seed", -1),
                     ("--photons", 0)):
        with pytest.raises(SystemExit):
            ap.parse_args(["irradiance", "scene.xml", opt, str(bad)])
    for args in (["demo", "--world-photons", str(MAX_PHOTONS + 1)],
                 ["light-study", "x.toml", "--sky-photons", str(MAX_PHOTONS + 1)]):
        with pytest.raises(SystemExit):
            ap.parse_args(args)


def test_no_module_writes_its_own_light_bound():
    """Bounds of photons, seed and max_depth of the light pass come from the table; the one
    exception is ``trace_paths`` (the differentiable pass's path store: at most 2^26 photons
    and 64 hits, documented there)."""
    found = []
    for path in list((ROOT / "mitsuba_veg").rglob("*.py")) + list((ROOT / "integrators")
                                                                  .rglob("*.py")):
        if path.name == "defaults.py":
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r'check_range\("(photons|seed)"', line) or \
                    re.search(r"ranged\(int, 1, (10\*\*9|1_000_000_000)", line):
                found.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert found == ['integrators/photon_irradiance.py:'
                     + str(_line_of("integrators/photon_irradiance.py",
                                    'check_range("photons", photons, 16, 2**26'))
                     + ': check_range("photons", photons, 16, 2**26, fix="a photon count such '
                       'as 200000")'], found


def _line_of(rel: str, text: str) -> int:
    for i, line in enumerate((ROOT / rel).read_text().splitlines(), 1):
        if text in line:
            return i
    raise AssertionError(text)
