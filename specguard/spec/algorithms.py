"""What specguard knows of the algorithms: which a spec can name, their policies and hyperparameters, loading.

An SB3 trainer's algorithm (:class:`specguard.spec.trainers.SB3`) is stable-baselines3's by name (``PPO``,
``A2C``, ``DQN``, ``SAC``, ``TD3``, ``DDPG``), sb3-contrib's by name (``ARS``, ``CrossQ``,
``MaskablePPO``, ``QRDQN`` (also ``QR-DQN``), ``RecurrentPPO``, ``TQC``,
``TRPO``; the ``contrib`` extra installs it), or any subclass of SB3's
``BaseAlgorithm``, given as a class or as ``"module:Class"``
(:func:`resolve_algorithm`). A class that is one of the named ones is its name.

Example:
    >>> collect_steps("PPO", {"n_steps": 1024}), collection_unit("PPO"), collect_parameter("DQN")
    (1024, 'rollouts', 'train_freq')
    >>> "Discrete" in ALGORITHMS["DQN"], "Box" in ALGORITHMS["DQN"]
    (True, False)
    >>> resolve_algorithm("Spec 'x'", "QR-DQN"), default_policy("RecurrentPPO")
    ('QRDQN', 'MlpLstmPolicy')
"""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from specguard.error import InvalidSpec
from specguard.utils.imports import ImportFailed, import_module
from specguard.utils.text import MAX_SHOWN, elide, shown, value_text
from specguard.validation import is_count

__all__ = [
    "ALGORITHMS",
    "CONTRIB",
    "SB3",
    "algorithm_class",
    "algorithm_name",
    "check_hyperparameters",
    "check_policy",
    "collect_parameter",
    "collect_steps",
    "collection_unit",
    "default_policy",
    "dict_policy",
    "hyperparameter_names",
    "load_saved",
    "resolve_algorithm",
    "takes_action_masks",
]

_ALL = ("Box", "Discrete", "MultiDiscrete", "MultiBinary")
SB3 = ("PPO", "A2C", "DQN", "SAC", "TD3", "DDPG")
"""stable-baselines3's algorithms, by name."""
CONTRIB = ("ARS", "CrossQ", "MaskablePPO", "QRDQN", "RecurrentPPO", "TQC", "TRPO")
"""sb3-contrib's algorithms, by name (its class names)."""
_ALIASES = {"QR-DQN": "QRDQN"}  # the paper's spelling; unambiguous

# The named algorithms and the action spaces each can act in (another class: SB3's own check, when it is built).
ALGORITHMS: dict[str, tuple[str, ...]] = {
    "PPO": _ALL,
    "A2C": _ALL,
    "DQN": ("Discrete",),
    "SAC": ("Box",),
    "TD3": ("Box",),
    "DDPG": ("Box",),
    "ARS": ("Box", "Discrete"),
    "CrossQ": ("Box",),
    "MaskablePPO": ("Discrete", "MultiDiscrete", "MultiBinary"),
    "QRDQN": ("Discrete",),
    "RecurrentPPO": _ALL,
    "TQC": ("Box",),
    "TRPO": _ALL,
}

# Keyword arguments specguard passes itself: a hyperparameter of that name is refused, with what to do instead.
_SET_BY_SPECGUARD = {
    "policy": "the policy is a field of the trainer: sg.SB3(..., policy=...)",
    "env": "the env is the spec's constructed env (Spec.make_env)",
    "seed": "each run's seed is set by specguard (Budget's seeds)",
    "device": "specguard trains on the CPU",
    "verbose": "specguard reports progress itself",
}


_IMPORT_HINT = "'module:Class' imports module (an absolute name, importable here) and takes its Class"


def _accepted() -> str:
    return f"{', '.join([*SB3, *CONTRIB])}, a BaseAlgorithm subclass or 'module:Class'"


def _base_algorithm() -> type:
    from stable_baselines3.common.base_class import BaseAlgorithm

    return BaseAlgorithm


