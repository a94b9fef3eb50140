"""A policy's evaluation episodes on a spec's env: what each goal and safety rate counts, and their seeds.

Evaluation episodes are seeded apart from training: training envs are seeded ``seed .. seed + n_envs - 1`` (as
``make_vec_env`` does), evaluation episode ``i`` of run ``seed`` uses ``EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE +
i``. A goal succeeds in an episode when the episode's last state lies in it, whether the episode terminated or was
truncated; a safety annotation counts the episodes without a violation, read from the last step's ``info["safe"]``
(docs/semantics.md, "Success"). Training's looks and final evaluation (:mod:`specguard.training.train`) and an agent
trained elsewhere (:mod:`specguard.engine.check_agent`) count their episodes here alike.

Example:
    >>> import specguard as sg
    >>> env = sg.make_env(sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega")),
    ...                   sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="kept"))
    >>> evaluate(lambda obs: 0, env, 2, [EVAL_SEED_BASE, EVAL_SEED_BASE + 1])
    {'kept': 0, 'kept/upright': 0}
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym

from specguard.construction.cap import CAPPED
from specguard.construction.episode_policy import EpisodePolicy
from specguard.error import SpecError, TrainingError
from specguard.utils.text import MAX_SHOWN, elide

__all__ = ["AGENT_FAILED", "EVAL_SEED_BASE", "EVAL_SEED_STRIDE", "count_episode", "evaluate"]


def count_episode(counts: dict[str, int], info: Mapping[str, Any]) -> None:
    """Add one finished episode's last ``info``: its goals (by path), then its safety (by ``path:name``)."""
    for key, ok in info["goals"].items():
        counts[key] = counts.get(key, 0) + int(ok)
    for key, ok in info.get("safe", {}).items():
        counts[key] = counts.get(key, 0) + int(ok)


EVAL_SEED_BASE = 1_000_000
EVAL_SEED_STRIDE = 100_000
AGENT_FAILED = (
    "the agent failed to act on an observation of the env: a trained model whose weights went NaN (a learning "
    "rate or clip range too large), or a trainer's agent that raised; call it on env.reset(seed=...)[0] to see"
)


def _policy_action(space: gym.Space[Any], action: Any) -> Any:
    return int(action) if isinstance(space, gym.spaces.Discrete) else action


def evaluate(
    policy: Callable[[Any], Any],
    env: gym.Env,
    episodes: int,
    seeds: list[int] | range,
    started: list[bool] | None = None,
    terminated: list[bool] | None = None,
    capped: list[bool] | None = None,
    outcomes: list[dict[str, int]] | None = None,
    starts: list[list[float]] | None = None,
) -> dict[str, int]:
    """Run ``episodes`` episodes of ``policy`` on ``env`` (which reports ``info["goals"]`` and ``info["safe"]``).

    An :class:`~specguard.construction.episode_policy.EpisodePolicy` (a trained model's
    :class:`~specguard.evaluation.policy.Policy`) is told as each episode starts.

    ``started``, if given, receives per episode whether its first state (at reset) was in the root goal
    (the first of ``info["goals"]``); ``terminated``, whether it ended by termination rather than
    truncation (a fall or a crash of the initial env, before its horizon); ``capped``, whether specguard's
    step cap cut it (``info[CAPPED]``: the env declares no episode limit, :mod:`specguard.construction.cap`);
    ``outcomes``, the episode's own counts (1 or 0 per key, as returned), for paired comparisons; ``starts``, the
    features of the episode's first state (``start_features`` of the constructed or baseline env, through its
    wrappers).

    Returns:
        Per node path, the number of episodes whose last state lies in the
        goal; then per safety key (``path:name``), the number of episodes
        without a violation (the last step's ``info["safe"]``).

    Raises:
        TrainingError: ``policy`` raised (specguard's own errors pass as they are); the env's errors propagate
            unchanged, for the caller to name.
    """
    counts: dict[str, int] = {}
    for i in range(episodes):
        obs, info = env.reset(seed=seeds[i])
        if isinstance(policy, EpisodePolicy):
            policy.start([env])
        if started is not None:
            started.append(bool(next(iter(info["goals"].values()))))
        if starts is not None:
            starts.append(list(env.get_wrapper_attr("start_features")))
        ended = cut = False
        while not (ended or cut):
            try:
                action = policy(obs)
            except SpecError:
                raise
            except Exception as e:  # the policy's failure, not the env's (a NaN network, a trainer's agent)
                raise TrainingError(
                    f"the agent raised {type(e).__name__}: {elide(str(e), MAX_SHOWN)}", hint=AGENT_FAILED
                ) from e
            obs, _, ended, cut, info = env.step(_policy_action(env.action_space, action))
        if terminated is not None:
            terminated.append(bool(ended))
        if capped is not None:
            capped.append(CAPPED in info)
        count_episode(counts, info)
        if outcomes is not None:
            episode: dict[str, int] = {}
            count_episode(episode, info)
            outcomes.append(episode)
    return counts
