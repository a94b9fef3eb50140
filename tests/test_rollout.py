"""Rollouts of a trained policy and their GIFs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from PIL import Image

import specguard as sg
from specguard.cache.models import load_cached
from specguard.cache.store import Cache
from specguard.evaluation.rollout import rollout_model
from specguard.report.gifs import Gif, report_gifs, write_gif
from specguard.training.train import train_run

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}


def cartpole_spec(**kwargs):
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    # the root (both goals) is hardly reached, so the episode runs until the pole falls: many frames
    tree = sg.All(sg.Goal("centre", x=(-0.5, 0.5)), sg.Goal("fast", v=(2.0, 100.0)), name="cartpole")
    budget = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=2)
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=TINY))
    return sg.Spec(cartpole, tree, budget=budget, **kwargs)


@pytest.fixture(scope="module")
def trained():
    spec = cartpole_spec()
    result, model = train_run(spec, 0)
    return spec, result, model


@pytest.mark.slow
def test_rollout_returns_the_steps_of_each_episode(trained):
    spec, _, model = trained
    episodes = rollout_model(model, spec, episodes=2)
    assert len(episodes) == 2
    for steps in episodes:
        assert steps and all(set(s) == {"obs", "action", "reward", "terminated", "truncated", "info"} for s in steps)
        assert steps[-1]["terminated"] or steps[-1]["truncated"]
        assert not any(s["terminated"] or s["truncated"] for s in steps[:-1])
        assert set(steps[-1]["info"]["goals"]) == {"cartpole", "cartpole/centre", "cartpole/fast"}
    again = rollout_model(model, spec, episodes=2)  # deterministic policy, seeded episodes
    assert [len(s) for s in again] == [len(s) for s in episodes]
    assert np.array_equal(again[1][-1]["obs"], episodes[1][-1]["obs"])


@pytest.mark.slow
def test_gif_has_the_episode_and_a_caption_naming_the_goals(trained, tmp_path):
    spec, _, model = trained
    gif = write_gif(model, spec, tmp_path / "cartpole.gif")
    assert gif.written and gif.path == tmp_path / "cartpole.gif"
    with Image.open(gif.path) as image:
        assert image.format == "GIF" and image.n_frames > 1
        image.seek(0)
        first = np.asarray(image.convert("L"))
        image.seek(image.n_frames - 1)
        last = np.asarray(image.convert("L"))
    # the caption is drawn at the bottom of the last frame (CartPole leaves that area blank)
    assert (first[-20:] < 100).sum() == 0 and (last[-20:] < 100).sum() > 50
    (steps,) = rollout_model(model, spec)  # the same episode: same seed, deterministic
    goals = steps[-1]["info"]["goals"]
    met = ", ".join(p for p, inside in goals.items() if inside) or "none"
    assert f"{len(steps)} steps; goals met at the end: {met}" in gif.text
    assert all(path in gif.text for path in goals)


@pytest.mark.slow
def test_a_gif_from_a_start_replays_the_falsifiers_episode_from_it(trained, tmp_path):
    from specguard.engine.falsify_run import batch_policy, property_keys
    from specguard.falsify.search import EpisodeRunner

    spec, _, model = trained
    space = sg.StartSpace({"theta": (-0.2, 0.2), "omega": (-1.0, 1.0)})
    runner = EpisodeRunner(spec.make_env, batch_policy(model, None, True), space, property_keys(spec))
    points = np.array([[0.0, 0.0, 0.19, 0.9], [0.0, 0.0, -0.19, -0.9], [0.0, 0.0, 0.0, 0.0]])
    outcomes = runner.run(points)
    assert len({o.steps for o in outcomes}) > 1  # the starts make different episodes
    for k, outcome in enumerate(outcomes):
        gif = write_gif(model, spec, tmp_path / f"start{k}.gif", start=outcome.start, starts=space)
        assert gif.written and f"{outcome.steps} steps;" in gif.text


@pytest.mark.slow
def test_long_episodes_are_subsampled(trained, tmp_path):
    spec, _, model = trained
    gif = write_gif(model, spec, tmp_path / "few.gif", max_frames=5)
    assert gif.written and 1 < gif.frames <= 5


class Blind(gym.Env):
    """An env that renders nothing."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (1,), dtype=np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, render_mode=None):
        self.render_mode = render_mode

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(1, dtype=np.float32), {}

    def step(self, action):
        return np.zeros(1, dtype=np.float32), 0.0, True, False, {}

    def render(self):
        return None


def blind_spec():
    tree = sg.All(sg.Goal("right", x=(0.5, 1.0)), name="blind")  # not where it starts (GoalMetAtStart)
    return sg.Spec(sg.InitialEnv(Blind, features=("x",)), tree, budget=sg.Budget(timesteps=64, min_seeds=1))


class Model:
    def predict(self, obs, state=None, episode_start=None, deterministic=False):  # SB3's signature
        return np.int64(0), None


def test_an_env_without_rgb_array_frames_gives_a_note(tmp_path):
    gif = write_gif(Model(), blind_spec(), tmp_path / "blind.gif")
    assert gif == Gif(None, gif.text) and "does not render rgb_array frames" in gif.text
    assert not (tmp_path / "blind.gif").exists()


