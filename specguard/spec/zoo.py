"""An algorithm's tuned hyperparameters for an env id, read from rl-zoo3's files, as a spec's own fields.

`rl-zoo3 <https://rl-baselines3-zoo.readthedocs.io>`_ keeps tuned settings per
algorithm and env id in YAML files (``rl_zoo3/hyperparams/ppo.yml``, ...).
:func:`zoo_settings` reads one entry the way rl-zoo3's ``ExperimentManager``
preprocesses it and maps it onto a :class:`~specguard.spec.trainers.SB3` trainer's fields:
``policy``, ``n_envs``, ``normalize``, ``hyperparameters`` (``policy_kwargs``
evaluated in a closed scope, ``lin_<x>`` schedules as :class:`LinearSchedule`),
and ``n_timesteps`` as :attr:`ZooSettings.timesteps`. What a spec cannot say
(env wrappers, frame stacking, action noise, VecNormalize options
other than its defaults, ...) is named in one :class:`~specguard.error.SpecWarning`
and kept in :attr:`ZooSettings.not_taken`; nothing is dropped silently.

The files are read without importing ``rl_zoo3`` (whose import patches
Gymnasium's ``TimeLimit`` and loads its training stack): only its location is looked up.

Example:
    >>> hp = _from_text("policy_kwargs", "dict(activation_fn=nn.ReLU, net_arch=dict(pi=[64], vf=[64]))", "where")
    >>> hp["activation_fn"].__name__, hp["net_arch"]
    ('ReLU', {'pi': [64], 'vf': [64]})
    >>> LinearSchedule(3e-4)(0.5)
    0.00015
"""

from __future__ import annotations

import ast
import difflib
import functools
import importlib
import importlib.util
import math
import warnings
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

from specguard.error import InvalidSpec, SpecWarning, user_stacklevel
from specguard.spec.algorithms import (
    algorithm_class,
    check_policy,
    default_policy,
    dict_policy,
    hyperparameter_names,
    resolve_algorithm,
)
from specguard.spec.schedules import SCHEDULED, LinearSchedule
from specguard.spec.trainers import SB3
from specguard.utils.text import MAX_VALUE, elide, value_text
from specguard.validation import check_text, is_count

__all__ = ["SCHEDULED", "ZOO_FILES", "LinearSchedule", "ZooSettings", "read_zoo_file", "zoo_settings"]

ZOO_FILES: dict[str, str] = {
    "PPO": "ppo",
    "A2C": "a2c",
    "DQN": "dqn",
    "SAC": "sac",
    "TD3": "td3",
    "DDPG": "ddpg",
    "ARS": "ars",
    "CrossQ": "crossq",
    "QRDQN": "qrdqn",
    "RecurrentPPO": "ppo_lstm",
    "TQC": "tqc",
    "TRPO": "trpo",
}
"""The algorithms rl-zoo3 has files for, by specguard's name: the file's stem (MaskablePPO has none)."""

SPEC_FIELDS = ("trainer", "observation")
"""The :class:`~specguard.spec.spec.Spec` keyword arguments a :class:`ZooSettings` unpacks into."""

_HINT = "pip install 'specguard[zoo]'"

# Keys rl-zoo3 reads itself (not the model's constructor), with why a spec does not take them.
_NOT_TAKEN = {
    "env_wrapper": "a wrapper around the env; a spec trains on its constructed env: wrap the initial env yourself",
    "vec_env_wrapper": "a wrapper around the vectorized env; specguard builds the training envs itself",
    "frame_stack": "VecFrameStack around the training envs; specguard builds the training envs itself",
    "env_kwargs": "the env's make kwargs: give them to sg.InitialEnv(env_id, ..., **kwargs)",
    "eval_env_kwargs": "the evaluation env's make kwargs; a spec evaluates on its constructed env",
    "monitor_kwargs": "Monitor's options; specguard records episodes itself",
    "noise_type": "rl-zoo3 builds the action noise from the env's action space: give "
    "hyperparameters={'action_noise': NormalActionNoise(...)} yourself",
    "noise_std": "see noise_type",
    "replay_buffer_class": "HER's replay buffer needs a goal-conditioned (dict observation) env",
    "replay_buffer_kwargs": "see replay_buffer_class",
}

