"""Falsifying a MuJoCo agent by joint name from the command line, and its counterexample's GIF, without a display.

One tiny InvertedPendulum-v5 agent (PPO, 1,024 steps: it keeps the pole up
from hardly any start) is trained once into a cache the tests share.
"""

from __future__ import annotations

import os
import textwrap

import gymnasium as gym
import numpy as np
import pytest
from PIL import Image

import specguard as sg
from specguard.cli.main import main
from specguard.report import offscreen
from specguard.report.gifs import write_gif

SPEC = """
import specguard as sg

FEATURES = ("slider", "hinge", "slider_vel", "hinge_vel")
PENDULUM = sg.InitialEnv("InvertedPendulum-v5", features=FEATURES, max_episode_steps=100)
BALANCE = sg.Always(sg.Goal("upright", hinge=(-0.1, 0.1)), name="balance")
BUDGET = sg.Budget(timesteps=1024, min_seeds=1, eval_episodes=2, checkpoints=1)
TINY = {"n_steps": 256, "batch_size": 64, "n_epochs": 2}
"""
STARTS = {"hinge": (-0.1, 0.1), "hinge_vel": (-0.5, 0.5)}


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("mujoco") / "cache"


@pytest.mark.slow
def test_the_command_line_falsifies_by_joint_name_with_no_setter_written(tmp_path, cache, capsys):
    path = tmp_path / "ip_specs.py"
    path.write_text(
        SPEC + "balance = sg.Spec(PENDULUM, BALANCE, budget=BUDGET, trainer=sg.SB3(hyperparameters=TINY))\n"
    )
    argv = ["falsify", f"{path}::balance", "--cache-dir", str(cache), "--examples", "40", "--uniform", "20", "--quiet"]
    code = main([*argv, "--starts", "hinge=-0.1:0.1", "hinge_vel=-0.5:0.5"])
    out = capsys.readouterr().out
    assert code == 1, out
    assert "== balance seed 0: COUNTEREXAMPLE" in out
    assert "StartSpace for InvertedPendulum-v5: starts set by state over hinge, hinge_vel" in out
    assert "counterexample (found after" in out and "hinge=" in out and "missed: balance" in out
    # An unknown name is refused before anything trains, in one line listing the env's variables.
    code = main([*argv, "--starts", "theta=-0.1:0.1"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.splitlines()[0].endswith(
        "the start space names 'theta', which its setter does not know; known: slider, hinge, slider_vel, hinge_vel"
    )


def test_the_report_writes_the_counterexamples_gif_without_a_display(pytester, cache, monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)  # specguard picks an off-screen backend itself
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    body = f"""
        @sg.goal_spec(expect={{"balance": 0.5}}, falsify=sg.Falsify({STARTS!r}, examples=20, uniform=0))
        def test_balance():
            return sg.Spec(PENDULUM, BALANCE, budget=BUDGET, trainer=sg.SB3(hyperparameters=TINY))
    """
    pytester.makepyfile(test_specs=SPEC + textwrap.dedent(body))
    pytester.makeini("[pytest]\ngoal_specs_workers = 1\n")
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", f"--goal-specs-cache-dir={cache}", "--goal-specs", "--goal-specs-report=report"
    )
    out = result.stdout.str()
    result.stdout.fnmatch_lines(["*StartSpace for InvertedPendulum-v5: starts set by state over hinge, hinge_vel"])
    result.stdout.fnmatch_lines(["FAILED test_specs.py::test_balance[[]falsify[]] - falsified:"])
    gif = pytester.path / "report" / "test_specs.py__test_balance-falsify-seed0.gif"
    assert gif.exists(), out
    assert f"seed 0: counterexample episode: {gif.relative_to(pytester.path)} (balance, " in out
    with Image.open(gif) as image:
        assert image.format == "GIF" and image.n_frames > 1
        image.seek(0)
        first = np.asarray(image.convert("RGB"))
    assert first.std() > 5  # the pendulum drawn, not a blank frame


class Still:
    """A model whose action is always 0: the pole falls from any start off upright."""

    def predict(self, obs, state=None, episode_start=None, deterministic=False):  # SB3's signature
        return np.zeros(1, dtype=np.float32), None


def factory_spec():
    """The pendulum through a factory that takes no ``render_mode``."""
    namespace: dict = {}
    exec(SPEC, namespace)

    def make_pendulum():
        return gym.make("InvertedPendulum-v5", max_episode_steps=30)

    initial = sg.InitialEnv(make_pendulum, features=namespace["FEATURES"])
    return sg.Spec(initial, namespace["BALANCE"], budget=namespace["BUDGET"])


@pytest.mark.slow
def test_a_factory_without_render_mode_renders_off_screen_and_leaves_mujoco_gl_unset(tmp_path, monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    space = sg.StartSpace({"hinge": (-0.1, 0.1)})
    gif = write_gif(Still(), factory_spec(), tmp_path / "ip.gif", start={"hinge": 0.08}, starts=space)
    assert gif.written, gif.text
    assert gif.frames > 1 and "missed: balance" in gif.text
    with Image.open(gif.path) as image:
        assert image.format == "GIF" and image.n_frames > 1
    assert "MUJOCO_GL" not in os.environ and "PYOPENGL_PLATFORM" not in os.environ


def test_where_no_backend_renders_the_note_says_how_to_enable_it(tmp_path, monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(offscreen, "working_backend", lambda: None)
    gif = write_gif(Still(), factory_spec(), tmp_path / "ip.gif")
    assert not gif.written and not (tmp_path / "ip.gif").exists()
    assert gif.text == (
        "no GIF of spec 'balance': MuJoCo cannot render off-screen here: install EGL (Debian/Ubuntu: "
        "apt-get install libegl1 libgl1-mesa-dri) and set MUJOCO_GL=egl, or OSMesa (apt-get install libosmesa6) "
        "and set MUJOCO_GL=osmesa"
    )
