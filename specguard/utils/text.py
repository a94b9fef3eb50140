"""Text every door writes the same way: plain tables, adapted weights."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

__all__ = ["per_seed_text", "render_table", "weights_text"]


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


def weights_text(weights: Mapping[str, Sequence[float]]) -> str:
    """Adapted weights as read in a report: ``pendulum (0.71, 0.29)``, nodes separated by ``; ``.

    Example:
        >>> weights_text({"pendulum": [0.714285, 0.285714]})
        'pendulum (0.71, 0.29)'
    """
    return "; ".join(f"{path} ({', '.join(f'{w:.2f}' for w in ws)})" for path, ws in weights.items())


def per_seed_text(seeds: Iterable[tuple[int, Mapping[str, Sequence[float]]]]) -> str:
    """Each seed's adapted weights: ``seed 0 pendulum (0.71, 0.29), seed 1 ...`` (seeds without any left out).

    Example:
        >>> per_seed_text([(0, {"p": [0.75, 0.25]}), (1, {})])
        'seed 0 p (0.75, 0.25)'
    """
    return ", ".join(f"seed {seed} {weights_text(weights)}" for seed, weights in seeds if weights)