# VecNormalize's defaults: what a spec's normalize=True is (specguard.training.train wraps VecNormalize(venv)).
_VECNORMALIZE = {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0, "clip_reward": 10.0, "gamma": 0.99}


@dataclass(frozen=True)
class ZooSettings(Mapping[str, Any]):
    """One rl-zoo3 entry as a spec's fields: unpack it into ``sg.Spec(..., **settings)``.

    As a mapping it holds exactly the :class:`~specguard.spec.spec.Spec` keyword arguments ``trainer`` (an
    :class:`~specguard.spec.trainers.SB3` with the entry's algorithm, policy, hyperparameters, ``n_envs``,
    ``normalize`` and callbacks) and ``observation``; change one of the trainer's with
    ``dataclasses.replace(settings.trainer, n_envs=1)``.
    The trainer's ``callbacks`` are the entry's ``callback`` classes as callback factories (a class, or a
    ``functools.partial`` with the entry's keyword arguments), as rl-zoo3's ``get_callback_list`` makes them
    (imported where the settings are read, and again in each training process: one of ``rl_zoo3.callbacks``
    imports rl_zoo3, which patches Gymnasium's ``TimeLimit`` in that process, as it does wherever rl-zoo3 trains).
    ``observation`` is ``"features+env"`` where the zoo's policy takes a ``Dict`` (``MultiInputPolicy``: the zoo's env
    gave one), so the agent sees the env's own observation beside the spec's features; else ``"features"``.

    Attributes:
        trainer: the entry's training settings.
        env_id: the entry's env id.
        timesteps: the zoo's ``n_timesteps`` (its whole training budget; ``sg.Budget(timesteps=...)`` takes it).
        not_taken: ``{zoo key: its value and why a spec does not take it}``, as the warning named them.
        source: where the entry was read (``rl-zoo3 2.9.2, ppo.yml``, or the file given).
    """

    trainer: SB3
    env_id: str
    timesteps: int
    observation: str = "features"
    not_taken: dict[str, str] = field(default_factory=dict)
    source: str = ""

    def __getitem__(self, key: str) -> Any:
        if key not in SPEC_FIELDS:
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(SPEC_FIELDS)

    def __len__(self) -> int:
        return len(SPEC_FIELDS)


# -- finding and reading the files ---------------------------------------------------------------


def _zoo_file(where: str, stem: str) -> tuple[Path, str]:
    """rl-zoo3's file ``<stem>.yml`` and its source in words, found without importing rl_zoo3."""
    found = importlib.util.find_spec("rl_zoo3")
    if found is None or not found.submodule_search_locations:
        raise InvalidSpec(where, "rl-zoo3 is not installed; its hyperparameter files come with it", hint=_HINT)
    version = metadata.version("rl_zoo3")
    path = Path(next(iter(found.submodule_search_locations))) / "hyperparams" / f"{stem}.yml"
    if not path.is_file():
        raise InvalidSpec(where, f"rl-zoo3 {version} has no file hyperparams/{stem}.yml")
    return path, f"rl-zoo3 {version}, {stem}.yml"


_DEEPEST = 64  # the most levels a zoo file nests (rl-zoo3's own: 3) or a value written as Python (its own: about 8)
_MOST_NODES = 100_000  # the most values a zoo file holds, aliases expanded (rl-zoo3's largest, ppo.yml: about 1,300)


def _yaml_error(e: Exception) -> str:
    """A YAML error (or a value its constructor refused) in one bounded line: what, and at which line and column."""
    import yaml

    if isinstance(e, yaml.MarkedYAMLError) and e.problem_mark is not None:
        mark = e.problem_mark
        return elide(f"{e.problem or e.context} (line {mark.line + 1}, column {mark.column + 1})", MAX_VALUE)
    return elide(" ".join(f"{type(e).__name__}: {e}".split()), MAX_VALUE)