def _named_class(name: str, where: str) -> type:
    if name in SB3:
        import stable_baselines3

        return getattr(stable_baselines3, name)  # type: ignore[no-any-return]
    try:
        import sb3_contrib
    except ImportError:
        raise InvalidSpec(
            where,
            f"{name} is an sb3-contrib algorithm, and sb3-contrib is not installed",
            hint="pip install 'specguard[contrib]'",
        ) from None
    return getattr(sb3_contrib, name)  # type: ignore[no-any-return]


def _imported(where: str, text: str) -> Any:
    module_name, _, qualname = text.partition(":")
    try:
        obj: Any = import_module(module_name)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportFailed, AttributeError) as e:
        why = str(e) if isinstance(e, ImportFailed) else f"AttributeError: {elide(str(e), MAX_SHOWN)}"
        raise InvalidSpec(where, f"cannot import algorithm {shown(text)}: {why}", hint=_IMPORT_HINT) from None
    return obj


def resolve_algorithm(where: str, value: object) -> str | type:
    """The algorithm ``value`` names: a name of :data:`ALGORITHMS` (an alias or a named class as its name), or the
    ``BaseAlgorithm`` subclass it is or names (``"module:Class"``).

    Raises:
        InvalidSpec: an unknown name, or an import or class that is no ``BaseAlgorithm`` subclass (one line, naming
            it and what is accepted).
    """
    if isinstance(value, str) and ":" not in value:
        name = _ALIASES.get(value, value)
        if name in ALGORITHMS:
            return name
        raise InvalidSpec(where, f"unknown algorithm {shown(value)}; expected one of {_accepted()}")
    cls = _imported(where, value) if isinstance(value, str) else value
    if not (isinstance(cls, type) and issubclass(cls, _base_algorithm())):
        raise InvalidSpec(where, f"expected algorithm to be one of {_accepted()}, got {shown(value)}")
    top = cls.__module__.split(".", 1)[0]
    named = top in ("stable_baselines3", "sb3_contrib") and cls.__name__ in ALGORITHMS
    return cls.__name__ if named and _named_class(cls.__name__, where) is cls else cls


def algorithm_class(algorithm: str | type, where: str = "algorithm") -> Any:
    """The class of ``algorithm`` (a :func:`resolve_algorithm` value; a name imported here, on first use)."""
    return _named_class(algorithm, where) if isinstance(algorithm, str) else algorithm


def algorithm_name(algorithm: str | type) -> str:
    """``algorithm`` in words: its name, or ``module:qualname`` for any other class."""
    return algorithm if isinstance(algorithm, str) else f"{algorithm.__module__}:{algorithm.__qualname__}"


# -- policies -----------------------------------------------------------------------------


_DICT_PREFIX = "MultiInput"  # SB3's policy names for a Dict observation: MultiInputPolicy, MultiInputLstmPolicy
_IMAGE_PREFIX = "Cnn"  # SB3's policy names for an image Box: CnnPolicy, CnnLstmPolicy

# What the agent sees, by Spec.observation, in words; a policy name fits it when it takes it (None: the env's own).
_SEEN = {
    "features": "a flat Box of numbers, not an image (observation='features')",
    "features+env": "a Dict (observation='features+env')",
}


def dict_policy(policy: object) -> bool:
    """``policy`` is named for a ``Dict`` observation (SB3's ``MultiInputPolicy``, ``MultiInputLstmPolicy``, ...)."""
    return isinstance(policy, str) and policy.startswith(_DICT_PREFIX)


def _takes(name: str, observation: str) -> bool:
    """The policy ``name`` takes what the agent sees: a Dict policy a Dict, any other but an image one a flat Box."""
    if observation == "features+env":
        return dict_policy(name)
    return not dict_policy(name) and not name.startswith(_IMAGE_PREFIX)


