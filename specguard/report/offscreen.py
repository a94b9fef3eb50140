"""Off-screen frames of MuJoCo envs on a machine without a display: the ``MUJOCO_GL`` backend that works here.

Gymnasium's MuJoCo envs draw ``rgb_array`` frames through an OpenGL context
chosen by the ``MUJOCO_GL`` environment variable (``glfw``, ``egl`` or
``osmesa``), read when an env first renders. Unset, Gymnasium tries ``glfw``
first, which needs a display: on a headless machine every render fails
with an OpenGL error. So, for its own GIFs only (:func:`offscreen`), where
``MUJOCO_GL`` is unset and there is no display, specguard sets the first
backend of :data:`BACKENDS` that renders a frame in a child process (probed
once per process), and unsets it again once the GIF is written. A
``MUJOCO_GL`` of the user's own is never changed.

Where none renders, :data:`ENABLE` says in one line how to enable it. CI
(``.ci/run``) installs the EGL libraries.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import gymnasium as gym

__all__ = ["BACKENDS", "ENABLE", "HOW", "NoOffscreen", "headless", "is_mujoco", "offscreen", "working_backend"]


class NoOffscreen(RuntimeError):
    """A MuJoCo env cannot render here: no display, ``MUJOCO_GL`` unset, and no off-screen backend works.

    An internal signal: :func:`offscreen` raises it; the GIF code turns it into the report's one-line note.
    """


BACKENDS = ("egl", "osmesa")
"""The off-screen backends tried, in order: EGL (Mesa's software renderer without a GPU), then OSMesa."""
HOW = (
    "install EGL (Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri) and set MUJOCO_GL=egl, "
    "or OSMesa (apt-get install libosmesa6) and set MUJOCO_GL=osmesa"
)
"""How to let MuJoCo render without a display, in one line."""
ENABLE = f"MuJoCo cannot render off-screen here: {HOW}"
"""The note where no backend renders."""
PROBE_SECONDS = 120
_PROBE = """
import mujoco
model = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size="1"/></worldbody></mujoco>')
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
with mujoco.Renderer(model, 16, 16) as renderer:
    renderer.update_scene(data)
    assert renderer.render().shape == (16, 16, 3)
"""


def is_mujoco(env: gym.Env) -> bool:
    """Whether ``env.unwrapped`` is a Gymnasium ``MujocoEnv`` (never imports MuJoCo)."""
    from specguard.starts.joints import mujoco_env

    return mujoco_env(env) is not None


def headless() -> bool:
    """Linux without a display (neither ``DISPLAY`` nor ``WAYLAND_DISPLAY``): ``glfw`` cannot open a context."""
    return sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _renders(backend: str) -> bool:
    """Whether MuJoCo renders a frame with ``MUJOCO_GL=backend``, in a child process (a failed OpenGL
    platform cannot be undone in this one)."""
    env = {k: v for k, v in os.environ.items() if k != "PYOPENGL_PLATFORM"} | {"MUJOCO_GL": backend}
    try:
        done = subprocess.run(
            [sys.executable, "-c", _PROBE], env=env, capture_output=True, timeout=PROBE_SECONDS, check=False
        )
    except (OSError, subprocess.SubprocessError):
        return False
    return done.returncode == 0


@functools.cache
def working_backend() -> str | None:
    """The first backend of :data:`BACKENDS` that renders here, or ``None`` (probed once per process)."""
    return next((b for b in BACKENDS if _renders(b)), None)


@contextmanager
def offscreen(env: gym.Env) -> Iterator[str | None]:
    """Within it, ``env`` renders off-screen: for a MuJoCo env on a headless machine with ``MUJOCO_GL`` unset,
    ``MUJOCO_GL`` is set to :func:`working_backend`'s for the duration (unset after, as is the
    ``PYOPENGL_PLATFORM`` that MuJoCo sets with it); otherwise nothing changes.

    Yields:
        The backend set, or ``None`` where nothing was set.

    Raises:
        NoOffscreen: a MuJoCo env on a headless machine where no backend works (its message: :data:`ENABLE`).
    """
    if "MUJOCO_GL" in os.environ or not headless() or not is_mujoco(env):
        yield None
        return
    backend = working_backend()
    if backend is None:
        raise NoOffscreen(ENABLE)
    platform = os.environ.get("PYOPENGL_PLATFORM")  # MuJoCo's EGL and OSMesa modules set it when unset
    os.environ["MUJOCO_GL"] = backend
    try:
        yield backend
    finally:
        os.environ.pop("MUJOCO_GL", None)
        if platform is None:
            os.environ.pop("PYOPENGL_PLATFORM", None)