def _too_deep(events: Iterator[Any]) -> bool:
    """Whether the collections of a YAML event stream nest deeper than :data:`_DEEPEST`.

    Read event by event, nothing recursing, and stopped at the first level too deep (PyYAML's scanner slows with each
    level of ``[`` it is inside: a document of 100,000 would take minutes to read to its end).
    """
    import yaml

    depth = 0
    for event in events:
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > _DEEPEST:
                return True
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1
    return False


def _expanded_size(node: Any) -> int:
    """How many values ``node`` holds with its aliases expanded, counted up to just over :data:`_MOST_NODES`.

    Each alias is counted as often as it is used, as a repr or a spec's fingerprint would expand it; a document of
    nested aliases (a few hundred bytes that expand to a billion values) stops the count early.
    """
    count, stack = 0, [node]
    while stack and count <= _MOST_NODES:
        node = stack.pop()
        count += 1
        if isinstance(node.value, list):  # a sequence's items, or a mapping's (key, value) pairs
            for item in node.value:
                stack.extend(item if isinstance(item, tuple) else (item,))
    return count


def _load(where: str, name: str, text: str) -> Any:
    """``yaml.safe_load(text)``, refusing documents nested deeper than :data:`_DEEPEST` or larger than
    :data:`_MOST_NODES` values once their aliases are expanded."""
    import yaml

    if _too_deep(yaml.parse(text, Loader=yaml.SafeLoader)):
        raise InvalidSpec(where, f"cannot read {name}: it nests deeper than {_DEEPEST} levels")
    loader = _loader()(text)
    try:
        node = loader.get_single_node()
        if node is not None and _expanded_size(node) > _MOST_NODES:
            raise InvalidSpec(
                where, f"cannot read {name}: with its aliases expanded it holds over {_MOST_NODES:,} values"
            )
        return None if node is None else loader.construct_document(node)
    finally:
        loader.dispose()


@functools.cache
def _loader() -> Any:
    """PyYAML's safe loader, reading also the two Python tags rl-zoo3 writes in a run's ``config.yml`` and ``args.yml``
    (``yaml.dump`` of an ``OrderedDict``: a mapping; of a tuple: a tuple); any other tag stays an error."""
    import yaml

    class ZooLoader(yaml.SafeLoader):  # type: ignore[misc]
        pass

    ZooLoader.add_constructor("tag:yaml.org,2002:python/object/apply:collections.OrderedDict", _ordered_dict)
    ZooLoader.add_constructor("tag:yaml.org,2002:python/tuple", _tuple)
    return ZooLoader


def _ordered_dict(loader: Any, node: Any) -> dict[Any, Any]:
    (pairs,) = loader.construct_sequence(node, deep=True)  # OrderedDict's one argument: its [key, value] pairs
    return {key: value for key, value in pairs}


def _tuple(loader: Any, node: Any) -> tuple[Any, ...]:
    return tuple(loader.construct_sequence(node, deep=True))


def _read(where: str, path: Path) -> dict[str, Any]:
    entries = read_zoo_file(where, path)
    if not isinstance(entries, dict):
        raise InvalidSpec(where, f"expected {str(path)!r} to map env ids to settings, got {type(entries).__name__}")
    return entries


