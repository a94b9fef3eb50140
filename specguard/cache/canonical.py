"""The canonical form of a spec's values: exact, JSON-able, every reference followed (the key's reading of code).

See :mod:`specguard.cache.fingerprint` for what enters a key and why.
"""

from __future__ import annotations

import builtins
import enum
import functools
import hashlib
import json
import types
from collections.abc import Iterable
from typing import Any

import numpy as np

from specguard.cache.versions import library_module
from specguard.error import FingerprintError
from specguard.extend import Annotation, Node

__all__ = ["canonical", "digest", "dumps"]

# -- the canonical form ------------------------------------------------------------

_HINT = (
    "a spec's functions and values must be plain data, functions, classes or picklable objects; "
    "build unpicklable things (envs, files, locks) inside the function that uses them"
)


class _Encoder:
    """Turns a value into nested JSON-able lists, exactly, following references recursively.

    Objects that can take part in a cycle are numbered on first visit and
    referred to by number afterwards (the numbers follow the traversal order,
    which is deterministic, never ``id``).
    """

    def __init__(self) -> None:
        self._seen: dict[int, int] = {}
        self._alive: list[Any] = []  # keeps visited objects alive so their ids stay unique

    def encode(self, obj: Any, where: str) -> Any:
        # Exact scalars first: they are never shared by reference.
        if obj is None or isinstance(obj, bool):
            return obj
        if isinstance(obj, int) and type(obj) is int:
            return ["int", str(obj)]
        if type(obj) is float:
            return ["float", obj.hex()]
        if type(obj) is str:
            return ["str", obj]
        if type(obj) is complex:
            return ["complex", obj.real.hex(), obj.imag.hex()]
        if isinstance(obj, (bytes, bytearray)):
            return ["bytes", hashlib.sha256(obj).hexdigest()]
        if isinstance(obj, np.generic):
            return ["npscalar", obj.dtype.str, obj.tobytes().hex()]
        if isinstance(obj, np.dtype):
            return ["dtype", obj.str]
        if isinstance(obj, types.CodeType):
            return self._code(obj, where)
        if isinstance(obj, tuple) and type(obj) is tuple:
            return ["tuple", [self.encode(v, f"{where}[{i}]") for i, v in enumerate(obj)]]
        if isinstance(obj, (frozenset, set)) and type(obj) in (set, frozenset):
            items = [self.encode(v, f"{where}{{}}") for v in obj]
            return [type(obj).__name__, sorted(items, key=dumps)]
        if isinstance(obj, (range, slice)):
            return [type(obj).__name__, self.encode((obj.start, obj.stop, obj.step), where)]
        if isinstance(obj, enum.Enum):
            return ["enum", self.encode(type(obj), where), obj.name]
        ref = self._seen.get(id(obj))
        if ref is not None:
            return ["ref", ref]
        self._seen[id(obj)] = len(self._seen)
        self._alive.append(obj)
        return self._compound(obj, where)

    def _compound(self, obj: Any, where: str) -> Any:
        if type(obj) is list:
            return ["list", [self.encode(v, f"{where}[{i}]") for i, v in enumerate(obj)]]
        if type(obj) is dict:
            return ["dict", self._items(obj.items(), where)]
        if isinstance(obj, types.MappingProxyType):  # e.g. a dataclass field's metadata, in a user class's body
            return ["mappingproxy", self._items(obj.items(), where)]
        if isinstance(obj, np.ndarray):
            if obj.dtype.hasobject:
                return ["ndarray", "object", list(obj.shape), self.encode(obj.tolist(), where)]
            data = np.ascontiguousarray(obj).tobytes()
            return ["ndarray", obj.dtype.str, list(obj.shape), hashlib.sha256(data).hexdigest()]
        if isinstance(obj, types.ModuleType):
            return self._module(obj, (), where)
        if isinstance(obj, type):
            return self._class(obj, where)
        if isinstance(obj, types.FunctionType):
            return self._function(obj, where)
        if isinstance(obj, types.MethodType):
            return ["method", self.encode(obj.__self__, where), self.encode(obj.__func__, where)]
        if isinstance(obj, (types.BuiltinFunctionType, np.ufunc)):
            return self._builtin(obj, where)
        if isinstance(obj, functools.partial):
            return ["partial", self.encode((obj.func, obj.args, obj.keywords), where)]
        if isinstance(obj, (staticmethod, classmethod)):
            return [type(obj).__name__, self.encode(obj.__func__, where)]
        if isinstance(obj, property):
            return ["property", self.encode((obj.fget, obj.fset, obj.fdel), where)]
        if isinstance(obj, (Node, Annotation)):
            # A goal-tree node through the protocol: its exact description (docs/semantics.md, "The operator
            # contract"), then what pickle stores of it (the functions its description only names, by their code).
            text = obj.describe()
            return ["spec-node", text, self._object(obj, f"{where} ({text})")]
        if isinstance(obj, types.CellType):
            try:
                contents = obj.cell_contents
            except ValueError:  # an empty cell
                return ["cell"]
            return ["cell", self.encode(contents, where)]
        return self._object(obj, where)

    def _items(self, items: Iterable[tuple[Any, Any]], where: str) -> list[Any]:
        keyed = [(self.encode(k, f"{where} key"), v, k) for k, v in items]
        keyed.sort(key=lambda e: dumps(e[0]))
        return [[k, self.encode(v, f"{where}[{raw!r}]")] for k, v, raw in keyed]

    def _code(self, code: types.CodeType, where: str) -> Any:
        # Bytecode and what it refers to; not the file, line numbers or line table,
        # so reformatting, comments and blank lines leave the key unchanged.
        return [
            "code",
            code.co_name,
            [code.co_argcount, code.co_posonlyargcount, code.co_kwonlyargcount, code.co_flags],
            code.co_code.hex(),
            [self.encode(c, f"{where} constant") for c in code.co_consts],
            list(code.co_names),
            list(code.co_varnames),
            list(code.co_freevars),
            list(code.co_cellvars),
        ]

    def _function(self, fn: types.FunctionType, where: str) -> Any:
        label = f"{where} ({fn.__qualname__})"
        tag = library_module(fn.__module__) if isinstance(fn.__module__, str) else None
        if tag is not None:
            return ["function", fn.__module__, fn.__qualname__, tag]
        freevars = zip(fn.__code__.co_freevars, fn.__closure__ or ())
        cells = [self.encode(c, f"{label} closure {name!r}") for name, c in freevars]
        referenced = sorted(_names(fn.__code__))
        globals_ = [
            [name, self.encode(fn.__globals__[name], f"{label} global {name!r}")]
            for name in referenced
            if name in fn.__globals__ and not isinstance(fn.__globals__[name], types.ModuleType)
        ]
        modules = [
            [name, self._module(fn.__globals__[name], referenced, f"{label} global {name!r}")]
            for name in referenced
            if isinstance(fn.__globals__.get(name), types.ModuleType)
        ]
        shadowed = [n for n in referenced if n not in fn.__globals__ and hasattr(builtins, n)]
        return [
            "function",
            self._code(fn.__code__, label),
            self.encode(fn.__defaults__, f"{label} defaults"),
            self.encode(fn.__kwdefaults__, f"{label} keyword defaults"),
            cells,
            globals_,
            modules,
            shadowed,
        ]

    def _module(self, module: types.ModuleType, attributes: Iterable[str], where: str) -> Any:
        tag = library_module(module.__name__)
        if tag is not None:
            return ["module", module.__name__, tag]
        # The user's own module: the attributes the code may read from it (names it mentions).
        found = [(a, getattr(module, a)) for a in sorted(set(attributes)) if hasattr(module, a)]
        return ["module", module.__name__, [[a, self.encode(v, f"{where}.{a}")] for a, v in found]]

    def _class(self, cls: type, where: str) -> Any:
        tag = library_module(cls.__module__)
        if tag is not None:
            return ["class", cls.__module__, cls.__qualname__, tag]
        # Not what the class computes: its namespace's bookkeeping, and an abstract base's cache of subclass checks.
        skip = {"__dict__", "__weakref__", "__module__", "__qualname__", "_abc_impl"}
        body = [
            [k, self.encode(v, f"{where} ({cls.__qualname__}.{k})")]
            for k, v in sorted(vars(cls).items())
            if k not in skip and not isinstance(v, (types.MemberDescriptorType, types.GetSetDescriptorType))
        ]
        return ["class", cls.__qualname__, [self.encode(b, f"{where} base") for b in cls.__bases__], body]

    def _builtin(self, fn: Any, where: str) -> Any:
        owner = getattr(fn, "__self__", None)
        module = getattr(fn, "__module__", None) or getattr(type(owner), "__module__", "")
        bound = None if owner is None or isinstance(owner, types.ModuleType) else self.encode(owner, where)
        return ["builtin", module, getattr(fn, "__qualname__", fn.__name__), bound]

    def _object(self, obj: Any, where: str) -> Any:
        # What pickle would store of the object: its class and its state.
        try:
            reduced = obj.__reduce_ex__(4)
        except Exception as e:
            raise FingerprintError(
                where,
                f"cannot fingerprint {type(obj).__module__}.{type(obj).__qualname__} exactly "
                f"(pickle cannot store it: {type(e).__name__}: {e})",
                hint=_HINT,
            ) from None
        if isinstance(reduced, str):  # a module-level singleton, by name
            return ["global", type(obj).__module__, reduced]
        parts = list(reduced) + [None] * (5 - len(reduced))
        callable_, args, state, list_items, dict_items = parts[:5]
        if isinstance(state, dict) and "_np_random" in state and _is_space(obj):
            # A space's random generator moves whenever it is sampled; it is not part of what the space is.
            state = {k: v for k, v in state.items() if k != "_np_random"}
        return [
            "object",
            self.encode(type(obj), where),
            self.encode(callable_, where),
            self.encode(args, where),
            self.encode(state, where),
            None if list_items is None else self.encode(list(list_items), where),
            None if dict_items is None else self._items(list(dict_items), where),
        ]


def _is_space(obj: Any) -> bool:
    import gymnasium as gym

    return isinstance(obj, gym.spaces.Space)


def _names(code: types.CodeType) -> set[str]:
    """Every global or attribute name the code (and the code nested in it) mentions."""
    names = set(code.co_names)
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            names |= _names(c)
    return names


def dumps(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"), ensure_ascii=True)


def canonical(value: Any, where: str = "value") -> Any:
    """The exact canonical form of ``value`` (nested lists of strings and numbers).

    Raises:
        FingerprintError: something in ``value`` cannot be fingerprinted
            exactly; the message says where it was found.
    """
    return _Encoder().encode(value, where)


def digest(value: Any, where: str = "value") -> str:
    """The SHA-256 of :func:`canonical` ``(value)``."""
    return hashlib.sha256(dumps(canonical(value, where)).encode()).hexdigest()
