"""Reading an agent's files without running the code they may hold.

A stable-baselines3 zip stores its class parameters (``data``) as JSON whose objects (spaces, the policy class,
schedules, arrays) are cloudpickled, and ``VecNormalize.save`` pickles the statistics whole. Unpickling runs
whatever the file says: a zip downloaded from a model hub can hold a function that runs at load time. So by
default specguard decodes them with :class:`SafeUnpickler`, which rebuilds only the objects an agent is made of:

* NumPy arrays, scalars, dtypes and random generators; ``collections.deque`` and ``OrderedDict``; sets, slices;
* Gymnasium's spaces;
* stable-baselines3's and sb3-contrib's policies, feature extractors, buffers, schedules, running statistics and
  ``VecNormalize``, and their enums and named tuples;
* torch's ``nn`` modules (an activation function in ``policy_kwargs``) and optimizers (``optimizer_class``).

Anything else (a function pickled by value, another module's class, ``builtins.eval``) is refused in one line that
names the field and the object; ``trust=True`` (``--trust-agent``) loads the file as SB3's own ``load`` does. The
weights (``.pth``) are read by SB3 with ``torch.load(weights_only=True)`` in both cases.

Example:
    >>> import pickle, numpy as np
    >>> safe_loads(pickle.dumps(np.arange(3)), "x.pkl").tolist()
    [0, 1, 2]
    >>> safe_loads(pickle.dumps(print), "x.pkl")
    Traceback (most recent call last):
        ...
    specguard.agents.decode.UnsafeObject: builtins.print
"""

from __future__ import annotations

import base64
import importlib
import io
import json
import pickle
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from specguard.error import AgentError
from specguard.utils.text import MAX_SHOWN, elide

__all__ = ["MAX_DATA_BYTES", "SafeUnpickler", "UnsafeObject", "read_data", "read_statistics", "safe_loads"]

MAX_DATA_BYTES = 64 * 1024 * 1024
"""The most bytes a model's ``data`` may inflate to (SB3 writes a few kilobytes, a replay of observations a few MB):
a crafted zip whose ``data`` inflates to gigabytes is refused before it is read."""

TRUST_HINT = "if you trust the file, load_agent(..., trust=True) or --trust-agent loads it as SB3's load does"

_ALLOWED_NAMES = {
    "builtins": {"set", "frozenset", "slice", "complex", "bytearray", "range", "object"},
    "collections": {"deque", "OrderedDict"},
    "copyreg": {"_reconstructor", "__newobj__", "__newobj_ex__"},
    "numpy.random._pickle": {"__generator_ctor", "__bit_generator_ctor", "__randomstate_ctor"},
    "numpy.random.bit_generator": {"__pyx_unpickle_SeedSequence", "SeedSequence"},
}
_NUMPY_ARRAYS = {"_reconstruct", "_frombuffer", "scalar", "ndarray", "dtype"}
_NUMPY_ARRAY_MODULES = {
    "numpy",
    "numpy.core.multiarray",
    "numpy._core.multiarray",
    "numpy.core.numeric",
    "numpy._core.numeric",
}
_CLASS_PACKAGES = ("numpy", "gymnasium.spaces", "stable_baselines3", "sb3_contrib", "torch.nn.modules", "torch.optim")


class UnsafeObject(pickle.UnpicklingError):
    """A pickle names an object :class:`SafeUnpickler` does not rebuild (``module.name``)."""


def _safe_bases() -> tuple[type, ...]:
    """The classes whose subclasses a file may rebuild (imported when a file is read, not before)."""
    import enum

    import gymnasium as gym
    import numpy as np
    import torch
    from stable_baselines3.common import utils
    from stable_baselines3.common.buffers import BaseBuffer
    from stable_baselines3.common.policies import BasePolicy
    from stable_baselines3.common.running_mean_std import RunningMeanStd
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
    from stable_baselines3.common.type_aliases import TrainFreq
    from stable_baselines3.common.vec_env import VecNormalize

    schedules = tuple(
        c for c in (getattr(utils, n, None) for n in ("FloatSchedule", "LinearSchedule", "ConstantSchedule")) if c
    )
    return (
        gym.spaces.Space,
        np.generic,
        np.dtype,
        np.random.Generator,
        np.random.BitGenerator,
        np.random.SeedSequence,
        BasePolicy,
        BaseFeaturesExtractor,
        BaseBuffer,
        RunningMeanStd,
        VecNormalize,
        TrainFreq,
        enum.Enum,
        torch.nn.Module,
        torch.optim.Optimizer,
        *schedules,
    )


def _allowed(module: str, name: str) -> bool:
    """``module.name`` is an object a :class:`SafeUnpickler` rebuilds (see the module); imports ``module`` only
    when it lies in a package the list names."""
    if name in _ALLOWED_NAMES.get(module, ()):
        return True
    if module in _NUMPY_ARRAY_MODULES and name in _NUMPY_ARRAYS:
        return True
    if not any(module == p or module.startswith(p + ".") for p in _CLASS_PACKAGES):
        return False
    try:
        obj = getattr(importlib.import_module(module), name, None)
    except ImportError:
        return False
    if not isinstance(obj, type) or obj.__module__ == "enum":  # Enum itself is no class of a listed package
        return False
    return issubclass(obj, _safe_bases())


