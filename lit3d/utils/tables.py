"""Markdown table helpers shared by the task reports."""
from __future__ import annotations

from collections.abc import Sequence


def fmt(value: float | None, digits: int = 3) -> str:
    """A number for a table cell; missing -> '–'."""
    if value is None or value != value:
        return "–"
    return f"{value:.{digits}f}"


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """GitHub markdown table from a header and string rows."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)
