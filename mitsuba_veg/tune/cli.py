"""``mitsuba-veg tune``: fit parameters of the relaxed moss model to a target coverage map.

    mitsuba-veg tune scenes/moss_garden/scenario.toml --target out/run/checkpoint.npz \\
        --params S1,T1 --species bryum_argenteum --days 30 --out out/tune
    python -m mitsuba_veg.tune SCENARIO.toml --target synthetic:S1=60,T1=299.15 --init S1=42

TARGET: a discrete run's ``checkpoint.npz`` (its covered fraction per triangle), a ``.npy``
file with one covered fraction per triangle (scene order, NaN = ignore), or
``synthetic:NAME=VALUE,...`` (a relaxed run with those parameters). Writes ``fitted.json``,
``loss_curve.png`` and ``coverage.png`` into ``--out``.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["add_parser", "main"]


def _pairs(text: str | None, what: str) -> dict:
    from ..errors import ParameterError
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
            raise ParameterError(f"{what} {k.strip()}", v, "a number") from None
    return out


def _cmd_tune(a) -> int:
    import drjit as dr
    import numpy as np

    from ..errors import ParameterError
    from . import coverage_from_checkpoint, fit, prepare
    from .smooth import SmoothMossModel
    species = [s.strip() for s in a.species.split(",")] if a.species else None
    params = [p.strip() for p in a.params.split(",") if p.strip()]
    albedo = any(p.startswith(("albedo.", "strength.")) for p in params)
    data = prepare(a.scenario, days=a.days, overrides=a.set or (), species=species,
                   photons=a.photons, light_every=a.light_every, differentiable_light=albedo,
                   progress=not a.quiet)
    model = SmoothMossModel(data, temperature=a.temperature, precision=a.precision)
    t = a.target
    if t.startswith("synthetic:"):
        with dr.suspend_grad():
            target = np.asarray(model.run(_pairs(t.split(":", 1)[1], "--target synthetic")).cover)
    else:
        p = Path(t)
        if not p.exists():
            raise ParameterError("--target", t, "an existing .npz checkpoint, .npy file or "
                                 "synthetic:NAME=VALUE,...")
        target = (coverage_from_checkpoint(p, data) if p.suffix == ".npz"
                  else np.load(p, allow_pickle=False))
    res = fit(model, target, params=params, loss=a.loss, steps=a.steps, lr=a.lr,
              init=_pairs(a.init, "--init"), out=a.out, progress=not a.quiet)
    if not a.quiet:
        for k, v in res.values.items():
            print(f"{k}: {res.initial[k]:.6g} -> {v:.6g}")
        print(f"loss {res.history[0]['loss']:.3e} -> {res.loss:.3e} ({res.seconds:.1f} s)")
        for f in res.files.values():
            print(f"  {f}")
    return 0


def add_parser(subparsers):
    """Add the ``tune`` command to an argparse sub-parser set (``mitsuba-veg tune``)."""
    p = subparsers.add_parser("tune", help="fit model parameters to a target coverage map "
                              "(differentiable relaxed moss model, Dr.Jit AD)")
    p.add_argument("scenario", help="scenario TOML, e.g. scenes/moss_garden/scenario.toml")
    p.add_argument("--target", required=True,
                   help="checkpoint.npz of a run, a .npy per-triangle cover, or "
                        "synthetic:S1=60,T1=299.15")
    p.add_argument("--params", default="S1,T1", help="comma-separated parameter names")
    p.add_argument("--init", help="starting values, e.g. S1=42,T1=306.65")
    p.add_argument("--species", help="comma-separated species keys (default: the scenario's)")
    p.add_argument("--days", type=int, default=30)
    p.add_argument("--steps", type=int, default=80)
    p.add_argument("--lr", type=float, default=0.08)
    p.add_argument("--loss", default="sqrt", choices=("sqrt", "mse", "l1"))
    p.add_argument("--temperature", type=float, default=0.05)
    p.add_argument("--precision", default="float32", choices=("float32", "float64"))
    p.add_argument("--photons", type=int, help="photons per up-front light pass")
    p.add_argument("--light-every", type=int, default=15, help="days between sun-path passes")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario field, e.g. --set climate.temperature=290")
    p.add_argument("--out", default="out/tune")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_tune)
    return p


def main(argv=None) -> int:
    """Stand-alone entry (``python -m mitsuba_veg.tune SCENARIO.toml --target ...``)."""
    from ..cli import standalone
    return standalone("tune", add_parser, argv)
