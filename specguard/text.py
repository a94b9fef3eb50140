"""The one plain-text table renderer (CLI tables, the pytest summary)."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["render_table"]


def render_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """Left-aligned columns two spaces apart, a rule of dashes under the header, no trailing spaces.

    Example:
        >>> print("\\n".join(render_table(["goal", "success"], [["pendulum", "91%"]])))
        goal      success
        --------  -------
        pendulum  91%
    """
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(str(c).ljust(w) for c, w in zip(cells, widths)).rstrip()

    return [line(header), "  ".join("-" * w for w in widths), *(line(r) for r in rows)]
