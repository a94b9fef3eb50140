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
    specguard.utils.imports.ImportFailed: its module '.rel' is relative; name it from its top package (package.rel)
"""

from __future__ import annotations

import contextlib
import importlib
import os
from collections.abc import Iterator
from types import ModuleType
from typing import NoReturn

from specguard.utils.text import MAX_SHOWN, elide, shown

__all__ = ["ExitAtImport", "ImportFailed", "import_module", "no_exit"]


class ExitAtImport(BaseException):
    """``os._exit`` called while a spec file (or a ``"module:Class"`` or ``"module:Id"`` string's module) was imported,
    raised instead of ending the process (an internal signal: :func:`no_exit` raises it).

    A ``BaseException``, as ``SystemExit`` is: the spec file's own ``except Exception`` cannot swallow it.
    :func:`specguard.spec.loading.import_file` turns it into a :class:`~specguard.error.SpecError` naming the file,
    :func:`import_module` into an :class:`ImportFailed` naming the string.
    """

    def __init__(self, status: object) -> None:
        super().__init__(status)
        self.status = status


class ImportFailed(Exception):
    """A module named by a user's string could not be imported; the message says why, in one bounded line.

    An internal signal: :func:`import_module` raises it, and each caller turns it into the
    :class:`~specguard.error.SpecError` of its field (an algorithm's ``InvalidSpec``, an env's ``InitialEnvError``).
    """


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
