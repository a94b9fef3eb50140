"""Start spaces of Gymnasium's MuJoCo envs: their joints by name, set through ``set_state``, observed by the env."""

from __future__ import annotations

import math
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv

from specguard.error import InvalidSpec, UnknownFeature
from specguard.starts.space import START_OPTION, StartSpace, start_variables


def start(env, values):
    """``env`` wrapped by the start space of ``values`` (each its own one-point range), reset into that start."""
    starts = StartSpace({n: (v, v) for n, v in values.items()}).resolve(env)
    wrapped = starts.wrap(env)
    obs, _ = wrapped.reset(seed=0, options={START_OPTION: values})
    return wrapped, obs


def reset_state(env_id):
    """``qpos``, ``qvel`` and the observation the env's reset with seed 0 gives, as the falsifier resets."""
    env = gym.make(env_id)
    obs, _ = env.reset(seed=0)
    return env.unwrapped.data.qpos.copy(), env.unwrapped.data.qvel.copy(), obs


def test_inverted_pendulum_names_its_slider_and_hinge_and_is_observed_in_the_state_set():
    env = gym.make("InvertedPendulum-v5")
    assert start_variables(env) == ("slider", "hinge", "slider_vel", "hinge_vel")
    values = {"slider": 0.5, "hinge": -0.15, "slider_vel": 1.0, "hinge_vel": -2.0}
    wrapped, obs = start(env, values)
    np.testing.assert_array_equal(env.unwrapped.data.qpos, [0.5, -0.15])
    np.testing.assert_array_equal(env.unwrapped.data.qvel, [1.0, -2.0])
    np.testing.assert_array_equal(obs, [0.5, -0.15, 1.0, -2.0])  # its observation: qpos, then qvel
    nxt = wrapped.step(np.zeros(1, dtype=np.float32))[0]  # the dynamics go on from there: the cart moves right
    assert nxt[0] == pytest.approx(0.5 + 1.0 * env.unwrapped.dt, abs=0.01) and nxt[1] < -0.15


def test_variables_left_out_keep_what_the_reset_gave():
    qpos, qvel, obs = reset_state("InvertedPendulum-v5")
    env = gym.make("InvertedPendulum-v5")
    _, set_obs = start(env, {"hinge": 0.1})
    np.testing.assert_array_equal(env.unwrapped.data.qpos, [qpos[0], 0.1])
    np.testing.assert_array_equal(env.unwrapped.data.qvel, qvel)
    np.testing.assert_array_equal(set_obs, [obs[0], 0.1, obs[2], obs[3]])


def test_reacher_sets_its_arm_and_its_target_and_observes_them():
    qpos, qvel, _ = reset_state("Reacher-v5")
    env = gym.make("Reacher-v5")
    assert start_variables(env) == (
        *("joint0", "joint1", "target_x", "target_y"),
        *("joint0_vel", "joint1_vel", "target_x_vel", "target_y_vel"),
    )
    _, obs = start(env, {"joint0": 1.0, "joint1": -0.5, "target_x": 0.1, "joint0_vel": 0.3})
    np.testing.assert_array_equal(env.unwrapped.data.qpos, [1.0, -0.5, 0.1, qpos[3]])
    np.testing.assert_array_equal(env.unwrapped.data.qvel, [0.3, *qvel[1:]])
    # Reacher observes cos and sin of its arm's angles, the target, the arm's velocities, fingertip - target.
    np.testing.assert_allclose(
        obs[:8], [math.cos(1.0), math.cos(-0.5), math.sin(1.0), math.sin(-0.5), 0.1, qpos[3], 0.3, qvel[1]]
    )
    # The fingertip: links of 0.1 and 0.11 from the origin, at the angles set (forward kinematics ran).
    tip = 0.1 * np.array([math.cos(1.0), math.sin(1.0)]) + 0.11 * np.array([math.cos(0.5), math.sin(0.5)])
    np.testing.assert_allclose(obs[8:10], tip - [0.1, qpos[3]], atol=1e-6)


