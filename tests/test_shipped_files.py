"""The files a new user meets first: the shipped meshes load without a warning, and a TOML file
saved with a UTF-8 byte-order mark (as some editors write it) is read like the same file without
one.
"""
import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (selects the variant, registers the plugins)
import mitsuba as mi
from mitsuba_veg.scenario import load_scenario, load_scene_file

ROOT = Path(__file__).resolve().parent.parent
BOM = b"\xef\xbb\xbf"
SHIPPED_PLY = sorted(list((ROOT / "scenes").glob("*/*.ply"))
                     + list((ROOT / "mitsuba_veg" / "data").rglob("*.ply")))


def _ply_format(path: Path) -> str:
    with open(path, "rb") as fh:
        assert fh.readline().strip() == b"ply", path
        return fh.readline().decode("ascii").strip()


def test_every_shipped_ply_is_binary():
    assert len(SHIPPED_PLY) >= 80        # the scenes' meshes and the moss tufts
    ascii_ = [str(p.relative_to(ROOT)) for p in SHIPPED_PLY
              if _ply_format(p) != "format binary_little_endian 1.0"]
    assert ascii_ == []


def _make_scene_module(scene: str):
    spec = importlib.util.spec_from_file_location(f"make_{scene}",
                                                  ROOT / "scenes" / scene / "make_scene.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_courtyard_generator_writes_the_shipped_files(tmp_path):
    """scenes/courtyard/make_scene.py writes binary PLY, byte for byte the shipped files."""
    m = _make_scene_module("courtyard")
    m.write_ply(tmp_path / "ground.ply", *m.ground())
    m.write_ply(tmp_path / "house.ply", *m.box(m.HOUSE_LO, m.HOUSE_HI))
    m.write_ply(tmp_path / "wall.ply", *m.box(m.WALL_LO, m.WALL_HI))
    for name in ("ground.ply", "house.ply", "wall.ply"):
        assert _ply_format(tmp_path / name) == "format binary_little_endian 1.0"
        assert (tmp_path / name).read_bytes() == \
            (ROOT / "scenes" / "courtyard" / name).read_bytes(), name


def _write_ascii_ply(path, V, F, uv=None):
    """The courtyard's PLY as its generator wrote them before (ASCII, 6 decimals)."""
    with open(path, "w") as f:
        f.write("ply\nformat ascii 1.0\n")
        f.write(f"element vertex {len(V)}\nproperty float x\nproperty float y\nproperty float z\n")
        if uv is not None:
            f.write("property float u\nproperty float v\n")
        f.write(f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n")
        for k, v in enumerate(V):
            f.write(" ".join(f"{c:.6f}" for c in v))
            if uv is not None:
                f.write(f" {uv[k, 0]:.6f} {uv[k, 1]:.6f}")
            f.write("\n")
        for t in F:
            f.write(f"3 {t[0]} {t[1]} {t[2]}\n")


def _mesh_arrays(path):
    p = mi.traverse(mi.load_dict({"type": "ply", "filename": str(path)}))
    return {k: np.asarray(p[k]) for k in ("vertex_positions", "vertex_normals",
                                          "vertex_texcoords", "faces")}


def test_the_binary_courtyard_is_the_ascii_one_as_mitsuba_reads_it(tmp_path, capfd):
    """The same float32 vertices, normals, UVs and faces as the ASCII files the courtyard had."""
    m = _make_scene_module("courtyard")
    parts = {"ground.ply": m.ground(), "house.ply": m.box(m.HOUSE_LO, m.HOUSE_HI),
             "wall.ply": m.box(m.WALL_LO, m.WALL_HI)}
    for name, arrays in parts.items():
        _write_ascii_ply(tmp_path / name, *arrays)
        old = _mesh_arrays(tmp_path / name)
        new = _mesh_arrays(ROOT / "scenes" / "courtyard" / name)
        for k in old:
            assert old[k].dtype == new[k].dtype, (name, k)
            if k == "vertex_normals":
                # Mitsuba computes the normals itself (the files have none) with parallel
                # atomic adds on the LLVM backend: their order, hence the last bit, varies
                np.testing.assert_allclose(old[k], new[k], rtol=0, atol=1e-6, err_msg=name)
            else:
                assert old[k].tobytes() == new[k].tobytes(), (name, k)
        assert old["vertex_positions"].size > 0 and old["faces"].size > 0
    assert parts["ground.ply"][2] is not None
    capfd.readouterr()                # (the ASCII files' warnings)


def test_loading_the_courtyard_prints_no_warning(capfd):
    capfd.readouterr()
    load_scenario(ROOT / "scenes" / "courtyard" / "scenario.toml").load_scene()
    out, err = capfd.readouterr()
    assert "WARN" not in out + err and "performance warning" not in out + err, out + err


def test_an_ascii_ply_would_be_said(tmp_path, capfd):
    """The check above can fail: Mitsuba's warning for an ASCII PLY reaches the captured
    output."""
    m = _make_scene_module("courtyard")
    v, f = m.box(m.WALL_LO, m.WALL_HI)
    with open(tmp_path / "wall.ply", "w") as fh:
        fh.write(f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\n"
                 f"property float y\nproperty float z\nelement face {len(f)}\n"
                 "property list uchar int vertex_indices\nend_header\n")
        fh.writelines(" ".join(f"{c:.6f}" for c in row) + "\n" for row in v)
        fh.writelines(f"3 {a} {b} {c}\n" for a, b, c in f)
    capfd.readouterr()
    mi.load_dict({"type": "ply", "filename": str(tmp_path / "wall.ply")})
    out, err = capfd.readouterr()
    assert "ASCII PLY" in out + err


# ---- a UTF-8 byte-order mark -----------------------------------------------------------------
def _with_bom(src: Path, dst: Path) -> Path:
    dst.write_bytes(BOM + src.read_bytes())
    return dst


def test_a_scenario_with_a_byte_order_mark_is_read(tmp_path):
    shutil.copytree(ROOT / "scenes" / "moss_garden", tmp_path / "garden")
    plain = tmp_path / "garden" / "scenario.toml"
    bom = _with_bom(plain, tmp_path / "garden" / "scenario_bom.toml")
    assert bom.read_bytes()[:3] == BOM
    assert load_scenario(bom, ["light.photons=20000"]).data == \
        load_scenario(plain, ["light.photons=20000"]).data


def test_a_sweep_file_with_a_byte_order_mark_is_read(tmp_path):
    from mitsuba_veg.sweeps.spec import load_sweep
    shutil.copytree(ROOT / "scenes" / "moss_garden", tmp_path / "garden")
    plain = tmp_path / "garden" / "sweep.toml"
    bom = _with_bom(plain, tmp_path / "garden" / "sweep_bom.toml")
    a, b = load_sweep(plain), load_sweep(bom)
    assert [r.values for r in a.runs] == [r.values for r in b.runs] and len(a.runs) == 8


def test_a_tree_file_with_a_byte_order_mark_is_read(tmp_path):
    from mitsuba_veg.cli.grow import load_tree_toml
    plain = ROOT / "scenes" / "trees" / "default.toml"
    bom = _with_bom(plain, tmp_path / "default.toml")
    assert load_tree_toml(bom) == load_tree_toml(plain)


def test_a_species_file_with_a_byte_order_mark_is_read(tmp_path):
    from mitsuba_veg.moss.species import load_species
    plain = ROOT / "mitsuba_veg" / "data" / "moss_species.toml"
    bom = _with_bom(plain, tmp_path / "species.toml")
    assert load_species(bom) == load_species(plain)


def test_a_weber_penn_file_with_a_byte_order_mark_is_read(tmp_path):
    from mitsuba_veg.trees.weber_penn import load_params, preset_path
    plain = preset_path("quaking_aspen")
    bom = _with_bom(plain, tmp_path / "quaking_aspen.toml")
    assert load_params(bom) == load_params(plain)


@pytest.mark.parametrize("text", [b"\xff\xfe[site]", b"\xe9t\xe9 = 1\n"])
def test_a_scenario_that_is_not_utf8_is_one_error(tmp_path, text):
    from mitsuba_veg.errors import ParameterError
    p = tmp_path / "scenario.toml"
    p.write_bytes(text)
    with pytest.raises(ParameterError, match="valid TOML text file"):
        load_scenario(p)