def read_zoo_file(where: str, path: Path) -> Any:
    """What the YAML file ``path`` of rl-zoo3 says: a hyperparameter file, or a run's ``config.yml``, ``args.yml`` or
    ``env_kwargs.yml`` (read safely: plain YAML and the ``OrderedDict`` and tuple rl-zoo3 writes, bounded in depth
    and size).

    Raises:
        InvalidSpec: ``where``: the file cannot be read (PyYAML missing, not UTF-8, not YAML), naming it.
    """
    try:
        import yaml
    except ImportError:
        raise InvalidSpec(where, "reading rl-zoo3's files needs PyYAML, which is not installed", hint=_HINT) from None
    name = repr(str(path))
    try:
        entries = _load(where, name, path.read_bytes().decode("utf-8"))
    except InvalidSpec:
        raise
    except OSError as e:
        raise InvalidSpec(where, f"cannot read {name}: {type(e).__name__}: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise InvalidSpec(
            where, f"cannot read {name}: not UTF-8 text (byte {e.object[e.start]:#04x} at offset {e.start})"
        ) from None
    except (yaml.YAMLError, ValueError, OverflowError, TypeError) as e:  # ValueError: an integer of over 4,300 digits;
        # TypeError: an OrderedDict's pairs that are no pairs
        raise InvalidSpec(where, f"cannot read {name}: {_yaml_error(e)}") from None
    return entries


def _entry(where: str, entries: Mapping[str, Any], env_id: str, source: str, algorithm: str) -> dict[str, Any]:
    if env_id not in entries:
        ids = [str(k) for k in entries]
        close = difflib.get_close_matches(env_id, ids, n=3, cutoff=0.6)
        maybe = f"; did you mean {' or '.join(value_text(c) for c in close)}?" if close else ""
        fallback = (
            f" (rl-zoo3 itself falls back to its 'default' entry: ask for it by name, zoo_settings({algorithm!r}, "
            "'default'))"
            if "default" in ids
            else ""
        )
        raise InvalidSpec(where, f"{source} has no entry for {env_id!r}{maybe}{fallback}")
    entry = entries[env_id]
    if not isinstance(entry, Mapping):
        raise InvalidSpec(where, f"expected {source}'s entry {env_id!r} to be a mapping, got {value_text(entry)}")
    return dict(entry)


# -- values written as Python text (policy_kwargs, normalize) --------------------------------------------


def _names() -> dict[str, Any]:
    """The names rl-zoo3's files may use in a value written as Python (its ``eval`` scope, closed to these)."""
    from stable_baselines3.common.sb2_compat.rmsprop_tf_like import RMSpropTFLike

    return {"RMSpropTFLike": RMSpropTFLike}


def _torch_nn(attribute: str, where: str) -> type:
    from torch import nn

    value = getattr(nn, attribute, None)
    if not (isinstance(value, type) and issubclass(value, nn.Module)):
        raise InvalidSpec(where, f"nn.{attribute} is not a torch.nn module class")
    return value


def _value(node: ast.expr, where: str) -> Any:
    """The value of ``node``: literals, ``dict(...)``, ``nn.<Module>`` and the names of :func:`_names`; nothing else."""
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        operand = _value(node.operand, where)
        if isinstance(operand, (int, float)) and not isinstance(operand, bool):
            return -operand if isinstance(node.op, ast.USub) else operand
    elif isinstance(node, (ast.List, ast.Tuple)):
        items = [_value(e, where) for e in node.elts]
        return items if isinstance(node, ast.List) else tuple(items)
    elif isinstance(node, ast.Dict) and None not in node.keys:
        return _dict(((_value(k, where), _value(v, where)) for k, v in zip(node.keys, node.values) if k), where)
    elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict" and not node.args:
        if all(k.arg is not None for k in node.keywords):
            return {k.arg: _value(k.value, where) for k in node.keywords}
    elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "nn":
        return _torch_nn(node.attr, where)
    elif isinstance(node, ast.Name) and node.id in _names():
        return _names()[node.id]
    raise InvalidSpec(
        where,
        f"cannot evaluate {value_text(ast.unparse(node))}: a value here may be a literal, dict(...), nn.<Module class> "
        f"or {', '.join(_names())}",
    )


def _dict(items: Iterable[tuple[Any, Any]], where: str) -> dict[Any, Any]:
    """A dict literal's value, refusing a key a dict cannot hold (``{[1]: 2}``, ``{([1],): 2}``)."""
    value = {}
    for key, item in items:
        try:
            value[key] = item
        except TypeError:  # unhashable
            raise InvalidSpec(
                where, f"a dict key must be hashable (a number, text or tuple of them), got {value_text(key)}"
            ) from None
    return value