def default_policy(algorithm: str | type, *, dict_observation: bool = False) -> str:
    """The policy a spec gets unless it names one: ``MlpPolicy``, or the algorithm's only other MLP policy
    (RecurrentPPO's ``MlpLstmPolicy``); for a ``Dict`` observation, ``MultiInputPolicy`` (RecurrentPPO's
    ``MultiInputLstmPolicy``)."""
    aliases = list(getattr(algorithm_class(algorithm), "policy_aliases", {}))
    prefix, plain = (_DICT_PREFIX, "MultiInputPolicy") if dict_observation else ("Mlp", "MlpPolicy")
    if plain in aliases:
        return plain
    named = [a for a in aliases if a.startswith(prefix)]
    return named[0] if len(named) == 1 else plain


def check_policy(where: str, algorithm: str | type, policy: object, observation: str | None = None) -> str | type:
    """``policy`` if ``algorithm`` can take it: one of its policy names, or a subclass of one of its policy classes.

    A name fits what the agent sees (``observation``, a ``Spec.observation``): a ``MultiInput`` policy a ``Dict``
    (``"features+env"``), one neither for a ``Dict`` nor for images (``Cnn``) a flat ``Box`` (``"features"``);
    ``None`` (the initial env's own, unknown before it is built): any of the algorithm's names. A class is
    SB3's to check against the observation.

    Raises:
        InvalidSpec: naming the policy, the algorithm and its policy names (or classes); or the observation it does
            not fit, with the algorithm's policies that do.
    """
    from stable_baselines3.common.policies import BasePolicy

    named = dict(getattr(algorithm_class(algorithm, where), "policy_aliases", {}))
    if isinstance(policy, type) and issubclass(policy, BasePolicy):
        return _check_policy_class(where, algorithm, policy, tuple(named.values()))
    aliases = list(named)
    fitting = aliases if observation is None else [a for a in aliases if _takes(a, observation)]
    if isinstance(policy, str) and policy in fitting:
        return policy
    if isinstance(policy, str) and observation is not None and (policy in aliases or not fitting):
        which = ", ".join(fitting) or f"none: {algorithm_name(algorithm)} has no policy for it"
        hint = _IMAGE_HINT if policy.startswith(_IMAGE_PREFIX) and observation == "features" else None
        raise InvalidSpec(
            where,
            f"the agent's observation is {_SEEN[observation]}, which {shown(policy)} does not take; "
            f"one that does: {which}",
            hint=hint,
        )
    raise InvalidSpec(
        where,
        f"expected policy to be one of {', '.join(aliases)} ({algorithm_name(algorithm)}'s policy names) "
        f"or a BasePolicy subclass, got {value_text(policy)}",
    )


_IMAGE_HINT = (
    "an image policy reads the env's image: give the agent the env's own observation beside the features "
    "with observation='features+env' (MultiInputPolicy reads an image part with a CNN)"
)


def _check_policy_class(where: str, algorithm: str | type, policy: type, classes: tuple[type, ...]) -> type:
    """``policy`` if it is (a subclass of) one of ``algorithm``'s policy classes, or the algorithm names none."""
    if not classes or issubclass(policy, classes):
        return policy
    names = ", ".join(dict.fromkeys(c.__name__ for c in classes))
    raise InvalidSpec(
        where,
        f"{policy.__qualname__} is no policy of {algorithm_name(algorithm)}: expected a subclass of one of its "
        f"policy classes ({names})",
        hint="derive your policy from the algorithm's own (SB3's custom policies do), or give a policy name",
    )


# -- hyperparameters ---------------------------------------------------------------------------


def hyperparameter_names(algorithm: str | type) -> tuple[str, ...] | None:
    """The keyword arguments ``algorithm``'s constructor takes, with those its ``**kwargs`` passes on to its base
    classes (as SB3 subclasses do); ``None`` where they cannot be known (``**kwargs`` all the way up).

    Leaves out private names (``_init_setup_model``) and the arguments specguard passes itself.
    """
    names: list[str] = []
    for klass in algorithm_class(algorithm).__mro__:
        init = vars(klass).get("__init__")
        if init is None:
            continue
        if klass is object:
            return None
        params = inspect.signature(init).parameters.values()
        names += [
            p.name
            for p in params
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
            and p.name not in ("self", *_SET_BY_SPECGUARD)
            and not p.name.startswith("_")
        ]
        if not any(p.kind is p.VAR_KEYWORD for p in params):
            return tuple(dict.fromkeys(names))
    return None


