"""Sphinx extension of the mitsuba-veg docs: pages generated from the code when the docs build.

- ``reference/api/``: one page per module of the package (autodoc + autosummary), listing the
  names of the module's ``__all__`` (its public names); a name re-exported by a package links
  to the page of the module that defines it.
- ``_gen/cli.md``: every ``mitsuba-veg`` command from the argument parsers
  (:func:`mitsuba_veg.cli.build_parser`): usage and a table of its arguments with the help
  text ``--help`` prints.
- ``reference/plugins/<name>.md``: one page per Mitsuba plugin registered by
  ``mitsuba_veg.integrators``, its parameter table from the plugin class's ``PARAMETERS``.
- ``_gen/performance.md``, ``_gen/validation.md``: tables of the headline figures that the
  benchmarks recorded in ``benchmarks/results/*.json`` (``benchmarks/_record.py``), each with
  its machine, variant and date.
- ``_gen/scenario_schema.md``: the scenario schema's table (:func:`mitsuba_veg.scenario.schema_markdown`).

Generated files are written only when their text changes (incremental builds stay quick) and
are not tracked by git.
"""
from __future__ import annotations

import argparse
import importlib
import inspect
import json
import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent
ROOT = DOCS.parent
GEN = DOCS / "_gen"
API = DOCS / "reference" / "api"
PLUGINS = DOCS / "reference" / "plugins"
RESULTS = ROOT / "benchmarks" / "results"
PACKAGE = "mitsuba_veg"
#: module files -> dotted names (``integrators/`` ships as ``mitsuba_veg.integrators``)
SOURCES = {PACKAGE: ROOT / "mitsuba_veg", f"{PACKAGE}.integrators": ROOT / "integrators"}


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


# ------------------------------------------------------------------------------------------
# the Python API
# ------------------------------------------------------------------------------------------
def module_names() -> list[str]:
    """Every module of the package (``__main__`` modules excepted), packages first."""
    out = []
    for pkg, base in SOURCES.items():
        for p in sorted(base.rglob("*.py")):
            rel = p.relative_to(base).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__main__" or "data" in parts:
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out.append(".".join([pkg] + parts))
    return sorted(set(out), key=lambda n: (n.split("."), n))


def public_names(mod) -> list[str]:
    """The module's ``__all__``; without one, the functions and classes it defines whose names
    do not start with ``_``."""
    if hasattr(mod, "__all__"):
        return list(mod.__all__)
    return [n for n, o in vars(mod).items() if not n.startswith("_")
            and (inspect.isfunction(o) or inspect.isclass(o))
            and getattr(o, "__module__", None) == mod.__name__]


def _kind(obj) -> str:
    if inspect.ismodule(obj):
        return "module"
    if inspect.isclass(obj):
        return "class"
    if callable(obj) and (inspect.isfunction(obj) or inspect.isbuiltin(obj)
                          or hasattr(obj, "__wrapped__")):
        return "function"
    return "data"


def _assigned(mname: str) -> set:
    """Names a module assigns at its top level (its own constants, not imported ones)."""
    import ast

    mod = sys.modules[mname]
    tree = ast.parse(Path(mod.__file__).read_text())
    out = set()
    for node in tree.body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            for t in (node.targets if isinstance(node, ast.Assign) else [node.target]):
                for n in (t.elts if isinstance(t, ast.Tuple) else [t]):
                    if isinstance(n, ast.Name):
                        out.add(n.id)
    return out