@pytest.mark.slow
def test_a_factory_without_render_mode_is_told_to_render_rgb_array_frames(trained, tmp_path):
    spec, _, model = trained

    def make_cartpole():  # takes no render_mode
        return gym.make("CartPole-v1")

    made = sg.Spec(sg.InitialEnv(make_cartpole, features=spec.initial_env.features), spec.tree, budget=spec.budget)
    gif = write_gif(model, made, tmp_path / "factory.gif")
    assert gif.written and gif.frames > 1
    with Image.open(gif.path) as image:
        assert image.format == "GIF" and image.n_frames > 1
    (steps,) = rollout_model(model, spec)  # the same episode as the env made with render_mode
    assert f"{len(steps)} steps;" in gif.text


def test_a_factory_without_render_mode_whose_env_lists_no_rgb_array_mode_gives_a_note(tmp_path):
    spec = blind_spec()
    spec = sg.Spec(
        sg.InitialEnv(lambda: Blind(), features=("x",)), spec.tree, budget=spec.budget
    )  # the factory takes no render_mode, and Blind lists no render mode
    gif = write_gif(Model(), spec, tmp_path / "blind.gif")
    assert not gif.written and gif.text == (
        "no GIF of spec 'blind': its env does not render rgb_array frames "
        "(its factory takes no render_mode, and Blind lists render modes [])"
    )


def test_a_render_that_raises_gives_a_note(tmp_path, monkeypatch):
    def broken(self):
        raise RuntimeError("no display")

    monkeypatch.setattr(Blind, "render", broken)
    gif = write_gif(Model(), blind_spec(), tmp_path / "blind.gif")
    assert not gif.written and "rendering failed (RuntimeError: no display)" in gif.text


@pytest.mark.slow
def test_report_gifs_load_the_first_seeds_cached_model(trained, tmp_path):
    spec, result, model = trained
    Cache(tmp_path / "cache").store(spec, 0, result, model)
    loaded, normalizer = load_cached(spec, 0, tmp_path / "cache")
    assert normalizer is None and type(loaded) is type(model)
    rows = [
        {"group": "t.py::test_cart", "per_seed": [{"seed": 0}]},
        {"group": "t.py::test_cart", "per_seed": [{"seed": 0}]},
        {"group": "t.py::test_elsewhere", "per_seed": [{"seed": 0}]},
        {"group": "t.py::test_uncached", "per_seed": [{"seed": 3}]},
    ]
    specs = {"t.py::test_cart": spec, "t.py::test_uncached": spec}
    gifs = report_gifs(tmp_path / "r", rows, specs, tmp_path / "cache")
    assert list(gifs) == ["t.py::test_cart", "t.py::test_elsewhere", "t.py::test_uncached"]
    assert gifs["t.py::test_cart"].path == tmp_path / "r" / "t.py__test_cart.gif" and gifs["t.py::test_cart"].frames > 1
    assert "another process" in gifs["t.py::test_elsewhere"].text and not gifs["t.py::test_elsewhere"].written
    assert "not in the cache" in gifs["t.py::test_uncached"].text
    assert "cache is off" in report_gifs(tmp_path / "r", rows[:1], specs, None)["t.py::test_cart"].text


@pytest.mark.slow
def test_writing_a_gif_prints_nothing_to_stderr(tmp_path):
    # SDL complains on stderr about a missing display ("XDG_RUNTIME_DIR is invalid") unless told it has none.
    import os
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent(
        """
        import sys
        import specguard as sg
        from specguard.training.train import train_run
        from specguard.report.gifs import write_gif

        pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
        up = sg.Goal("up", x=(0.9, 1.0), omega=(-0.1, 0.1))  # met at none of the sampled starts: no SpecWarning
        spec = sg.Spec(pendulum, up, budget=sg.Budget(timesteps=64, eval_episodes=1),
                       trainer=sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1}))
        _, model = train_run(spec, seed=0)
        gif = write_gif(model, spec, sys.argv[1], max_frames=5)
        assert gif.written, gif.text
        """
    )
    env = {k: v for k, v in os.environ.items() if k not in ("XDG_RUNTIME_DIR", "SDL_VIDEODRIVER")}
    done = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "a.gif")], capture_output=True, text=True, env=env, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == ""


@pytest.mark.slow
def test_a_policy_acts_on_one_torch_thread_and_the_process_keeps_its_setting(trained, monkeypatch):
    # Two threads for a few-row batch of a small network were 60 times slower on a busy 2-core machine.
    import torch

    from specguard.engine.falsify_run import falsify_run

    spec, _, model = trained
    seen: list[int] = []
    predict = model.predict

    def counting(*args, **kwargs):
        seen.append(torch.get_num_threads())
        return predict(*args, **kwargs)

    monkeypatch.setattr(model, "predict", counting)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        rollout_model(model, spec, episodes=1)
        falsify_run(spec, model, None, seed=0, spec_key=None, examples=2, uniform=0)
        assert seen and set(seen) == {1}
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