def _too_deep_text(tree: ast.AST) -> bool:
    """Whether ``tree`` nests deeper than :data:`_DEEPEST` nodes (walked without recursing: ``-`` 2,000 times)."""
    stack = [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        if depth > _DEEPEST:
            return True
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return False


def _from_text(key: str, text: str, where: str) -> Any:
    """``text`` (a zoo value written as Python) evaluated in the closed scope of :func:`_value`."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as e:
        raise InvalidSpec(where, f"{key}: cannot parse {value_text(text)}: {e.msg}") from None
    except RecursionError:  # Python's parser gives up on ``not`` 5,000 times
        tree = None
    if tree is None or _too_deep_text(tree):
        raise InvalidSpec(where, f"{key}: cannot evaluate {value_text(text)}: it nests deeper than {_DEEPEST} levels")
    return _value(tree.body, f"{where}, {key}")


# -- mapping an entry onto a spec ----------------------------------------------------------------


def _schedule(key: str, value: Any, where: str) -> Any:
    """``"lin_<x>"`` as a :class:`LinearSchedule`, as rl-zoo3 reads it; numbers as they are (SB3 takes constants)."""
    if not isinstance(value, str):
        return value
    kind, _, initial = value.partition("_")
    try:
        start = float(initial)
    except ValueError:
        start = None
    if kind != "lin" or start is None or not math.isfinite(start):
        raise InvalidSpec(
            where,
            f"{key}: expected a number or a schedule 'lin_<initial value>', a finite one, got {value_text(value)}",
        )
    return LinearSchedule(start)


def _normalize(value: Any, gamma: Any, where: str, not_taken: dict[str, str]) -> bool:
    """The spec's ``normalize`` for the zoo's, naming in ``not_taken`` what VecNormalize's defaults do differently."""
    options = _from_text("normalize", value, where) if isinstance(value, str) else value
    if isinstance(options, bool):
        options = {} if options else None
    if options is None:
        return False
    if not isinstance(options, Mapping):
        raise InvalidSpec(where, f"normalize: expected True, False or VecNormalize's options, got {value_text(value)}")
    wanted = dict(options)
    if gamma is not None:  # rl-zoo3 discounts normalized rewards by the algorithm's gamma, over any it was given
        wanted["gamma"] = gamma
    if not wanted.get("norm_reward", True):  # the discount only scales rewards: without them it changes nothing
        wanted.pop("gamma", None)
    differs = {k: v for k, v in wanted.items() if _VECNORMALIZE.get(k, object()) != v}
    if differs:
        said = ", ".join(f"{elide(str(k), MAX_VALUE)}={value_text(v)}" for k, v in differs.items())
        not_taken["normalize"] = (
            f"{said}: a spec's normalize=True is VecNormalize with its defaults "
            f"({', '.join(f'{k}={v!r}' for k, v in _VECNORMALIZE.items())})"
        )
    return True


def _callbacks(where: str, value: Any, not_taken: dict[str, str]) -> tuple[Any, ...]:
    """The entry's ``callback`` (a dotted class name, ``{name: kwargs}``, or a list of them, as rl-zoo3's
    ``get_callback_list`` reads it) as callback factories; each one that cannot be taken is named in ``not_taken``."""
    from stable_baselines3.common.callbacks import BaseCallback

    if value is None:
        return ()
    factories = []
    for i, item in enumerate(value if isinstance(value, list) else [value]):
        key = "callback" if not isinstance(value, list) else f"callback[{i}]"
        name: Any = item
        kwargs: Any = {}
        if isinstance(item, dict) and len(item) == 1:
            name, kwargs = next(iter(item.items()))
        if not isinstance(name, str) or "." not in name or not isinstance(kwargs, dict):
            not_taken[key] = f"{value_text(item)}: expected a class's dotted name, or {{name: keyword arguments}}"
            continue
        module, _, attribute = name.rpartition(".")
        try:
            found = getattr(importlib.import_module(module), attribute)
        except (ImportError, AttributeError) as e:
            not_taken[key] = f"{value_text(item)}: cannot import it ({type(e).__name__}: {elide(str(e), MAX_VALUE)})"
            continue
        if not (isinstance(found, type) and issubclass(found, BaseCallback)):
            not_taken[key] = f"{value_text(item)}: not a stable_baselines3 BaseCallback class"
            continue
        factories.append(functools.partial(found, **kwargs) if kwargs else found)
    return tuple(factories)


def _map(where: str, algorithm: str, entry: dict[str, Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """The entry's spec fields and what is not taken (rl-zoo3's ``_preprocess_hyperparams``, step by step)."""
    not_taken: dict[str, str] = {}
    entry = dict(entry)
    if "n_timesteps" not in entry:
        raise InvalidSpec(where, "the entry has no n_timesteps")
    timesteps = entry.pop("n_timesteps")
    fields: dict[str, Any] = {
        "timesteps": timesteps,
        "n_envs": entry.pop("n_envs", 1),
        "policy": entry.pop("policy", None),
        "normalize": _normalize(entry.pop("normalize", False), entry.get("gamma"), where, not_taken),
    }
    fields["callbacks"] = _callbacks(where, entry.pop("callback", None), not_taken)
    for key in SCHEDULED:
        if key in entry:
            entry[key] = _schedule(key, entry[key], where)
    if isinstance(entry.get("train_freq"), list):
        entry["train_freq"] = tuple(entry["train_freq"])
    if isinstance(entry.get("policy_kwargs"), str):
        entry["policy_kwargs"] = _from_text("policy_kwargs", entry["policy_kwargs"], where)
    known = hyperparameter_names(algorithm) or ()
    hyperparameters: dict[str, Any] = {}
    for key, value in entry.items():
        if key in _NOT_TAKEN:
            not_taken[key] = f"{value_text(value)}: {_NOT_TAKEN[key]}"
        elif key in known:
            hyperparameters[key] = value
        else:
            not_taken[key] = f"{value_text(value)}: {algorithm}'s constructor takes no {value_text(key)}"
    fields["hyperparameters"] = hyperparameters
    return fields, not_taken


def _is_timesteps(value: Any) -> bool:
    """A zoo's ``n_timesteps``: a whole number ``>= 1``, as an integer or a float (``!!float 1e6``), never a bool."""
    if isinstance(value, float):
        return value >= 1 and value.is_integer()
    return is_count(value)


def zoo_settings(algorithm: str | type, env_id: str, *, file: str | Path | None = None) -> ZooSettings:
    """rl-zoo3's tuned settings of ``algorithm`` for ``env_id``, as a spec's ``trainer`` and ``observation``.

    Unpack the result into a spec, and take its budget where you want the zoo's::

        zoo = sg.zoo_settings("PPO", "CartPole-v1")
        spec = sg.Spec(initial_env, tree, budget=sg.Budget(timesteps=zoo.timesteps), **zoo)

    Taken: ``callback`` (its classes, with their keyword arguments, as the trainer's ``callbacks``; one that cannot
    be imported, or is no SB3 callback, is named below), ``policy``, ``n_envs``,
    ``normalize`` (``True``, or VecNormalize's options: see below),
    ``n_timesteps`` (as :attr:`ZooSettings.timesteps`), and every key the algorithm's constructor takes as a
    hyperparameter, as rl-zoo3 preprocesses it: ``"lin_<x>"`` of ``learning_rate``, ``clip_range``,
    ``clip_range_vf`` and ``delta_std`` as a :class:`LinearSchedule`, a ``train_freq`` list as a tuple,
    ``policy_kwargs`` written as Python evaluated in a closed scope (literals, ``dict(...)``, ``nn.<Module class>``
    from ``torch.nn``, and ``RMSpropTFLike``; anything else is refused).

    Not taken, each named in one :class:`~specguard.error.SpecWarning` and in :attr:`ZooSettings.not_taken`:
    the keys rl-zoo3 reads itself (``env_wrapper``, ``vec_env_wrapper``, ``frame_stack``,
    ``env_kwargs``, ``monitor_kwargs``, ``noise_type`` and ``noise_std``, ``replay_buffer_class`` and
    ``replay_buffer_kwargs``), any other key the constructor does not take, and VecNormalize options other than its
    defaults: rl-zoo3 discounts normalized rewards by the algorithm's ``gamma`` (a spec's ``normalize=True`` by
    0.99) and may normalize only observations or only rewards (a spec's, both): ``normalize`` is then still
    ``True``, and the difference is named.

    Args:
        algorithm: a name of :data:`ZOO_FILES` (or an alias or class :func:`resolve_algorithm` reads as one).
        env_id: the entry's env id, as the file writes it (``"CartPole-v1"``; ``"default"`` and ``"atari"`` are
            entries too; rl-zoo3's fallback to ``"default"`` is not made for you).
        file: a YAML file in rl-zoo3's format (your own tuned settings) instead of rl-zoo3's file for the algorithm.

    Raises:
        InvalidSpec: rl-zoo3 (or PyYAML) is not installed, the algorithm has no zoo file, the env id no entry (with
            close matches), or a value cannot be read; one line, naming it.
    """
    where = f"zoo_settings({algorithm!r}, {env_id!r})"
    resolved = resolve_algorithm(f"{where}.algorithm", algorithm)
    env_id = check_text(where, "env_id", env_id)
    if not isinstance(resolved, str) or resolved not in ZOO_FILES:
        name = resolved if isinstance(resolved, str) else f"{resolved.__module__}:{resolved.__qualname__}"
        raise InvalidSpec(where, f"rl-zoo3 has no settings for {name}; it has files for {', '.join(ZOO_FILES)}")
    algorithm_class(resolved, where)  # an sb3-contrib algorithm without sb3-contrib: what to install
    if file is None:
        path, source = _zoo_file(where, ZOO_FILES[resolved])
    else:
        path = Path(file)
        source = str(path)
    entry = _entry(where, _read(where, path), env_id, source, resolved)
    fields, not_taken = _map(f"{where}, {source}", resolved, entry)
    policy = fields["policy"] if fields["policy"] is not None else default_policy(resolved)
    dict_observation = dict_policy(policy)  # the zoo's env gave a Dict
    policy = check_policy(f"{where}.policy", resolved, policy)  # the zoo's env's own observation: any of its names
    timesteps, n_envs = fields["timesteps"], fields["n_envs"]
    if not _is_timesteps(timesteps):
        raise InvalidSpec(
            where, f"expected n_timesteps to be a whole number of steps >= 1, got {value_text(timesteps)}"
        )
    if not (isinstance(n_envs, int) and not isinstance(n_envs, bool) and n_envs >= 1):
        raise InvalidSpec(where, f"expected n_envs to be a count, got {value_text(n_envs)}")
    if not_taken:
        lines = "\n".join(f"  {elide(str(key), MAX_VALUE)}: {reason}" for key, reason in not_taken.items())
        warnings.warn(
            f"{where}: {source}: not taken as written (a spec cannot say them):\n{lines}",
            SpecWarning,
            stacklevel=user_stacklevel(),
        )
    trainer = SB3(
        algorithm=resolved,
        hyperparameters=fields["hyperparameters"],
        policy=policy,
        n_envs=n_envs,
        normalize=fields["normalize"],
        callbacks=fields["callbacks"],
    )
    return ZooSettings(
        trainer=trainer,
        env_id=env_id,
        timesteps=int(timesteps),
        observation="features+env" if dict_observation else "features",
        not_taken=not_taken,
        source=source,
    )