def test_hopper_sets_its_height_a_joint_and_a_velocity():
    env = gym.make("Hopper-v5")
    assert start_variables(env)[:6] == ("rootx", "rootz", "rooty", "thigh_joint", "leg_joint", "foot_joint")
    _, obs = start(env, {"rootz": 1.5, "thigh_joint": -0.3, "rootx_vel": 2.0})
    # Hopper observes qpos without rootx, then qvel (clipped to +-10).
    assert obs[0] == 1.5 and obs[2] == -0.3 and obs[5] == 2.0
    np.testing.assert_array_equal(obs, np.concatenate([env.unwrapped.data.qpos[1:], env.unwrapped.data.qvel]))


def test_a_limited_joint_is_bounded_by_its_range_and_the_rest_are_not():
    starts = StartSpace({"hinge": (-1.5, 1.5), "slider_vel": (-100.0, 100.0)}).resolve(gym.make("InvertedPendulum-v5"))
    assert starts.names == ("hinge", "slider_vel") and starts.how == "state"
    with pytest.raises(InvalidSpec, match=r"the range of 'hinge' is \(-2, 0\), outside its bounds \(-1.5708, 1.5708\)"):
        StartSpace({"hinge": (-2.0, 0.0)}).resolve(gym.make("InvertedPendulum-v5"))
    with pytest.raises(InvalidSpec, match=r"the range of 'slider' is \(0, 1.5\), outside its bounds \(-1, 1\)"):
        StartSpace({"slider": (0.0, 1.5)}).resolve(gym.make("InvertedPendulum-v5"))


def test_an_unknown_name_is_one_line_listing_the_envs_variables():
    with pytest.raises(UnknownFeature) as info:
        StartSpace({"theta": (-0.1, 0.1)}).resolve(gym.make("InvertedPendulum-v5"))
    assert str(info.value).splitlines()[0] == (
        "StartSpace for InvertedPendulum-v5: the start space names 'theta', which its setter does not know; "
        "known: slider, hinge, slider_vel, hinge_vel"
    )
    assert "docs/guide/falsify.md" in str(info.value)


def test_a_space_naming_no_joint_searches_the_envs_reset_seeds_and_says_why():
    starts = StartSpace().resolve(gym.make("InvertedPendulum-v5"))
    assert starts.how == "reset seeds" and starts.names == ("seed",)
    assert starts.note == (
        "StartSpace for InvertedPendulum-v5: no ranges were given for its variables, "
        "so reset seeds are searched instead"
    )


# -- a model of its own: a free joint, an unnamed ball joint, an unnamed limited hinge ---------------------------

TOY = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="body" pos="0 0 1">
      <freejoint name="float"/>
      <geom size="0.1"/>
      <body pos="0 0 -0.3">
        <joint type="ball"/>
        <geom size="0.05"/>
        <body pos="0 0 -0.2">
          <joint type="hinge" axis="0 1 0" limited="true" range="-1 1"/>
          <geom size="0.05"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
CLASH = """
<mujoco>
  <worldbody>
    <body><joint name="arm" type="hinge"/><geom size="0.1"/>
      <body pos="0 0 -0.3"><joint name="arm_vel" type="hinge"/><geom size="0.1"/></body>
    </body>
  </worldbody>
</mujoco>
"""


class Toy(MujocoEnv):
    """A MuJoCo env over the model at ``path``: observes ``qpos`` and ``qvel``; no actuators."""

    metadata: ClassVar[dict] = {"render_modes": ["human", "rgb_array", "depth_array", "rgbd_tuple"], "render_fps": 500}

    def __init__(self, path, **kwargs):
        space = gym.spaces.Box(-np.inf, np.inf, (1,), np.float64)  # replaced once the model is loaded
        MujocoEnv.__init__(self, str(path), 1, observation_space=space, **kwargs)
        size = self.model.nq + self.model.nv
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float64)

    def _get_obs(self):
        return np.concatenate([self.data.qpos, self.data.qvel])

    def reset_model(self):
        self.set_state(self.init_qpos, self.init_qvel + 0.01)
        return self._get_obs()

    def step(self, action):
        self.do_simulation(action, self.frame_skip)
        return self._get_obs(), 0.0, False, False, {}


