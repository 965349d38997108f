"""LaTeX text of lfbench's tables: every string that reaches a .tex file (titles, captions, method
labels, scene names, notes, column headers, paper columns) goes through :func:`escape`.

:func:`escape` makes any string typeset as itself and stay on one line: TeX's special characters become
their text commands, and line breaks and other control characters become a space, so a title such as
``"tiny\\n\\\\input{/etc/passwd}"`` can neither end a ``%`` comment nor start a line with a command.
:func:`comment` writes caption lines as ``%`` comments; :func:`tabular` a booktabs ``tabular``.
"""

from __future__ import annotations

import unicodedata
from collections.abc import Sequence
from typing import Any

__all__ = ["escape", "comment", "tabular"]

# TeX's ten special characters, and < > | (other glyphs in the default OT1 font); the text commands are
# braced, so no line of a table starts with a command. [ and ] are braced too: after a row's \\ a cell
# starting with [ would be read as the \\[<length>] of the row before.
_REPLACEMENTS = {
    "\\": r"{\textbackslash}", "{": r"\{", "}": r"\}", "$": r"\$", "&": r"\&", "%": r"\%", "#": r"\#",
    "_": r"\_", "^": r"{\textasciicircum}", "~": r"{\textasciitilde}", "<": r"{\textless}",
    ">": r"{\textgreater}", "|": r"{\textbar}", "[": "{[}", "]": "{]}",
}
_LINE_BREAKING = frozenset({"Cc", "Zl", "Zp"})  # control characters (\n, \r, \f, \x85, ...), line/paragraph separators


def escape(text: Any) -> str:
    """``text`` (any value, as ``str``) as LaTeX that typesets as the same characters on one line."""
    out = []
    for ch in str(text):
        if ch in _REPLACEMENTS:
            out.append(_REPLACEMENTS[ch])
        elif unicodedata.category(ch) in _LINE_BREAKING:
            out.append(" ")
        else:
            out.append(ch)
    return "".join(out)


def comment(lines: Sequence[Any]) -> str:
    """Each line as one ``% `` comment line (escaped: a line break inside a line cannot end the comment)."""
    return "".join(f"% {escape(line)}\n" for line in lines)


def tabular(headers: Sequence[Any], rows: Sequence[Sequence[Any]]) -> str:
    """A booktabs ``tabular`` with left-aligned columns: ``headers`` then ``rows``, every cell escaped
    and padded to its column's width (as text, for people reading the .tex)."""
    cells = [[escape(c) for c in headers], *([escape(c) for c in row] for row in rows)]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]

    def line(row: Sequence[str]) -> str:
        return " " + " & ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) + " \\\\"

    body = [f"\\begin{{tabular}}{{{'l' * len(headers)}}}", "\\toprule", line(cells[0]), "\\midrule",
            *(line(r) for r in cells[1:]), "\\bottomrule", "\\end{tabular}"]
    return "\n".join(body) + "\n"
