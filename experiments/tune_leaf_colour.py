"""PROSPECT-D in Dr.Jit and fits of leaf pigments to a colour (docs/tuning.md, "Leaf colour").

Measures: the exponential integral against SciPy; Dr.Jit against NumPy PROSPECT-D on random
leaves; AD gradients against central finite differences; the Dr.Jit colour against
``spectrum_to_srgb`` and colour-science; timings; what a colour identifies (the sensitivity of
the pigments to ΔE*ab = 1 at Ishikura's stages, fits to 8-bit sRGB targets, fits with a wrong
N); and the synthetic inverse problems (Adam from ±30 % boxes, from the look-up-table start
and from a fixed start; least squares; a reflectance spectrum with six unknowns).

    python experiments/tune_leaf_colour.py [--out out/tune_leaf_colour]
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import drjit as dr  # noqa: E402

import mitsuba_veg  # noqa: E402,F401
from mitsuba_veg.foliage import colour_dr as cdr  # noqa: E402
from mitsuba_veg.foliage import prospect, prospect_dr, spectra  # noqa: E402
from mitsuba_veg.foliage.pigments import LeafTraits, pigments_at_stage  # noqa: E402
from mitsuba_veg.tune import colour_sensitivity, fit_leaf_colour  # noqa: E402

F = prospect_dr.Float64
TR = LeafTraits()
TRAITS = {"N": TR.N, "Cw": TR.Cw, "Cm": TR.Cm, "Cbrown": TR.Cbrown}
PIG = ("Cab", "Car", "Anth")


def stage(st):
    pig = {k: float(v) for k, v in pigments_at_stage(st).items()}
    wl, R, T = prospect.prospect_d(**TRAITS, **pig)
    return pig, wl, R, T


def timed(fn, repeat=20):
    fn()
    t = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return float(np.median(t))


def accuracy():
    from scipy.special import exp1
    out = {}
    x = np.concatenate([np.geomspace(1e-12, 200.0, 20000), np.linspace(2.4, 2.6, 2001)])
    out["exp1_max_rel_err"] = float(np.max(np.abs(np.asarray(prospect_dr.exp1(x)) / exp1(x) - 1)))
    rng = np.random.default_rng(1)
    n = 500
    p = {"N": rng.uniform(1, 3.5, n), "Cab": rng.uniform(0, 120, n), "Car": rng.uniform(0, 30, n),
         "Anth": rng.uniform(0, 60, n), "Cbrown": rng.uniform(0, 2, n),
         "Cw": rng.uniform(0, 0.08, n), "Cm": rng.uniform(0, 0.04, n)}
    _, R, T = prospect.prospect_d(**p)
    Rd, Td = prospect_dr.prospect_d(**p).numpy()
    out["prospect_max_abs_diff_R"] = float(np.max(np.abs(Rd - R)))
    out["prospect_max_abs_diff_T"] = float(np.max(np.abs(Td - T)))
    out["prospect_max_rel_diff_T"] = float(np.max(np.abs(Td - T) / np.maximum(T, 1e-300)))
    # gradients of a random projection of R and T against central differences (3 leaves)
    worst = {}
    for i in range(3):
        base = {k: float(v[i]) for k, v in p.items()}
        wR, wT = rng.uniform(0, 1, 2101), rng.uniform(0, 1, 2101)
        xs = {k: F(v) for k, v in base.items()}
        for v in xs.values():
            dr.enable_grad(v)
        s = prospect_dr.prospect_d(**xs)
        dr.backward(dr.sum(s.reflectance * F(wR) + s.transmittance * F(wT)))
        for k, v in base.items():
            h = 1e-4 * max(v, 1e-3)

            def f(q):
                _, r, t = prospect.prospect_d(**{**base, k: q})
                return float(r @ wR + t @ wT)
            fd = (f(v + h) - f(max(v - h, 0.0))) / (v + h - max(v - h, 0.0))
            worst[k] = max(worst.get(k, 0.0), abs(float(dr.grad(xs[k])[0]) / fd - 1))
    out["grad_rel_err_vs_fd"] = worst
    # colour
    spec = np.array([s for st in range(1, 8) for s in stage(st)[2:]])
    wl = prospect.WAVELENGTHS
    d = 0.0
    for e in (1.0, 4.0):
        ref = spectra.spectrum_to_srgb(wl, spec, e)
        got = np.stack([np.asarray(c) for c in
                        cdr.spectrum_to_srgb(wl, F(spec.ravel()), e, n_leaves=len(spec))], 1)
        d = max(d, float(np.max(np.abs(got - ref))))
    out["srgb_max_abs_diff"] = d
    import colour
    W = cdr.colour_weights(wl)
    white = cdr.white_point(W)
    lab = np.stack([np.asarray(c) for c in cdr.xyz_to_lab(
        cdr.spectrum_to_xyz(F(spec.ravel()), W, n_leaves=len(spec)), white)], 1)
    ref = colour.XYZ_to_Lab(spec @ W, illuminant=colour.XYZ_to_xy(white))
    out["lab_max_abs_diff"] = float(np.max(np.abs(lab - ref)))
    return out


def timings():
    out = {}
    base = {**TRAITS, "Cab": 25.0, "Car": 4.0, "Anth": 12.0}

    def numpy_full():
        prospect.prospect_d(**base)

    def dr_full():
        s = prospect_dr.prospect_d(**base)
        dr.eval(s.reflectance, s.transmittance)
        dr.sync_thread()

    W = cdr.colour_weights(np.arange(400.0, 831.0))
    white = cdr.white_point(W)

    def dr_lab_grad():
        x = {k: F(v) for k, v in base.items()}
        for k in PIG:
            dr.enable_grad(x[k])
        s = prospect_dr.prospect_d(**x, wavelengths=(400, 830), check=False)
        lab = cdr.xyz_to_lab(cdr.spectrum_to_xyz(s.reflectance, W), white)
        dr.backward(sum(c * c for c in lab))
        [float(dr.grad(x[k])[0]) for k in PIG]

    many = {k: np.full(1000, v) for k, v in base.items()}

    def dr_many():
        s = prospect_dr.prospect_d(**many)
        dr.eval(s.reflectance)
        dr.sync_thread()

    out["numpy_one_leaf_400_2500_ms"] = 1e3 * timed(numpy_full)
    out["drjit_one_leaf_400_2500_ms"] = 1e3 * timed(dr_full)
    out["drjit_1000_leaves_400_2500_ms"] = 1e3 * timed(dr_many, 5)
    out["numpy_1000_leaves_400_2500_ms"] = 1e3 * timed(lambda: prospect.prospect_d(**many), 5)
    out["drjit_lab_value_and_grad_ms"] = 1e3 * timed(dr_lab_grad)
    return out


def identifiability():
    rows = []
    for st in range(1, 8):
        pig, wl, R, _ = stage(st)
        srgb = spectra.spectrum_to_srgb(wl, R)
        s = colour_sensitivity(pig)
        q = np.round(srgb * 255) / 255
        r8 = fit_leaf_colour(q, init=pig, method="least_squares", steps=100, progress=False)
        rN = fit_leaf_colour(srgb, init={**pig, "N": 1.6}, method="least_squares", steps=100,
                             progress=False)
        rows.append({"stage": st, "pigments": pig, "lab": s["lab"].tolist(),
                     "srgb8": (q * 255).round().astype(int).tolist(),
                     "per_delta_e": s["per_delta_e"],
                     "cond": float(s["singular_values"][0] / s["singular_values"][-1]),
                     "fit_8bit": r8.values, "delta_e_8bit_target": float(
                         np.linalg.norm(r8.target.lab - s["lab"])),
                     "fit_N1.6": rN.values, "delta_e_N1.6": rN.delta_e})
    s4 = colour_sensitivity(stage(5)[0], ("N", "Cab", "Car", "Anth"))
    return {"stages": rows, "null_space_stage5": s4["null_space"][0].tolist()}


def inverse():
    out = {}
    # Adam from the 8 corners of the ±30 % box at stages 5 and 7
    for st in (5, 7):
        pig, wl, R, _ = stage(st)
        target = spectra.spectrum_to_srgb(wl, R)
        errs, des, secs = [], [], []
        for signs in itertools.product((-1, 1), repeat=3):
            init = {k: v * (1 + 0.3 * s) for (k, v), s in zip(pig.items(), signs)}
            r = fit_leaf_colour(target, init=init, progress=False)
            errs.append(max(abs(r.values[k] / pig[k] - 1) for k in pig))
            des.append(r.delta_e)
            secs.append(r.seconds)
        out[f"adam_box_stage{st}"] = {"max_rel_err": max(errs), "max_delta_e": max(des),
                                      "median_s": float(np.median(secs))}
    # ten leaves (5 stages + 5 random): LUT start (default), fixed start, least squares
    rng = np.random.default_rng(0)
    cases = [stage(st)[0] for st in (1, 3, 5, 6, 7)]
    cases += [{"Cab": rng.uniform(2, 60), "Car": rng.uniform(1, 12), "Anth": rng.uniform(0, 30)}
              for _ in range(5)]
    for name, kw in (("adam_lut_start", {}),
                     ("adam_fixed_start", {"init": {"Cab": 30.0, "Car": 5.0, "Anth": 5.0}}),
                     ("least_squares_lut_start", {"method": "least_squares", "steps": 100})):
        rows = []
        for pig in cases:
            _, R, _ = prospect.prospect_d(**TRAITS, **pig)
            target = spectra.spectrum_to_srgb(prospect.WAVELENGTHS, R)
            r = fit_leaf_colour(target, progress=False, **kw)
            rows.append({"truth": pig, "fit": r.values, "delta_e": r.delta_e,
                         "evaluations": r.stats["evaluations"], "seconds": r.seconds})
        out[name] = {"rows": rows, "worst_delta_e": max(x["delta_e"] for x in rows),
                     "n_delta_e_below_1e-3": sum(x["delta_e"] < 1e-3 for x in rows),
                     "max_rel_err": max(abs(x["fit"][k] - x["truth"][k]) / max(x["truth"][k], 1)
                                        for x in rows for k in PIG),
                     "median_s": float(np.median([x["seconds"] for x in rows]))}
    # a reflectance spectrum, six unknowns
    truth = {"N": 1.4, "Cab": 25.0, "Car": 4.0, "Anth": 12.0, "Cw": 0.012, "Cm": 0.0045}
    _, R, _ = prospect.prospect_d(**truth)
    for name, kw in (("spectrum_adam", {}), ("spectrum_least_squares",
                                             {"method": "least_squares", "steps": 100})):
        r = fit_leaf_colour({"reflectance": R}, params=list(truth), progress=False, **kw)
        out[name] = {"max_rel_err": max(abs(r.values[k] / v - 1) for k, v in truth.items()),
                     "rms": float(np.sqrt(r.loss)), "evaluations": r.stats["evaluations"],
                     "seconds": r.seconds, "start": r.initial}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/tune_leaf_colour")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    res = {"accuracy": accuracy(), "timings": timings(), "identifiability": identifiability(),
           "inverse": inverse()}
    (out / "results.json").write_text(json.dumps(res, indent=1, default=float))
    print(json.dumps({k: v for k, v in res.items() if k != "inverse"}, indent=1, default=float))
    for k, v in res["inverse"].items():
        print(k, {kk: vv for kk, vv in v.items() if kk != "rows"})
    print(f"written {out / 'results.json'}")


if __name__ == "__main__":
    main()
