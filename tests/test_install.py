"""A normal (non-editable) install ships the integrators and the scenes."""
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_non_editable_install_has_integrators_and_scenes(tmp_path):
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "out", "build",
                                                            "*.egg-info", "__pycache__"))
    site = tmp_path / "site"
    p = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps",
                        "--no-build-isolation", "--target", str(site), str(src)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    code = ("import mitsuba_veg, mitsuba as mi, mitsuba_veg.integrators as I;"
            "from mitsuba_veg.cli.command import _default_scenario as d;"
            "print(I.__file__); print(d());"
            "print(mi.load_dict({'type': 'veg_photon_irradiance'}))")
    env = {"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    q = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=tmp_path, env=env, timeout=300)
    assert q.returncode == 0, q.stderr[-2000:]
    lines = q.stdout.splitlines()
    assert lines[0].startswith(str(site)) and lines[0].endswith("integrators/__init__.py")
    assert lines[1].startswith(str(site)) and lines[1].endswith("courtyard/scenario.toml")
    assert "PhotonIrradianceIntegrator" in q.stdout
