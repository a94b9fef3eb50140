"""specguard: pytest for reinforcement-learning specifications.

State what an agent must achieve as a goal tree, get a trainable Gymnasium
environment built from it (the paper's Algorithm 1; docs/semantics.md), train it within a budget and
judge every goal.

The public names below are imported on first use (PEP 562), so ``import
specguard`` and the pytest plugin stay cheap in projects that do not run specs.

Example:
    >>> import numpy as np
    >>> import specguard as sg
    >>> pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    >>> tree = sg.All(
    ...     sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)).annotate(
    ...         sg.Distance(lambda s: np.hypot(s.x - 1.0, s.y), scale=2.0)
    ...     ),
    ...     sg.Goal("stabilization", omega=(-0.25, 0.25)),
    ...     name="pendulum",
    ...     weights=(0.8, 0.2),
    ... )
    >>> env = sg.make_env(pendulum, tree)
    >>> sg.formula(tree)
    'R = 0.8*(0.5*R[position] + 0.5*D[position]) + 0.2*R[stabilization]'
"""

from __future__ import annotations

import importlib
import warnings
from typing import TYPE_CHECKING, Any

from specguard.version import __version__

_EXPORTS = {
    # the language
    "InitialEnv": "specguard.construction.initial_env",
    "Goal": "specguard.tree.nodes",
    "All": "specguard.tree.nodes",
    "Always": "specguard.tree.nodes",
    "Distance": "specguard.tree.builtin_annotations",
    "Constraint": "specguard.tree.builtin_annotations",
    "Node": "specguard.extend",
    "StartSpace": "specguard.starts.space",
    "formula": "specguard.tree.formula",
    # the spec, its budget, its trainer's settings
    "Spec": "specguard.spec.spec",
    "Budget": "specguard.spec.budget",
    "SB3": "specguard.spec.trainers",
    "zoo_settings": "specguard.spec.zoo",
    # the constructed env
    "make_env": "specguard.construction.env",
    "SpecEnv": "specguard.construction.env",
    "compile_tree": "specguard.construction.compiled",
    # training and judging a spec
    "run_spec": "specguard.engine.run_spec",
    "SpecResult": "specguard.engine.spec_result",
    "table": "specguard.report.table",
    "load_model": "specguard.engine.result_models",
    "rollout": "specguard.engine.result_models",
    "falsify_runs": "specguard.engine.falsify_run",
    # agents trained elsewhere
    "load_agent": "specguard.agents.sources",
    "check_agent": "specguard.engine.check_agent",
    "AgentCheck": "specguard.engine.check_agent",
    "compare_agents": "specguard.gate.agent_gate",
    "falsify_agent": "specguard.engine.falsify_run",
    "Falsify": "specguard.falsify.assertion",
    # the pytest door
    "goal_spec": "specguard.pytest_plugin.declare",
    "goal_specs": "specguard.pytest_plugin.declare",
    # every error a user may catch derives from it; each one is in specguard.error
    "SpecError": "specguard.error",
}

_SUBMODULES = ("error", "extend", "strategies", "testing")
"""The public submodules, reached as attributes (``sg.error.InvalidSpec``) as Gymnasium's ``gym.spaces`` is."""

_MOVED = {
    **dict.fromkeys(
        (
            "AgentError",
            "AgentMismatch",
            "CacheWarning",
            "EvaluationError",
            "FingerprintError",
            "GoalMetAtStart",
            "InitialEnvError",
            "InvalidSpec",
            "SpecWarning",
            "StateMappingError",
            "UnknownFeature",
            "UnreachableGoal",
            "VersionMismatch",
        ),
        "specguard.error",
    ),
    "BaselineEnv": "specguard.construction.env",
    "make_baseline_env": "specguard.construction.env",
    "CompiledTree": "specguard.construction.compiled",
    "Annotation": "specguard.extend",
    "Cache": "specguard.cache.store",
    "GoalVerdict": "specguard.engine.spec_result",
    "check_spec": "specguard.spec.spec",
    "load_normalizer": "specguard.engine.result_models",
}
"""The names the face gave up (0.x, CHANGELOG): each still resolves, with a ``DeprecationWarning`` naming its home."""

# The one list of public names: __all__ is derived from it, and the TYPE_CHECKING imports
# below (for type checkers, which cannot follow __getattr__) are checked against it by tests/test_init.py.
__all__ = [*sorted(_EXPORTS), "__version__"]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        if name in _SUBMODULES:
            return importlib.import_module(f"specguard.{name}")
        if name in _MOVED:
            warnings.warn(
                f"specguard.{name} moved to {_MOVED[name]}.{name}; the top level keeps only the names of "
                "specguard.__all__ (this alias goes in a later 0.x release)",
                DeprecationWarning,
                stacklevel=2,
            )
            return getattr(importlib.import_module(_MOVED[name]), name)
        if name[:1].isupper():  # an operator from an installed plugin, e.g. sg.AnyOf
            from specguard.registry import registered

            found = registered().get(name)
            if found is not None:
                return found
        raise AttributeError(f"module 'specguard' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # explicit re-exports (`name as name`) for type checkers
    from specguard.agents.sources import load_agent as load_agent
    from specguard.construction.compiled import compile_tree as compile_tree
    from specguard.construction.env import SpecEnv as SpecEnv
    from specguard.construction.env import make_env as make_env
    from specguard.construction.initial_env import InitialEnv as InitialEnv
    from specguard.engine.check_agent import AgentCheck as AgentCheck
    from specguard.engine.check_agent import check_agent as check_agent
    from specguard.engine.falsify_run import falsify_agent as falsify_agent
    from specguard.engine.falsify_run import falsify_runs as falsify_runs
    from specguard.engine.result_models import load_model as load_model
    from specguard.engine.result_models import rollout as rollout
    from specguard.engine.run_spec import run_spec as run_spec
    from specguard.engine.spec_result import SpecResult as SpecResult
    from specguard.error import SpecError as SpecError
    from specguard.extend import Node as Node
    from specguard.falsify.assertion import Falsify as Falsify
    from specguard.gate.agent_gate import compare_agents as compare_agents
    from specguard.pytest_plugin.declare import goal_spec as goal_spec
    from specguard.pytest_plugin.declare import goal_specs as goal_specs
    from specguard.report.table import table as table
    from specguard.spec.budget import Budget as Budget
    from specguard.spec.spec import Spec as Spec
    from specguard.spec.trainers import SB3 as SB3
    from specguard.spec.zoo import zoo_settings as zoo_settings
    from specguard.starts.space import StartSpace as StartSpace
    from specguard.tree.builtin_annotations import Constraint as Constraint
    from specguard.tree.builtin_annotations import Distance as Distance
    from specguard.tree.formula import formula as formula
    from specguard.tree.nodes import All as All
    from specguard.tree.nodes import Always as Always
    from specguard.tree.nodes import Goal as Goal
