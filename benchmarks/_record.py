"""Record a benchmark's headline figures: ``benchmarks/results/<name>.json``.

Every script in ``benchmarks/`` ends by handing its headline figures to :class:`Recorder`, which
writes one JSON file per benchmark (and per case, e.g. ``photon_throughput_world``) with each
figure's value and unit, the machine that measured it (CPU model and cores from
``/proc/cpuinfo``, the GPU's name on a CUDA variant), the Mitsuba variant, the versions, the
load average, the command and the date. The docs' performance and validation pages are tables
built from these files when the docs are built; nothing is copied into prose by hand.

Usage in a benchmark::

    from _record import Recorder

    rec = Recorder("photon_throughput_garden")
    rec.add("ratio_preliminary_1M", 0.51, "ratio",
            "photon-pass ray casts/s / ray_intersect_preliminary rays/s, 1M photons")
    rec.write()          # -> benchmarks/results/photon_throughput_garden.json

Figures measured elsewhere (a GPU this machine does not have, a run of hours) are carried with
``source="recorded earlier"`` and the machine they were measured on (:func:`write_recorded`),
never re-stated as this machine's. ``MITSUBA_VEG_BENCH_RESULTS`` redirects the folder (tests).
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

__all__ = ["Recorder", "machine", "results_dir", "load_results", "write_recorded", "SCHEMA"]

#: version of the JSON layout written by :class:`Recorder`
SCHEMA = 1
ROOT = Path(__file__).resolve().parent.parent


def results_dir() -> Path:
    """The folder the JSON files go to.

    Returns
    -------
    pathlib.Path
        ``$MITSUBA_VEG_BENCH_RESULTS`` when set, else ``benchmarks/results``.
    """
    env = os.environ.get("MITSUBA_VEG_BENCH_RESULTS")
    return Path(env) if env else ROOT / "benchmarks" / "results"


def _cpu() -> tuple[str, int]:
    """CPU model name and logical core count from /proc/cpuinfo (platform's as a fallback)."""
    model, cores = "", 0
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name") and not model:
                model = line.split(":", 1)[1].strip()
            if line.startswith("processor"):
                cores += 1
    except OSError:  # pragma: no cover - not Linux
        pass
    return model or platform.processor() or platform.machine(), cores or (os.cpu_count() or 0)


def _gpu_name(variant: str | None) -> str | None:
    """The CUDA device's name when the variant runs on it (nvidia-smi), else None."""
    if not variant or not variant.startswith("cuda"):
        return None
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=20)
        names = [n.strip() for n in out.stdout.splitlines() if n.strip()]
        return names[0] if names else "CUDA device"
    except (OSError, subprocess.SubprocessError):
        return "CUDA device"


def _variant() -> str | None:
    mi = sys.modules.get("mitsuba")
    try:
        return mi.variant() if mi is not None else None
    except Exception:  # noqa: BLE001 - no variant set
        return None


def machine(variant: str | None = None) -> dict:
    """The machine a figure is measured on.

    Parameters
    ----------
    variant : str, optional
        Mitsuba variant of the run (default: the active one); a ``cuda_*`` variant adds the
        GPU's name.

    Returns
    -------
    dict
        ``cpu`` (model name), ``cores`` (logical cores), ``usable_cores`` (this process's
        affinity), ``gpu`` (name or None), ``system`` (OS, release, architecture).
    """
    model, cores = _cpu()
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        usable = cores
    return {"cpu": model, "cores": cores, "usable_cores": usable,
            "gpu": _gpu_name(variant if variant is not None else _variant()),
            "system": f"{platform.system()} {platform.release()} {platform.machine()}"}


def _versions() -> dict:
    out = {"python": sys.version.split()[0]}
    for mod in ("mitsuba", "drjit", "numpy"):
        m = sys.modules.get(mod)
        if m is not None:
            out[mod] = getattr(m, "__version__", "?")
    mv = sys.modules.get("mitsuba_veg")
    if mv is not None:
        out["mitsuba_veg"] = getattr(mv, "__version__", "?")
    return out


