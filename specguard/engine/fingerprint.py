"""Exact fingerprints of specs: the one identity the run cache, shared results and baselines key on.

A cached verdict is only as good as its key: a key that misses a change
reuses an old run for a changed reward. So the key is built from what a spec
*computes*, exactly:

* numbers in full precision (``float.hex``), numpy arrays by dtype, shape and
  content, containers by their items (dicts and sets sorted, so hash seeds do
  not matter);
* user functions by their bytecode (not their source text: formatting,
  comments and blank lines do not change it), constants, defaults, closure
  cells, and every module-level name they reference, followed recursively
  (helper functions, constants, arrays, classes, names read from a user module);
* installed libraries by name and distribution version (code under the
  interpreter's ``stdlib``/``site-packages`` directories); specguard by its
  version and a digest of its own source files;
* any other object by what pickle would store of it (``__reduce_ex__``); an
  object pickle cannot store is a :class:`~specguard.error.FingerprintError`
  naming where it was found. No ``repr``, memory address or ``id`` enters a key.

The static part cannot see code it cannot reach by name (an env class
instantiated from a string id, a C extension's internals), so a **behavioural
probe** adds a short fixed-seed rollout of the constructed env (for a baseline
spec, the initial env): seeded random actions for :data:`PROBE_STEPS` steps,
whose observations, rewards, reward terms, goals and terminations are hashed.
It cannot see behaviour off those states (say, a branch only near the goal),
nor anything in training beyond the library versions.

Example:
    >>> import specguard as sg
    >>> from example_specs import pendulum
    >>> spec = sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(timesteps=1000))
    >>> fp = fingerprint_spec(spec)
    >>> fp.run_key(0) != fp.run_key(1) and len(fp.spec_key) == 64
    True
"""

from __future__ import annotations

import builtins
import copy
import dataclasses
import enum
import functools
import hashlib
import json
import sys
import sysconfig
import types
import warnings
from collections.abc import Callable, Iterable, Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from specguard.error import FingerprintError, VersionMismatch
from specguard.extend import Annotation, Node
from specguard.version import __version__

__all__ = [
    "PROBE_STEPS",
    "SpecFingerprint",
    "canonical",
    "check_versions",
    "digest",
    "fingerprint_spec",
    "probe",
    "versions",
]

PROBE_STEPS = 256

# Spec fields that change how many runs are trained or how they are counted, not what one run does:
# they are part of the spec's identity (shared results, baselines) but not of a run's cache key.
_SPEC_ONLY_FIELDS = frozenset({"quorum", "undecided", "name", "xfail"})
_BUDGET_SPEC_ONLY_FIELDS = frozenset({"min_seeds", "max_seeds"})
_VERSIONED = ("gymnasium", "stable-baselines3", "torch", "numpy", "scipy", "cloudpickle")


# -- where code comes from --------------------------------------------------------


@functools.cache
def _library_roots() -> tuple[str, ...]:
    paths = sysconfig.get_paths()
    roots = {str(Path(paths[k]).resolve()) for k in ("stdlib", "platstdlib", "purelib", "platlib") if k in paths}
    return tuple(sorted(roots))


@functools.cache
def _distribution_versions() -> dict[str, str]:
    """Top-level import name -> "dist==version" of the installed distributions."""
    out: dict[str, str] = {}
    for top, dists in metadata.packages_distributions().items():
        found = []
        for d in sorted(set(dists)):
            try:
                found.append(f"{d}=={metadata.version(d)}")
            except metadata.PackageNotFoundError:
                continue
        out[top] = ",".join(found)
    return out


@functools.cache
def _specguard_digest() -> str:
    """specguard's version and a digest of its own source: a change to the engine misses the cache too."""
    return f"{__version__}+{source_digest(Path(__file__).resolve().parents[1])}"


