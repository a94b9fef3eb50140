"""The constructed reward written out as the paper writes it.

``R[g]`` is the enter/exit reward of leaf ``g``, ``D[g]`` a distance shaping
term and ``P[g]`` a constraint penalty; each node contributes its weighted
components (SPEC.md section 2).

Example:
    >>> import specguard as sg
    >>> tree = sg.All(
    ...     sg.Goal("position", x=(0.966, 1.0)).annotate(sg.Distance(abs, scale=2.0)),
    ...     sg.Goal("stabilization", omega=(-0.25, 0.25)),
    ...     name="pendulum",
    ...     weights=(0.8, 0.2),
    ... )
    >>> sg.formula(tree)
    'R = 0.8*(0.5*R[position] + 0.5*D[position]) + 0.2*R[stabilization]'
"""

from __future__ import annotations

from collections import Counter

from specguard.nodes import All, Goal, Node, component_weights

__all__ = ["formula"]


def _weighted(w: float, expr: str) -> str:
    if w == 1.0:
        return expr
    if " + " in expr:
        expr = f"({expr})"
    return f"{w:g}*{expr}"


def formula(tree: Node) -> str:
    """The root reward of ``tree`` as a formula over its components.

    Components are labelled by node name, or by the path below the root where
    a name occurs twice; annotations other than the default ``distance`` and
    ``constraint`` add their name (``D[position:near]``).
    """
    paths = list(tree.walk())
    counts = Counter(node.name for _, node in paths)
    root_prefix = tree.name + "/"

    def label(path: str, node: Node) -> str:
        if counts[node.name] == 1:
            return node.name
        return path[len(root_prefix) :] if path.startswith(root_prefix) else path

    def expr(node: Node, path: str) -> str:
        name = label(path, node)
        if isinstance(node, Goal):
            core = f"R[{name}]"
        elif isinstance(node, All):
            core = " + ".join(
                _weighted(w, expr(c, f"{path}/{c.name}")) for c, w in zip(node.children, node.child_weights())
            )
        else:
            core = f"{type(node).__name__}[{name}]"
        core_w, ann_w = component_weights(node)
        parts = [_weighted(core_w, core)]
        for a, w in zip(node.annotations, ann_w):
            suffix = "" if a.name in ("distance", "constraint") else f":{a.name}"
            parts.append(_weighted(w, f"{a.symbol}[{name}{suffix}]"))
        return " + ".join(parts)

    return f"R = {expr(tree, tree.name)}"
