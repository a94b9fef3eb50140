"""InvertedPendulum-v5 (MuJoCo, ``gymnasium[mujoco]``): keep the pole upright until the episode ends.

The pole starts upright (every component within 0.01 of zero), so "upright" as a reach goal would
be met before the agent acts: specguard refuses it (``GoalMetAtStart``). What is asked is that it
*stays* upright, so the goal is wrapped in ``sg.Always``: the episode is not ended by the goal, runs
to the env's own end, and succeeds when the pole was upright at every state, the last included.
InvertedPendulum-v5 itself terminates once ``|theta| > 0.2``: a fall ends the episode outside the
goal, and fails it.

The features are the observation's four components (``x``, ``theta``, ``v``, ``omega``). The
horizon is part of what "until the end" promises: Gymnasium's is 1000 steps, shortened here to
``HORIZON`` steps (``max_episode_steps``, passed to ``gymnasium.make``) to keep evaluation cheap for
the main job: the spec says "upright for HORIZON steps", not for 1000.

Needs the ``examples`` extra (``pip install -e ".[examples]"``). Run
``python example_specs/inverted_pendulum.py`` to print the tree and its reward formula.
"""

from __future__ import annotations

import specguard as sg

HORIZON = 200

initial_env = sg.InitialEnv("InvertedPendulum-v5", features=("x", "theta", "v", "omega"), max_episode_steps=HORIZON)

tree = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")

# Budget: PPO with SB3's defaults (one env, 2048 steps a rollout), at most 50k steps per run; under anytime
# verdicts a run stops at the first tenth of its budget where every threshold is met. No distance: the
# goal's own -1 on leaving it (the fall) is the whole reward, and enough. Measured on the 2-core development
# machine, one run at a time: seeds 0-7 keep the pole up in 30/30 evaluation episodes, stopping at 20k-25k
# steps (0/30 at every checkpoint before), 20-30 s of training each when the machine is otherwise idle.
# With Gymnasium's own 1000-step horizon, seeds 0 and 1 stopped at 25k and 30k steps, in about 35 s each.
BUDGET = sg.Budget(timesteps=50_000, min_seeds=2, eval_episodes=30)
specs: dict[str, sg.Spec] = {
    "balance": sg.Spec(
        initial_env,
        tree,
        expect={"balance": 0.8},
        name="inverted_pendulum",
        budget=BUDGET,
    )
}


if __name__ == "__main__":
    print(tree)
    print(sg.formula(tree))
