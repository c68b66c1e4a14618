"""Noise of a shipped render against a 512-spp render of the same view, command to command.

The demo's midsummer overview (``out/demo/world``, the day ``make demo`` renders as
``render_summer``) at 480x270: ``mitsuba-veg render`` at the shipped settings (its default
samples, the denoiser on) and at 512 samples per pixel without the denoiser, each as its own
command, timed from start to end. The error is sqrt(mean((a - b)²)) / mean(b) over all pixels of
linear sRGB: ``a`` the shipped PNG's linear image (the EXR's ``display`` channels), ``b`` the
reference's rendered RGB. Targets: <= 5 % at <= 1/8 of the reference's wall time.

Also printed: the shipped render without the denoiser, and the frame-to-frame flicker of an
animation of a static scene (the same day twice at ``animate``'s settings), mean |frame 1 -
frame 2| / mean over linear sRGB: with one sampler seed for every frame (as ``animate`` renders
them) and with a new seed per frame, denoised and not.

Each command runs ``--repeat`` times (default 2, alternating shipped, reference and 1-spp) and
its fastest time counts: the wall time of a command on a shared machine varies by a quarter
from run to run (7.1-10.4 s measured for the same shipped command within minutes), and a
render whose kernels are not yet in Dr.Jit's cache pays their compilation once.

    python benchmarks/render_noise.py [RUN_DIR] [--ref-spp 512] [--repeat 2]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _cmd(args) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "mitsuba_veg.cli", *args], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _rgb(exr, display: bool) -> np.ndarray:
    from mitsuba_veg.render.film import read_exr
    ch = read_exr(exr)
    pre = "display." if display and "display.R" in ch else ""
    return np.stack([ch[f"{pre}{c}"] for c in "RGB"], -1).astype(np.float64)


def summer_day(run_dir) -> int:
    """The day ``mitsuba-veg demo`` renders as midsummer: the most PAR absorbed by the trees."""
    s = json.loads((Path(run_dir) / "summary.json").read_text())
    rec = max(s["days_record"], key=lambda r: sum(t["absorbed_par_W"]
                                                  for t in r["trees"].values()))
    return int(rec["day"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_dir", nargs="?", default="out/demo/world")
    ap.add_argument("--camera", default="overview")
    ap.add_argument("--ref-spp", type=int, default=512)
    ap.add_argument("--repeat", type=int, default=2,
                    help="runs of each command; the fastest counts (default 2)")
    ap.add_argument("--json", help="write the figures here")
    a = ap.parse_args(argv)
    if not (Path(a.run_dir) / "summary.json").is_file():
        raise SystemExit(f"{a.run_dir}: no run folder (make demo writes out/demo/world)")
    day = summer_day(a.run_dir)
    view = ["render", a.run_dir, "--day", str(day), "--camera", a.camera, "--width", "480",
            "--height", "270", "--quiet"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        times = {"ship": [], "ref": [], "fixed": []}
        for _ in range(max(a.repeat, 1)):
            times["ship"].append(_cmd(view + ["--out", str(tmp / "ship")]))
            times["ref"].append(_cmd(view + ["--out", str(tmp / "ref"), "--spp", str(a.ref_spp),
                                             "--no-denoise"]))
            # what every render command costs whatever its samples: start, run, trees, scene,
            # the integrator's tracing (its Python plugins), outputs
            times["fixed"].append(_cmd(view + ["--out", str(tmp / "fixed"), "--spp", "1",
                                               "--no-denoise"]))
        t_ship, t_ref, t_fixed = (min(times[k]) for k in ("ship", "ref", "fixed"))
        exr = f"render_{a.camera}.exr"
        ref = _rgb(tmp / "ref" / exr, False)
        ship = _rgb(tmp / "ship" / exr, True)
        raw = _rgb(tmp / "ship" / exr, False)
        spp = json.loads((tmp / "ship" / "render.json").read_text())["settings"]["spp"]

    def err(x):
        return float(np.sqrt(np.mean((x - ref) ** 2)) / np.mean(ref))

    # flicker: the same day twice as an animation renders it (its settings and seeds)
    import mitsuba_veg  # noqa: F401
    from mitsuba_veg.render import history, scene as S, still
    from mitsuba_veg.render.animation import ANIMATE_DEFAULTS
    from mitsuba_veg.render.world import trees_for_run
    run = history.load_run(a.run_dir)
    fr = run.frame(day)
    trees, seasons = trees_for_run(run, None, day)
    for s in seasons:
        s.apply(fr.date)
    o = S.RenderOptions(width=ANIMATE_DEFAULTS["width"], height=ANIMATE_DEFAULTS["height"],
                        spp=ANIMATE_DEFAULTS["spp"], camera=ANIMATE_DEFAULTS["camera"],
                        max_depth=5)
    rs = S.build_scene(run.scenario, fr.moss, moss_size=run.moss_size, trees=trees,
                       date=fr.date, options=o, terrain=S.Terrain.from_scenario(run.scenario))
    flicker = {}
    for name, seeds in (("one_seed", (0, 0)), ("seed_per_frame", (0, 1))):
        for dn in (True, False):
            f1, f2 = (still.render(rs, seed=k, denoise=dn)["display"] for k in seeds)
            flicker[f"{name}_{'denoised' if dn else 'raw'}"] = \
                float(np.mean(np.abs(f1 - f2)) / np.mean(f1))
    out = {"run": a.run_dir, "day": day, "camera": a.camera, "width": 480, "height": 270,
           "spp": spp, "ref_spp": a.ref_spp, "shipped_s": t_ship, "reference_s": t_ref,
           "fixed_s": t_fixed, "time_ratio": t_ship / t_ref,
           "time_ratio_beyond_fixed": (t_ship - t_fixed) / max(t_ref - t_fixed, 1e-9),
           "error_denoised": err(ship), "error_raw": err(raw),
           **{f"flicker_{k}": v for k, v in flicker.items()},
           "animation_spp": ANIMATE_DEFAULTS["spp"], "runs_s": times}
    ok = "ok" if out["error_denoised"] <= 0.05 and out["time_ratio"] <= 1 / 8 else "MISSED"
    print(f"{a.run_dir} day {day}, {a.camera} at 480x270:")
    print(f"  shipped ({spp} spp, denoised) {t_ship:.1f} s, reference ({a.ref_spp} spp) "
          f"{t_ref:.1f} s: time ratio {out['time_ratio']:.3f} (target <= 0.125); a 1-spp "
          f"command {t_fixed:.1f} s, the ratio beyond it {out['time_ratio_beyond_fixed']:.3f}")
    print("  every run [s]: " + "; ".join(f"{k} " + ", ".join(f"{t:.1f}" for t in v)
                                          for k, v in times.items()))
    print(f"  error against the reference: {100 * out['error_denoised']:.2f} % denoised "
          f"(target <= 5 %), {100 * out['error_raw']:.2f} % without the denoiser  {ok}")
    print(f"  animation frames of a static scene ({ANIMATE_DEFAULTS['spp']} spp), flicker: "
          f"one seed (animate) {100 * flicker['one_seed_denoised']:.2f} % denoised; a seed per "
          f"frame {100 * flicker['seed_per_frame_denoised']:.2f} % denoised, "
          f"{100 * flicker['seed_per_frame_raw']:.2f} % without")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    from _record import Recorder
    rec = Recorder("render_noise", notes=f"the courtyard's midsummer {a.camera} (day {day}) at "
                   f"480x270: the shipped render ({spp} spp, denoised) against {a.ref_spp} "
                   f"spp; the fastest of {max(a.repeat, 1)} runs of each command")
    rec.add("error_denoised", out["error_denoised"], "ratio",
            "RMS error / mean, shipped (denoised) against the reference (target <= 0.05)")
    rec.add("error_raw", out["error_raw"], "ratio", "the same without the denoiser")
    rec.add("time_ratio", out["time_ratio"], "ratio",
            "shipped / reference wall time, command to command (target <= 0.125)")
    rec.add("time_ratio_beyond_fixed", out["time_ratio_beyond_fixed"], "ratio",
            "the same beyond a 1-spp command's cost (start, scene, tracing, outputs)")
    rec.add("fixed_s", t_fixed, "s", "a 1-spp render command without the denoiser")
    rec.add("shipped_s", t_ship, "s", "the shipped render command")
    rec.add("reference_s", t_ref, "s", f"the {a.ref_spp}-spp render command")
    rec.add("flicker_one_seed", flicker["one_seed_denoised"], "ratio",
            "mean |frame - frame| / mean of a static scene, animate's settings (one seed)")
    rec.add("flicker_seed_per_frame", flicker["seed_per_frame_denoised"], "ratio",
            "the same with a new seed per frame, denoised")
    rec.write()
    return out


if __name__ == "__main__":
    main()
