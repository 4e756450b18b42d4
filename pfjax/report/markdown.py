"""Markdown for the reports: tables whose cells cannot break them.

A ``|`` inside a cell ends the cell in every Markdown renderer (GitHub's included), so text such
as ``|d| < 3 mm`` silently loses its evidence; :func:`cell` escapes it (``\\|``), and line breaks
become spaces. Every Markdown table pfjax writes goes through :func:`table`.
"""

from __future__ import annotations

import math


def cell(value) -> str:
    """One table cell: ``str(value)`` with ``|`` escaped and line breaks as spaces; None and
    non-finite floats as an em dash."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    text = " ".join(str(value).splitlines())
    return text.replace("\\|", "|").replace("|", "\\|")


def table(header, rows) -> str:
    """A GitHub-flavoured Markdown table (no trailing newline)."""
    header = [cell(h) for h in header]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def split_row(line: str) -> list[str]:
    """The cells of one table row written by :func:`table` (escaped pipes kept inside their cell)."""
    body = line.strip()
    body = body[1:] if body.startswith("|") else body
    body = body[:-1] if body.endswith("|") and not body.endswith("\\|") else body
    cells, cur, i = [], "", 0
    while i < len(body):
        if body[i] == "\\" and i + 1 < len(body) and body[i + 1] == "|":
            cur += "|"
            i += 2
            continue
        if body[i] == "|":
            cells.append(cur.strip())
            cur = ""
        else:
            cur += body[i]
        i += 1
    cells.append(cur.strip())
    return cells
