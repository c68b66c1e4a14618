"""The parameter table of a Mitsuba plugin of the package, as data.

Each plugin class declares ``PLUGIN`` (the name it is registered under), ``PLUGIN_KIND``
(``"integrator"``, ``"emitter"``, ``"bsdf"``) and ``PARAMETERS``, a tuple of :class:`Parameter`
(every property its constructor reads, and no other: ``tests/test_plugins.py``). The decorator
:func:`with_parameter_table` writes that table into the class docstring (what ``help()`` and the
API reference show); the docs' plugin pages are generated from the same tuple
(:func:`markdown_table`).
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass

__all__ = ["Parameter", "with_parameter_table", "list_table", "markdown_table"]


@dataclass(frozen=True)
class Parameter:
    """One property of a plugin.

    Parameters
    ----------
    name : str
        Property name (``"a, b, c"`` for a group of properties read alike).
    type : str
        Its type in a scene file (``integer``, ``float``, ``boolean``, ``string``,
        ``spectrum or float``, ``vector``).
    default : str
        The default as text (or what applies without it, e.g. ``(required by perez)``).
    description : str
        Meaning, unit in brackets and allowed range.
    """

    name: str
    type: str
    default: str
    description: str

    @property
    def names(self) -> list[str]:
        """The property names of this row (one, or a group written ``a, b, c``)."""
        return [n.strip() for n in self.name.split(",")]


def list_table(params) -> str:
    """The parameters as a reStructuredText ``list-table`` (for a docstring).

    Parameters
    ----------
    params : sequence of Parameter
        The plugin's table.

    Returns
    -------
    str
        The directive, unindented.
    """
    rows = [".. list-table::", "   :header-rows: 1", "",
            "   * - Property", "     - Type", "     - Default", "     - Description"]
    for p in params:
        rows += [f"   * - {p.name}", f"     - {p.type}", f"     - {p.default}",
                 f"     - {p.description}"]
    return "\n".join(rows)


def markdown_table(params) -> str:
    """The parameters as a Markdown table (for the docs' plugin pages).

    Parameters
    ----------
    params : sequence of Parameter
        The plugin's table.

    Returns
    -------
    str
        A pipe table with the columns property, type, default, description.
    """
    def cell(s):
        return " ".join(str(s).split()).replace("|", "\\|")
    rows = ["| property | type | default | description |", "|---|---|---|---|"]
    rows += [f"| `{cell(p.name)}` | {cell(p.type)} | {cell(p.default)} | {cell(p.description)} |"
             for p in params]
    return "\n".join(rows)


def with_parameter_table(cls):
    """Class decorator: put ``cls.PARAMETERS`` as a list-table after the docstring's first
    paragraph.

    The parts of the docstring before and after the table stay available as
    ``cls.DOC_SUMMARY`` and ``cls.DOC_REST`` (the docs' plugin pages use them).

    Parameters
    ----------
    cls : type
        A plugin class with ``PARAMETERS``.

    Returns
    -------
    type
        ``cls``, its docstring completed.
    """
    doc = inspect.cleandoc(cls.__doc__ or "")
    summary, _, rest = doc.partition("\n\n")
    cls.DOC_SUMMARY, cls.DOC_REST = summary, rest
    cls.__doc__ = "\n\n".join(s for s in (summary, list_table(cls.PARAMETERS), rest) if s)
    return cls
