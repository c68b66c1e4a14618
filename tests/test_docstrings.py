"""Every public function and method of the package has a numpydoc docstring.

Checked on the source with ``ast`` (nothing is imported): a public function is a top-level
``def`` of a module under ``mitsuba_veg/`` or ``integrators/``, or a method of a public class
there, whose name does not start with ``_``. Its docstring must

- exist;
- have a ``Parameters`` section (numpydoc: the word, then a line of dashes) naming every
  argument other than ``self`` / ``cls`` as ``name : type`` (or ``a, b : type``; ``*args`` and
  ``**kwargs`` by their names with or without stars), when it takes any;
- have a ``Returns`` (or ``Yields``) section when its own body returns a value (properties
  excepted: their summary line says what they are).

Units go in brackets in the descriptions (``[W m-2]``), as everywhere in the package; that part
is for review, not for this test. ``python tests/test_docstrings.py [files...]`` prints every
finding.
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SOURCES = [ROOT / "mitsuba_veg", ROOT / "integrators"]


def _files() -> list[Path]:
    out = []
    for base in SOURCES:
        out += [p for p in sorted(base.rglob("*.py")) if p.name != "__main__.py"]
    return out


def _section(doc: str, name: str) -> str | None:
    """The text of numpydoc section ``name`` (up to the next section), or None."""
    m = re.search(rf"^\s*{name}\s*\n\s*-{{3,}}\s*$", doc, flags=re.M)
    if not m:
        return None
    rest = doc[m.end():]
    nxt = re.search(r"^\s*[A-Z][A-Za-z ]+\s*\n\s*-{3,}\s*$", rest, flags=re.M)
    return rest[: nxt.start()] if nxt else rest


def _documented_names(section: str) -> set[str]:
    names: set[str] = set()
    for line in section.splitlines():
        m = re.match(r"^\s*([*\w][\w*, ]*?)\s*:(\s|$)", line)
        if m:
            for part in m.group(1).split(","):
                names.add(part.strip().lstrip("*"))
    return names


def _returns_value(fn: ast.FunctionDef) -> bool:
    """Whether ``fn``'s own body (not nested functions or classes) returns a value."""
    stack = list(fn.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda)):
            continue
        if isinstance(node, ast.Return) and node.value is not None:
            if not (isinstance(node.value, ast.Constant) and node.value.value is None):
                return True
        if isinstance(node, (ast.Yield, ast.YieldFrom)):
            return True
        stack.extend(ast.iter_child_nodes(node))
    return False


def _decorators(fn: ast.FunctionDef) -> set[str]:
    out = set()
    for d in fn.decorator_list:
        if isinstance(d, ast.Name):
            out.add(d.id)
        elif isinstance(d, ast.Attribute):
            out.add(d.attr)
    return out


def _check_function(fn: ast.FunctionDef, where: str) -> list[str]:
    doc = ast.get_docstring(fn)
    if not doc:
        return [f"{where}: no docstring"]
    deco = _decorators(fn)
    if {"property", "setter", "cached_property"} & deco:
        return []
    args = [a.arg for a in fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs]
    if args and args[0] in ("self", "cls") and "staticmethod" not in deco:
        args = args[1:]
    if fn.args.vararg:
        args.append(fn.args.vararg.arg)
    if fn.args.kwarg:
        args.append(fn.args.kwarg.arg)
    problems = []
    if args:
        sec = _section(doc, "Parameters")
        if sec is None:
            problems.append(f"{where}: no 'Parameters' section (takes {', '.join(args)})")
        else:
            missing = [a for a in args if a not in _documented_names(sec)]
            if missing:
                problems.append(f"{where}: parameters not documented: {', '.join(missing)}")
    if _returns_value(fn) and _section(doc, "Returns") is None and _section(doc, "Yields") is None:
        problems.append(f"{where}: returns a value but has no 'Returns' section")
    return problems


def findings(path: Path) -> list[str]:
    """Every missing or incomplete docstring of the public functions in ``path``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    rel = path.relative_to(ROOT)
    out: list[str] = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
            out += _check_function(node, f"{rel}:{node.lineno} {node.name}")
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for sub in node.body:
                if isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef)) and not sub.name.startswith("_"):
                    out += _check_function(sub, f"{rel}:{sub.lineno} {node.name}.{sub.name}")
    return out


@pytest.mark.parametrize("path", _files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_public_functions_have_numpydoc(path):
    problems = findings(path)
    assert not problems, "\n".join(problems)


def test_checker_finds_what_is_missing(tmp_path):
    src = tmp_path / "m.py"
    src.write_text(
        "def a(x):\n    return x\n\n"
        "def b(x, *rest, **kw):\n    '''Sum.\n\n    Parameters\n    ----------\n"
        "    x : float\n        A value [m].\n    *rest : float\n        More.\n\n"
        "    Returns\n    -------\n    float\n        The sum [m].\n    '''\n    return x\n\n"
        "def c(x, y):\n    '''Doc.\n\n    Parameters\n    ----------\n    x : int\n        X.\n    '''\n\n"
        "class K:\n    @property\n    def p(self):\n        '''A property.'''\n        return 1\n"
        "    def m(self):\n        '''No return section.'''\n        return 2\n"
        "    def _private(self, z):\n        return z\n"
    )
    global ROOT
    old, ROOT = ROOT, tmp_path
    try:
        got = findings(src)
    finally:
        ROOT = old
    assert got == [
        "m.py:1 a: no docstring",
        "m.py:4 b: parameters not documented: kw",
        "m.py:21 c: parameters not documented: y",
        "m.py:35 K.m: returns a value but has no 'Returns' section",
    ], got


if __name__ == "__main__":
    paths = [Path(p).resolve() for p in sys.argv[1:]] or _files()
    total = 0
    for p in paths:
        for line in findings(p):
            print(line)
            total += 1
    print(f"{total} findings")
