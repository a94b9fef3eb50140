"""Where an agent trained elsewhere comes from, loaded as one :class:`~specguard.agents.agent.Agent` by
:func:`load_agent`.

Four sources, told apart once, when the agent is loaded:

1. a stable-baselines3 or sb3-contrib ``.zip``: the algorithm is read from the file (its policy class, the
   hyperparameters it stores, and the names rl-zoo3 and the Hub give its folders and files), or named with
   ``algorithm=``; a ``vecnormalize.pkl`` beside it (rl-zoo3's, under ``<env_id>/``; the Hub's
   ``vec_normalize.pkl``) normalizes its observations;
2. a folder as rl-zoo3 (``<algo>/<env_id>_<n>/``: ``<env_id>.zip``, ``best_model.zip``, ``<env_id>/config.yml``,
   ``args.yml``, ``vecnormalize.pkl``) or the Hugging Face Hub (``<algo>-<env_id>.zip``, ``config.yml``,
   ``env_kwargs.yml``, ``vec_normalize.pkl``) lays it out on disk: its one model zip (rl-zoo3's final model,
   ``<env_id>.zip``, where there are others, as ``rl_zoo3.enjoy`` loads by default), and what its files say the
   env was made with (:attr:`Agent.env_kwargs`) and the agent trained with (:attr:`Agent.config`);
3. an object with SB3's ``predict(obs, state=None, episode_start=None, deterministic=True)``: a model in memory,
   whose recurrent state is carried from step to step (:class:`specguard.evaluation.policy.Policy`);
4. a callable ``obs -> action`` for one observation (CleanRL's, TorchRL's, a hand-written rule).

A text ``FILE.py::NAME`` names the object ``NAME`` of a Python file, loaded as the object itself is (a callable, a
model in memory, a path): how a command line names a hand-written policy.

Every bad input is one :class:`~specguard.error.AgentError` naming the path or the agent.

Example:
    >>> agent = load_agent(lambda obs: 0)
    >>> agent.name, agent.observation_space, len(agent.identity)
    ('<lambda>', None, 64)
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from specguard.agents.agent import Agent, observation_kind
from specguard.agents.decode import read_data, read_statistics
from specguard.agents.wrappers import zoo_wrappers
from specguard.cache.store import file_sha256
from specguard.cache.weights import normalizer_digest, parts_digest, weights_digest
from specguard.error import AgentError, InvalidSpec, SpecError
from specguard.evaluation.policy import Policy, normalizer_of
from specguard.spec.algorithms import ALGORITHMS, CONTRIB, SB3, algorithm_class, hyperparameter_names
from specguard.spec.algorithms import resolve_algorithm as _resolve
from specguard.spec.loading import import_file
from specguard.spec.zoo import read_zoo_file
from specguard.utils.text import MAX_SHOWN, elide, function_text, shown

__all__ = ["STATISTICS", "load_agent", "named_object"]

STATISTICS = ("vecnormalize.pkl", "vec_normalize.pkl")
"""The names a model's ``VecNormalize`` statistics have beside it: rl-zoo3's and SB3's, then the Hub's."""

_ZOO_NAMES = {"ppo_lstm": "RecurrentPPO", "qr-dqn": "QRDQN"}  # rl-zoo3's algorithm names that are not ours lowered


def _zero(_: float) -> float:
    return 0.0


# What rl_zoo3.enjoy replaces on loading: schedules pickled by another Python may not unpickle, and acting needs none.
_CUSTOM_OBJECTS = {"learning_rate": 0.0, "lr_schedule": _zero, "clip_range": _zero, "exploration_schedule": _zero}


def load_agent(
    agent: Any,
    *,
    algorithm: str | type | None = None,
    normalizer: Any = None,
    deterministic: bool = True,
    batch: bool = False,
    trust: bool = False,
) -> Agent:
    """``agent`` as an :class:`~specguard.agents.agent.Agent`, from wherever it was trained (see the module).

    Args:
        agent: a path to a ``.zip`` or a folder (``str`` or ``PathLike``), an object with SB3's ``predict``, or a
            callable ``obs -> action``.
        algorithm: the zip's algorithm (a name of :data:`specguard.spec.algorithms.ALGORITHMS`, a ``BaseAlgorithm``
            subclass or ``"module:Class"``); default: read from the file.
        normalizer: ``VecNormalize`` statistics (the object, or the path of its ``.pkl``) applied to every
            observation; default: the ``vecnormalize.pkl`` beside a zip, a model's own training env's.
        deterministic: a model's deterministic action, or a sampled one.
        batch: the agent takes a batch of observations (one row per env), as
            :class:`~specguard.evaluation.policy.Policy` does; :meth:`Agent.batched` turns it.
        trust: run the code an agent's files may hold. By default a zip's ``data`` and a ``vecnormalize.pkl`` are
            decoded without running any (:mod:`specguard.agents.decode`: arrays, spaces, SB3's and sb3-contrib's own
            classes), and a file that needs more is refused naming the field; ``trust=True`` unpickles them as SB3's
            ``load`` does, for files you made or trust. The weights are read with ``torch.load(weights_only=True)``
            either way. (A ``FILE.py::NAME`` is a Python file: importing it runs it, as importing a spec file does.)

    Raises:
        AgentError: one line naming what cannot be loaded and why (see :class:`~specguard.error.AgentError`).
    """
    if isinstance(agent, str) and "::" in agent:
        return load_agent(
            _named(agent),
            algorithm=algorithm,
            normalizer=normalizer,
            deterministic=deterministic,
            batch=batch,
            trust=trust,
        )
    if isinstance(agent, (str, os.PathLike)):
        return _from_path(Path(agent), algorithm, normalizer, deterministic=deterministic, batch=batch, trust=trust)
    if algorithm is not None:
        raise AgentError(
            f"algorithm={shown(algorithm)} names a saved zip's algorithm, and the agent {shown(agent)} is no path",
            hint="leave algorithm out for a model in memory or a callable",
        )
    if callable(getattr(agent, "predict", None)):
        return _from_model(agent, normalizer, deterministic=deterministic, batch=batch, trust=trust)
    if callable(agent):
        return _from_callable(agent, normalizer, batch=batch, trust=trust)
    raise AgentError(f"cannot load an agent from {shown(agent)} (a {type(agent).__name__})")


def _named(target: str) -> Any:
    """The object ``NAME`` of the Python file ``FILE.py::NAME`` (imported as spec files are)."""
    return named_object(target, "agent", example="policies.py::lean")


def named_object(target: str, what: str, *, example: str) -> Any:
    """The object ``NAME`` of the Python file ``FILE.py::NAME`` (imported as spec files are), ``what`` it is for (an
    agent, a ``wrap``), as a command line names a Python object.

    Raises:
        AgentError: one line: the file cannot be imported, defines no such name, or names another ``FILE.py::NAME``.
    """
    path, _, name = target.partition("::")
    try:
        module = import_file(Path(path))
    except SpecError as e:
        raise AgentError(f"{what} {target!r}: {e}", hint=None) from None
    if not name or not hasattr(module, name):
        defined = [k for k, v in vars(module).items() if not k.startswith("_") and callable(v)]
        raise AgentError(
            f"{what} {target!r}: {path} defines nothing named {name!r}; its callables: {', '.join(defined) or 'none'}",
            hint=f"name an object defined in the file, e.g. {example}",
        )
    found = getattr(module, name)
    if isinstance(found, str) and "::" in found:  # a name for another name: followed, it may lead back to itself
        raise AgentError(
            f"{what} {target!r}: {name} is the text {found!r}, another FILE.py::NAME",
            hint="name the object itself, not a name for it",
        )
    return found


# -- a model in memory, a callable ---------------------------------------------------------------------------


def _from_model(model: Any, normalizer: Any, *, deterministic: bool, batch: bool, trust: bool) -> Agent:
    from stable_baselines3.common.base_class import BaseAlgorithm

    name = type(model).__name__
    observation_space = getattr(model, "observation_space", None)
    norm = normalizer_of(model, _statistics(f"agent {name!r}", normalizer, observation_space, trust=trust))
    sb3 = isinstance(model, BaseAlgorithm)
    return Agent(
        Policy(model, norm, deterministic=deterministic, batch=batch),
        name=name,
        identity=lambda: weights_digest(model, norm, name=name),
        observation_space=observation_space,
        action_space=getattr(model, "action_space", None),
        normalizer=norm,
        batch=batch,
        check_actions=not sb3,  # an SB3 model's actions are its action space's
        model=model,
        algorithm=type(model) if sb3 else None,
    )


def _from_callable(fn: Callable[[Any], Any], normalizer: Any, *, batch: bool, trust: bool) -> Agent:
    name = function_text(fn)
    norm = _statistics(f"agent {name!r}", normalizer, None, trust=trust)
    return Agent(
        _torch_acting(fn),
        name=name,
        identity=lambda: weights_digest(fn, norm, name=name, kind="callable"),
        normalizer=norm,
        batch=batch,
    )


def _torch_acting(fn: Callable[[Any], Any]) -> Callable[[Any], Any]:
    """``fn`` acting as a policy gives actions: a torch module (a CleanRL or TorchRL actor) is asked without
    gradients, on the observation as a tensor; a tensor it returns is an array, and of a tuple (TorchRL's
    ``out_keys``, ``(action, log_prob, ...)``) or a mapping with an ``"action"`` key, the action is taken."""
    import torch

    def action_of(out: Any) -> Any:
        if isinstance(out, Mapping) and "action" in out:
            out = out["action"]
        elif isinstance(out, tuple) and out and isinstance(out[0], torch.Tensor):
            out = out[0]
        return out.detach().cpu().numpy() if isinstance(out, torch.Tensor) else out

    if not isinstance(fn, torch.nn.Module):
        return lambda obs: action_of(fn(obs))

    def act(obs: Any) -> Any:
        with torch.no_grad():
            x = obs if isinstance(obs, Mapping) else torch.as_tensor(np.asarray(obs), dtype=torch.float32)
            return action_of(fn(x))

    return act


# -- VecNormalize statistics ---------------------------------------------------------------------------------------


def _statistics(where: str, source: Any, observation_space: Any, *, trust: bool) -> Any:
    """The ``VecNormalize`` statistics ``source`` is or holds (a path to their pickle, decoded by
    :func:`~specguard.agents.decode.read_statistics`), checked against the observations the agent reads; ``None``:
    none."""
    from stable_baselines3.common.vec_env import VecNormalize

    if source is None:
        return None
    norm = source
    if isinstance(source, (str, os.PathLike)):
        where = repr(str(source))
        norm = read_statistics(Path(source), trust=trust)
    if not isinstance(norm, VecNormalize):
        raise AgentError(f"{where}: expected VecNormalize statistics, got {shown(norm)} (a {type(norm).__name__})")
    if observation_space is not None and observation_kind(norm.observation_space) != observation_kind(
        observation_space
    ):
        raise AgentError(
            f"{where}: VecNormalize statistics of observations {norm.observation_space}, and the model reads "
            f"{observation_space}",
            hint="use the vecnormalize.pkl saved with this model (rl-zoo3: <env_id>/vecnormalize.pkl)",
        )
    norm.training, norm.norm_reward = False, False  # as rl_zoo3.enjoy: the statistics stay as they were saved
    return norm


def _why(e: BaseException) -> str:
    text = str(e).strip()
    return f"{type(e).__name__}: {elide(text.splitlines()[0], MAX_SHOWN)}" if text else type(e).__name__


# -- a path: a zip or a folder ---------------------------------------------------------------------------------


def _from_path(path: Path, algorithm: Any, normalizer: Any, *, deterministic: bool, batch: bool, trust: bool) -> Agent:
    if not path.exists():
        hub = str(path).count("/") == 1 and not str(path).startswith((".", "/")) and path.suffix != ".zip"
        raise AgentError(
            f"{str(path)!r}: no such file or folder",
            hint=f"a Hugging Face Hub repo id? specguard downloads nothing: download it first (huggingface-cli "
            f"download {path} --local-dir DIR, or rl_zoo3.load_from_hub) and give the folder"
            if hub
            else None,
        )
    if not path.is_dir() and not path.is_file():  # a named pipe, a device: opening it may block forever
        raise AgentError(f"{str(path)!r}: not a regular file or a folder", hint=None)
    model_zip = _model_zip(path) if path.is_dir() else path
    folder = model_zip.parent
    data, custom = _data(model_zip, trust=trust)
    settings = _settings_folder(folder, model_zip)
    config = _yaml_mapping(settings / "config.yml")
    args = _yaml_mapping(settings / "args.yml")
    cls = _algorithm(model_zip, data, algorithm, hints=[str(args.get("algo", "")), *_path_words(model_zip)])
    stats = normalizer
    if stats is None:
        # the zip's own statistics beside it first, then its rl-zoo3 run's
        stats = next((p for d in (folder, settings) for p in (d / n for n in STATISTICS) if p.is_file()), None)
    wrappers = zoo_wrappers(config, repr(str(settings / "config.yml")), trust=trust)
    stats_file = Path(stats) if isinstance(stats, (str, os.PathLike)) else None
    if wrappers is not None and wrappers.frame_stack is not None and stats is not None:
        # rl-zoo3 normalizes each env's frames, then stacks them: the statistics are of one frame, applied before
        norm = _statistics(repr(str(model_zip)), stats, None, trust=trust)
        _check_stacked(model_zip, norm, wrappers.stacked_space(norm.observation_space), data["observation_space"])
        wrappers, norm = wrappers.normalized(norm, stats_file.name if stats_file else "its VecNormalize"), None
    else:
        norm = _statistics(repr(str(model_zip)), stats, data["observation_space"], trust=trust)
    try:  # every serialized field is in custom: SB3 unpickles none of them
        model = cls.load(model_zip, device="cpu", custom_objects=custom)
    except Exception as e:
        raise AgentError(f"{str(model_zip)!r}: {cls.__name__} cannot load it: {_why(e)}") from e
    return Agent(
        Policy(model, norm, deterministic=deterministic, batch=batch),
        # an rl-zoo3 run's zips share their names (<env_id>.zip in <env_id>_1/, _2/, ...): its folder tells them apart
        name=f"{cls.__name__} ({model_zip.name if settings == folder else f'{folder.name}/{model_zip.name}'})",
        identity=lambda: parts_digest(
            [
                ("zip", file_sha256(model_zip)),
                ("normalizer", file_sha256(stats_file) if stats_file is not None else normalizer_digest(norm)),
                ("deterministic", deterministic),
                # the config's wrappers change what it sees: part of what it computes (none: as before)
                *([("wrappers", wrappers.identity())] if wrappers is not None else []),
            ]
        ),
        observation_space=model.observation_space,
        action_space=model.action_space,
        normalizer=norm,
        batch=batch,
        check_actions=False,
        model=model,
        algorithm=cls,
        path=model_zip,
        env_kwargs=_env_kwargs(settings, config, args),
        config=config,
        wrappers=wrappers,
        normalizer_source=str(stats_file) if stats_file is not None else None,
        env_id=args["env"] if isinstance(args.get("env"), str) else None,
    )


def _check_stacked(model_zip: Path, norm: Any, stacked: Any, reads: Any) -> None:
    """Refuse frame statistics that, stacked, are not what the model reads."""
    if observation_kind(stacked) != observation_kind(reads):
        raise AgentError(
            f"{str(model_zip)!r}: VecNormalize statistics of frames {norm.observation_space}, stacked {stacked}, and "
            f"the model reads {reads}",
            hint="use the vecnormalize.pkl saved with this model (rl-zoo3: <env_id>/vecnormalize.pkl)",
        )


def _is_model(path: Path) -> bool:
    """``path`` is a zip that holds SB3's ``data`` (a model; rl-zoo3's ``train_eval_metrics.zip`` is not); a named
    pipe called ``*.zip`` is none (never opened: it would block)."""
    if not path.is_file():
        return False
    try:
        with zipfile.ZipFile(path) as z:
            return "data" in z.namelist()
    except (zipfile.BadZipFile, OSError):
        return False


def _model_zip(folder: Path) -> Path:
    """The one model zip of ``folder``: rl-zoo3's final model ``<env_id>.zip`` beside its ``<env_id>/`` settings,
    else the only one."""
    zips = [p for p in sorted(folder.glob("*.zip")) if _is_model(p)]
    settings = _settings_folder(folder)
    final = folder / f"{settings.name}.zip"
    if settings != folder and final in zips:
        return final
    if len(zips) == 1:
        return zips[0]
    if zips:
        names = ", ".join(p.name for p in zips)
        raise AgentError(
            f"{str(folder)!r} holds {len(zips)} models ({names}): which is to be judged?",
            hint="give the path of the model's zip",
        )
    below = [*sorted(folder.glob("*/*.zip")), *sorted(folder.glob("*/*/*.zip"))]  # a Hub folder's, rl-zoo3's
    found = [str(p.relative_to(folder)) for p in below if _is_model(p)][:3]
    raise AgentError(
        f"{str(folder)!r} holds no stable-baselines3 model (a .zip holding 'data')",
        hint=f"its subfolders hold {', '.join(found)}: give one's path" if found else None,
    )


def _data(model_zip: Path, *, trust: bool) -> tuple[dict[str, Any], dict[str, Any]]:
    """The model's ``data`` (its class parameters, as SB3's ``load`` reads them) and the ``custom_objects`` that
    hand SB3 the fields decoded here (:func:`~specguard.agents.decode.read_data`): refused unless it is a model's."""
    where = repr(str(model_zip))
    data, custom = read_data(model_zip, trust=trust, replace=_CUSTOM_OBJECTS)
    missing = [k for k in ("policy_class", "observation_space", "action_space") if k not in data]
    if missing or not isinstance(data["policy_class"], type):
        what = f"its data has no {', '.join(missing)}" if missing else "its policy class cannot be read here"
        raise AgentError(f"{where}: not a stable-baselines3 model ({what})")
    return data, custom