class Unobserved(Toy):
    """A MuJoCo env without ``_get_obs``: the observation of a set state is not known."""

    _get_obs = None

    def reset_model(self):
        self.set_state(self.init_qpos, self.init_qvel)
        return np.concatenate([self.data.qpos, self.data.qvel])


@pytest.fixture
def toy(tmp_path):
    (tmp_path / "toy.xml").write_text(TOY)
    return Toy(tmp_path / "toy.xml")


def test_free_and_ball_joints_name_their_coordinates_and_unnamed_joints_their_index(toy):
    positions = ("float_x", "float_y", "float_z", "float_qw", "float_qx", "float_qy", "float_qz")
    positions += ("joint1_qw", "joint1_qx", "joint1_qy", "joint1_qz", "joint2")
    velocities = ("float_vel_x", "float_vel_y", "float_vel_z", "float_vel_rx", "float_vel_ry", "float_vel_rz")
    velocities += ("joint1_vel_rx", "joint1_vel_ry", "joint1_vel_rz", "joint2_vel")
    assert start_variables(toy) == positions + velocities
    assert len(positions) == toy.model.nq and len(velocities) == toy.model.nv
    _, obs = start(toy, {"float_z": 2.0, "float_vel_rz": 0.5, "joint1_qx": 1.0, "joint2": 0.7, "joint1_vel_ry": -1.0})
    qpos, qvel = toy.data.qpos, toy.data.qvel
    assert qpos[2] == 2.0 and qvel[5] == 0.5 and qvel[7] == -1.0 and qpos[11] == 0.7
    # The ball's quaternion (1, 0, 0, 0) at reset, its x set to 1: normalised to (1, 1, 0, 0) / sqrt(2).
    np.testing.assert_allclose(qpos[7:11], [math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])
    np.testing.assert_allclose(qvel[[0, 1, 2, 3, 4, 6, 8, 9]], 0.01)  # left out: what the reset gave
    np.testing.assert_array_equal(obs, np.concatenate([qpos, qvel]))


def test_a_quaternion_component_is_bounded_by_one_and_a_free_position_is_not(toy):
    StartSpace({"float_x": (-50.0, 50.0), "float_vel_x": (-50.0, 50.0)}).resolve(toy)
    with pytest.raises(InvalidSpec, match=r"the range of 'float_qw' is \(0, 2\), outside its bounds \(-1, 1\)"):
        StartSpace({"float_qw": (0.0, 2.0)}).resolve(toy)
    with pytest.raises(InvalidSpec, match=r"the range of 'joint2' is \(0, 2\), outside its bounds \(-1, 1\)"):
        StartSpace({"joint2": (0.0, 2.0)}).resolve(toy)


def test_variables_that_would_share_a_name_are_refused(tmp_path):
    (tmp_path / "clash.xml").write_text(CLASH)
    with pytest.raises(InvalidSpec, match=r"two entries of the MuJoCo model's state are both named 'arm_vel'"):
        StartSpace({"arm": (0.0, 1.0)}).resolve(Toy(tmp_path / "clash.xml"))


def test_a_mujoco_env_without_get_obs_is_refused_with_the_hook_to_use(tmp_path):
    (tmp_path / "toy.xml").write_text(TOY)
    with pytest.raises(InvalidSpec, match=r"Unobserved is a MuJoCo env without _get_obs\(\).*\nHint: pass set_state="):
        StartSpace({"joint2": (0.0, 1.0)}).resolve(Unobserved(tmp_path / "toy.xml"))
