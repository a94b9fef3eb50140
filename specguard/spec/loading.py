"""Spec files: a user's Python file imported by path, and the specs (or trees) it defines, by name.

A file's specs are its module-level ``Spec`` objects (named by variable) and
the values of its module-level dicts of specs (named by key). The CLI's
``show``/``run`` and ``reproduce`` all load files here.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import cloudpickle

from specguard.error import SpecError
from specguard.spec.spec import Spec
from specguard.utils.imports import ExitAtImport, no_exit

__all__ = ["import_file", "load_objects", "spec_path"]


_IMPORTED: dict[tuple[Path, int], ModuleType] = {}


def spec_path(target: str) -> Path:
    """The Python file ``PATH[::NAME]`` names, checked: a regular ``.py`` file that exists.

    Raises:
        SpecError: one line saying what the path is instead (missing, a directory,
            not a regular file, not a ``.py`` file, or no path at all).
    """
    text = target.partition("::")[0]
    if not text:
        raise SpecError(f"{target!r}: no file named before '::'; expected PATH[::NAME]")
    path = Path(text)
    if path.is_dir():
        raise SpecError(f"{path}: is a directory; expected a Python file of specs, e.g. {path / 'specs.py'}")
    if not path.exists():
        raise SpecError(f"{path}: no such file")
    if not path.is_file():
        raise SpecError(f"{path}: not a regular file; expected a Python file of specs")
    if path.suffix != ".py":
        raise SpecError(f"{path}: not a Python file (expected a .py file of specs)")
    return path


def import_file(path: Path) -> ModuleType:
    """The module of a Python file, imported once per process and version of the file (its specs keep one identity).

    Raises:
        SpecError: ``path`` is no Python file (:func:`spec_path`), or importing it raised or tried to end the process.
    """
    path = spec_path(str(path))
    key = (path.resolve(), path.stat().st_mtime_ns)
    if key not in _IMPORTED:
        _IMPORTED[key] = _import_file(path)
    return _IMPORTED[key]


def _import_file(path: Path) -> ModuleType:
    name = f"specguard_user_{abs(hash(path.resolve()))}"
    for folder in _import_roots(path):  # let the file import its neighbours, and its package by name
        if folder not in sys.path:
            sys.path.insert(0, folder)
    module_spec = importlib.util.spec_from_file_location(name, path)
    if module_spec is None or module_spec.loader is None:  # spec_path checked the suffix: not expected
        raise SpecError(f"{path}: Python cannot import it as a module")
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[name] = module
    hint = 'keep scripts\' own runs under `if __name__ == "__main__":`'
    try:
        with no_exit():
            module_spec.loader.exec_module(module)
    except SpecError:
        raise
    except SystemExit as e:  # sys.exit() at import: a spec file may not end the command
        raise SpecError(f"{path}: importing it called sys.exit({e.code!r})", hint=hint) from None
    except ExitAtImport as e:
        raise SpecError(f"{path}: importing it called os._exit({e.status!r})", hint=hint) from None
    except Exception as e:
        raise SpecError(f"{path}: importing it raised {type(e).__name__}: {e}") from e
    # Workers are separate processes: ship this file's functions by value.
    cloudpickle.register_pickle_by_value(module)
    return module


def _import_roots(path: Path) -> list[str]:
    """The file's folder and, when that is a package, the folder above its top package (pytest's rootdir rule).

    So ``example_specs/weights.py`` may write ``from example_specs import pendulum``
    under ``specguard run`` as it does under pytest.
    """
    folder = path.resolve().parent
    top = folder
    while (top / "__init__.py").is_file():
        top = top.parent
    return [str(folder)] if top == folder else [str(top), str(folder)]


def load_objects(target: str, kinds: tuple[type, ...] = (Spec,)) -> dict[str, Any]:
    """The specs (or other ``kinds``) named by ``PATH[::NAME]``, by name, in file order."""
    path_text, _, wanted = target.partition("::")
    module = import_file(spec_path(target))
    found: dict[str, Any] = {}
    for kind in kinds:  # earlier kinds win a shared name: specs["w"] over trees["w"]
        for attr, value in vars(module).items():
            if attr.startswith("_"):
                continue
            if isinstance(value, kind):
                found.setdefault(attr, value)
            elif isinstance(value, dict):
                for key, item in value.items():
                    if isinstance(key, str) and isinstance(item, kind):
                        found.setdefault(key, item)
    if wanted:
        if wanted not in found:
            known = ", ".join(found) or "none"
            raise SpecError(f"{path_text}: nothing named {wanted!r}; it defines: {known}")
        return {wanted: found[wanted]}
    if not found:
        raise SpecError(f"{path_text}: defines no {' or '.join(k.__name__ for k in kinds)} objects")
    return found
