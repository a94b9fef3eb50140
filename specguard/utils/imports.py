"""A user's ``"module:name"`` string imported the one way: algorithms' ``"module:Class"``, envs' ``"module:Id"``.

Importing runs the user's module, which may raise anything, fail to compile, or
end the process (``sys.exit``, ``os._exit``): each becomes one
:class:`ImportFailed`, whose message says what happened, for the caller to put
in its own :class:`~specguard.error.SpecError` beside the string.

Example:
    >>> import_module("json").__name__
    'json'
    >>> import_module(".rel")
    Traceback (most recent call last):
    ...
    specguard.error.ImportFailed: its module '.rel' is relative; name it from its top package (package.rel)
"""

from __future__ import annotations

import contextlib
import importlib
import os
from collections.abc import Iterator
from types import ModuleType
from typing import NoReturn

from specguard.error import ExitAtImport, ImportFailed
from specguard.utils.text import MAX_SHOWN, elide, shown

__all__ = ["import_module", "no_exit"]


@contextlib.contextmanager
def no_exit() -> Iterator[None]:
    """While a user's module is imported, ``os._exit`` in this process raises :class:`ExitAtImport` instead.

    ``sys.exit`` raises ``SystemExit``, which the importer catches; ``os._exit``
    would end the command at once, with no output and exit status 0. A process
    the module forks keeps the real ``os._exit``.
    """
    real, importer = os._exit, os.getpid()

    def guarded(status: int) -> NoReturn:
        if os.getpid() != importer:
            real(status)
        raise ExitAtImport(status)

    os._exit = guarded
    try:
        yield
    finally:
        os._exit = real


def import_module(name: str) -> ModuleType:
    """The module ``name``, imported (an absolute name: a user's string has no package to be relative to).

    Raises:
        ImportFailed: ``name`` is empty or relative, or importing it raised (an error, a syntax error) or tried to
            end the process (``sys.exit``, ``os._exit``); ``KeyboardInterrupt`` passes through.
    """
    if not name:
        raise ImportFailed("it names no module before ':'")
    if name.startswith("."):
        absolute = elide(name.lstrip("."), MAX_SHOWN)
        raise ImportFailed(f"its module {shown(name)} is relative; name it from its top package (package.{absolute})")
    try:
        with no_exit():
            return importlib.import_module(name)
    except KeyboardInterrupt:
        raise
    except SystemExit as e:
        raise ImportFailed(f"importing {shown(name)} called sys.exit({shown(e.code)})") from None
    except ExitAtImport as e:
        raise ImportFailed(f"importing {shown(name)} called os._exit({shown(e.status)})") from None
    except BaseException as e:  # the user's module: any error, a SyntaxError, a BaseException of its own
        raise ImportFailed(f"{type(e).__name__}: {elide(str(e), MAX_SHOWN)}") from None
