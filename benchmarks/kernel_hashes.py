"""Whether a world day compiles to the same kernels in every process (Dr.Jit's disk cache hits).

    python benchmarks/kernel_hashes.py [--processes 3] [--days 2] [--photons 20000]

Runs ``--processes`` separate Python processes, each setting up the courtyard world of
benchmarks/world_year.py (1 July) and simulating ``--days`` days with Dr.Jit's kernel history
on, and compares the hashes of the JIT kernels each day's stages launched. A kernel whose code
differs between processes (e.g. because an input's address alignment is part of its code:
docs/architecture.md, "Kernel inputs, not literals") misses Dr.Jit's disk cache and is compiled
again by every run; the target is one hash per kernel over all processes. Printed: per stage,
the kernels of the last day and how many distinct hashes each had.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import json, shutil, sys, tempfile
from pathlib import Path
sys.path.insert(0, {bench!r})
import drjit as dr
from mitsuba_veg.daily import Simulation
from mitsuba_veg.daily import pipeline as P
from mitsuba_veg.scenario import load_scenario
from world_year import EXTRA
tmp = Path(tempfile.mkdtemp())
shutil.copytree(Path({root!r}) / "scenes" / "courtyard", tmp / "courtyard")
f = tmp / "courtyard" / "scenario.toml"
f.write_text(f.read_text().replace("[phenology]", EXTRA + "\n[phenology]", 1))
scn = load_scenario(f, ['simulation.start_date="2026-07-01"', "light.photons={photons}"])
sim = Simulation(scn, tmp / "run", days={days}, progress=False)
sim.setup()
sim.initialise()
seen = []
count = P._Launches.__call__
def call(self, stage):
    # the history read by the day's own counter, kept per stage (JIT kernels only)
    if self.on:
        h = dr.kernel_history()
        seen.extend((stage, x["hash"], int(x["size"])) for x in h
                    if x["type"] == dr.KernelType.JIT)
        self.n[stage] = self.n.get(stage, 0) + len(h)
P._Launches.__call__ = call
dr.set_flag(dr.JitFlag.KernelHistory, True)
for _ in range({days}):
    seen.clear()
    sim.step()
dr.set_flag(dr.JitFlag.KernelHistory, False)
shutil.rmtree(tmp, ignore_errors=True)
print("HASHES " + json.dumps(seen))
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--processes", type=int, default=3)
    ap.add_argument("--days", type=int, default=2)
    ap.add_argument("--photons", type=int, default=20_000)
    a = ap.parse_args(argv)
    code = CHILD.format(bench=str(ROOT / "benchmarks"), root=str(ROOT), days=a.days,
                        photons=a.photons)
    runs = []
    for i in range(a.processes):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True)
        # (Mitsuba's log may leave a colour code before the line)
        line = [ln for ln in r.stdout.splitlines() if "HASHES " in ln][-1]
        runs.append(json.loads(line.split("HASHES ", 1)[1]))
        print(f"process {i + 1}: {len(runs[-1])} JIT kernels on its day {a.days}", flush=True)
    # the k-th kernel of a stage in each process (the same launches in the same order)
    shape = [[(s, n) for s, _, n in r] for r in runs]
    if any(s != shape[0] for s in shape[1:]):
        print("the processes launched different kernels (stage, width): compare by hand")
        return 1
    per_stage: dict = {}
    for k, (stage, width) in enumerate(shape[0]):
        hashes = {r[k][1] for r in runs}
        per_stage.setdefault(stage, []).append((width, len(hashes)))
    varying = 0
    for stage, ks in per_stage.items():
        varying += sum(1 for _, h in ks if h > 1)
        print(f"{stage}: " + ", ".join(f"width {w:,d} {h} hash{'es' if h > 1 else ''}"
                                       for w, h in ks))
    total = sum(len(v) for v in per_stage.values())
    print(f"kernels whose code differs between the {a.processes} processes: {varying} of "
          f"{total} (target 0: every run finds them in Dr.Jit's disk cache)")
    from _record import Recorder
    rec = Recorder("kernel_hashes", notes=f"{a.processes} processes, the world's day {a.days}, "
                   f"{a.photons:,d} photons")
    rec.add("kernels", total, "", "JIT kernels of the day")
    rec.add("kernels_differing", varying, "", "kernels whose code differs between processes")
    rec.write()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
