"""The behavioural probe: a digest of a short fixed-seed rollout of a spec's training env.

It sees what the static part of a key cannot reach by name (an env class made
from a string id, a C extension), on the states that rollout visits.
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from specguard.cache.canonical import canonical, dumps
from specguard.error import FingerprintError

__all__ = ["PROBE_STEPS", "probe"]

PROBE_STEPS = 256


# -- the behavioural probe ---------------------------------------------------------


def probe(spec: Any, steps: int = PROBE_STEPS, build: Callable[[], Any] | None = None) -> str:
    """A digest of a fixed-seed rollout of the spec's training env (seeded random actions).

    An env that raises is not an error here: the exception's type and message
    are hashed and the rollout ends (the training run reports the failure
    with its seed, where it belongs). ``build`` makes the env (``None``:
    :meth:`Spec.make_env <specguard.spec.spec.Spec.make_env>`); probes of one spec share
    one :meth:`Spec.env_factory <specguard.spec.spec.Spec.env_factory>`, so its tree is compiled once.
    """
    h = hashlib.sha256()
    env = None
    try:
        env = spec.make_env() if build is None else build()  # the spec's factory checks it once, where it is run
        h.update(dumps(canonical((env.observation_space, env.action_space), "spaces")).encode())
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


def _hash_observation(h: Any, obs: Any) -> None:
    """An observation by dtype, shape and content; a ``Dict`` observation's parts by key, in sorted order."""
    if isinstance(obs, Mapping):
        for key in sorted(obs):
            h.update(str(key).encode() + b"\0")
            _hash_observation(h, obs[key])
        return
    arr = np.asarray(obs)
    h.update(arr.dtype.str.encode() + repr(arr.shape).encode() + np.ascontiguousarray(arr).tobytes())


def _hash_step(h: Any, obs: Any, reward: Any, terminated: Any, truncated: Any, info: dict[str, Any]) -> None:
    _hash_observation(h, obs)
    if reward is not None:
        h.update(float(reward).hex().encode() + bytes([bool(terminated), bool(truncated)]))
    for key in ("goals", "reward_terms"):
        for name, value in (info.get(key) or {}).items():
            h.update(name.encode() + b"\0" + (float(value).hex().encode()))