def canonical_places(modules: dict) -> dict:
    """``{(module, name): canonical 'module.name'}`` for every public name.

    A function or class is documented in the module that defines it when that module lists
    it in ``__all__``; a constant in the module that assigns it; otherwise in the deepest
    module that exports it.
    """
    assigned = {m: _assigned(m) for m in modules}
    exporters: dict = {}
    for mname, mod in modules.items():
        for n in public_names(mod):
            obj = getattr(mod, n)
            if inspect.ismodule(obj):
                continue
            if _kind(obj) == "data":
                key = ("data", n, repr(obj)[:200])
            else:
                key = id(obj)
            exporters.setdefault(key, []).append((mname, n))
    place = {}
    for key, lst in exporters.items():
        obj = getattr(modules[lst[0][0]], lst[0][1])
        if _kind(obj) == "data":
            home_entry = [(m, n) for m, n in lst if n in assigned[m]]
        else:
            home = getattr(obj, "__module__", None)
            home_entry = [(m, n) for m, n in lst if m == home]
        canon = home_entry[0] if home_entry else max(
            lst, key=lambda mn: (mn[0].count("."), len(mn[0])))
        for m, n in lst:
            if _kind(obj) == "data" and n in assigned[m]:
                place[(m, n)] = f"{m}.{n}"      # a constant of its own with the same name
            else:
                place[(m, n)] = f"{canon[0]}.{canon[1]}"
    return place


def _relative(target: str, module: str) -> str:
    """``target`` as autosummary wants it on ``module``'s page: relative below the module."""
    return target[len(module) + 1:] if target.startswith(module + ".") else target


def _title(text: str, ch: str = "=") -> str:
    return f"{text}\n{ch * len(text)}\n"


def generate_api() -> list[str]:
    """Write ``reference/api/<module>.rst`` for every module and the API index."""
    modules = {n: importlib.import_module(n) for n in module_names()}
    place = canonical_places(modules)
    pages = []
    for mname, mod in modules.items():
        names = public_names(mod)
        here, elsewhere, subs = [], [], []
        for n in names:
            if not hasattr(mod, n):
                raise RuntimeError(f"{mname}.__all__ names {n!r}, which it does not define")
            obj = getattr(mod, n)
            if inspect.ismodule(obj):
                subs.append(obj.__name__)
            elif place[(mname, n)] == f"{mname}.{n}":
                here.append(n)
            else:
                elsewhere.append((n, place[(mname, n)]))
        lines = [_title(f"``{mname}``"),
                 f".. automodule:: {mname}", "   :no-members:", ""]
        if here:
            lines += [".. rubric:: Public names", "", ".. autosummary::", "   :nosignatures:", ""]
            lines += [f"   {n}" for n in here] + [""]
        if elsewhere:
            lines += [".. rubric:: Also exported here (documented where they are defined)", "",
                      ".. autosummary::", "   :nosignatures:", ""]
            lines += [f"   {_relative(target, mname)}" for _, target in elsewhere] + [""]
        if subs:
            lines += [".. rubric:: Submodules", ""]
            lines += [f"- :mod:`{s}`" for s in subs] + [""]
        for n in here:
            obj = getattr(mod, n)
            kind = _kind(obj)
            if kind == "class":
                lines += [f".. autoclass:: {mname}.{n}", "   :members:", "   :show-inheritance:",
                          ""]
            elif kind == "function":
                lines += [f".. autofunction:: {mname}.{n}", ""]
            else:
                lines += [f".. autodata:: {mname}.{n}", "   :no-value:", ""]
        _write(API / f"{mname}.rst", "\n".join(lines))
        pages.append(mname)
    # the index: every module with its first docstring line, grouped by package
    idx = [_title("Python API"),
           "Every module of the package, one page each, with the names of its ``__all__`` (its "
           "public names). ``import mitsuba_veg as mv`` selects the Mitsuba variant and "
           "registers the plugins; the subpackages are then ``mv.light``, ``mv.moss``, "
           "``mv.trees`` and so on.", "",
           ".. toctree::", "   :hidden:", "", *[f"   {p}" for p in pages], ""]
    groups: dict[str, list[str]] = {}
    for p in pages:
        parts = p.split(".")
        top = ".".join(parts[:2]) if len(parts) > 1 else p
        groups.setdefault(top, []).append(p)
    idx += [".. list-table::", "   :header-rows: 1", "   :widths: 35 65", "",
            "   * - module", "     - what it holds"]
    for top, mods in groups.items():
        for p in mods:
            doc = inspect.getdoc(modules[p]) or ""
            first = " ".join(doc.split("\n\n")[0].split())
            first = first.replace("|", "/")
            idx += [f"   * - :mod:`{p}`", f"     - {first}"]
    idx.append("")
    _write(API / "index.rst", "\n".join(idx))
    # pages of modules that are gone
    keep = {f"{p}.rst" for p in pages} | {"index.rst"}
    for f in API.glob("*.rst"):
        if f.name not in keep:
            f.unlink()
    return pages


