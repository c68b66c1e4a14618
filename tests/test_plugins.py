"""Every Mitsuba plugin of the package as a Mitsuba user meets it: a class docstring that is its
parameter table (every property the plugin reads, and no other), loading from a scene dict and
from XML with the same effect, and an unknown property refused. Every plugin class lives in
``integrators/`` (``mitsuba_veg.integrators``), the package's one plugins folder."""
import inspect
import re
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (selects the variant, registers the plugins)
import mitsuba as mi
from mitsuba_veg.integrators.photon_irradiance import PhotonIrradianceIntegrator
from mitsuba_veg.integrators.veg_fisheye import VegFisheye
from mitsuba_veg.integrators.veg_leaf import LeafBSDF
from mitsuba_veg.integrators.veg_sky import VegSky
from mitsuba_veg.integrators.veg_sun import VegSunPath, VegSunSteps

# plugin name -> (class, kind, one non-default property as (XML tag, name, value), what shows
# that the value took effect)
PLUGINS = {
    "veg_photon_irradiance": (PhotonIrradianceIntegrator, "integrator",
                              ("integer", "photons", 12345), lambda p: p.photons == 12345),
    "veg_sky": (VegSky, "emitter", ("integer", "resolution", 64), lambda p: p.rows == 64),
    "veg_sun_path": (VegSunPath, "emitter", ("float", "scale", 2.5), lambda p: p.scale == 2.5),
    "veg_sun_steps": (VegSunSteps, "emitter", ("float", "irradiance", 3.0),
                      lambda p: _flat_value(p.m_spec) == pytest.approx(3.0)),
    "veg_leaf": (LeafBSDF, "bsdf", ("float", "reflectance", 0.3),
                 lambda p: _flat_value(p.reflectance) == pytest.approx(0.3)),
    "veg_fisheye": (VegFisheye, "sensor", ("float", "fov", 150.0),
                    lambda p: p.fov == 150.0 and p.theta_max == pytest.approx(1.308997)),
}


def _flat_value(tex) -> float:
    si = mi.SurfaceInteraction3f()
    si.wavelengths = mi.Spectrum(500.0, 550.0, 600.0, 650.0)
    return float(np.asarray(tex.eval(si)).ravel()[0])


def _table(cls) -> list[str]:
    """Property names of the class docstring's list-table (``a, b, c`` rows give three)."""
    doc = inspect.getdoc(cls) or ""
    assert ".. list-table::" in doc, f"{cls.__name__}: no parameter table in its docstring"
    names = []
    for row in re.findall(r"^\s*\* - (.+)$", doc, flags=re.M):
        if row.strip() == "Property":
            continue
        names += [n.strip() for n in row.split(",")]
    return names


def _read(cls) -> set[str]:
    """The properties a plugin's constructor reads (from its source)."""
    src = inspect.getsource(cls.__init__)
    names = set(re.findall(r'props\.get\("(\w+)"', src))
    names |= set(re.findall(r'"(\w+)" in props', src))
    names |= set(re.findall(r'props\["(\w+)"\]', src))
    names |= set(re.findall(r'_texture\(props, "(\w+)"', src))
    names |= set(re.findall(r'_vector\(props, "(\w+)"', src))
    # objects the Mitsuba base class's constructor reads (a sensor's film and sampler)
    names |= set(getattr(cls, "BASE_PROPERTIES", ()))
    for letters in re.findall(r'props\.get\(k, None\) for k in "(\w+)"', src):
        names |= set(letters)
    return names


@pytest.mark.parametrize("name", sorted(PLUGINS))
def test_docstring_is_the_parameter_table(name):
    """The class's ``PARAMETERS`` (the machine-readable table the docs' plugin page is made
    from) names every property the constructor reads and no other, and the docstring shows it."""
    cls = PLUGINS[name][0]
    table, read = _table(cls), _read(cls)
    assert read, f"{name}: found no property reads in {cls.__name__}.__init__"
    assert len(table) == len(set(table)), table
    assert set(table) == read, (set(table) ^ read)
    assert f"``{name}``" in inspect.getdoc(cls)
    assert cls.PLUGIN == name and cls.PLUGIN_KIND == PLUGINS[name][1]
    assert [n for p in cls.PARAMETERS for n in p.names] == table


@pytest.mark.parametrize("name", sorted(PLUGINS))
def test_loads_from_a_dict_and_from_xml_alike(name):
    cls, kind, (tag, prop, value), took = PLUGINS[name]
    base = {"radiance": 0.1} if name == "veg_sky" else {}   # (the sky needs a spectrum)
    from_dict = mi.load_dict({"type": name, prop: value, **base})
    xml = (f'<{kind} version="3.0.0" type="{name}">'
           + "".join(f'<float name="{k}" value="{v}"/>' for k, v in base.items())
           + f'<{tag} name="{prop}" value="{value}"/></{kind}>')
    from_xml = mi.load_string(xml)
    for p in (from_dict, from_xml):
        assert isinstance(p, cls) and took(p)
    # a property the plugin does not read is refused (Mitsuba's loader names it)
    with pytest.raises(Exception, match="unreferenced propert"):
        mi.load_dict({"type": name, prop: value, "not_a_property": 1.0, **base})


def _registrations() -> dict[str, str]:
    """Plugin name -> file (relative to the repository) of every ``mi.register_*`` call in the
    package's source (``mitsuba_veg/`` and ``integrators/``); a name given as a module constant
    is looked up in the same file."""
    root = Path(__file__).resolve().parent.parent
    out = {}
    for folder in ("mitsuba_veg", "integrators"):
        for path in (root / folder).rglob("*.py"):
            src = path.read_text()
            for arg in re.findall(r"\bmi\.register_\w+\(\s*([^,]+),", src):
                name = arg.strip()
                if not name.startswith(('"', "'")):
                    found = re.search(rf"^{name}\s*=\s*(['\"]\w+['\"])", src, flags=re.M)
                    assert found, f"{path}: cannot resolve the plugin name {name}"
                    name = found.group(1)
                out[name.strip("'\"")] = str(path.relative_to(root))
    return out


def test_every_plugin_lives_in_the_integrators_folder():
    """``integrators/`` is the one plugins folder: every plugin the package registers is in the
    table above (all six), each registered there, each class defined in a module of
    ``mitsuba_veg.integrators`` (one file per plugin family)."""
    regs = _registrations()
    assert set(PLUGINS) == set(regs) == {"veg_photon_irradiance", "veg_sky", "veg_sun_path",
                                         "veg_sun_steps", "veg_leaf", "veg_fisheye"}
    for name, (cls, *_) in PLUGINS.items():
        assert regs[name].startswith("integrators/"), (name, regs[name])
        assert cls.__module__.startswith("mitsuba_veg.integrators."), (name, cls.__module__)