class SafeUnpickler(pickle.Unpickler):
    """An unpickler that rebuilds only what an agent's files are made of (see the module); any other global is an
    :class:`UnsafeObject`."""

    def find_class(self, module: str, name: str) -> Any:
        if not _allowed(module, name):
            raise UnsafeObject(f"{module}.{name}")
        return super().find_class(module, name)


def safe_loads(blob: bytes, where: str) -> Any:
    """``blob`` unpickled by :class:`SafeUnpickler`.

    Raises:
        UnsafeObject: it names an object outside the list.
        AgentError: it is no pickle, or its objects raised while being rebuilt (``where`` named).
    """
    try:
        return SafeUnpickler(io.BytesIO(blob)).load()
    except UnsafeObject:
        raise
    except RecursionError:
        raise AgentError(f"{where}: cannot be decoded (nested too deeply)", hint=None) from None
    except Exception as e:
        raise AgentError(f"{where}: cannot be decoded ({_why(e)})", hint=None) from None


def _why(e: BaseException) -> str:
    text = str(e).strip()
    return f"{type(e).__name__}: {elide(text.splitlines()[0], MAX_SHOWN)}" if text else type(e).__name__


def _read_entry(archive: zipfile.ZipFile, name: str, where: str, limit: int) -> bytes:
    """Entry ``name`` of ``archive``, refused when it declares more than ``limit`` bytes (zipfile never inflates
    past what an entry declares)."""
    size = archive.getinfo(name).file_size
    if size > limit:
        raise AgentError(
            f"{where}: its {name!r} inflates to {size:,} bytes, more than the {limit:,} a model's data may have",
            hint=None,
        )
    return archive.read(name)


def read_data(model_zip: Path, *, trust: bool, replace: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """A model zip's ``data`` (its class parameters) and the objects to hand SB3's ``load`` as ``custom_objects``
    (every serialized field, decoded here, so that SB3 unpickles none; with ``trust``, only ``replace``).

    ``replace``: fields not decoded at all (schedules acting does not need), by their stand-ins.

    Raises:
        AgentError: one line: not a zip or no ``data``, ``data`` too large or not JSON of a mapping, or a field that
            cannot be decoded or names code outside the list (with the hint to trust the file).
    """
    where = repr(str(model_zip))
    try:
        with zipfile.ZipFile(model_zip) as archive:
            text = _read_entry(archive, "data", where, MAX_DATA_BYTES).decode()
    except AgentError:
        raise
    except (zipfile.BadZipFile, KeyError, OSError, ValueError, RuntimeError, NotImplementedError, EOFError) as e:
        # RuntimeError: an encrypted entry; NotImplementedError: an unknown compression; KeyError: no 'data'.
        raise AgentError(f"{where}: not a stable-baselines3 model ({_why(e)})", hint=None) from None
    try:
        fields = json.loads(text)
    except RecursionError:
        raise AgentError(f"{where}: not a stable-baselines3 model (its data is nested too deeply)", hint=None) from None
    except ValueError as e:
        raise AgentError(f"{where}: not a stable-baselines3 model ({_why(e)})", hint=None) from None
    if not isinstance(fields, dict):
        kind = "null" if fields is None else type(fields).__name__
        raise AgentError(f"{where}: not a stable-baselines3 model (its data is a {kind}, not a mapping)", hint=None)
    if trust:
        from stable_baselines3.common.save_util import json_to_data

        try:
            return json_to_data(text, custom_objects=dict(replace)), dict(replace)
        except Exception as e:
            raise AgentError(f"{where}: cannot be loaded ({_why(e)})", hint=None) from None
    data: dict[str, Any] = {}
    custom: dict[str, Any] = dict(replace)
    for key, item in fields.items():
        if key in replace:
            data[key] = replace[key]
        elif isinstance(item, dict) and ":serialized:" in item:
            data[key] = custom[key] = _field(where, key, item[":serialized:"])
        else:
            data[key] = item
    return data, custom


def _field(where: str, key: str, serialized: Any) -> Any:
    try:
        blob = base64.b64decode(str(serialized).encode(), validate=True)
    except ValueError as e:
        raise AgentError(f"{where}: its field {key!r} is not base64 ({_why(e)})", hint=None) from None
    return _untrusted(blob, where, f"its field {key!r}")


def _untrusted(blob: bytes, where: str, what: str) -> Any:
    """``blob`` decoded by :func:`safe_loads`; an object outside the list is one line naming ``what`` holds it."""
    try:
        return safe_loads(blob, f"{where}: {what}")
    except UnsafeObject as e:
        raise AgentError(
            f"{where}: {what} holds {e}, which specguard does not load without trust (it may run code)",
            hint=TRUST_HINT,
        ) from None


def read_statistics(path: Path, *, trust: bool) -> Any:
    """The object a ``vecnormalize.pkl`` holds, decoded as :func:`read_data` decodes a field (unpickled whole, with
    ``trust``).

    Raises:
        AgentError: it cannot be read or decoded, or names code outside the list.
    """
    where = repr(str(path))
    try:
        blob = path.read_bytes()
    except OSError as e:
        raise AgentError(f"{where}: cannot read VecNormalize statistics: {_why(e)}", hint=None) from None
    if trust:
        try:
            return pickle.loads(blob)  # VecNormalize.save pickles itself (its venv left out)
        except Exception as e:
            raise AgentError(f"{where}: cannot read VecNormalize statistics: {_why(e)}", hint=None) from None
    return _untrusted(blob, where, "the VecNormalize statistics file")
