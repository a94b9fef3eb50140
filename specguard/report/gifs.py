"""Animated GIFs of a trained policy: one deterministic episode, its last frame captioned with the goals met.

A missing renderer (an env without an ``rgb_array`` render mode, a render
that raises, Pillow not installed) never raises: :func:`write_gif` returns a
:class:`Gif` with a note instead of a path. An env whose factory takes no
``render_mode`` is built without one and told to render ``rgb_array`` frames
(``env.unwrapped.render_mode``); a MuJoCo env on a machine without a display
renders off-screen (:mod:`specguard.report.offscreen`), or the note says how
to enable it. :func:`report_gifs` is what
``pytest --goal-specs --goal-specs-report DIR`` writes: one GIF per spec, of
its first seed's cached model, or of the agent an agent test judged (an
:class:`~specguard.engine.check_agent.AgentCheck`: its agent acts itself, in
the env ``check_agent`` judges it in; nothing is read from the cache).
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from specguard.cache.models import load_cached
from specguard.error import InitialEnvError, SpecError
from specguard.evaluation.episodes import EVAL_SEED_BASE
from specguard.evaluation.policy import policy
from specguard.evaluation.rollout import episode
from specguard.report.offscreen import HOW, NoOffscreen, is_mujoco, offscreen
from specguard.spec.spec import Spec
from specguard.starts.space import START_OPTION, StartSpace

__all__ = ["MAX_FRAMES", "Gif", "NoFrames", "agent_gif", "counterexample_gifs", "gif_stem", "report_gifs", "write_gif"]

MAX_FRAMES = 100  # frames a GIF keeps at most (an episode's frames are subsampled evenly)
LAST_FRAME_MS = 2000  # how long the captioned last frame stays


class NoFrames(Exception):
    """An env's ``render()`` gave no RGB frame, so a GIF cannot be written.

    An internal signal, raised and caught here: the report notes it and goes on.
    """


@dataclass(frozen=True)
class Gif:
    """What :func:`write_gif` did.

    Attributes:
        path: the GIF written, or ``None`` when none could be.
        text: the caption drawn on the last frame (goals met at the end), or,
            without a GIF, a note saying why.
        frames: frames in the GIF.
    """

    path: Path | None
    text: str
    frames: int = 0

    @property
    def written(self) -> bool:
        return self.path is not None


def _subsample(frames: list[Any], limit: int) -> list[Any]:
    """At most ``limit`` frames, evenly spread, keeping the first and the last."""
    if len(frames) <= limit:
        return frames
    n = len(frames) - 1
    return [frames[round(i * n / (limit - 1))] for i in range(limit)]


def _caption(spec: Spec, steps: int, goals: Mapping[str, bool]) -> str:
    met = [p for p, inside in goals.items() if inside]
    missed = [p for p, inside in goals.items() if not inside]
    return f"{spec.label}, {steps} steps; goals met at the end: {', '.join(met) or 'none'}" + (
        f"; missed: {', '.join(missed)}" if missed else ""
    )


def _draw_caption(image: Any, text: str) -> Any:
    from PIL import ImageDraw, ImageFont

    try:
        font: Any = ImageFont.load_default(size=max(10, image.width // 40))
    except (TypeError, OSError):  # an old Pillow, or no FreeType: the bitmap font
        font = ImageFont.load_default()
    draw = ImageDraw.Draw(image)
    lines: list[str] = []
    for word in text.split(" "):  # greedy wrap by the rendered width
        if lines and draw.textlength(f"{lines[-1]} {word}", font=font) <= image.width - 8:
            lines[-1] += f" {word}"
        else:
            lines.append(word)
    line_height = draw.textbbox((0, 0), "Ag", font=font)[3] + 3
    top = max(0, image.height - line_height * len(lines) - 6)
    draw.rectangle((0, top, image.width, image.height), fill=(255, 255, 255), outline=(160, 160, 160))
    for i, line in enumerate(lines):
        draw.text((4, top + 3 + i * line_height), line, fill=(0, 0, 0), font=font)
    return image


def _refuses_render_mode(error: InitialEnvError) -> bool:
    """The initial env's factory (or the env's constructor) does not take the keyword ``render_mode``."""
    cause = error.__cause__
    return isinstance(cause, TypeError) and "render_mode" in str(cause)


def rendering_env(spec: Spec, *, starts: StartSpace | None = None, make: Callable[..., Any] | None = None) -> Any:
    """``spec``'s env, rendering ``rgb_array`` frames: made with ``render_mode="rgb_array"``, or, where its
    factory takes no ``render_mode``, made without and its ``unwrapped.render_mode`` set.

    ``starts``: the start space it is made with (as ``spec.make_env(starts=...)``); ``None``: none.
    ``make``: the env factory, ``make(starts=..., **make_kwargs)`` (an agent's,
    :func:`~specguard.engine.check_agent.agent_envs`); default ``spec.make_env``.

    Raises:
        NoFrames: the env lists its render modes and ``rgb_array`` is not among them.
        SpecError: the env cannot be made (as ``spec.make_env``).
    """
    make = spec.make_env if make is None else make
    try:
        return make(render_mode="rgb_array", starts=starts)
    except InitialEnvError as e:
        if not _refuses_render_mode(e):
            raise
    env = make(starts=starts)
    base = env.unwrapped
    modes = (getattr(base, "metadata", None) or {}).get("render_modes")
    if modes is not None and "rgb_array" not in modes:
        env.close()
        raise NoFrames(f"its factory takes no render_mode, and {type(base).__name__} lists render modes {list(modes)}")
    base.render_mode = "rgb_array"
    return env


def _one_line(error: BaseException) -> str:
    return " ".join(f"{type(error).__name__}: {error}".split())


def write_gif(
    model: Any,
    spec: Spec,
    path: Path | str,
    *,
    seed: int = EVAL_SEED_BASE,
    normalizer: Any = None,
    max_frames: int = MAX_FRAMES,
    start: Mapping[str, float] | None = None,
    starts: StartSpace | None = None,
    make: Callable[..., Any] | None = None,
) -> Gif:
    """Render one deterministic episode of ``model`` on ``spec``'s env into an animated GIF at ``path``.

    ``model``: an SB3 model (with its ``normalizer``), a callable, or an agent trained elsewhere (an
    :class:`~specguard.agents.agent.Agent`, acting as loaded, in the env ``make`` builds:
    :func:`rendering_env`'s ``make``).

    The env is made with ``render_mode="rgb_array"`` (:func:`rendering_env`); frames are subsampled
    evenly to at most ``max_frames``; the last frame carries the caption: the
    goals met (and missed) when the episode ended (``info["goals"]``).

    ``start`` (with the space it was drawn from, ``starts``; ``None``: the env's
    own) puts the env in that start first, as the falsifier's episodes begin:
    the episode of a counterexample, replayed.

    Returns:
        The GIF's path and caption; or no path and a note when the env cannot
        render ``rgb_array`` frames or Pillow is missing (never an error for those).
    """
    import numpy as np

    try:
        from PIL import Image
    except ImportError:
        return Gif(None, f"no GIF of spec {spec.label!r}: Pillow is not installed (pip install pillow)")
    try:
        # Frames are drawn off-screen: SDL needs no display (and prints no complaint about a missing one).
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
        options = None
        if start is not None:  # as the falsifier's runner: made with the start space, reset seed 0
            options, seed = {START_OPTION: dict(start)}, 0
        env = rendering_env(spec, starts=(starts or StartSpace()) if start is not None else None, make=make)
    except NoFrames as e:
        return Gif(None, f"no GIF of spec {spec.label!r}: its env does not render rgb_array frames ({e})")
    except Exception as e:
        return Gif(None, f"no GIF of spec {spec.label!r}: its env cannot be made to render rgb_array frames ({e})")
    from specguard.agents.agent import Agent, check_fits

    if isinstance(model, Agent):  # as check_agent has it act: its actions checked against the env's action space
        act: Any = model if not model.batch else model.batched(False)
        try:
            check_fits(act, env.observation_space, env.action_space)
        except Exception as e:
            env.close()
            return Gif(None, f"no GIF of spec {spec.label!r}: {_one_line(e)}")
    else:
        act = policy(model, normalizer, deterministic=True)
    frames: list[Any] = []
    stride = 1
    last = -1

    def capture(step: int) -> None:
        # Keep every `stride`-th frame; when twice the limit is held, drop every other and double the stride,
        # so a long episode never holds more than 2 * max_frames frames in memory.
        nonlocal stride, last, frames
        if step % stride:
            return
        frame = env.render()
        if not (isinstance(frame, np.ndarray) and frame.ndim == 3 and frame.shape[-1] in (3, 4)):
            raise NoFrames(f"render() returned {type(frame).__name__}, not an RGB array")
        frames.append(frame)
        last = step
        if len(frames) > 2 * max_frames:
            frames, stride = frames[::2], stride * 2

    try:
        try:
            with offscreen(env):
                steps = episode(env, act, seed, capture, options)
                if last != len(steps):  # the final state, whatever the stride
                    frame = env.render()
                    if isinstance(frame, np.ndarray):
                        frames.append(frame)
        finally:
            env.close()
    except NoOffscreen as e:
        return Gif(None, f"no GIF of spec {spec.label!r}: {e}")
    except NoFrames as e:
        return Gif(None, f"no GIF of spec {spec.label!r}: its env does not render rgb_array frames ({e})")
    except Exception as e:
        how = f"; to render MuJoCo off-screen, {HOW}" if is_mujoco(env) else ""
        return Gif(None, f"no GIF of spec {spec.label!r}: rendering failed ({_one_line(e)}){how}")
    goals = steps[-1]["info"].get("goals", {}) if steps else {}
    caption = _caption(spec, len(steps), goals)
    images = [Image.fromarray(np.asarray(f[..., :3], dtype=np.uint8)) for f in _subsample(frames, max_frames)]
    images[-1] = _draw_caption(images[-1], caption)
    fps = float(getattr(env, "metadata", {}).get("render_fps") or 30)
    shown = max(1.0, (len(steps) + 1) / len(images))  # episode steps per GIF frame
    duration = [max(20, round(1000 * shown / fps))] * (len(images) - 1) + [LAST_FRAME_MS]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:], duration=duration, loop=0, optimize=False)
    return Gif(path, caption, len(images))


_PLAIN = re.compile(r"[a-z0-9.-]+(?:(?:::|_)[a-z0-9.-]+)*")  # keys whose readable name is their own, one to one
_FALSIFY = "-falsify-seed"
_READABLE = 60  # characters of a key kept in a hashed name


def gif_stem(group: str, *, falsify_seed: int | None = None) -> str:
    """The file name (without ``.gif``) of a spec's rollout GIF, or of its counterexample for ``falsify_seed``.

    Unique and stable per spec key: a plain key (lower-case letters, digits,
    ``.``, ``-``, single ``_``, ``::``) keeps its own name, ``::`` written
    ``__``; any other (``/``, spaces, brackets, capitals, accents, a long key)
    gets a readable part and ``~`` with a hash of the whole key, so keys that
    read alike never share a file, on a case-insensitive disk either.

    Example:
        >>> gif_stem("t.py::test_up"), gif_stem("t.py::test_up", falsify_seed=0)
        ('t.py__test_up', 't.py__test_up-falsify-seed0')
        >>> gif_stem("t.py::test_[a/b]")
        't.py__test__a_b~da266a8a3e'
    """
    readable = group.replace("::", "__")
    lossless = len(group) <= _READABLE and _PLAIN.fullmatch(group) and not re.search(rf"{_FALSIFY}\d+$", group)
    if not lossless:
        digest = hashlib.sha256(group.encode()).hexdigest()[:10]
        readable = re.sub(r"[^A-Za-z0-9_.-]+", "_", readable)[:_READABLE].strip("_") or "spec"
        readable = f"{readable}~{digest}"
    return readable if falsify_seed is None else f"{readable}{_FALSIFY}{falsify_seed}"


def report_gifs(
    directory: Path,
    rows: Sequence[Mapping[str, Any]],
    specs: Mapping[str, Spec],
    cache_dir: Path | str | None,
    agents: Mapping[str, Any] | None = None,
) -> dict[str, Gif]:
    """One GIF per spec (group) of ``rows``: its first seed's cached model, or its agent's, written to ``directory``.

    Args:
        specs: the trained spec of each group; a group without one (the xdist
            controller, which built no spec) gets a note instead of a GIF.
        cache_dir: the run cache; ``None`` (no cache): notes only, except for an agent's group.
        agents: per agent test's group, its :class:`~specguard.engine.check_agent.AgentCheck` (its agent loaded or
            loadable): the GIF is the agent's own first evaluation episode (the env seed of its episode 0), in the
            env ``check_agent`` judged it in; no cache is read.

    Returns:
        Per group, the GIF or the note saying why there is none; never raises.
    """
    gifs: dict[str, Gif] = {}
    for row in rows:
        group = row["group"]
        if group in gifs:
            continue
        spec = specs.get(group)
        seeds = [s["seed"] for s in row.get("per_seed") or []]
        if spec is None:
            gifs[group] = Gif(None, "no rollout GIF: the spec was built in another process (pytest-xdist worker)")
        elif group in (agents or {}):
            try:
                gifs[group] = agent_gif((agents or {})[group], directory / f"{gif_stem(group)}.gif")
            except Exception as e:  # a report must not fail the session
                gifs[group] = Gif(None, f"no rollout GIF: {_one_line(e)}")
        elif cache_dir is None:
            gifs[group] = Gif(None, "no rollout GIF: the run cache is off (--goal-specs-no-cache), no model to load")
        elif not seeds:
            gifs[group] = Gif(None, "no rollout GIF: no run of the spec finished")
        else:
            try:
                model, normalizer = load_cached(spec, seeds[0], cache_dir)
                gif = write_gif(model, spec, directory / f"{gif_stem(group)}.gif", normalizer=normalizer)
                gifs[group] = gif
            except Exception as e:  # a report must not fail the session
                gifs[group] = Gif(None, f"no rollout GIF: {type(e).__name__}: {e}")
    return gifs


def agent_gif(
    check: Any, path: Path | str, *, start: Mapping[str, float] | None = None, starts: StartSpace | None = None
) -> Gif:
    """A GIF of the agent of ``check`` (an :class:`~specguard.engine.check_agent.AgentCheck`), acting as loaded
    in the env :func:`~specguard.engine.check_agent.check_agent` judges it in (its ``observation`` and ``wrap``):
    its evaluation episode 0, or the episode from ``start`` (a counterexample's, in ``starts``).

    Raises:
        AgentError: the agent cannot be loaded (a loaded one is used as it is).

    Example:
        >>> import tempfile, specguard as sg
        >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
        >>> spec = sg.Spec(cartpole, sg.Goal("right", theta=(0.1, None)), budget=sg.Budget(timesteps=1))
        >>> gif = agent_gif(sg.AgentCheck(spec, lambda obs: 1), Path(tempfile.mkdtemp()) / "a.gif")
        >>> gif.path.name, gif.frames > 1
        ('a.gif', True)
    """
    from specguard.engine.check_agent import agent_envs, agent_wrap, seed_base, spec_agent

    spec = check.spec
    agent = spec_agent(spec, check.agent, algorithm=check.algorithm, batch=False, trust=check.trust)
    make = agent_envs(spec, check.observation, agent_wrap(agent, check.wrap))
    return write_gif(agent, spec, path, seed=seed_base(check.seed), start=start, starts=starts, make=make)


def counterexample_gifs(
    directory: Path,
    group: str,
    result: Any,
    found: Mapping[int, Any],
    starts: StartSpace | None,
    agent: Any = None,
) -> dict[int, Gif]:
    """A GIF of each run's counterexample episode (``found``: per seed, its falsification), in ``directory``.

    ``agent``: the :class:`~specguard.engine.check_agent.AgentCheck` falsified (``result`` is then unused): its
    agent's episode from the counterexample's start (:func:`agent_gif`), no cache read.

    Returns:
        Per seed with a counterexample, its GIF or the note saying why there is none; never raises for a
        missing renderer.
    """
    gifs: dict[int, Gif] = {}
    for seed, falsification in sorted(found.items()):
        if falsification.counterexample is None:
            continue
        path = directory / f"{gif_stem(group, falsify_seed=seed)}.gif"
        start = falsification.counterexample.start
        if agent is not None:
            try:
                gifs[seed] = agent_gif(agent, path, start=start, starts=starts)
            except SpecError as e:
                gifs[seed] = Gif(None, f"no GIF: {e}")
            continue
        if result.cache_dir is None or result.trained is None:
            gifs[seed] = Gif(None, "no GIF: the run cache is off, no model to load")
            continue
        model, normalizer = load_cached(result.trained, seed, result.cache_dir)
        gifs[seed] = write_gif(model, result.trained, path, normalizer=normalizer, start=start, starts=starts)
    return gifs
