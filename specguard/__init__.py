"""specguard: pytest for reinforcement-learning specifications.

State what an agent must achieve as a goal tree, get a trainable Gymnasium
environment built from it (SPEC.md, Algorithm 1), and check it.

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

from specguard.budget import Budget
from specguard.cache import Cache
from specguard.compiled import CompiledTree, compile_tree
from specguard.engine import GoalVerdict, SpecResult, run_spec
from specguard.env import GoalEnv, GoalInfo, make_baseline_env, make_env
from specguard.error import (
    EvaluationError,
    InitialEnvError,
    InvalidSpec,
    SpecError,
    StateMappingError,
    UnknownFeature,
)
from specguard.formula import formula
from specguard.initial_env import InitialEnv
from specguard.nodes import All, Annotation, Constraint, Distance, Goal, Node
from specguard.spec import Spec

__version__ = "0.1.0"

__all__ = [
    "All",
    "Annotation",
    "Budget",
    "Cache",
    "CompiledTree",
    "Constraint",
    "Distance",
    "EvaluationError",
    "Goal",
    "GoalEnv",
    "GoalInfo",
    "GoalVerdict",
    "InitialEnv",
    "InitialEnvError",
    "InvalidSpec",
    "Node",
    "Spec",
    "SpecError",
    "SpecResult",
    "StateMappingError",
    "UnknownFeature",
    "__version__",
    "compile_tree",
    "formula",
    "make_baseline_env",
    "make_env",
    "run_spec",
]
