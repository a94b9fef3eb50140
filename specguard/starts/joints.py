"""Start variables of Gymnasium's MuJoCo envs: the model's joints, positions and velocities, set by ``set_state``.

For an env whose ``unwrapped`` is a ``gymnasium.envs.mujoco.MujocoEnv``, each
joint ``J`` of the model (``model.joint(i).name``; an unnamed joint is
``joint<i>``, ``i`` its index in the model) gives these variables:

============  =================================  ===============================================
joint type    position (``qpos``)                velocity (``qvel``)
============  =================================  ===============================================
hinge, slide  ``J``                              ``J_vel``
ball          ``J_qw, J_qx, J_qy, J_qz``         ``J_vel_rx, J_vel_ry, J_vel_rz``
free          ``J_x, J_y, J_z, J_qw, ..., J_qz`` ``J_vel_x, J_vel_y, J_vel_z, J_vel_rx, ..., J_vel_rz``
============  =================================  ===============================================

All positions come first, in the model's joint order, then all velocities,
as ``qpos`` and ``qvel`` are laid out. A limited joint's position is bounded
by its range (``jnt_range``), a quaternion's components by ``[-1, 1]``
(the quaternion is normalised once set), anything else is unbounded.

A start is set as the falsifier's episodes begin: the env is reset (seed 0),
the named variables replace their entries of ``qpos`` and ``qvel``, the rest
keep what the reset gave, and ``set_state(qpos, qvel)`` puts the env there;
the observation is the env's own ``_get_obs()`` of that state. No variable
has a default range: one the start space leaves out is not searched.

Nothing here imports MuJoCo: an env is a MuJoCo env only where Gymnasium's
``mujoco_env`` module was already imported (making one imports it).

Example:
    >>> import gymnasium as gym
    >>> joint_setter(gym.make("CartPole-v1")) is None
    True
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from specguard.error import InvalidSpec
from specguard.starts.setter import Range, Setter, env_label

__all__ = ["joint_setter", "mujoco_env"]

_FREE, _BALL = 0, 1  # mujoco.mjtJoint.mjJNT_FREE, mjJNT_BALL (slide 2, hinge 3: one qpos, one qvel entry)
_QUATERNION = ("qw", "qx", "qy", "qz")
_POSITION_SUFFIXES: Mapping[int, tuple[str, ...]] = {_FREE: ("x", "y", "z", *_QUATERNION), _BALL: _QUATERNION}
_VELOCITY_SUFFIXES: Mapping[int, tuple[str, ...]] = {
    _FREE: ("vel_x", "vel_y", "vel_z", "vel_rx", "vel_ry", "vel_rz"),
    _BALL: ("vel_rx", "vel_ry", "vel_rz"),
}
_UNBOUNDED: Range = (-math.inf, math.inf)


def mujoco_env(env: gym.Env) -> Any | None:
    """``env.unwrapped`` if it is a Gymnasium ``MujocoEnv`` (never imports MuJoCo), else ``None``."""
    module = sys.modules.get("gymnasium.envs.mujoco.mujoco_env")
    base = getattr(module, "MujocoEnv", None)
    return env.unwrapped if base is not None and isinstance(env.unwrapped, base) else None


def _slots(where: str, model: Any) -> tuple[dict[str, tuple[str, int]], dict[str, Range], list[int]]:
    """Per variable, its array (``"qpos"`` or ``"qvel"``) and index there, and its bounds; where quaternions start."""
    positions: dict[str, tuple[str, int]] = {}
    velocities: dict[str, tuple[str, int]] = {}
    bounds: dict[str, Range] = {}
    quaternions: list[int] = []
    for i in range(model.njnt):
        joint = model.joint(i)
        name = joint.name or f"joint{i}"
        kind = int(np.ravel(joint.type)[0])
        qpos, dof = int(np.ravel(joint.qposadr)[0]), int(np.ravel(joint.dofadr)[0])
        position_names = [f"{name}_{s}" for s in _POSITION_SUFFIXES[kind]] if kind in _POSITION_SUFFIXES else [name]
        velocity_names = (
            [f"{name}_{s}" for s in _VELOCITY_SUFFIXES[kind]] if kind in _VELOCITY_SUFFIXES else [f"{name}_vel"]
        )
        for k, variable in enumerate(position_names):
            _add(where, positions, bounds, variable, ("qpos", qpos + k), _position_bounds(model, i, kind, variable))
        for k, variable in enumerate(velocity_names):
            _add(where, velocities, bounds, variable, ("qvel", dof + k), _UNBOUNDED)
        if kind in (_FREE, _BALL):
            quaternions.append(qpos + len(position_names) - 4)
    return positions | velocities, bounds, quaternions


def _add(
    where: str,
    slots: dict[str, tuple[str, int]],
    bounds: dict[str, Range],
    name: str,
    slot: tuple[str, int],
    rng: Range,
) -> None:
    if name in bounds:
        raise InvalidSpec(
            where,
            f"two entries of the MuJoCo model's state are both named {name!r} (joint names and their suffixes clash)",
            hint="rename a joint in the model, or pass set_state=fn(env, values)",
        )
    slots[name], bounds[name] = slot, rng


def _position_bounds(model: Any, joint: int, kind: int, variable: str) -> Range:
    if kind in (_FREE, _BALL):
        return (-1.0, 1.0) if variable.rsplit("_", 1)[-1] in _QUATERNION else _UNBOUNDED
    if bool(model.jnt_limited[joint]):
        lo, hi = (float(v) for v in model.jnt_range[joint])
        return lo, hi
    return _UNBOUNDED


def joint_setter(env: gym.Env) -> Setter | None:
    """The setter of a MuJoCo env's joints (see the module), or ``None`` when ``env`` is no ``MujocoEnv``.

    Raises:
        InvalidSpec: two variables would share a name, or the env has no ``_get_obs()`` to observe a set state.
    """
    unwrapped = mujoco_env(env)
    if unwrapped is None:
        return None
    where = f"StartSpace for {env_label(env)}"
    if not callable(getattr(unwrapped, "_get_obs", None)):
        raise InvalidSpec(
            where,
            f"{type(unwrapped).__name__} is a MuJoCo env without _get_obs(): the observation of a set state is unknown",
            hint="pass set_state=fn(env, values), which sets the state and returns its observation",
        )
    slots, bounds, quaternions = _slots(where, unwrapped.model)

    def apply(env: gym.Env, values: Mapping[str, float]) -> Any:
        u: Any = env.unwrapped
        qpos, qvel = np.array(u.data.qpos, dtype=np.float64), np.array(u.data.qvel, dtype=np.float64)
        arrays = {"qpos": qpos, "qvel": qvel}
        for name, value in values.items():
            array, index = slots[name]
            arrays[array][index] = value
        for a in quaternions:  # a start is a state the model can be in: unit quaternions (0 is the identity)
            norm = float(np.linalg.norm(qpos[a : a + 4]))
            qpos[a : a + 4] = qpos[a : a + 4] / norm if norm > 0 else (1.0, 0.0, 0.0, 0.0)
        u.set_state(qpos, qvel)
        return u._get_obs()

    return Setter(names=tuple(slots), bounds=bounds, default={}, apply=apply)
