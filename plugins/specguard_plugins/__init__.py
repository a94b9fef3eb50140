"""specguard-plugins: goal-tree operators written only against specguard's public extension API.

* :class:`AnyOf` (OR): the goal is the union of the children's goals;
* :class:`Sequence` (THEN): the children's goals reached one after the other;
* :class:`Avoid`: a safety annotation counting the steps that end in a region.

Installed, they are found by name through the ``specguard.operators`` entry
points, so ``sg.AnyOf`` works without importing this package.

Example:
    >>> import specguard as sg
    >>> from specguard_plugins import AnyOf, Avoid, Sequence
    >>> tree = Sequence(
    ...     AnyOf(sg.Goal("left", x=(None, -1.0)), sg.Goal("right", x=(1.0, None)), name="edge"),
    ...     sg.Goal("home", x=(-0.1, 0.1)),
    ...     name="out_and_back",
    ... ).annotate(Avoid({"omega": (2.0, None)}, name="spin"))
    >>> print(tree)
    Sequence 'out_and_back'
    │   + Avoid(Goal 'spin': omega >= 2, budget=1, name='spin')
    ├── AnyOf 'edge'
    │   ├── Goal 'left': x <= -1
    │   └── Goal 'right': x >= 1
    └── Goal 'home': -0.1 <= x <= 0.1
    >>> sg.formula(tree)
    'R = Seq[out_and_back] + P[out_and_back:spin]'
"""

from __future__ import annotations

from specguard_plugins.anyof import AnyOf
from specguard_plugins.avoid import Avoid
from specguard_plugins.sequence import Sequence

__all__ = ["AnyOf", "Avoid", "Sequence"]
__version__ = "0.1.0"
