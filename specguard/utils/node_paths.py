"""Node paths: how a node of a goal tree is named, ``parent/child``, and an annotation's key, ``path:name``.

Tree walks, compiled envs, reference rewards, contract checks, weights and
reports all key their nodes by :func:`child_path`; node and annotation names
may contain neither separator (:func:`specguard.validation.check_name`), so a
path splits back into its names, and a goal's key never reads as a safety key.

Example:
    >>> child_path(child_path("", "pendulum"), "position")
    'pendulum/position'
    >>> "pendulum/position" + ANNOTATION_SEPARATOR + "fast"
    'pendulum/position:fast'
"""

from __future__ import annotations

__all__ = ["ANNOTATION_SEPARATOR", "PATH_SEPARATOR", "child_path"]

PATH_SEPARATOR = "/"
"""Between a parent's path and a child's name: ``pendulum/position``."""
ANNOTATION_SEPARATOR = ":"
"""Between a node's path and one of its annotations' names: ``pendulum/position:fast``."""


def child_path(parent: str, name: str) -> str:
    """The path of the node ``name`` below the node whose path is ``parent``: ``parent/name``.

    The one place a node path is built. A root has no parent: ``child_path("", name)`` is ``name``.

    Example:
        >>> child_path("pendulum", "position"), child_path("", "pendulum")
        ('pendulum/position', 'pendulum')
    """
    return f"{parent}{PATH_SEPARATOR}{name}" if parent else name
