"""Scenes written by others through the photon pass: Mitsuba's tutorial Cornell box and an
exported-style scene (PLY meshes, shapegroup/instance plants, an ``envmap`` sky) via the API and
``mitsuba-veg irradiance``, against Mitsuba's ``path`` integrator + ``irradiancemeter``."""
import subprocess
import sys

import numpy as np
import pytest

import mitsuba_veg as mv  # noqa: F401  (selects the variant, registers plugins)
import mitsuba as mi

from mitsuba_veg.light import photon_irradiance
from mitsuba_veg.light import validation as V


def test_cornell_box_agrees_with_mitsuba_path_tracer():
    """``mi.cornell_box()`` as Mitsuba's tutorials build it (RGB reflectances and an RGB area
    light, upsampled to spectra): every lit triangle within 5 % of path + irradiancemeter, in
    total and in its indirect part alone."""
    d = V.as_meshes(mi.cornell_box())
    scene = mi.load_dict(d, optimize=False)
    res = photon_irradiance(scene, photons=4_000_000, seed=1, max_depth=16, bands=("total",))
    assert res.single_element_shapes == {}
    top = max(res.irradiance(s).max() for s in res.index.shape_ids if s != "light")
    n = 0
    for sid in ("floor", "ceiling", "back", "red-wall", "green-wall", "small-box", "large-box"):
        irr = res.irradiance(sid)
        tris = [int(t) for t in np.flatnonzero(irr > 0.05 * top)]
        ref, err = V.path_reference(d, sid, tris, spp=131072, seed=2)
        for t, r in zip(tris, ref):
            assert irr[t] == pytest.approx(r, rel=0.05), (sid, t, irr[t], r)
            n += 1
        # the indirect part alone (path depth 16 minus depth 1: 14-100 % of these triangles'
        # light; measured within 1.9 %)
        direct, _ = V.path_reference(d, sid, tris, spp=131072, seed=2, max_depth=1)
        np.testing.assert_allclose(res.irradiance(sid, component="indirect")[tris],
                                   ref - direct, rtol=0.05)
    assert n >= 20


def _write_exported_scene(folder):
    """An exported-style scene on disk: ground and two plant meshes as PLY, plants placed by
    shapegroup/instance, an RGB ``envmap`` sky from an EXR. Returns (xml path, the same scene
    as a dict with in-memory meshes for the reference)."""
    rng = np.random.default_rng(4)
    gv, gf = V.grid_mesh(8, 8)
    ground = V.make_mesh("ground", gv, gf, 0.25)
    ground.write_ply(str(folder / "ground.ply"))
    plants = []
    for k in range(2):
        pv, pf = V.plant_mesh(k)
        pv = pv * 3.0  # 15-60 cm plants
        m = V.make_mesh(f"plant{k}", pv, pf, 0.45)
        m.write_ply(str(folder / f"plant{k}.ply"))
        plants.append(m)
    # sky: bluish, brighter towards the zenith, a warm bright patch (the sun's aureole)
    h, w = 32, 64
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = (np.arange(w) + 0.5) / w * 2 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    up = np.clip(np.cos(T), 0.0, None)
    sky = np.stack([0.3 + 0.4 * up, 0.4 + 0.6 * up, 0.6 + 0.9 * up], -1)
    spot = np.exp(-((T - 0.7) ** 2 + (P - 2.0) ** 2) / 0.05)[..., None]
    sky = (sky * (np.cos(T) > -0.05)[..., None] + 20.0 * spot * np.array([1.0, 0.9, 0.7]))
    mi.Bitmap(sky.astype(np.float32)).write(str(folder / "sky.exr"))
    xml = ['<scene version="3.0.0">',
           '  <emitter type="envmap" id="sky"><string name="filename" value="sky.exr"/></emitter>',
           '  <shape type="ply" id="ground"><string name="filename" value="ground.ply"/>',
           '    <bsdf type="diffuse"><spectrum name="reflectance" value="0.25"/></bsdf></shape>']
    d = {"type": "scene", "sky": {"type": "envmap", "filename": str(folder / "sky.exr")},
         "ground": ground}
    for k in range(2):
        xml += [f'  <shape type="shapegroup" id="plant{k}">',
                f'    <shape type="ply" id="leaves{k}"><string name="filename" '
                f'value="plant{k}.ply"/>',
                '      <bsdf type="diffuse"><spectrum name="reflectance" value="0.45"/></bsdf>',
                '    </shape>', '  </shape>']
        d[f"plant{k}"] = {"type": "shapegroup", f"leaves{k}": plants[k]}
    for i in range(30):
        x, z = rng.uniform(-0.9, 0.9, 2)
        a = float(rng.uniform(0, 360))
        xml += [f'  <shape type="instance" id="tuft{i:02d}"><ref id="plant{i % 2}"/>',
                f'    <transform name="to_world"><rotate y="1" angle="{a:.3f}"/>'
                f'<translate x="{x:.4f}" z="{z:.4f}"/></transform>', '  </shape>']
        d[f"tuft{i:02d}"] = {"type": "instance",
                             "shapegroup": {"type": "ref", "id": f"plant{i % 2}"},
                             "to_world": mi.ScalarTransform4f().translate([float(f"{x:.4f}"), 0.0,
                                                                          float(f"{z:.4f}")])
                             .rotate([0, 1, 0], float(f"{a:.3f}"))}
    xml.append("</scene>")
    path = folder / "scene.xml"
    path.write_text("\n".join(xml))
    return path, d


@pytest.mark.slow
def test_exported_scene_with_instances_and_envmap(tmp_path):
    xml, d = _write_exported_scene(tmp_path)
    # the command line and the API give the same pass
    out = tmp_path / "irr"
    p = subprocess.run([sys.executable, "-m", "mitsuba_veg.cli", "irradiance", str(xml),
                        "--photons", "4000000", "--seed", "4", "--out", str(out), "--quiet"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    data = np.load(out / "irradiance.npz")
    scene = mi.load_file(str(xml), optimize=False)
    res = photon_irradiance(scene, photons=4_000_000, seed=4)
    np.testing.assert_array_equal(data["ground/total/total"], res.irradiance("ground"))
    np.testing.assert_array_equal(data["tuft07/par/total"], res.irradiance("tuft07", "par"))
    np.testing.assert_array_equal(data["elements/total/direct"],
                                  res.element_irradiance("total", "direct"))
    assert list(data["instances/ids"]) == [f"tuft{i:02d}" for i in range(30)]
    assert len(res.instances) == 30 and res.irradiance("tuft04").shape == (8,)
    assert res.irradiance("tuft03").shape == (10,)  # plant1: 5 leaf quads
    # energy bookkeeping
    assert res.absorbed.sum() + res.escaped.sum() + res.truncated.sum() == pytest.approx(
        res.emitted.sum(), rel=1e-4)
    # against path + irradiancemeter on ground triangles (lit, shaded by the tufts, between)
    irr = res.irradiance("ground")
    order = np.argsort(irr)
    tris = sorted({int(t) for t in np.concatenate([order[-3:], order[len(order) // 2:][:3],
                                                   order[:4]])})
    ref, err = V.path_reference(d, "ground", tris, spp=262144, seed=1)
    for t, r in zip(tris, ref):
        assert irr[t] == pytest.approx(r, rel=0.05), (t, irr[t], r)
    assert ref.max() > 1.3 * ref.min()  # the check sees shade and light
