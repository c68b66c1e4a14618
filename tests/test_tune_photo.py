"""The photographed-map path (mitsuba_veg.tune.photo): an image of the terrain seen from above
with its camera -> covered fraction per triangle; round trips through synthetic photographs, a
fit of S1 to a photographed target, bad inputs."""
import json
from pathlib import Path

import drjit as dr
import numpy as np
import pytest

from mitsuba_veg import tune
from mitsuba_veg.errors import ParameterError
from mitsuba_veg.tune import photo

ROOT = Path(__file__).resolve().parent.parent
SCEN = ROOT / "scenes" / "moss_garden" / "scenario.toml"
CAM = {"origin": [0.0, 5.0, 0.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 0.0, -1.0],
       "fov": 26.0, "width": 400, "height": 400}


@pytest.fixture(scope="module")
def model():
    data = tune.prepare(SCEN, days=20, species=["bryum_argenteum"], photons=100_000,
                        light_every=10)
    return tune.SmoothMossModel(data, temperature=0.05)


@pytest.fixture(scope="module")
def cover(model):
    with dr.suspend_grad():
        return np.asarray(model.run({"S1": 60.0}).cover, float)


@pytest.mark.parametrize("mode", ["colour", "gray"])
def test_round_trip(model, cover, tmp_path, mode):
    d = model.data
    png = tmp_path / "photo.png"
    photo.render_cover_image(cover, CAM, d.scene, d.index, png, mode=mode)
    back = photo.cover_from_image(png, CAM, d.scene, d.index, living=d.living, mode=mode)
    seen = np.isfinite(back)
    # measured: max error 0.011 (colour, 8-bit sRGB unmixing), 0.002 (gray, 1/255 steps)
    assert np.nanmax(np.abs(back - cover)) < (0.015 if mode == "colour" else 0.0025)
    g = d.shape_slices["ground"]
    # from above: the open ground is seen, the ground under the roof is not (NaN: no target)
    assert seen[d.regions["open"]].all()
    assert not seen[d.regions["under_roof"] & (np.arange(d.n) < g.stop)].any()
    assert 0.3 < seen[g].mean() < 0.6                      # measured 0.425 of the ground
    # a camera file and an RGBA image give the same
    cam = tmp_path / "camera.json"
    cam.write_text(json.dumps(CAM))
    img = photo._read_image(png)
    rgba = np.concatenate([img if img.ndim == 3 else np.repeat(img[..., None], 3, -1),
                           np.ones(img.shape[:2] + (1,))], -1)
    again = photo.cover_from_image(rgba if mode == "colour" else img, cam, d.scene, d.index,
                                   living=d.living, mode=mode)
    assert np.allclose(again, back, equal_nan=True, atol=1e-12)


@pytest.mark.slow
def test_fit_to_photographed_target(model, cover, tmp_path):
    """A 16-bit classified map (gray = cover) seen from above: S1 from -30 % (the ground under
    the roof and most of the wall are not seen and not part of the loss). ~50 s."""
    d = model.data
    png = tmp_path / "map16.png"
    photo.render_cover_image(cover, CAM, d.scene, d.index, png, mode="gray", bits=16)
    target = photo.cover_from_image(png, CAM, d.scene, d.index, living=d.living, mode="gray")
    assert np.nanmax(np.abs(target - cover)) < 1e-4
    res = tune.fit(model, target, params=["S1"], init={"S1": 42.0}, steps=40, lr=0.15,
                   out=None, progress=False)
    assert abs(res.values["S1"] / 60.0 - 1) < 0.05, res.values


def test_bad_inputs(model, tmp_path):
    d = model.data
    with pytest.raises(ParameterError, match="bits"):
        photo.render_cover_image(np.zeros(d.n), CAM, d.scene, d.index, bits=16)
    with pytest.raises(ParameterError, match="camera.fov"):
        photo.load_camera(dict(CAM, fov=200))
    with pytest.raises(ParameterError, match="camera.up"):
        photo.load_camera(dict(CAM, up=[0, 1, 0]))
    with pytest.raises(ParameterError, match="camera.zoom"):
        photo.load_camera(dict(CAM, zoom=2))
    with pytest.raises(ParameterError, match="camera.width"):
        photo.load_camera(dict(CAM, width=0))
    with pytest.raises(ParameterError, match="image"):
        photo.cover_from_image(np.zeros((10, 10)), CAM, d.scene, d.index)
    with pytest.raises(ParameterError, match="mode"):
        photo.cover_from_image(np.zeros((400, 400)), CAM, d.scene, d.index, mode="hsv")
    with pytest.raises(ParameterError, match="moss"):
        photo.cover_from_image(np.zeros((400, 400, 3)), CAM, d.scene, d.index, mode="colour",
                               moss=(0.45, 0.36, 0.26))
    bad = tmp_path / "x.png"
    bad.write_text("not an image")
    with pytest.raises(ParameterError, match="image"):
        photo.cover_from_image(bad, CAM, d.scene, d.index)


def test_cli_image_target(model, cover, tmp_path, capsys):
    from mitsuba_veg.cli.tune import main
    d = model.data
    png = tmp_path / "photo.png"
    photo.render_cover_image(cover, CAM, d.scene, d.index, png)
    cam = tmp_path / "camera.json"
    cam.write_text(json.dumps(CAM))
    args = [str(SCEN), "--target", str(png), "--params", "S1", "--species", "bryum_argenteum",
            "--days", "3", "--steps", "2", "--photons", "20000", "--out", str(tmp_path / "o"),
            "--quiet"]
    assert main(args + ["--camera", str(cam)]) == 0
    f = json.loads((tmp_path / "o" / "fitted.json").read_text())
    assert f["steps"] == 2
    assert main(args) == 2 and "--camera" in capsys.readouterr().err
    assert main(args + ["--camera", str(cam), "--discrete-seeds", "x"]) == 2
    assert "--discrete-seeds" in capsys.readouterr().err
