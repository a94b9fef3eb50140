"""MiniGrid-Empty-5x5-v0 (``minigrid``): reach the green square, without a wrapper of our own.

``import minigrid`` registers the MiniGrid ids, so the plain id works here and in every process that
trains it (``"minigrid:MiniGrid-Empty-5x5-v0"`` would work without the import). The observation is a
``Dict`` (an egocentric image, the direction, a mission string); the agent's position and direction live
on the env object, so the features are read from it with ``from_env``. The 5x5 grid's walls leave the
agent the cells 1..3 of each axis; it starts at (1, 1) facing right, and the green square is at (3, 3).

Of MiniGrid's seven actions only turning left, turning right and moving forward act in an empty room;
``action_space`` and ``execute`` leave the agent those three. The distance is the Manhattan distance to
the square, at most 4 from any cell the agent can reach. The env's own episode limit is 100 steps.

The file is not named ``minigrid.py``: ``python FILE`` and ``specguard run FILE`` put the file's folder
first on ``sys.path``, where a ``minigrid.py`` would stand in for the package that ``import minigrid``
means. Needs the ``examples`` extra (``pip install -e ".[examples]"``). Run
``python example_specs/minigrid_empty.py`` to print the tree and its reward formula.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import minigrid  # noqa: F401  (registers the MiniGrid ids)
from minigrid.core.actions import Actions

import specguard as sg

MOVES = (Actions.left, Actions.right, Actions.forward)


def to_move(action: Any) -> int:
    """The agent's action 0, 1 or 2 as MiniGrid's: turn left, turn right, move forward."""
    return int(MOVES[int(action)])


initial_env = sg.InitialEnv(
    "MiniGrid-Empty-5x5-v0",
    from_env={
        "x": lambda env: env.agent_pos[0],
        "y": lambda env: env.agent_pos[1],
        "direction": lambda env: env.agent_dir,
    },
    bounds={"x": (1, 3), "y": (1, 3), "direction": (0, 3)},
    execute=to_move,
    action_space=gym.spaces.Discrete(len(MOVES)),
)


def to_square(s):  # type: ignore[no-untyped-def]
    """Manhattan distance to the green square (3, 3); at most 4 from the cells 1..3 of each axis."""
    return abs(3 - s.x) + abs(3 - s.y)


tree = sg.Goal("green_square", x=(3, 3), y=(3, 3)).annotate(sg.Distance(to_square, scale=4.0))

# Budget: PPO (4 envs x 256 steps a rollout) at most 50k steps per run; under anytime verdicts a run stops
# at the first tenth of its budget where every threshold is met. The start is fixed, so a deterministic
# policy's 30 evaluation episodes are one episode repeated: 30/30 or 0/30. Measured on the 2-core
# development machine, one run at a time: seeds 0-19 all reach the square in 30/30 episodes, stopping at
# 15k-20k steps (seed 11: 30k), 3-7 s of training each; PPO with 4096 steps gave 0/10 in an earlier try.
BUDGET = sg.Budget(timesteps=50_000, min_seeds=2, eval_episodes=30)
PPO: dict[str, Any] = {"n_steps": 256, "batch_size": 64, "n_epochs": 4}
specs: dict[str, sg.Spec] = {
    "green_square": sg.Spec(
        initial_env,
        tree,
        expect={"green_square": 0.8},
        name="minigrid",
        budget=BUDGET,
        trainer=sg.SB3(hyperparameters=PPO, n_envs=4),
    )
}


if __name__ == "__main__":
    print(tree)
    print(sg.formula(tree))
