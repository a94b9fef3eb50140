"""highway-fast-v0 (``highway-env``): never crash, and keep going fast, until the episode ends.

``import highway_env`` registers the highway ids. The ego car starts at 25 m/s among 20 cars on three
lanes; its five actions are highway-env's meta-actions (change lane left, idle, change lane right,
faster, slower: target speeds 20, 25 and 30 m/s). The agent sees highway-env's own observation, the
kinematics of the 5 nearest cars (``present``, ``x``, ``y``, ``vx``, ``vy`` each, normalised to
[-1, 1]: 25 features, flattened by ``state``). The crash and the speed are not in it: highway-env
reports them in ``info``, and ``from_info`` reads them as features, so the agent sees them and the
goals can name them:

* **never crash**: a ``Constraint`` on ``crashed``, judged at every state (the crash ends the
  episode, and that last state is judged too); its safety rate is asserted;
* **keep going fast**: ``Always`` at least 24 m/s, so the root holds until the end: the episode
  runs to highway-env's end (30 policy steps of 1 s; ``max_episode_steps=30`` says so to specguard)
  and succeeds when the car never dropped below 24 m/s and did not crash (a crash is the env's
  termination, before the horizon, which ``Always`` does not keep). Braking ("slower") drops it below at once:
  without this goal, a spec of the episode's end without a crash was met at 2k steps (the car
  may slow down behind the traffic).

Opt-in: marked ``highway`` in ``test_case_studies.py`` (``pytest --goal-specs example_specs -m
highway``), since highway-env steps about 60 times a second on one core: training takes minutes per
seed (docs/guide/your-environment.md, "Example specs"). Needs the ``highway`` extra
(``pip install -e ".[highway]"``). Run ``python example_specs/highway.py`` to print the tree and its
reward formula.
"""

from __future__ import annotations

from typing import Any

import highway_env  # noqa: F401  (registers the highway ids)
import numpy as np

import specguard as sg

CARS = 5  # highway-env's Kinematics observation: the ego car, then the 4 nearest
COLUMNS = ("present", "x", "y", "vx", "vy")
OBSERVED = tuple(f"{column}{car}" for car in range(CARS) for column in COLUMNS)


def flatten(obs: np.ndarray) -> np.ndarray:
    """The 5 x 5 kinematics table, row by row: ``present0, x0, ..., vy4``."""
    return obs.ravel()


initial_env = sg.InitialEnv(
    "highway-fast-v0",
    features=OBSERVED,
    state=flatten,
    from_info={"crashed": "crashed", "speed": "speed"},
    # highway-env normalises and clips the kinematics to [-1, 1]; its cars' speeds lie in [-40, 40] m/s.
    bounds={**{feature: (-1.0, 1.0) for feature in OBSERVED}, "crashed": (0, 1), "speed": (-40.0, 40.0)},
    max_episode_steps=30,  # highway-fast-v0 ends its episodes itself after 30 s at 1 policy step a second
)


def crashed(s, a):  # type: ignore[no-untyped-def]
    """The ego car collided (highway-env's ``info["crashed"]``)."""
    return s.crashed > 0.5


tree = sg.Always(sg.Goal("fast", speed=(24.0, None)), name="keep_fast").annotate(sg.Constraint(crashed, name="crash"))

# highway-env's own DQN settings for highway-fast-v0 (its scripts/sb3_highway_dqn.py).
DQN: dict[str, Any] = {
    "policy_kwargs": {"net_arch": [256, 256]},
    "learning_rate": 5e-4,
    "buffer_size": 15_000,
    "learning_starts": 200,
    "batch_size": 32,
    "gamma": 0.8,
    "train_freq": 1,
    "gradient_steps": 1,
    "target_update_interval": 50,
    "exploration_fraction": 0.7,
}
# Budget: at most 50k steps per run. highway-env steps about 60 times a second on one core, so the budget
# is 20-25 minutes per seed on the 2-core development machine. Measured there (`-m highway`, 2 seeds in
# parallel, another test run beside it): 1315 s; at 50k fast in 85/120 and 92/120, crash-free in 81/120
# and 86/120 evaluation episodes (seeds 0 / 1; 74% and 70% pooled), below the 0.8 asked. Seed 0's
# checkpoints from 5k to 45k steps were 0/30 but one (at 25k, fast in 30/30 and crashing in all 30: the
# Always goal then counted an episode that a crash ends at speed; it no longer does, so these figures
# predate that change and "fast" would read lower now). Both goals are declared expected to miss at
# this budget (XFAIL; XPASS once they pass).
BUDGET = sg.Budget(timesteps=50_000, min_seeds=2, eval_episodes=30)
MEASURED = "measured 70-74% at 50k steps (2 seeds), below 0.8: highway-env needs a longer budget"
specs: dict[str, sg.Spec] = {
    "keep_fast": sg.Spec(
        initial_env,
        tree,
        expect={"keep_fast": 0.8, "keep_fast:crash": 0.8},
        xfail={"keep_fast": MEASURED, "keep_fast:crash": MEASURED},
        name="highway",
        trainer=sg.SB3("DQN", hyperparameters=DQN),
        budget=BUDGET,
    )
}


if __name__ == "__main__":
    print(tree)
    print(sg.formula(tree))