def source_digest(package: Path) -> str:
    """A digest of every Python source file under ``package``, subpackages included, and of where each lies.

    A file's path relative to ``package`` is part of the digest, so moving a
    module changes it as much as editing one.
    """
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        relative = path.relative_to(package).as_posix()
        if "__pycache__" in relative:
            continue
        h.update(relative.encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


@functools.cache
def _library_module(name: str) -> str | None:
    """The version tag of ``name`` if it is library code (stdlib, an installed package or specguard), else None."""
    top = name.split(".", 1)[0]
    if top == "specguard":
        return _specguard_digest()
    if top in sys.stdlib_module_names or top in sys.builtin_module_names:
        return f"python=={sys.version.split()[0]}"
    module = sys.modules.get(name) or sys.modules.get(top)
    file = getattr(module, "__file__", None)
    if module is None or file is None:
        return None
    resolved = str(Path(file).resolve())
    if not any(resolved.startswith(root + "/") for root in _library_roots()):
        return None  # the user's own code (also an editable install): followed by content
    return _distribution_versions().get(top, "unversioned")


def versions() -> dict[str, str]:
    """The versions that decide a run's outcome beside the spec: Python, specguard and the RL stack."""
    found = {"python": sys.version.split()[0], "specguard": _specguard_digest()}
    for name in _VERSIONED:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "absent"
    return found


def check_versions(expected: Mapping[str, str], where: str) -> None:
    """Refuse to go on in a process whose :func:`versions` differ from ``expected`` (the ones a key was made with).

    Raises:
        VersionMismatch: naming each version that differs, expected and found.
    """
    found = versions()
    differing = [
        f"{name} {expected.get(name, 'absent')!s} (keyed) != {found.get(name, 'absent')!s} (here)"
        for name in sorted(set(expected) | set(found))
        if expected.get(name) != found.get(name)
    ]
    if differing:
        named = "; ".join(differing)
        raise VersionMismatch(f"{where}: this process runs other code than the run's cache key names: {named}")


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
            return [type(obj).__name__, sorted(items, key=_dumps)]
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
            # A goal-tree node through the protocol: its exact description (SPEC.md section 6), then
            # what pickle stores of it (the functions its description only names, by their code).
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
        keyed.sort(key=lambda e: _dumps(e[0]))
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
        tag = _library_module(fn.__module__) if isinstance(fn.__module__, str) else None
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
        tag = _library_module(module.__name__)
        if tag is not None:
            return ["module", module.__name__, tag]
        # The user's own module: the attributes the code may read from it (names it mentions).
        found = [(a, getattr(module, a)) for a in sorted(set(attributes)) if hasattr(module, a)]
        return ["module", module.__name__, [[a, self.encode(v, f"{where}.{a}")] for a, v in found]]

    def _class(self, cls: type, where: str) -> Any:
        tag = _library_module(cls.__module__)
        if tag is not None:
            return ["class", cls.__module__, cls.__qualname__, tag]
        skip = {"__dict__", "__weakref__", "__module__", "__qualname__"}
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


def _dumps(value: Any) -> str:
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
    return hashlib.sha256(_dumps(canonical(value, where)).encode()).hexdigest()


# -- the behavioural probe ---------------------------------------------------------


def probe(spec: Any, steps: int = PROBE_STEPS, build: Callable[[], Any] | None = None) -> str:
    """A digest of a fixed-seed rollout of the spec's training env (seeded random actions).

    An env that raises is not an error here: the exception's type and message
    are hashed and the rollout ends (the training run reports the failure
    with its seed, where it belongs). ``build`` makes the env (``None``:
    :func:`~specguard.engine.train.make_single_env`); probes of one spec share
    one :func:`~specguard.engine.train.env_factory`, so its tree is compiled once.
    """
    from specguard.engine.train import make_single_env

    h = hashlib.sha256()
    env = None
    try:
        env = make_single_env(spec) if build is None else build()
        h.update(_dumps(canonical((env.observation_space, env.action_space), "spaces")).encode())
        actions = copy.deepcopy(env.action_space)  # seeding the user's own space would change it
        actions.seed(0)
        episode = 0
        obs, info = env.reset(seed=0)
        _hash_step(h, obs, None, None, None, info)
        for _ in range(steps):
            obs, reward, terminated, truncated, info = env.step(actions.sample())
            _hash_step(h, obs, reward, terminated, truncated, info)
            if terminated or truncated:
                episode += 1
                obs, info = env.reset(seed=episode)
                _hash_step(h, obs, None, None, None, info)
    except FingerprintError:
        raise
    except Exception as e:
        h.update(f"raised {type(e).__module__}.{type(e).__qualname__}: {e}".encode())
    finally:
        if env is not None:
            env.close()
    return h.hexdigest()


def _hash_step(h: Any, obs: Any, reward: Any, terminated: Any, truncated: Any, info: dict[str, Any]) -> None:
    arr = np.asarray(obs)
    h.update(arr.dtype.str.encode() + repr(arr.shape).encode() + np.ascontiguousarray(arr).tobytes())
    if reward is not None:
        h.update(float(reward).hex().encode() + bytes([bool(terminated), bool(truncated)]))
    for key in ("goals", "reward_terms"):
        for name, value in (info.get(key) or {}).items():
            h.update(name.encode() + b"\0" + (float(value).hex().encode()))


# -- a spec's identity ---------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class SpecFingerprint:
    """A spec's identity: the key of its shared result and of each of its runs.

    Attributes:
        spec_key: every field that can change the spec's verdict (seeds,
            quorum and ``undecided`` included), the probe and the versions.
        run_base: what decides one run (the spec less the fields that only
            count runs), the probe and the versions; :meth:`run_key` adds the seed.
        reproducible: the probe gave the same digest twice; an env that does
            not is never cached (its runs could not be reproduced from a key).
    """

    spec_key: str
    run_base: str
    reproducible: bool = True

    def run_key(self, seed: int) -> str:
        """The cache key of run ``seed``."""
        return hashlib.sha256(f"{self.run_base}:{int(seed)}".encode()).hexdigest()


def _fields(obj: Any, exclude: frozenset[str]) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.name not in exclude}


