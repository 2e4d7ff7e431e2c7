"""A table of the report (Markdown and HTML), numbers in a few significant figures, a nested field

SYNOPSIS

    >>> from rotstar_mrcal.report.table import Table, fmt, get
    >>> print(Table(["method", "px"], [["rotstar", fmt(0.01234)]], bold={(0, 1)}).markdown())
    | method | px |
    |---|---|
    | rotstar | **0.0123** |
    >>> get({"heldout": {"A->B": {"mean_px": 0.1}}}, "heldout", "A->B", "mean_px")
    0.1
"""

from __future__ import annotations

import dataclasses
import html as _html

import numpy as np


def fmt(v, digits: int = 3) -> str:
    """A number in `digits` significant figures, '-' for none"""
    if v is None or not np.isfinite(v):
        return "-"
    return f"{v:.{digits}g}"


@dataclasses.dataclass
class Table:
    header: list[str]
    rows: list[list[str]]
    caption: str = ""
    bold: set = dataclasses.field(default_factory=set)  # (row, col) cells to emphasise

    def markdown(self) -> str:
        def cell(i, j, s):
            return f"**{s}**" if (i, j) in self.bold and s != "-" else s

        out = ["| " + " | ".join(self.header) + " |", "|" + "---|" * len(self.header)]
        out += ["| " + " | ".join(cell(i, j, s) for j, s in enumerate(r)) + " |" for i, r in enumerate(self.rows)]
        return "\n".join(out)

    def html(self) -> str:
        e = _html.escape
        out = ["<table>"]
        if self.caption:
            out.append(f"<caption>{e(self.caption)}</caption>")
        out.append("<tr>" + "".join(f"<th>{e(h)}</th>" for h in self.header) + "</tr>")
        for i, r in enumerate(self.rows):
            cells = [f"<td><b>{e(s)}</b></td>" if (i, j) in self.bold and s != "-" else f"<td>{e(s)}</td>"
                     for j, s in enumerate(r)]
            out.append("<tr>" + "".join(cells) + "</tr>")
        out.append("</table>")
        return "\n".join(out)


def get(d, *keys):
    """d[keys[0]][keys[1]]..., None where a key is missing, its value None or not a dict

    SYNOPSIS

        >>> get({"a": {"b": 1}}, "a", "b"), get({"a": None}, "a", "b"), get(None, "a")
        (1, None, None)
    """
    for k in keys:
        if not isinstance(d, dict) or d.get(k) is None:
            return None
        d = d[k]
    return d
