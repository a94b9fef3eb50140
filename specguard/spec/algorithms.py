"""What specguard knows of stable-baselines3: the algorithms, what each collects between updates, and loading.

Example:
    >>> collect_steps("PPO", {"n_steps": 1024}), collection_unit("PPO"), collect_parameter("DQN")
    (1024, 'rollouts', 'train_freq')
    >>> "Discrete" in ALGORITHMS["DQN"], "Box" in ALGORITHMS["DQN"]
    (True, False)
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from specguard.validation import is_count

__all__ = ["ALGORITHMS", "algorithm_class", "collect_parameter", "collect_steps", "collection_unit", "load_model"]

# stable-baselines3 algorithms by name, and the action spaces each can act in.
ALGORITHMS: dict[str, tuple[str, ...]] = {
    "PPO": ("Box", "Discrete", "MultiDiscrete", "MultiBinary"),
    "A2C": ("Box", "Discrete", "MultiDiscrete", "MultiBinary"),
    "DQN": ("Discrete",),
    "SAC": ("Box",),
    "TD3": ("Box",),
    "DDPG": ("Box",),
}

# stable-baselines3's defaults: on-policy algorithms train whole rollouts of
# n_steps per env; off-policy ones collect train_freq steps per env between updates.
_ROLLOUT_STEPS = {"PPO": ("n_steps", 2048), "A2C": ("n_steps", 5)}
_TRAIN_FREQ = {"DQN": 4, "SAC": 1, "TD3": 1, "DDPG": 1}


def collect_steps(algorithm: str, hyperparameters: Mapping[str, Any]) -> int:
    """Steps per env that one collection takes (1 where stable-baselines3 counts episodes instead)."""
    if algorithm in _ROLLOUT_STEPS:
        key, default = _ROLLOUT_STEPS[algorithm]
        value = hyperparameters.get(key, default)
    else:
        freq = hyperparameters.get("train_freq", _TRAIN_FREQ.get(algorithm, 1))
        if isinstance(freq, (tuple, list)):
            freq = freq[0] if len(freq) == 2 and str(freq[1]) == "step" else 1
        value = freq
    if not is_count(value):
        return 1  # the algorithm rejects it when training, with its own message
    return int(value)


def collection_unit(algorithm: str) -> str:
    """What one collection of ``algorithm`` is called: ``"rollouts"`` (on-policy) or ``"collections"``."""
    return "rollouts" if algorithm in _ROLLOUT_STEPS else "collections"


def collect_parameter(algorithm: str) -> str:
    """The hyperparameter that sets one collection's size: ``"n_steps"`` (on-policy) or ``"train_freq"``."""
    return _ROLLOUT_STEPS[algorithm][0] if algorithm in _ROLLOUT_STEPS else "train_freq"


def algorithm_class(algorithm: str) -> Any:
    """stable-baselines3's class of ``algorithm`` (imported here, on first use)."""
    import stable_baselines3

    return getattr(stable_baselines3, algorithm)


def load_model(algorithm: str, path: Path | str) -> Any:
    """A saved model of ``algorithm``, loaded on the CPU."""
    return algorithm_class(algorithm).load(path, device="cpu")
