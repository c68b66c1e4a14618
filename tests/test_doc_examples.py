"""Every code block of the README and of the docs runs as written.

A page's fenced blocks run in order in a fresh process, in a scratch folder that holds links to
the repository's ``scenes/``, ``benchmarks/``, ``experiments/`` and ``examples/`` (so the
relative paths of the docs work and outputs land in the scratch folder's ``out/``):

- ``python`` blocks are executed in one namespace (a page reads like a notebook);
- ``sh`` / ``bash`` / ``console`` blocks run with ``bash -euo pipefail`` (``mitsuba-veg`` and
  ``python`` from this environment first on ``PATH``); a ``$ `` prompt is stripped;
- ``toml`` blocks must parse (``tomllib``), ``xml`` blocks must be well-formed.

A block whose first line is a comment ``# [skip: REASON]`` (``<!-- [skip: REASON] -->`` in XML)
is shown to the reader with that marker and not run: it needs a GPU, a Dask cluster or more
time than this check has. Marked ``docs``: ``make docs`` runs this file; ``make test`` leaves it
out (``-m "not slow and not docs"``). ``python tests/test_doc_examples.py PAGE`` runs one page
and prints each block's time.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: pages whose code blocks are checked
PAGES = [ROOT / "README.md"] + sorted(
    p for p in (ROOT / "docs").rglob("*.md")
    if not any(part in {"_build", "_gen", "gallery", "api", "plugins"}
               for part in p.relative_to(ROOT / "docs").parts))
#: pages left out for now, with the reason
NOT_YET: dict[str, str] = {}
FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})(?P<info>[^`\n]*)$")
SKIP = re.compile(r"^\s*(#|<!--)\s*\[skip:\s*(?P<why>[^\]]+)\]")
RUN = {"python": "python", "py": "python", "sh": "sh", "bash": "sh", "console": "sh",
       "shell": "sh", "toml": "toml", "xml": "xml"}


def blocks(path: Path) -> list[dict]:
    """The fenced code blocks of a Markdown page: ``lang``, ``code``, ``line``, ``skip``.

    MyST directives (```` ```{name} ````, e.g. a toctree or ``{eval-rst}``) are not code and
    are passed over with their bodies.
    """
    out, lines, i = [], path.read_text().splitlines(), 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, info = m.group("fence"), m.group("info").strip()
        start, body, i = i + 1, [], i + 1
        while i < len(lines) and not re.match(rf"^ {{0,3}}{re.escape(fence[0])}{{{len(fence)},}}\s*$",
                                              lines[i]):
            body.append(lines[i])
            i += 1
        i += 1
        if info.startswith("{"):       # a directive, not code
            continue
        lang = info.split()[0].lower() if info else ""
        code = textwrap.dedent("\n".join(body))
        first = code.lstrip().splitlines()[0] if code.strip() else ""
        sk = SKIP.match(first)
        out.append({"lang": lang, "code": code, "line": start,
                    "skip": sk.group("why").strip() if sk else None})
    return out


DRIVER = r'''
import json, subprocess, sys, time, tomllib, traceback
import xml.etree.ElementTree as ET
steps = json.load(open(sys.argv[1]))
ns = {"__name__": "__main__"}
for s in steps:
    t = time.perf_counter()
    where = f"{s['page']}:{s['line']} ({s['lang']})"
    try:
        if s["kind"] == "python":
            exec(compile(s["code"], where, "exec"), ns)
        elif s["kind"] == "sh":
            code = "\n".join(l[2:] if l.startswith("$ ") else l for l in s["code"].splitlines())
            r = subprocess.run(["bash", "-euo", "pipefail", "-c", code])
            if r.returncode:
                raise SystemExit(f"exit code {r.returncode}")
        elif s["kind"] == "toml":
            tomllib.loads(s["code"])
        elif s["kind"] == "xml":
            ET.fromstring(s["code"])
    except BaseException as e:
        print(f"FAILED {where}: {type(e).__name__}: {e}", flush=True)
        traceback.print_exc()
        sys.exit(1)
    print(f"ok {where} {time.perf_counter() - t:.1f} s", flush=True)
'''


def scratch(tmp: Path) -> Path:
    """A scratch folder with links to the repository's inputs."""
    for name in (".venv", "scenes", "benchmarks", "experiments", "examples", "notebooks", "docs",
                 "mitsuba_veg", "tests", "scripts", "README.md", "pyproject.toml", "Makefile"):
        if (ROOT / name).exists() and not (tmp / name).exists():
            (tmp / name).symlink_to(ROOT / name)
    (tmp / "out").mkdir(exist_ok=True)
    return tmp


def run_page(page: Path, tmp: Path, timeout: float = 900.0) -> subprocess.CompletedProcess:
    """Run every runnable block of ``page`` in order in one process (see the module doc)."""
    import json

    rel = str(page.relative_to(ROOT))
    steps = [{"page": rel, "line": b["line"], "lang": b["lang"], "kind": RUN[b["lang"]],
              "code": b["code"]} for b in blocks(page) if b["lang"] in RUN and not b["skip"]]
    work = scratch(tmp)
    (tmp / "_steps.json").write_text(json.dumps(steps))
    (tmp / "_driver.py").write_text(DRIVER)
    env = dict(os.environ, MPLBACKEND="Agg",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    return subprocess.run([sys.executable, str(tmp / "_driver.py"), str(tmp / "_steps.json")],
                          cwd=work, env=env, capture_output=True, text=True, timeout=timeout)


def _pages_with_code() -> list[Path]:
    return [p for p in PAGES if any(b["lang"] in RUN and not b["skip"] for b in blocks(p))]


@pytest.mark.docs
@pytest.mark.parametrize("page", _pages_with_code(), ids=lambda p: str(p.relative_to(ROOT)))
def test_code_blocks_run_as_written(page, tmp_path):
    rel = str(page.relative_to(ROOT))
    if rel in NOT_YET:
        pytest.skip(NOT_YET[rel])
    r = run_page(page, tmp_path)
    assert r.returncode == 0, (r.stdout[-4000:] + "\n" + r.stderr[-8000:])


def test_every_skipped_block_says_why():
    """A skipped block carries its reason, and only the reasons the docs allow: a GPU, a Dask
    cluster, or a duration (``takes ...``)."""
    bad = []
    for p in PAGES:
        for b in blocks(p):
            if b["skip"] and not re.match(r"(needs a (GPU|Dask cluster)|takes |needs )", b["skip"]):
                bad.append(f"{p.relative_to(ROOT)}:{b['line']}: {b['skip']}")
    assert not bad, "\n".join(bad)


def test_pages_stay_short():
    """The README fits on a few screens (<= 200 lines) and no docs page passes 400 lines."""
    long = [f"{p.relative_to(ROOT)}: {n} lines" for p in PAGES
            if (n := len(p.read_text().splitlines())) > (200 if p.name == "README.md" else 400)]
    assert not long, "\n".join(long)


def test_block_parser(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("text\n\n```python\nx = 1\n```\n\n```{note}\nA note.\n```\n\n"
                    "````sh\n# [skip: needs a GPU]\nmake test-gpu\n````\n\n    indented\n\n"
                    "```\nplain\n```\n")
    got = blocks(page)
    assert [(b["lang"], b["code"].strip(), b["skip"]) for b in got] == [
        ("python", "x = 1", None), ("sh", "# [skip: needs a GPU]\nmake test-gpu", "needs a GPU"),
        ("", "plain", None)]


if __name__ == "__main__":
    import tempfile
    for arg in sys.argv[1:]:
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            r = run_page(Path(arg).resolve(), Path(d))
            print(r.stdout)
            if r.returncode:
                print(r.stderr[-6000:])
            print(f"{arg}: exit {r.returncode}, {time.perf_counter() - t0:.1f} s")
