"""``mitsuba-veg hemiphoto RUN_DIR --at X,Z [--at ...] (--day N | --years)``: hemispherical
photographs of a run's floor, what field instruments would read there, and the truth
(:func:`mitsuba_veg.canopy_photo.hemiphoto.run_hemiphoto`; docs/hemiphoto.md)."""
from __future__ import annotations

import argparse

from ..canopy_photo.hemiphoto import parse_at, run_hemiphoto
from ..canopy_photo.light_truth import DEFAULT_PHOTONS, DEFAULT_SIZE
from ..integrators.veg_fisheye import PROJECTIONS
from ..errors import ParameterError
from .args import add_out, add_quiet, light_type, ranged

__all__ = ["add_parser"]


def _at(text: str):
    """``--at X,Z`` for argparse: its error is argparse's one line."""
    try:
        return parse_at(text)
    except ParameterError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_parser(subparsers):
    """Add ``hemiphoto`` to an argparse subparsers object.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The ``mitsuba-veg`` command's subparsers.

    Returns
    -------
    argparse.ArgumentParser
        The ``hemiphoto`` parser.
    """
    p = subparsers.add_parser(
        "hemiphoto", help="hemispherical canopy photographs of a run's floor: gap fractions, "
                          "LAI-2000 and Miller LAI, site factors, against the true LAI and light",
        description="Fisheye photographs at floor points of a run (binary, from the geometry; "
                    "optionally in colour), read as a field instrument would (LAI-2000 rings, "
                    "openness, effective and clumping-corrected LAI, site factors of the year's "
                    "sun paths), beside the true leaf and plant area in the view cone and, with "
                    "--truth, a photon pass of the day (docs/hemiphoto.md).")
    p.add_argument("run_dir", help="a run folder (mitsuba-veg run ... --out DIR)")
    p.add_argument("--at", action="append", type=_at, metavar="X,Z", required=True,
                   help="a floor position [m] (repeat for several points)")
    p.add_argument("--day", type=ranged(int, 1, 100_000, "day"),
                   help="the simulated day (1-based) to photograph")
    p.add_argument("--years", action="store_true",
                   help="photograph the day --on of every year of the run")
    p.add_argument("--on", default="07-15", metavar="MM-DD",
                   help="day of the year of --years")
    p.add_argument("--height", type=ranged(float, 0.01, 100.0, "m"), default=1.0,
                   help="lens height above the ground [m]")
    p.add_argument("--size", type=ranged(int, 16, 8192, "pixels"), default=1024,
                   help="photograph side [pixels]")
    p.add_argument("--projection", choices=PROJECTIONS, default="equidistant",
                   help="lens projection")
    p.add_argument("--ring-width", type=ranged(float, 0.5, 90.0, "deg"), default=5.0,
                   help="width of the extra zenith rings of the tables [deg]")
    p.add_argument("--truth", action="store_true",
                   help="also a photon pass of each day: the direct and scattered shares of the "
                        "open's sky and sun light at the points")
    p.add_argument("--photons", type=light_type("photons"), default=DEFAULT_PHOTONS, metavar="N",
                   help="photons of the --truth sky pass (its sun pass: half)")
    p.add_argument("--sensor-size", type=ranged(float, 0.01, 10.0, "m"), default=DEFAULT_SIZE,
                   help="side of the --truth pass's sensor at each point [m]")
    p.add_argument("--colour", action="store_true",
                   help="also a colour photograph (spectral render) beside each binary one")
    p.add_argument("--colour-size", type=ranged(int, 16, 8192, "pixels"), default=512,
                   help="side of the colour photograph [pixels]")
    p.add_argument("--spp", type=ranged(int, 1, 65536, "samples"), default=32,
                   help="samples per pixel of the colour photograph")
    p.add_argument("--hour", type=ranged(float, 0, 24, "h"), default=12.0,
                   help="local hour of the colour photograph's daylight [h]")
    p.add_argument("--scenario", metavar="TOML",
                   help="scenario file of the run (default: the one summary.json names)")
    add_out(p, None, "the photographs, tables and figures (default RUN_DIR/hemiphoto)")
    add_quiet(p, "no line per day")
    p.set_defaults(func=_cmd)
    return p


def _cmd(a) -> int:
    s = run_hemiphoto(a.run_dir, a.out, at=a.at, day=a.day, years=a.years, on=a.on,
                      height=a.height, size=a.size, projection=a.projection,
                      ring_width=a.ring_width, truth=a.truth, photons=a.photons,
                      sensor_size=a.sensor_size, colour=a.colour, colour_size=a.colour_size,
                      spp=a.spp, hour=a.hour, scenario=a.scenario, progress=not a.quiet)
    for r in s["photographs"]:
        line = (f"{r['date']} {r['photo']} ({r['x_m']:g}, {r['z_m']:g}): openness "
                f"{r['openness']:.3f}, LAI-2000 Le {r['lai_lai2000']:.2f}, Lang-Xiang "
                f"{r['lai_lang_xiang']:.2f}, true LAI {r['lai_true']:.2f} (PAI "
                f"{r['pai_true']:.2f}), DSF {r['site_factor_diffuse']:.3f}")
        if r["sky_direct_share"] == r["sky_direct_share"]:
            line += (f", pass: direct sky {r['sky_direct_share']:.3f} +- "
                     f"{r['sky_direct_share_se']:.3f}, scattered {r['sky_scattered_share']:.3f}")
        print(line)
    for c in s["comparison"]:
        print(f"{c['date']} {c['label']}: {c['method_mean']:.3f} vs {c['truth_mean']:.3f} "
              f"(mean |difference| {c['mean_abs_difference']:.3f})")
    print(f"{s['timings_s']['total']:.1f} s (loading {s['timings_s']['load']:.1f} s)")
    print("wrote:")
    for k in ("series", "comparison", "comparison_figure"):
        if k in s["files"]:
            print(f"  {s['files'][k]}")
    print(f"  {len(s['photographs'])} photographs (PNG + CSV) in "
          f"{s['files']['series'].rsplit('/', 1)[0]}")
    return 0