class Recorder:
    """Collect a benchmark's headline figures and write them as one JSON file.

    Parameters
    ----------
    name : str
        File stem: ``benchmarks/results/<name>.json`` (letters, digits, ``_`` and ``-``).
    command : str, optional
        The command that reproduces the figures (default: this process's ``python`` command
        line, relative to the repository).
    notes : str, optional
        One sentence on the set-up (scene, sizes) shown beside the table.
    """

    def __init__(self, name: str, command: str | None = None, notes: str = ""):
        if not name or not all(c.isalnum() or c in "_-" for c in name):
            raise ValueError(f"benchmark name {name!r}: use letters, digits, '_' and '-'")
        self.name = name
        self.command = command or self._command()
        self.notes = notes
        self.figures: list[dict] = []

    @staticmethod
    def _command() -> str:
        argv = list(sys.argv)
        if argv:
            try:
                argv[0] = str(Path(argv[0]).resolve().relative_to(ROOT))
            except ValueError:
                pass
        return " ".join(["python"] + argv)

    def add(self, key: str, value: float, unit: str, label: str, **extra) -> "Recorder":
        """Add one headline figure.

        Parameters
        ----------
        key : str
            Stable id of the figure within this benchmark (pages look figures up by it).
        value : float
            The measured value.
        unit : str
            Its unit (``"s"``, ``"ms"``, ``"ratio"``, ``"M photons/s"``, ...).
        label : str
            What was measured, in a few words (the table's row).
        **extra
            More fields of the figure (JSON values), e.g. a validation row's ``tolerance``
            and ``test``.

        Returns
        -------
        Recorder
            ``self``, so that calls chain.
        """
        if any(f["key"] == key for f in self.figures):
            raise ValueError(f"figure {key!r} recorded twice in {self.name}")
        v = float(value) if not isinstance(value, (int, bool)) else value
        self.figures.append({"key": key, "label": label, "value": v, "unit": unit, **extra})
        return self

    def as_dict(self, source: str = "measured", machine_: dict | None = None,
                variant: str | None = None, date: str | None = None) -> dict:
        """The JSON document.

        Parameters
        ----------
        source : str
            ``"measured"`` (by this process) or ``"recorded earlier"``.
        machine_ : dict, optional
            The machine (default: this one, :func:`machine`).
        variant : str, optional
            Mitsuba variant (default: the active one).
        date : str, optional
            ISO date (default: today, UTC).

        Returns
        -------
        dict
            ``schema``, ``name``, ``source``, ``date``, ``command``, ``machine``,
            ``variant``, ``versions``, ``load_average``, ``notes``, ``figures``.
        """
        variant = variant if variant is not None else _variant()
        try:
            load = [round(x, 2) for x in os.getloadavg()] if source == "measured" else None
        except OSError:  # pragma: no cover
            load = None
        return {"schema": SCHEMA, "name": self.name, "source": source,
                "date": date or _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d"),
                "command": self.command,
                "machine": machine_ if machine_ is not None else machine(variant),
                "variant": variant,
                "versions": _versions() if source == "measured" else {},
                "load_average": load, "notes": self.notes, "figures": self.figures}

    def write(self, **kw) -> Path:
        """Write ``<results>/<name>.json`` (replacing an earlier one) and print its path.

        Parameters
        ----------
        **kw
            Passed to :meth:`as_dict`.

        Returns
        -------
        pathlib.Path
            The file written.
        """
        if not self.figures:
            raise ValueError(f"benchmark {self.name}: no figures to record")
        out = results_dir()
        out.mkdir(parents=True, exist_ok=True)
        path = out / f"{self.name}.json"
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(self.as_dict(**kw), indent=1, ensure_ascii=False) + "\n")
        os.replace(tmp, path)
        print(f"recorded {len(self.figures)} figures in {path}")
        return path


def write_recorded(name: str, command: str, figures: list[tuple], machine_: dict,
                   variant: str, date: str, notes: str = "") -> Path:
    """Carry figures measured earlier on another machine (stated in the docs) as a JSON file.

    Parameters
    ----------
    name : str
        File stem.
    command : str
        The command that measured them.
    figures : list of tuple
        ``(key, value, unit, label)`` per figure.
    machine_ : dict
        The machine they were measured on (``cpu``, ``cores``, ``gpu``, ``system``).
    variant : str
        Its Mitsuba variant.
    date : str
        The date of the measurement (ISO).
    notes : str, optional
        Where the figures come from.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    rec = Recorder(name, command=command, notes=notes)
    for key, value, unit, label in figures:
        rec.add(key, value, unit, label)
    return rec.write(source="recorded earlier", machine_=machine_, variant=variant, date=date)


def load_results(folder: Path | None = None) -> dict[str, dict]:
    """Every recorded benchmark, by name.

    Parameters
    ----------
    folder : pathlib.Path, optional
        Default :func:`results_dir`.

    Returns
    -------
    dict
        ``{name: document}`` for every ``*.json`` in the folder, sorted by name.
    """
    folder = folder or results_dir()
    out = {}
    for p in sorted(Path(folder).glob("*.json")):
        doc = json.loads(p.read_text())
        out[doc.get("name", p.stem)] = doc
    return out
