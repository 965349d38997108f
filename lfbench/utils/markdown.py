"""Markdown text from untrusted strings: a table cell stays one cell on one line.

Method labels, scene names and notes come from users and from folders read back; in a GitHub table a
``|`` would start a new column and a newline would end the row.
"""
from __future__ import annotations

__all__ = ["markdown_cell", "markdown_table"]


def markdown_cell(value: object) -> str:
    """``value`` as one Markdown table cell: whitespace runs (newlines included) as one space, ``|``
    escaped as ``\\|``."""
    return " ".join(str(value).split()).replace("|", "\\|")


def markdown_table(head: list[str], rows: list[list[str]]) -> str:
    """A GitHub Markdown table of ``head`` and ``rows``; every cell on one line, ``|`` escaped."""
    lines = ["| " + " | ".join(markdown_cell(c) for c in head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(markdown_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"
