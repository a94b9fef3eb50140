"""Look before you train: a spec as text (tree, reward formula, observation layout, budget), and its plan.

:func:`render_spec` is the one rendering, used by ``specguard show`` and by
``pytest --goal-specs --goal-specs-show``; it builds the env (to read its
observation space, and so runs the static checks of :mod:`specguard.construction.preflight`)
but trains nothing. :func:`show_goal_spec_file` shows the goal specs of a
pytest file, whose fixtures only pytest can resolve (conftest files, other
plugins' fixtures, ``request``), by running ``python -m pytest --goal-specs-show``
on it in a child process: the CLI imports neither pytest nor the plugin, and
the user's test file is imported by pytest, not into the CLI's process.
:func:`plan_text` is the plan of a goal item's spec (``--goal-specs-plan``,
:mod:`specguard.gate.plan`), and :func:`plan_goal_spec_file` the same for
``specguard plan`` on a pytest file.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path
from typing import Any

from specguard.spec.spec import Spec
from specguard.tree.formula import formula
from specguard.tree.nodes import Node
from specguard.utils.text import bounds_text

__all__ = [
    "SHOWN",
    "SHOW_PROPERTY",
    "has_goal_specs",
    "plan_goal_spec_file",
    "plan_text",
    "render_spec",
    "render_tree",
    "show_goal_spec_file",
]

SHOW_PROPERTY = "specguard.show"  # the user property that carries a rendered spec to the summary
SHOWN = "shown, not trained"  # the skip reason of a goal item under --goal-specs-show


def render_tree(tree: Node) -> list[str]:
    """The tree drawn, then its reward formula."""
    return [tree.pretty(), formula(tree)]


def _layout(spec: Spec) -> list[str]:
    import gymnasium as gym

    from specguard.construction.env import SPEC_KEY, features_space, make_baseline_env, make_env

    if spec.baseline:
        env: Any = make_baseline_env(spec.initial_env, spec.tree)
        try:
            return [f"observation: the initial env's own, {env.observation_space}"]
        finally:
            env.close()
    env = make_env(spec.initial_env, spec.tree, observation=spec.observation)
    try:
        space = features_space(env.observation_space)
        names = list(spec.initial_env.features) + [f"{slot.name} {k}" for k, slot in env.evaluator.slots]
        parts = "features, then the own state of nodes and annotations"
        if spec.observation == "features":
            lines = [f"observation: {len(names)} components ({parts})"]
        else:
            lines = [f"observation: a Dict; {SPEC_KEY!r}: {len(names)} components ({parts})"]
        width = max(len(n) for n in names)
        for name, lo, hi in zip(names, space.low.tolist(), space.high.tolist()):
            lines.append(f"  {name:<{width}}  {bounds_text(lo, hi)}")
        if isinstance(env.observation_space, gym.spaces.Dict):
            lines.append("beside it, the initial env's own observation:")
            lines += [f"  {k!r}: {part}" for k, part in env.observation_space.spaces.items() if k != SPEC_KEY]
        return lines
    finally:
        env.close()


def _budget(spec: Spec) -> str:
    b = spec.budget
    steps = spec.trainer.steps_text(b.timesteps)
    seeds = f"{b.min_seeds} seeds" + (f" (up to {b.max_seeds})" if b.max_seeds != b.min_seeds else "")
    cap = f", wall clock <= {b.wall_clock_s:g}s" if b.wall_clock_s is not None else ""
    anytime = (
        f"; judged at {b.checkpoints} checkpoints, training stops once every threshold is met"
        if b.checkpoints > 1
        else ""
    )
    return f"budget: {steps}, {seeds}, {b.eval_episodes} eval episodes (up to {b.max_eval_episodes}){cap}{anytime}"


def render_spec(spec: Spec, name: str | None = None) -> str:
    """A spec as text: header, tree, reward formula, observation layout, budget, thresholds, xfail; trains nothing.

    Raises:
        SpecError: the env cannot be built or the spec is refused
            (e.g. :class:`specguard.error.UnreachableGoal`).
    """
    kind = "baseline: the initial env's own reward" if spec.baseline else "constructed env"
    lines = [
        f"== {name or spec.label}",
        f"{spec.initial_env!r}, {spec.trainer.title}, {kind}",
        *render_tree(spec.tree),
        *_layout(spec),
        _budget(spec),
    ]
    if spec.thresholds:
        lines.append("expect: " + ", ".join(f"{p} >= {t:g}" for p, t in spec.thresholds.items()))
    lines.extend(f"xfail: {path} may miss ({reason})" for path, reason in spec.xfail.items())
    return "\n".join(lines)


def has_goal_specs(path: Path) -> bool:
    """Whether the Python file ``path`` declares goal specs for pytest (read, not imported): test functions with
    ``@goal_spec``, or tests made by ``goal_specs(...)``."""
    try:
        module = ast.parse(path.read_text(), filename=str(path))
    except (OSError, SyntaxError, ValueError):
        return False

    def name(node: ast.expr) -> str | None:
        target = node.func if isinstance(node, ast.Call) else node
        return target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", None)

    for node in ast.walk(module):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            if any(name(deco) == "goal_spec" for deco in node.decorator_list):
                return True
        elif isinstance(node, ast.Call) and name(node) == "goal_specs":
            return True
    return False


def show_goal_spec_file(target: str) -> int:
    """Show the goal specs of a pytest file ``PATH[::TEST]``: pytest resolves their fixtures; nothing trains.

    Returns:
        0 when every spec was shown, else 2 (pytest's report says which failed).
    """
    return _look_at_goal_spec_file(target, "--goal-specs-show")


def plan_goal_spec_file(target: str, *, compare_seeds: int) -> int:
    """Print the plan of the goal specs of a pytest file ``PATH[::TEST]`` (``--goal-specs-plan``); nothing trains."""
    return _look_at_goal_spec_file(target, "--goal-specs-plan", f"--goal-specs-compare-seeds={compare_seeds}")


def _look_at_goal_spec_file(target: str, *flags: str) -> int:
    """``python -m pytest PATH[::TEST] --goal-specs FLAGS`` in a child process, its output on ours: 0 if it passed."""
    path, _, test = target.partition("::")
    args = [f"{path}::{test}" if test else path, "--goal-specs", *flags, "-q", "-p", "no:cacheprovider"]
    sys.stdout.flush()  # what was printed before comes before pytest's lines
    done = subprocess.run([sys.executable, "-m", "pytest", *args], check=False)
    return 0 if done.returncode == 0 else 2


def plan_text(spec: Spec, group: str, *, family: int, compare_seeds: int, baseline: Any = None) -> str:
    """The plan of a goal item's spec (:mod:`specguard.gate.plan`), its baseline's figures where it has them."""
    from specguard.gate.plan import plan_spec
    from specguard.report.plan_lines import plan_lines

    runs = None
    if baseline is not None:
        keys = {path: f"{group}::{path}" for path in spec.thresholds}
        runs = {path: baseline.runs[key] for path, key in keys.items() if key in baseline.runs}
    plan = plan_spec(spec, family=family, compare_seeds=compare_seeds, baseline=runs, label=group)
    return "\n".join(plan_lines(plan))


def agent_plan_text(check: Any, group: str, *, family: int, baseline: Any = None) -> str:
    """What an agent item's gate can see (``--goal-specs-plan``), playing nothing: the episodes it is paired on (the
    agent its baseline saved, :mod:`specguard.gate.saved_agent`), the level of each comparison, and the smallest
    bound on a drop those pairs give (none discordant), which must be under the margin for a comparison to be fine.

    Example:
        >>> import specguard as sg
        >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
        >>> spec = sg.Spec(cartpole, sg.Goal("right", theta=(0.1, None)), budget=sg.Budget(timesteps=1), expect=0.3)
        >>> text = agent_plan_text(sg.AgentCheck(spec, print, max_episodes=40), "t.py::test", family=4)
        >>> text.splitlines()[1].split(";")[0]
        'comparison with a baseline: a saved baseline stores its 40 episodes'
        >>> "with no discordant pair a drop is at most 10 points, under the margin of 20" in text
        True
    """
    from specguard.engine.check_agent import agent_stages
    from specguard.stats.family import first_level
    from specguard.stats.paired import TEST, drop_upper_bound
    from specguard.stats.sequential import DEFAULT_ALPHA, DEFAULT_MARGIN

    head = f"{group}: an agent trained elsewhere (AgentCheck), judged by check_agent: nothing to train"
    saved = baseline.agents.get(group) if baseline is not None else None
    if baseline is not None and saved is None:
        return f"{head}\ncomparison with a baseline: none, the baseline holds no agent saved for this test"
    if saved is None:
        n = agent_stages("AgentCheck", check.spec, check.episodes, check.max_episodes)[-1]
        where = f"a saved baseline stores its {n} episodes; a new agent is paired on them"
    else:
        n = len(saved.seeds)
        where = f"paired on {n} saved episodes (agent {saved.name!r}, env seeds {saved.seeds[0]}..{saved.seeds[-1]})"
    bound = drop_upper_bound(0, 0, n)
    fine = "under" if bound < DEFAULT_MARGIN else "not under: no comparison can be fine, only dropped or undecided"
    return (
        f"{head}\ncomparison with a baseline: {where}; {TEST}, each judged at "
        f"{first_level(DEFAULT_ALPHA, family):.2g} (5% over {family} comparisons, Holm's first step); with no "
        f"discordant pair a drop is at most {bound * 100:.0f} points, {fine} the margin of {DEFAULT_MARGIN * 100:.0f}"
    )
