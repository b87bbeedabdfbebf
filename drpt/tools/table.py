"""Markdown (GitHub-flavoured) tables, the form every tool's report uses.

:func:`markdown_table` writes a header line, a rule line and one line per
row, each as ``| a | b |``. Cells are written as given (``str`` of each);
the caller formats numbers, and a ``|`` inside a cell is not escaped.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

__all__ = ["markdown_table"]

_RULES = {"-": "---", "l": ":---", "r": "---:", "c": ":---:"}


def markdown_table(header: Sequence, rows: Iterable[Sequence], align: str | None = None,
                   padded_rule: bool = True) -> str:
    """The lines of a markdown table, joined by ``\\n`` (no trailing newline).

    Args:
        header: the column titles.
        rows: one sequence of cells per row, as many cells as ``header``.
        align: one character per column: ``-`` (the renderer's default),
            ``l``, ``r`` or ``c`` (rule cells ``---``, ``:---``, ``---:``,
            ``:---:``); ``None`` means ``-`` for every column.
        padded_rule: ``| --- | --- |`` when true, ``|---|---|`` when false.

    Raises :class:`ValueError` when ``align`` or a row has the wrong number
    of entries, or ``align`` has a character other than ``-lrc``.
    """
    n = len(header)
    align = "-" * n if align is None else align
    if len(align) != n or any(a not in _RULES for a in align):
        raise ValueError(f"align must be {n} characters of '-lrc', got {align!r}")
    rule = [_RULES[a] for a in align]
    lines = [_line(header), _line(rule) if padded_rule else "|" + "".join(r + "|" for r in rule)]
    for i, row in enumerate(rows):
        if len(row) != n:
            raise ValueError(f"row {i} has {len(row)} cells, the header {n}")
        lines.append(_line(row))
    return "\n".join(lines)


def _line(cells: Sequence) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"
