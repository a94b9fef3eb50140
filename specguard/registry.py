"""Operators and annotations by name: the built-ins, installed plugins, and explicit registrations.

Installed distributions contribute classes through the entry-point group
``specguard.operators`` (one entry point per class, its name the class's
public name)::

    [project.entry-points."specguard.operators"]
    AnyOf = "specguard_plugins.anyof:AnyOf"

They are loaded the first time a name is looked up, so a plain ``pytest``
run imports no plugin. A broken plugin (import error, a value that is not a
:class:`~specguard.extend.Node` or :class:`~specguard.extend.Annotation`
subclass, a name already taken) is reported once, as a
:class:`PluginWarning` naming the distribution, and skipped: other plugins
and every spec that does not use it keep working.

Example:
    >>> import specguard as sg
    >>> from specguard.registry import lookup, register
    >>> lookup("All") is sg.All
    True
    >>> @register
    ... class Never(sg.Goal):
    ...     kind = "Never"
    >>> lookup("Never") is Never
    True
"""

from __future__ import annotations

import threading
import warnings
from collections.abc import Callable
from importlib import metadata
from typing import TypeVar

from specguard.error import InvalidSpec, PluginWarning

__all__ = ["GROUP", "PluginWarning", "lookup", "register", "registered"]

GROUP = "specguard.operators"

T = TypeVar("T", bound=type)

_lock = threading.Lock()
_explicit: dict[str, type] = {}
_plugins: dict[str, type] | None = None


def _builtins() -> dict[str, type]:
    from specguard.tree.builtin_annotations import Constraint, Distance
    from specguard.tree.nodes import All, Always, Goal

    return {c.__name__: c for c in (Goal, All, Always, Distance, Constraint)}


def _is_extension(value: object) -> bool:
    from specguard.extend import Annotation, Node

    return isinstance(value, type) and issubclass(value, (Node, Annotation))


def _load_plugins() -> dict[str, type]:
    taken = set(_builtins())
    found: dict[str, type] = {}
    origin: dict[str, str] = {}
    for ep in metadata.entry_points(group=GROUP):
        dist = ep.dist.name if ep.dist is not None else "an unknown distribution"
        where = f"specguard: plugin {dist!r}, entry point {ep.name} = {ep.value!r}"
        try:
            value = ep.load()
        except Exception as e:  # a plugin's import failing must not break anything else
            warnings.warn(f"{where}: failed to load ({type(e).__name__}: {e}); skipped", PluginWarning, stacklevel=4)
            continue
        if not _is_extension(value):
            warnings.warn(
                f"{where}: expected a subclass of specguard.extend.Node or Annotation, got {value!r}; skipped",
                PluginWarning,
                stacklevel=4,
            )
            continue
        if ep.name in taken or ep.name in found:
            owner = "specguard itself" if ep.name in taken else f"plugin {origin[ep.name]!r}"
            warnings.warn(
                f"{where}: the name {ep.name!r} is already taken by {owner}; skipped", PluginWarning, stacklevel=4
            )
            continue
        found[ep.name] = value  # type: ignore[assignment]
        origin[ep.name] = dist
    return found


def _plugin_classes() -> dict[str, type]:
    global _plugins
    with _lock:
        if _plugins is None:
            _plugins = _load_plugins()
        return _plugins


def registered() -> dict[str, type]:
    """Every operator and annotation class by name: built-ins, then plugins, then explicit registrations."""
    return {**_builtins(), **_plugin_classes(), **_explicit}


def lookup(name: str) -> type:
    """The operator or annotation class registered as ``name``.

    Raises:
        KeyError: nothing is registered under ``name``; the message lists what is.
    """
    classes = registered()
    if name not in classes:
        raise KeyError(f"no specguard operator or annotation named {name!r}; known: {', '.join(sorted(classes))}")
    return classes[name]


def register(cls: T | None = None, *, name: str | None = None) -> T | Callable[[T], T]:
    """Register an operator or annotation class by name (usable as a decorator).

    Args:
        cls: a :class:`~specguard.extend.Node` or :class:`~specguard.extend.Annotation` subclass.
        name: the name to register; its class name by default.

    Raises:
        InvalidSpec: ``cls`` is not such a class, or the name is taken by another class.
    """

    def add(c: T) -> T:
        key = getattr(c, "__name__", repr(c)) if name is None else name
        if not _is_extension(c):
            raise InvalidSpec(
                f"register({key!r})",
                f"expected a subclass of specguard.extend.Node or Annotation, got {c!r}",
                hint="operators subclass specguard.extend.Node; annotations specguard.extend.Annotation",
            )
        current = {**_builtins(), **_plugin_classes(), **_explicit}.get(key)
        if current is not None and current is not c:
            raise InvalidSpec(
                f"register({key!r})",
                f"the name {key!r} is already taken by {current.__module__}.{current.__qualname__}",
                hint="pass name=... to register it under another name",
            )
        with _lock:
            _explicit[key] = c
        return c

    return add if cls is None else add(cls)