# ------------------------------------------------------------------------------------------
# the command line
# ------------------------------------------------------------------------------------------
def _md_cell(s: str) -> str:
    return " ".join(str(s).split()).replace("|", "\\|")


def _parser_section(name: str, parser, level: int, help_text: str = "") -> list[str]:
    fmt = parser._get_formatter()
    out = [f"{'#' * level} `{name}`", ""]
    desc = parser.description or help_text
    if desc:
        out += [_md_cell(desc), ""]
    out += ["```text", parser.format_usage().strip(), "```", ""]
    rows, subs = [], []
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            helps = {c.dest: c.help for c in a._choices_actions}
            subs += [(n, p, helps.get(n, "")) for n, p in a.choices.items()]
            continue
        if a.help == argparse.SUPPRESS:
            continue
        if a.option_strings:
            flags = ", ".join(f"`{o}`" for o in a.option_strings)
            if a.nargs != 0:
                mv = fmt._format_args(a, fmt._get_default_metavar_for_optional(a))
                flags += f" `{mv}`"
        else:
            flags = f"`{fmt._format_args(a, fmt._get_default_metavar_for_positional(a))}`"
        text = fmt._expand_help(a) if a.help else ""
        if a.choices is not None and not isinstance(a, argparse._SubParsersAction):
            text += f" (choices: {', '.join(str(c) for c in a.choices)})"
        rows.append(f"| {flags} | {_md_cell(text)} |")
    if rows:
        out += ["| argument | meaning |", "|---|---|", *rows, ""]
    for n, p, h in subs:
        out += _parser_section(f"{name} {n}", p, level + 1, h)
    return out


def generate_cli() -> None:
    """Write ``_gen/cli.md``: every command of ``mitsuba-veg`` from its parser."""
    from mitsuba_veg.cli import build_parser

    ap = build_parser()
    lines = _parser_section("mitsuba-veg", ap, 2)
    _write(GEN / "cli.md", "\n".join(lines) + "\n")


# ------------------------------------------------------------------------------------------
# the Mitsuba plugins
# ------------------------------------------------------------------------------------------
def plugin_classes() -> dict:
    """``{plugin name: class}`` of every plugin class in ``mitsuba_veg.integrators`` that
    declares its ``PLUGIN`` name and ``PARAMETERS``."""
    import mitsuba_veg.integrators as integ

    found = {}
    for mname in module_names():
        if not mname.startswith(integ.__name__):
            continue
        mod = importlib.import_module(mname)
        for obj in vars(mod).values():
            if inspect.isclass(obj) and obj.__module__ == mname and "PLUGIN" in vars(obj):
                found[obj.PLUGIN] = obj
    return dict(sorted(found.items()))


