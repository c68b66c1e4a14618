"""Running a parsed command: logging, and library errors turned into one line on stderr and
an exit code (:func:`run_parsed`); one sub-command on its own (:func:`standalone`)."""
from __future__ import annotations

import logging
import sys

from ..daily import Interrupted
from ..errors import MitsubaVegError
from .args import Parser


__all__ = ["run_parsed", "standalone"]

def _setup_logging(a) -> None:
    level = (getattr(a, "log_level", None) or ("info" if getattr(a, "verbose", False)
                                               else "warning")).upper()
    log = logging.getLogger("mitsuba_veg")
    log.setLevel(level)
    if not any(getattr(h, "_mitsuba_veg", False) for h in log.handlers):
        h = logging.StreamHandler(sys.stderr)
        h.setFormatter(logging.Formatter("mitsuba-veg: %(levelname)s: %(message)s"))
        h._mitsuba_veg = True
        log.addHandler(h)
        log.propagate = False


def run_parsed(a) -> int:
    """Run a parsed command.

    A library error (bad input) becomes one line on stderr and exit code 2; an interrupted run
    exit code 130; an unexpected error one line and exit code 1 (``--verbose`` adds the
    traceback).

    Parameters
    ----------
    a : argparse.Namespace
        With ``func`` (the command) and the options.

    Returns
    -------
    int
        The exit code.
    """
    _setup_logging(a)
    try:
        return a.func(a)
    except Interrupted as e:
        print(f"\nmitsuba-veg: {e}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("\nmitsuba-veg: interrupted", file=sys.stderr)
        return 130
    except MitsubaVegError as e:
        print(f"mitsuba-veg: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    except OSError as e:  # a file that cannot be read or written
        where = f"{e.filename}: " if e.filename else ""
        print(f"mitsuba-veg: error: {where}{e.strerror or e} (check the path and its "
              "permissions)", file=sys.stderr)
        return 2
    except Exception as e:  # noqa: BLE001 - the command line's last resort
        if getattr(a, "verbose", False):
            raise
        msg = " ".join(str(e).split())[:300]
        print(f"mitsuba-veg: internal error: {type(e).__name__}: {msg} (run again with "
              "--verbose for the traceback, and please report it)", file=sys.stderr)
        return 1


def standalone(command: str, add_parser, argv=None) -> int:
    """Run one sub-command on its own (``python -m ...``).

    Parameters
    ----------
    command : str
        The sub-command's name.
    add_parser : callable
        Adds it to an argparse sub-parser set.
    argv : list of str, optional
        The arguments after the command's name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit code.
    """
    ap = Parser(prog="mitsuba-veg")
    add_parser(ap.add_subparsers(dest="cmd", required=True))
    return run_parsed(ap.parse_args([command, *(sys.argv[1:] if argv is None else argv)]))
