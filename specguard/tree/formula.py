"""The constructed reward written out as the paper writes it.

``R[g]`` is the enter/exit reward of leaf ``g``, ``D[g]`` a distance shaping
term and ``P[g]`` a constraint penalty; each node contributes its weighted
components (docs/semantics.md, "Reward").

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

from specguard.extend import SAFETY, SHAPING, Annotation, ChildWeights, Node, adapted_annotations, component_weights
from specguard.utils.node_paths import PATH_SEPARATOR, child_path
from specguard.utils.text import number_text

__all__ = ["formula"]

_ROLES = ("core", SHAPING, SAFETY)


def _weighted(w: float, expr: str) -> str:
    if w == 1.0:
        return expr
    if " + " in expr:
        expr = f"({expr})"
    return f"{number_text(w)}*{expr}"


def formula(tree: Node) -> str:
    """The root reward of ``tree`` as a formula over its components.

    Components are labelled by node name, or by the path below the root where
    a name occurs twice; annotations other than the default ``distance`` and
    ``constraint`` add their name (``D[position:near]``). A child whose
    components its parent passes on with different weights per role (an
    ``AnyOf`` passes its children's distances but not their goal rewards) shows
    each group with its weight; a group weighted 0 is left out.
    """
    paths = list(tree.walk())
    counts = Counter(node.name for _, node in paths)
    root_prefix = tree.name + PATH_SEPARATOR

    def label(path: str, node: Node) -> str:
        if counts[node.name] == 1:
            return node.name
        return path[len(root_prefix) :] if path.startswith(root_prefix) else path

    def expr(node: Node, path: str, roles: frozenset[str]) -> str:
        """The node's reward restricted to the components of ``roles``."""
        name = label(path, node)
        core_parts = []
        if node.own_reward and "core" in roles:
            core_parts.append(node.formula_term(name))
        for c, passed in zip(node.children, node.child_weights()):
            core_parts.extend(_child(c, child_path(path, c.name), passed, roles))
        core_w, ann_w = component_weights(node)
        parts = [_weighted(core_w, " + ".join(core_parts))] if core_parts else []
        for a, w in zip(node.annotations, ann_w):
            if a.role in roles and w != 0:
                parts.append(_weighted(w, _annotation_text(name, a)))
        return " + ".join(parts)

    def _child(c: Node, path: str, w: ChildWeights, roles: frozenset[str]) -> list[str]:
        groups: dict[float, set[str]] = {}
        for role in _ROLES:
            if role in roles and w.of(role) != 0:
                groups.setdefault(w.of(role), set()).add(role)
        out = []
        for weight, group in groups.items():
            e = expr(c, path, frozenset(group))
            if e:
                out.append(_weighted(weight, e))
        return out

    out = f"R = {expr(tree, tree.name, frozenset(_ROLES)) or '0'}"
    adapting = [_adapting_text(label(path, node), node) for path, node in paths if node.adapts_weights]
    if adapting:  # the formula shows where they start (specguard.training.auto_weights)
        out += f"\n  weights of {', '.join(adapting)}: as written at the start, adapted during training"
    return out


def _annotation_text(name: str, a: Annotation) -> str:
    """An annotation's term: ``D[position]``, or ``P[lander:crash]`` for a name other than the default."""
    suffix = "" if a.name in ("distance", "constraint") else f":{a.name}"
    return f"{a.symbol}[{name}{suffix}]"


def _adapting_text(name: str, node: Node) -> str:
    """``p`` or ``p with P[p:crash]``: an adapting node and the annotations whose weights adapt with it."""
    adapted = [_annotation_text(name, node.annotations[i]) for i in adapted_annotations(node)]
    return name + (f" with {', '.join(adapted)}" if adapted else "")