def generate_plugins() -> list[str]:
    """Write ``reference/plugins/<name>.md`` for every plugin and the plugins' index."""
    from mitsuba_veg.integrators.plugin_table import markdown_table

    classes = plugin_classes()
    for name, cls in classes.items():
        lines = [f"# `{name}`", "",
                 f"*{cls.PLUGIN_KIND}* · class {{py:class}}`~{cls.__module__}.{cls.__name__}` · "
                 f"module {{py:mod}}`{cls.__module__}`", "",
                 "```{eval-rst}", cls.DOC_SUMMARY, "```", "",
                 "## Parameters", "", markdown_table(cls.PARAMETERS), ""]
        if cls.DOC_REST.strip():
            lines += ["## Use", "", "```{eval-rst}", cls.DOC_REST.strip(), "```", ""]
        lines += ["## The module", "", "```{eval-rst}", f".. automodule:: {cls.__module__}",
                  "   :no-index:", "   :no-members:", "```", ""]
        _write(PLUGINS / f"{name}.md", "\n".join(lines))
    idx = ["# Mitsuba plugins", "",
           "`import mitsuba_veg` registers these plugins with Mitsuba; a scene file or "
           "`mi.load_dict` then names them by their type. Each page's parameter table is "
           "generated from the plugin class's `PARAMETERS` (the table its constructor reads, "
           "checked by `tests/test_plugins.py`).", "",
           "| plugin | kind | what it is |", "|---|---|---|"]
    for name, cls in classes.items():
        first = " ".join((inspect.getdoc(cls) or "").split("\n\n")[0].split())
        first = first.split(":", 1)[1].strip() if ":" in first else first
        idx.append(f"| [`{name}`]({name}.md) | {cls.PLUGIN_KIND} | {_md_cell(first)} |")
    idx += ["", "```{toctree}", ":hidden:", "", *classes.keys(), "```", ""]
    _write(PLUGINS / "index.md", "\n".join(idx))
    for f in PLUGINS.glob("*.md"):
        if f.stem not in classes and f.name != "index.md":
            f.unlink()
    return list(classes)


# ------------------------------------------------------------------------------------------
# benchmark tables
# ------------------------------------------------------------------------------------------
def _load_results() -> dict:
    out = {}
    for p in sorted(RESULTS.glob("*.json")):
        doc = json.loads(p.read_text())
        out[doc.get("name", p.stem)] = doc
    return out


def _machine(doc) -> str:
    m = doc.get("machine") or {}
    if m.get("gpu"):
        return m["gpu"]
    cores = f", {m['cores']} cores" if m.get("cores") else ""
    return f"{m.get('cpu', 'unknown CPU')}{cores}"


def _fmt(v, unit: str) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        s = f"{v:,d}"
    elif v == 0:
        s = "0"
    elif abs(v) >= 1000:
        s = f"{v:,.0f}"
    elif abs(v) >= 10:
        s = f"{v:.1f}"
    elif abs(v) >= 0.01:
        s = f"{v:.3g}" if abs(v) < 1 else f"{v:.2f}"
    else:
        s = f"{v:.2e}"
    if unit in ("", "ratio", "-"):
        return s + ("x" if unit == "ratio" else "")
    if unit == "fraction":
        return f"{100 * v:.2f} %"
    return f"{s} {unit}"


def performance_tables(results: dict, skip=("validation",)) -> str:
    """One table per recorded benchmark, with its machine, variant, date and command."""
    out = []
    for name, doc in results.items():
        if name in skip:
            continue
        src = doc.get("source", "measured")
        out += [f"### `{name}`", ""]
        if doc.get("notes"):
            out += [_md_cell(doc["notes"]), ""]
        out += ["| figure | value |", "|---|---|"]
        for f in doc["figures"]:
            out.append(f"| {_md_cell(f['label'])} | {_fmt(f['value'], f['unit'])} |")
        load = doc.get("load_average")
        load_s = f"; load average {load[0]:.1f}" if load else ""
        out += ["", f"*{_machine(doc)}; `{doc.get('variant')}`; {doc.get('date')}; "
                    f"{'measured' if src == 'measured' else '**' + src + '**'}{load_s}.* "
                    f"Reproduce: `{doc.get('command')}`", ""]
    return "\n".join(out) + "\n"


def headline_table(results: dict, picks: list[tuple[str, str]]) -> str:
    """A table of chosen figures ``(benchmark, key)`` across benchmarks."""
    out = ["| figure | value | machine | benchmark |", "|---|---|---|---|"]
    for bench, key in picks:
        doc = results.get(bench)
        if doc is None:
            raise RuntimeError(f"benchmarks/results/{bench}.json is missing (headline table)")
        f = {x["key"]: x for x in doc["figures"]}.get(key)
        if f is None:
            raise RuntimeError(f"benchmarks/results/{bench}.json has no figure {key!r}")
        out.append(f"| {_md_cell(f['label'])} | {_fmt(f['value'], f['unit'])} | "
                   f"{_machine(doc)} ({doc.get('date')}) | [`{bench}`](#{bench.replace('_', '-')}) |")
    return "\n".join(out) + "\n"


