"""The Markdown table every report writes: one home for its layout."""

from __future__ import annotations


def table_lines(rows, heads) -> list:
    """A Markdown table's lines: the header, the separator and one line per row (each cell as
    ``str``, already formatted by the caller)."""
    out = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    return out + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