def check_hyperparameters(where: str, algorithm: str | type, hyperparameters: Mapping[Any, Any]) -> None:
    """Refuse hyperparameters ``algorithm``'s constructor does not take, before anything trains; their values are
    SB3's to check.

    Raises:
        InvalidSpec: one line per name refused: a name specguard sets itself (with what to do instead), or an
            unknown one (with the algorithm and close matches; the hint lists every name it takes).
    """
    known = hyperparameter_names(algorithm)
    name = algorithm_name(algorithm)
    lines = []
    for key in hyperparameters:
        if not isinstance(key, str):
            lines.append(f"expected hyperparameter names to be strings, got {key!r}")
        elif key in _SET_BY_SPECGUARD:
            lines.append(f"{key!r} is not a hyperparameter here: {_SET_BY_SPECGUARD[key]}")
        elif known is not None and key not in known:
            close = difflib.get_close_matches(key, known, n=3)
            maybe = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            lines.append(f"{name} takes no hyperparameter {key!r}{maybe}")
    if lines:
        hint = "use sg.SB3(..., policy=...)" if "policy" in hyperparameters else None
        if hint is None and known is not None:
            hint = f"{name} takes {', '.join(known)}"
        raise InvalidSpec(where, "\n".join(lines), hint=hint)


# -- collections ---------------------------------------------------------------------------------


def _collection(algorithm: str | type) -> tuple[str, int] | None:
    """The hyperparameter that sets one collection's size and its default: ``n_steps`` (on-policy algorithms),
    ``train_freq`` (off-policy), or ``None`` (others: stable-baselines3 counts episodes)."""
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    cls = algorithm_class(algorithm)
    if issubclass(cls, OnPolicyAlgorithm):
        key = "n_steps"
    elif issubclass(cls, OffPolicyAlgorithm):
        key = "train_freq"
    else:
        return None
    for klass in cls.__mro__:
        init = vars(klass).get("__init__")
        param = inspect.signature(init).parameters.get(key) if init is not None else None
        if param is not None and param.default is not param.empty:
            default = param.default
            return key, int(default) if is_count(default) else 1
    return key, 1


def collect_steps(algorithm: str | type, hyperparameters: Mapping[str, Any]) -> int:
    """Steps per env that one collection takes (1 where stable-baselines3 counts episodes instead)."""
    found = _collection(algorithm)
    if found is None:
        return 1
    key, default = found
    value = hyperparameters.get(key, default)
    if key == "train_freq" and isinstance(value, (tuple, list)):
        value = value[0] if len(value) == 2 and str(value[1]) == "step" else 1
    if not is_count(value):
        return 1  # the algorithm rejects it when training, with its own message
    return int(value)


def collection_unit(algorithm: str | type) -> str:
    """What one collection of ``algorithm`` is called: ``"rollouts"`` (on-policy) or ``"collections"``."""
    found = _collection(algorithm)
    return "rollouts" if found is not None and found[0] == "n_steps" else "collections"


def collect_parameter(algorithm: str | type) -> str:
    """The hyperparameter that sets one collection's size: ``"n_steps"`` (on-policy), ``"train_freq"``
    (off-policy), else ``"n_envs"`` (one step per env)."""
    found = _collection(algorithm)
    return found[0] if found is not None else "n_envs"


# -- acting and loading -----------------------------------------------------------------------------


def takes_action_masks(model_or_class: Any) -> bool:
    """The algorithm's ``predict`` takes ``action_masks`` (sb3-contrib's MaskablePPO): it acts on the env's masks."""
    predict = getattr(model_or_class, "predict", None)
    return predict is not None and "action_masks" in inspect.signature(predict).parameters


def load_saved(algorithm: str | type, path: Path | str) -> Any:
    """A saved model of ``algorithm`` (SB3's zip at ``path``), loaded on the CPU; a result's trained run is
    :func:`specguard.load_model`'s."""
    return algorithm_class(algorithm).load(path, device="cpu")
