"""Plain-text tables for the terminal (pandas formatting)."""

from __future__ import annotations

from typing import Sequence


def format_table(rows: Sequence[dict], columns: Sequence[str] | None = None, floatfmt: str = "{:.4g}") -> str:
    """Render dict rows as an aligned text table.

    Parameters
    ----------
    rows : sequence of dict
        One dict per row; missing keys print empty.
    columns : sequence of str, optional
        Column order (default: keys of the first row).
    floatfmt : str
        Format for floats.
    """
    import pandas as pd

    if not rows:
        return "(no rows)"
    df = pd.DataFrame(list(rows), columns=list(columns) if columns else None)
    return df.to_string(index=False, float_format=lambda v: floatfmt.format(v), na_rep="")


def markdown_table(df, align: str = "---") -> str:
    """A pandas DataFrame as a Markdown table (``align="---:"`` right-aligns every column); cells as ``str``."""
    head = "| " + " | ".join(map(str, df.columns)) + " |"
    rule = "|" + "|".join(align for _ in df.columns) + "|"
    body = ["| " + " | ".join(str(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join([head, rule, *body])