#: the headline figures of the performance page (and the README): (benchmark, figure key)
HEADLINES = [
    ("photon_vs_path", "speedup_at_target"),
    ("photon_throughput_plants1000", "ratio_preliminary_1M"),
    ("world_day_cpu", "day_over_pass"),
    ("world_day_gpu", "day_ms"),
    ("forest_hectare_gpu", "ten_years_s"),
    ("moss_run", "moss_share_full"),
]


def validation_table(doc: dict) -> str:
    """The validation page's tables from ``validation.json`` (benchmarks/validation_page.py)."""
    out = ["| reference | compared (how the error is taken) | error | bound | within | test |",
           "|---|---|---|---|---|---|"]
    thr, files = [], []
    for f in doc["figures"]:
        if f.get("tolerance") is None:
            thr.append(f)
            continue
        unit = f["unit"] if f["unit"] not in ("", "fraction") else ""
        if unit:
            err, tol = f"{f['value']:.2e} {unit}", f"{f['tolerance']:.0e} {unit}"
        else:
            err = f"{f['value']:.2e}" if f["value"] < 0.01 else f"{100 * f['value']:.2f} %"
            tol = f"{f['tolerance']:.0e}" if f["tolerance"] < 0.01 else \
                f"{100 * f['tolerance']:.1f} %"
        test = f.get("test", "")
        fname, _, func = test.partition("::")
        if fname and fname not in files:
            files.append(fname)
        ok = "yes" if f.get("passed") else "**no**"
        out.append(f"| {_md_cell(f['label'])} | {_md_cell(f.get('compared', ''))} "
                   f"({_md_cell(f.get('measure', ''))}) | {err} | {tol} | {ok} | `{func or test}` |")
    out += ["", "Tests: " + ", ".join(f"`{x}`" for x in files) + ".", "",
            f"*{_machine(doc)}; `{doc.get('variant')}`; {doc.get('date')}. "
            f"Reproduce: `{doc.get('command')}`*", ""]
    if thr:
        out += ["**Photon-pass throughput in the same run** (ray casts per second of the whole "
                "pass ÷ Mitsuba's raw casts of as many rays drawn like the photons):", "",
                "| compared | ratio |", "|---|---|"]
        out += [f"| {_md_cell(f.get('compared', f['label']))} | {f['value']:.2f} |" for f in thr]
        out.append("")
    return "\n".join(out) + "\n"


def generate_tables() -> None:
    """Write the performance and validation tables from ``benchmarks/results``."""
    results = _load_results()
    _write(GEN / "performance_headlines.md", headline_table(results, HEADLINES))
    _write(GEN / "performance.md", performance_tables(results))
    # the render page's figures: its benchmarks (render_*) only
    _write(GEN / "render_figures.md", performance_tables(
        {k: v for k, v in results.items() if k.startswith("render_")}))
    if "validation" in results:
        _write(GEN / "validation.md", validation_table(results["validation"]))
    else:
        raise RuntimeError("benchmarks/results/validation.json is missing: run "
                           "benchmarks/validation_page.py")


def generate_scenario() -> None:
    """Write the scenario schema's table."""
    from mitsuba_veg.scenario import schema_markdown

    _write(GEN / "scenario_schema.md", schema_markdown() + "\n")


# ------------------------------------------------------------------------------------------
def generate_all(app=None) -> None:
    """Every generated page (called when the builder starts)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import mitsuba_veg  # noqa: F401  (selects the variant, registers the plugins)

    generate_cli()
    generate_plugins()
    if not os.environ.get("MVDOCS_DEV"):
        generate_tables()
    generate_scenario()
    generate_api()


def setup(app):
    """Register the generation step with Sphinx.

    Parameters
    ----------
    app : sphinx.application.Sphinx
        The application.

    Returns
    -------
    dict
        Extension metadata.
    """
    app.connect("builder-inited", generate_all)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