def _settings_folder(folder: Path, model_zip: Path | None = None) -> Path:
    """Where a run's settings lie: rl-zoo3's ``<env_id>/`` subfolder with ``config.yml`` or ``args.yml``, the one
    that belongs to the run's final model ``<env_id>.zip`` beside it (or is named as ``model_zip``), else the folder
    itself (the Hub's layout). Another subfolder's settings are another run's, never this one's."""
    named = [
        d
        for d in sorted(folder.iterdir())
        if d.is_dir()
        and ((d / "config.yml").is_file() or (d / "args.yml").is_file())
        and ((folder / f"{d.name}.zip").is_file() or (model_zip is not None and model_zip.stem == d.name))
    ]
    return named[0] if len(named) == 1 else folder


def _yaml_mapping(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    try:
        value = read_zoo_file(str(path), path)
    except InvalidSpec as e:
        raise AgentError(e.message, hint=e.hint) from None
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise AgentError(f"{str(path)!r}: expected a mapping of names to values, got {shown(value)}")
    return dict(value)


def _env_kwargs(settings: Path, config: Mapping[str, Any], args: Mapping[str, Any]) -> dict[str, Any]:
    """What the env was made with: ``env_kwargs.yml`` (the Hub's), else ``args.yml``'s (rl-zoo3's command line),
    else ``config.yml``'s, as ``rl_zoo3.enjoy`` reads them."""
    if (settings / "env_kwargs.yml").is_file():
        return _yaml_mapping(settings / "env_kwargs.yml")
    for said in (args.get("env_kwargs"), config.get("env_kwargs")):
        if isinstance(said, Mapping):
            return dict(said)
    return {}


def _path_words(model_zip: Path) -> list[str]:
    """The words of a zip's path that may name its algorithm: the Hub's ``<algo>-<env_id>.zip``, rl-zoo3's
    ``<algo>/<env_id>_<n>/``."""
    return [model_zip.stem.split("-", 1)[0], model_zip.parent.parent.name, model_zip.parent.name]


# -- the algorithm of a zip -----------------------------------------------------------------------------------------


def _named_classes() -> dict[str, type]:
    """The named algorithms installed here, by name."""
    out = {}
    for name in (*SB3, *CONTRIB):
        try:
            out[name] = algorithm_class(name)
        except SpecError:  # sb3-contrib not installed
            break
    return out


def _algorithm(model_zip: Path, data: Mapping[str, Any], algorithm: Any, hints: list[str]) -> Any:
    """The algorithm class that saved ``model_zip``: ``algorithm`` if it fits, else the one its policy class, its
    path's words and its stored hyperparameters name.

    The candidates are the algorithms whose policy classes hold the zip's (PPO, A2C and TRPO share one). A zip stores
    almost every hyperparameter of the algorithm that saved it, so of the candidates it is one of those with the
    fewest hyperparameters the zip does not store (on an A2C zip: A2C misses 3, PPO 6), and of those the one that
    takes the most it does store (TD3 before DDPG, which fixes three of TD3's); a word of its path that names a
    candidate (the Hub's ``ppo-CartPole-v1.zip``, rl-zoo3's ``ppo/`` or ``args.yml``) decides first.
    """
    where = repr(str(model_zip))
    policy = data["policy_class"]
    named = _named_classes()

    def policies(cls: type) -> tuple[type, ...]:
        return tuple(getattr(cls, "policy_aliases", {}).values())

    candidates = {n: c for n, c in named.items() if policy in policies(c)}
    candidates = candidates or {n: c for n, c in named.items() if policies(c) and issubclass(policy, policies(c))}
    stored = set(data)
    takes = {n: set(hyperparameter_names(c) or ()) for n, c in candidates.items()}
    missing = {n: len(takes[n] - stored) for n in candidates}
    fewest = min(missing.values(), default=0)
    best = sorted((n for n in candidates if missing[n] == fewest), key=lambda n: -len(takes[n] & stored))
    if algorithm is not None:
        try:
            cls = algorithm_class(_resolve(where, algorithm))
        except InvalidSpec as e:
            raise AgentError(f"{e.where}: {e.message}", hint=e.hint) from None
        own = policies(cls)
        name = next((n for n, c in named.items() if c is cls), None)
        if (own and not issubclass(policy, own)) or (name is not None and name not in best):
            saved = " or ".join(best) or f"an algorithm of the policy {policy.__qualname__}"
            raise AgentError(f"{where}: saved by {saved}, not by {cls.__name__} (algorithm={shown(algorithm)})")
        return cls
    lowered = {n.lower(): n for n in ALGORITHMS} | _ZOO_NAMES
    said = [lowered[w.lower()] for w in hints if w.lower() in lowered and lowered[w.lower()] in candidates]
    if said:
        return candidates[said[0]]
    if len(best) == 1 or (best and len(takes[best[0]] & stored) > len(takes[best[1]] & stored)):
        return candidates[best[0]]
    which = " or ".join(best) if best else "none of the algorithms installed here"
    raise AgentError(
        f"{where}: cannot tell which algorithm saved it (its policy {policy.__qualname__} fits {which})",
        hint="name it: load_agent(path, algorithm='PPO')",
    )