def _compute(spec: Any) -> SpecFingerprint:
    where = f"Spec {spec.label!r}"
    full = _fields(spec, frozenset())
    run = _fields(spec, _SPEC_ONLY_FIELDS)
    run["budget"] = _fields(spec.budget, _BUDGET_SPEC_ONLY_FIELDS)
    from specguard.engine.train import env_factory

    build = env_factory(spec)  # a fresh env per probe, on one compiled tree
    first, second = probe(spec, build=build), probe(spec, build=build)
    if first != second:
        warnings.warn(
            f"specguard: {where}: the env does not repeat a fixed-seed rollout (it draws randomness its seed does "
            "not control), so its runs cannot be reproduced from a key and are not cached",
            stacklevel=3,
        )
    common = {"probe": first, "versions": versions()}
    return SpecFingerprint(
        spec_key=digest({"spec": full, **common}, where),
        run_base=digest({"run": run, **common}, where),
        reproducible=first == second,
    )


_MEMO: dict[int, tuple[Any, SpecFingerprint]] = {}
_MEMO_SIZE = 128


def fingerprint_spec(spec: Any) -> SpecFingerprint:
    """The fingerprint of ``spec`` (computed once per spec object and process).

    Raises:
        FingerprintError: a value in the spec cannot be fingerprinted exactly.
        SpecError: the env failed during the behavioural probe.
    """
    hit = _MEMO.get(id(spec))
    if hit is not None and hit[0] is spec:
        return hit[1]
    fp = _compute(spec)
    if len(_MEMO) >= _MEMO_SIZE:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[id(spec)] = (spec, fp)  # holding the spec keeps its id from being reused
    return fp
