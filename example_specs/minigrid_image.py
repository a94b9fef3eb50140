"""MiniGrid-Empty-5x5-v0 (``minigrid``) with its image: the agent sees what MiniGrid shows it, beside the features.

The same goal as ``minigrid_empty.py`` (reach the green square, the features read from the env object
with ``from_env``), with ``observation="features+env"``: the agent's observation is a ``Dict`` of the
spec's features and own state (``"spec"``) and MiniGrid's own observation, trained with
stable-baselines3's ``MultiInputPolicy``. The goals are judged on the features alone.

MiniGrid's observation is a ``Dict`` of a 7x7x3 egocentric grid encoding, the direction and a mission
string (a ``MissionSpace``, a ``Text`` that stable-baselines3 cannot take). The factory wraps the env as
MiniGrid's own documentation does for stable-baselines3: ``RGBImgPartialObsWrapper`` renders the agent's
view as a 56x56 RGB image (stable-baselines3's ``NatureCNN`` needs images of at least 36x36; the 7x7
encoding is too small for it), and ``ImgObsWrapper`` keeps only that image, which then stands under the
key ``"observation"``. ``from_env`` reads ``env.unwrapped``, so the wrappers change no feature.

Needs the ``examples`` extra (``pip install -e ".[examples]"``). Run ``python example_specs/minigrid_image.py``
to print the tree and the agent's observation.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import minigrid  # noqa: F401  (registers the MiniGrid ids)
from minigrid.wrappers import ImgObsWrapper, RGBImgPartialObsWrapper

import specguard as sg
from example_specs import minigrid_empty

plain = minigrid_empty.initial_env


def image_grid(**kwargs: Any) -> gym.Env:
    """MiniGrid-Empty-5x5-v0 whose observation is the agent's view as a 56x56 RGB image (MiniGrid's wrappers)."""
    return ImgObsWrapper(RGBImgPartialObsWrapper(gym.make("MiniGrid-Empty-5x5-v0", **kwargs)))


# minigrid_empty.py's features (x, y, direction from the env object), actions and bounds, on the wrapped env.
initial_env = sg.InitialEnv(
    image_grid,
    from_env=dict(plain.from_env),
    bounds={feature: (lo, hi) for feature, lo, hi in plain.bounds},
    execute=plain.execute,
    action_space=plain.action_space,
)
tree = minigrid_empty.tree

# minigrid_empty.py's goal, threshold, budget and PPO settings; the agent sees the image beside the features.
specs: dict[str, sg.Spec] = {
    "green_square": sg.Spec(
        initial_env,
        tree,
        expect={"green_square": 0.8},
        name="minigrid_image",
        budget=minigrid_empty.BUDGET,
        trainer=sg.SB3(hyperparameters=minigrid_empty.PPO, n_envs=4),
        observation="features+env",
    )
}

if __name__ == "__main__":
    print(tree)
    print(specs["green_square"].make_env().observation_space)
