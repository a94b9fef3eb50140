"""A custom operator from zero: ``AtLeast(k, *children)``, met when at least ``k`` children are.

docs/guide/writing-an-operator.md walks through this file; ``tests/test_docs.py``
runs specguard's contract kit on it, as an operator author would in their own
tests::

    import specguard.testing as sgt

    @sgt.parametrize_with_checks([AtLeast])
    def test_at_least(operator, check):
        check(operator)

Example:
    >>> import specguard as sg
    >>> tree = AtLeast(2, sg.Goal("left", x=(None, -1)), sg.Goal("slow", v=(-0.1, 0.1)),
    ...                sg.Goal("upright", theta=(-0.05, 0.05)), name="two")
    >>> print(tree)
    AtLeast 'two' k=2
    ├── Goal 'left': x <= -1
    ├── Goal 'slow': -0.1 <= v <= 0.1
    └── Goal 'upright': -0.05 <= theta <= 0.05
    >>> sg.formula(tree)
    'R = AtLeast[two]'
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from specguard.error import InvalidSpec
from specguard.extend import Annotation, ChildWeights, Context, Node, set_fields

if TYPE_CHECKING:
    from hypothesis.strategies import SearchStrategy


@dataclass(frozen=True, init=False, repr=False)
class AtLeast(Node):
    """At least ``k`` of the children's goals hold.

    The goal is ``{s : #{i : s in G_i} >= k}``; the core reward is the default
    membership difference ``1[s' in G] - 1[s in G]`` (potential: membership),
    paid once for the node. The children's own goal rewards are not added (their
    distances and constraints are), and it has no state and no termination of
    its own. ``AtLeast(1, ...)`` is an OR; ``AtLeast(N, ...)`` an AND.
    """

    kind: ClassVar[str] = "AtLeast"
    k: int
    nodes: tuple[Node, ...]
    name: str
    annotations: tuple[Annotation, ...]

    def __init__(self, k: int, *children: Node, name: str) -> None:
        name, kids = self.init_node(name, children)  # checked; kept as `nodes`, which `children` returns
        if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= len(kids):
            raise InvalidSpec(f"AtLeast {name!r}", f"expected k to be an integer in [1, {len(kids)}], got {k!r}")
        set_fields(self, k=k)  # also on a frozen dataclass

    def child_weights(self) -> tuple[ChildWeights, ...]:
        # Pay once for the node's goal; the children keep their distances and penalties.
        return (ChildWeights(core=0.0, shaping=1.0, safety=1.0),) * len(self.nodes)

    def contains(self, ctx: Context) -> bool:
        return sum(ctx.inside) >= self.k

    def describe(self) -> str:
        return f"AtLeast {self.name!r} k={self.k}"

    def __repr__(self) -> str:
        kids = ", ".join(map(repr, self.nodes))
        return f"AtLeast({self.k}, {kids}, name={self.name!r}){self._annotations_repr()}"

    def formula_term(self, label: str) -> str:
        return f"AtLeast[{label}]"

    @classmethod
    def strategy(cls, children: Sequence[Node], name: str) -> SearchStrategy[Node]:
        from hypothesis import strategies as st

        return st.integers(1, len(children)).map(lambda k: cls(k, *children, name=name))
