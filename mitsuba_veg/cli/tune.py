"""``mitsuba-veg tune``: fit parameters of the relaxed moss model to a target coverage map.

Example::

    mitsuba-veg tune scenes/moss_garden/scenario.toml --target out/run/checkpoint.npz \\
        --params S1,T1 --species bryum_argenteum --days 30 --out out/tune
    python -m mitsuba_veg.tune SCENARIO.toml --target synthetic:S1=60,T1=299.15 --init S1=42

TARGET: a discrete run's ``checkpoint.npz`` (its covered fraction per triangle), a ``.npy``
file with one covered fraction per triangle (scene order, NaN = ignore), an image of the
terrain (``.png``/``.jpg``) with ``--camera camera.json`` (``tune.photo``: per-triangle cover
from the pixels each triangle covers; ``--photo-mode colour|gray``), or
``synthetic:NAME=VALUE,...`` (a relaxed run with those parameters). Writes ``fitted.json``,
``loss_curve.png`` and ``coverage.png`` into ``--out``. ``--discrete-seeds 0-7`` fits the
*discrete* model on those seeds (``tune.fit_discrete``: defect correction, the relaxed model
supplies the gradient; writes ``fitted_discrete.json``).
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import drjit as dr
import numpy as np

from ..daily import MOSS_DEFAULTS
from ..errors import ParameterError
from ..moss.species import PARAMETER_FIELDS
from ..outputs import OutputFolder
from ..scenario import load_scenario
from ..tune import coverage_from_checkpoint, fit, prepare
from ..tune.discrete import DiscreteMossModel, fit_discrete
from ..tune.photo import cover_from_image, load_camera
from ..tune.smooth import SmoothMossModel
from .args import add_out, add_photons, add_quiet, add_set, ranged
from .entry import standalone

__all__ = ["add_parser", "main"]

#: --params when none are given (a run of one species; with several, refused with the choices)
DEFAULT_PARAMS = "S1,T1"
log = logging.getLogger("mitsuba_veg")


def _pairs(text: str | None, what: str) -> dict:
    out = {}
    for item in (text or "").split(","):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            raise ParameterError(what, item, "NAME=VALUE pairs separated by commas",
                                 f"e.g. {what} S1=42,T1=306")
        k, v = item.split("=", 1)
        try:
            out[k.strip()] = float(v)
        except ValueError:
            out[k.strip()] = float("nan")
        if not math.isfinite(out[k.strip()]):
            raise ParameterError(f"{what} {k.strip()}", v.strip(), "a finite number",
                                 f"e.g. {what} {k.strip()}=42")
    return out


def _seeds(text: str) -> list[int]:
    try:
        if "-" in text:
            lo, hi = (int(x) for x in text.split("-"))
            out = list(range(lo, hi + 1))
        else:
            out = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        out = []
    if not out or min(out) < 0:
        raise ParameterError("--discrete-seeds", text, "a range A-B or a list A,B,C of seeds "
                             ">= 0", "e.g. --discrete-seeds 0-7")
    return out


def _cmd_tune(a) -> int:

    species = [s.strip() for s in a.species.split(",")] if a.species else None
    text = DEFAULT_PARAMS if a.params is None else a.params
    params = [p.strip() for p in text.split(",") if p.strip()]
    if not params:
        raise ParameterError("--params", a.params, "comma-separated parameter names",
                             "e.g. --params S1,T1")
    twice = sorted({p for p in params if params.count(p) > 1})
    if twice:
        raise ParameterError("--params", a.params, f"each parameter once ({twice[0]} is "
                             "named twice)", "remove the repeated name")
    init = _pairs(a.init, "--init")
    for k in init:
        if k not in params:
            raise ParameterError("--init", f"{k}={init[k]}", "starting values of the fitted "
                                 f"parameters ({', '.join(params)})",
                                 f"add {k} to --params or remove it from --init")
    scn = load_scenario(a.scenario, a.set or ())  # bad fields refused before any work
    keys = species or list((scn.get("moss") or {}).get("species") or
                           MOSS_DEFAULTS["species"])
    t = a.target
    target = None
    synthetic = None
    if t.startswith("synthetic:"):
        synthetic = _pairs(t.split(":", 1)[1], "--target synthetic")
        if not synthetic:
            raise ParameterError("--target", t, "synthetic:NAME=VALUE,...",
                                 "e.g. --target synthetic:S1=60")
    else:
        p = Path(t)
        image = p.suffix.lower() in (".png", ".jpg", ".jpeg")
        if not p.is_file() or not (p.suffix in (".npz", ".npy") or image):
            raise ParameterError("--target", t, "an existing .npz checkpoint, .npy file, "
                                 ".png/.jpg image (with --camera) or synthetic:NAME=VALUE,...",
                                 "check the path")
        if image and not a.camera:
            raise ParameterError("--camera", None, "a camera JSON file for an image target",
                                 "give --camera camera.json (origin, target, up, fov, width, "
                                 "height; docs/tuning.md)")
        if image:
            load_camera(a.camera)  # refused before any work
        if p.suffix == ".npy":
            try:
                target = np.load(p, allow_pickle=False)
            except (OSError, ValueError, EOFError) as e:
                raise ParameterError("--target", t, "a NumPy .npy file of covered fractions "
                                     "(one per triangle)", f"it cannot be read "
                                     f"({type(e).__name__}); write it with numpy.save") from None
            if target.ndim != 1 or not np.issubdtype(target.dtype, np.floating):
                raise ParameterError("--target", t, "a 1-D float array of covered fractions "
                                     f"(got shape {target.shape}, dtype {target.dtype})",
                                     "one value in [0, 1] per triangle, NaN = ignore")
            if np.isinf(target).any():
                raise ParameterError("--target", t, "covered fractions in [0, 1] (NaN = "
                                     f"ignore; it holds {int(np.isinf(target).sum())} "
                                     "infinite values)", "write NaN where there is no "
                                     "value, else a fraction in [0, 1]")
            fin = target[np.isfinite(target)]
            if fin.size == 0 or fin.min() < 0 or fin.max() > 1:
                raise ParameterError("--target", t, "covered fractions in [0, 1] (NaN = "
                                     "ignore), at least one finite", "check the array")
    # a species parameter without its species is ambiguous when the run has several: say so
    # now (not after the set-up), and name the choices
    if len(keys) > 1:
        for opt, names in (("--params", params), ("--target synthetic", synthetic or {})):
            bare = [n for n in names if n in PARAMETER_FIELDS]
            if bare:
                default = " (the default)" if opt == "--params" and a.params is None else ""
                raise ParameterError(opt, ",".join(names) + default, f"species parameters "
                                     f"named with their species: the run has {len(keys)} "
                                     f"species ({', '.join(keys)}), e.g. {keys[0]}.{bare[0]}",
                                     f"write {keys[0]}.{bare[0]} (also in --params, --init and "
                                     f"synthetic targets), or tune one species with --species "
                                     f"{keys[0]}")
    folder = OutputFolder(a.out, "tune")
    albedo = any(p.startswith(("albedo.", "strength.")) for p in params)
    data = prepare(a.scenario, days=a.days, overrides=a.set or (), species=species,
                   photons=a.photons, light_every=a.light_every, differentiable_light=albedo,
                   progress=not a.quiet)
    model = SmoothMossModel(data, temperature=a.temperature, precision=a.precision,
                            closure=a.closure)
    if t.startswith("synthetic:"):
        with dr.suspend_grad():
            target = np.asarray(model.run(synthetic).cover)
    elif target is None and Path(t).suffix.lower() in (".png", ".jpg", ".jpeg"):
        target = cover_from_image(Path(t), a.camera, data.scene, data.index, living=data.living,
                                  mode=a.photo_mode)
    elif target is None:
        target = coverage_from_checkpoint(Path(t), data)
    if target.shape != (data.n,):
        raise ParameterError("--target", t, f"one covered fraction per triangle ({data.n} "
                             f"values; got {target.shape[0]})", "use a target made for this "
                             "scenario's scene")
    usable = np.isfinite(target) & np.asarray(data.living, bool)
    if not usable.any():   # NaN everywhere moss can live: the fit would see no data at all
        raise ParameterError("--target", t, "a finite covered fraction on at least one "
                             f"triangle moss can live on (all {int(data.living.sum())} of "
                             "them are NaN here)", "give values for the living surfaces "
                             "(NaN = ignore that triangle)")
    n_nan = int(np.asarray(data.living, bool).sum() - usable.sum())
    if n_nan:
        log.warning("--target: %d of %d triangles moss can live on are NaN and left out of "
                    "the fit", n_nan, int(data.living.sum()))
    if a.discrete_seeds:
        seeds = _seeds(a.discrete_seeds)
        if a.loss == "l1":
            raise ParameterError("--loss", a.loss, "sqrt or mse with --discrete-seeds")
        dm = DiscreteMossModel(a.scenario, data.days, species=species, seeds=seeds,
                               photons=a.photons, overrides=a.set or ())
        dres = fit_discrete(dm, model, target, params, init=init, loss=a.loss,
                            out=a.out, verbose=not a.quiet)
        folder.release()
        if not a.quiet:
            for k, v in dres.values.items():
                print(f"{k}: {dres.initial[k]:.6g} -> {v:.6g} (discrete model, seeds "
                      f"{a.discrete_seeds})")
            print(f"  {dres.files['fitted']}")
        return 0
    res = fit(model, target, params=params, loss=a.loss, steps=a.steps, lr=a.lr,
              init=init, out=a.out, progress=not a.quiet)
    folder.release()
    if not a.quiet:
        for k, v in res.values.items():
            print(f"{k}: {res.initial[k]:.6g} -> {v:.6g}")
        print(f"loss {res.history[0]['loss']:.3e} -> {res.loss:.3e} ({res.seconds:.1f} s)")
        for f in res.files.values():
            print(f"  {f}")
    return 0


def add_parser(subparsers):
    """Add the ``tune`` command to an argparse sub-parser set (``mitsuba-veg tune``).

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command registry of the ``mitsuba-veg`` parser (``add_subparsers()``).

    Returns
    -------
    argparse.ArgumentParser
        The ``tune`` parser.
    """
    p = subparsers.add_parser("tune", help="fit model parameters to a target coverage map "
                              "(differentiable relaxed moss model, Dr.Jit AD)")
    p.add_argument("scenario", help="scenario TOML, e.g. scenes/moss_garden/scenario.toml")
    p.add_argument("--target", required=True,
                   help="checkpoint.npz of a run, a .npy per-triangle cover, or "
                        "synthetic:S1=60,T1=299.15")
    p.add_argument("--params", help="comma-separated parameter names, each once (species "
                   "thresholds S1, T1, alpha_g, ... written SPECIES.S1 when the run has "
                   "several species; T, rh; albedo.SHAPE; strength.sun, strength.sky; default "
                   f"{DEFAULT_PARAMS}, for a run of one species)")
    p.add_argument("--init", help="starting values of fitted parameters, e.g. S1=42,T1=306.65 "
                   "(default: the species table's)")
    p.add_argument("--species", help="comma-separated species keys (default: the scenario's)")
    p.add_argument("--days", type=ranged(int, 1, 100_000, "days"), default=30,
                   help="simulated days")
    p.add_argument("--steps", type=ranged(int, 1, 100_000, "steps"), default=80,
                   help="optimiser steps")
    p.add_argument("--lr", type=ranged(float, 1e-9, 10.0), default=0.08,
                   help="Adam learning rate (in units of each parameter's scale)")
    p.add_argument("--loss", default="sqrt", choices=("sqrt", "mse", "l1"),
                   help="loss between covered fractions")
    p.add_argument("--relax-temperature", "--temperature", dest="temperature",
                   type=ranged(float, 0.0, 10.0), default=0.05,
                   help="relaxation temperature t of the smoothed thresholds (dimensionless; "
                        "0 = the discrete life cycle; not the air temperature, which is "
                        "climate.temperature)")
    p.add_argument("--precision", default="float32", choices=("float32", "float64"),
                   help="floating-point precision of the relaxed model")
    p.add_argument("--closure", default="mean-field", choices=("mean-field", "near-field"),
                   help="spatial closure of the relaxed model (near-field: gemmae crowded by "
                        "their siblings, closer to discrete runs; docs/tuning.md)")
    p.add_argument("--camera", help="camera JSON of an image target (origin, target, up, fov, "
                   "width, height)")
    p.add_argument("--photo-mode", default="colour", choices=("colour", "gray"),
                   help="image target: colour photograph unmixed between bare soil and moss, "
                        "or gray value = covered fraction")
    p.add_argument("--discrete-seeds", help="fit the discrete model on these seeds, e.g. 0-7 "
                   "(defect correction; slow: 1 discrete run per seed and iteration)")
    add_photons(p, None, "per up-front light pass (default: the scenario's light.photons)")
    p.add_argument("--light-every", type=ranged(int, 1, 100_000, "days"), default=15,
                   help="days between sun-path light passes")
    add_set(p, "scenario", "climate.temperature=290")
    add_out(p, "out/tune", "fitted.json, loss_curve.png and coverage.png")
    add_quiet(p)
    p.set_defaults(func=_cmd_tune)
    return p


def main(argv=None) -> int:
    """Stand-alone entry (``python -m mitsuba_veg.tune SCENARIO.toml --target ...``).

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``tune`` (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit code.
    """
    return standalone("tune", add_parser, argv)
