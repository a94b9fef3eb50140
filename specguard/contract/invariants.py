"""The extension contract (docs/semantics.md, "The operator contract") as named, property-based checks.

Each ``check_*`` function states one invariant in the first line of its
docstring, in the manner of Gymnasium's ``utils/env_checker.py``, and tests it
with Hypothesis on random goal trees that contain the class under test (an
operator: at the root and maybe deeper; an annotation: on the root and maybe
deeper), with ``Constraint`` annotations so that children can end episodes,
over random trajectories of the features ``a, b, c``
(:mod:`specguard.contract.trees`). Runs are derandomized, so CI sees the
same examples every time.

A failure raises :class:`AssertionError` built from the shrunk counterexample:
the invariant, the tree (``tree.pretty()``), the trajectory (states and
actions) and the values that differ. :mod:`specguard.testing` collects the
checks for pytest (:func:`specguard.testing.parametrize_with_checks`).

Example:
    >>> import specguard as sg
    >>> from specguard.contract.invariants import check_core_reward_telescopes
    >>> check_core_reward_telescopes(sg.Distance, max_examples=5)
"""

from __future__ import annotations

import inspect
import json
import math
import os
import re
import subprocess
import sys
from collections.abc import Callable
from typing import Any

import cloudpickle
import numpy as np

from specguard.construction.compiled import CompiledTree, compile_tree
from specguard.construction.evaluator import Evaluator, StepResult
from specguard.construction.reference import ReferenceEvaluator, process
from specguard.contract.trees import (
    FEATURES,
    MARKOV_EXAMPLES,
    MAX_EXAMPLES,
    Broken,
    Example,
    context,
    extended_states,
    fail,
    play,
    refinement_cases,
    replay_env,
    run_property,
    step_name,
    trees_with,
    value_text,
    visiting_cases,
)
from specguard.extend import Annotation, Context, Node, annotation_key
from specguard.tree.nodes import Goal
from specguard.utils.node_paths import child_path

__all__ = [
    "CHECKS",
    "check_contains_depends_on_ctx_alone",
    "check_core_reward_telescopes",
    "check_description_is_exact",
    "check_flat_matches_reference",
    "check_markov",
    "check_observations_in_space",
    "check_refinement_preserves_root_goal",
    "check_reset_restores_own_state",
    "check_rewards_are_finite_sums_of_terms",
    "check_state_methods_have_slots",
    "check_termination_includes_children",
    "checks_for",
]

ADDRESS = re.compile(r"0x[0-9a-fA-F]{6,}| at 0x")
"""What a memory address in a description looks like (``object.__repr__``, a function's ``repr``)."""
TOL = 1e-9

Check = Callable[..., None]


def _close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=TOL, abs_tol=TOL)


# -- the checks -------------------------------------------------------------------


def check_observations_in_space(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """Every observation, after reset and after every step, lies in the env's observation_space.

    Own state (stages, counters) must stay within the bounds its slots declare.
    """

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.actions is not None
        env = replay_env(case.tree, case.trajectory, terminate=case.terminate)
        for t, step in enumerate(play(env, case.actions)):
            if step.obs not in env.observation_space:
                n = len(FEATURES)
                own = [
                    f"{key}.{slot.name} = {value_text(v)} (declared [{value_text(slot.low)}, {value_text(slot.high)}])"
                    for (key, slot), v in zip(env.evaluator.slots, step.obs[n:].tolist())
                    if not slot.low <= v <= slot.high
                ]
                raise Broken(
                    f"{step_name(t)} the observation {step.obs.tolist()} is not in {env.observation_space}"
                    + (f": own state out of its bounds: {'; '.join(own)}" if own else "")
                )

    run_property(check_observations_in_space, cls, max_examples, body)


def check_rewards_are_finite_sums_of_terms(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """Every reward is a finite Python float equal to the sum of info["reward_terms"] (both evaluators)."""

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.actions is not None
        for evaluator in ("reference", "flat"):
            for t, step in enumerate(
                play(replay_env(case.tree, case.trajectory, evaluator, case.terminate), case.actions)
            ):
                if t == 0:
                    continue
                r, terms = step.reward, step.info["reward_terms"]
                where = f"{step_name(t)}, {evaluator} evaluator,"
                if type(r) is not float:
                    raise Broken(f"{where} the reward {r!r} is a {type(r).__name__}, not a Python float")
                if not math.isfinite(r) or not all(math.isfinite(v) for v in terms.values()):
                    raise Broken(f"{where} the reward {r!r} or a term is not finite: {terms}")
                if not _close(r, sum(terms.values())):
                    raise Broken(f"{where} the reward {r!r} != the sum {sum(terms.values())!r} of the terms {terms}")

    run_property(check_rewards_are_finite_sums_of_terms, cls, max_examples, body)


def check_core_reward_telescopes(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """Over any trajectory, the rewards of every node/annotation of the class sum to potential(last) - potential(first).

    So re-entering a goal is never paid twice. The contexts (own state,
    children's memberships) come from the reference requirements.
    """

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.actions is not None
        req, xs = extended_states(case.tree, case.trajectory, case.actions, case.terminate)
        acts = case.actions
        for path, node in case.tree.walk():
            if isinstance(node, cls):
                ctxs = [context(req, path, node, x) for x in xs]
                rewards = [float(node.reward(b, a, c)) for b, a, c in zip(ctxs, acts, ctxs[1:])]
                phi = [float(node.potential(c)) for c in ctxs]
                _telescopes(f"node {path!r} ({node.kind})", rewards, phi)
            for ann in node.annotations:
                if isinstance(ann, cls):
                    key = annotation_key(path, ann)
                    qs = [tuple(x.states.get(key, ())) for x in xs]
                    steps = zip(xs, qs, acts, xs[1:], qs[1:])
                    rewards = [float(ann.reward(x.s, q, a, x2.s, q2)) for x, q, a, x2, q2 in steps]
                    phi = [float(ann.potential(x.s, q)) for x, q in zip(xs, qs)]
                    _telescopes(f"annotation {key!r}", rewards, phi)

    run_property(check_core_reward_telescopes, cls, max_examples, body)


def _telescopes(what: str, rewards: list[float], phi: list[float]) -> None:
    total, want = math.fsum(rewards), phi[-1] - phi[0]
    if not math.isclose(total, want, rel_tol=TOL, abs_tol=TOL * (1.0 + math.fsum(abs(r) for r in rewards))):
        raise Broken(
            f"the rewards of {what} sum to {total!r}, but potential(last) - potential(first) = "
            f"{phi[-1]!r} - {phi[0]!r} = {want!r}; rewards per step {rewards}, potentials {phi}"
        )


def check_markov(cls: type, max_examples: int = MARKOV_EXAMPLES) -> None:
    """Each transition evaluated alone from its observation (step_batch) reproduces the env: the env is Markov.

    ``compile_tree(tree, F).step_batch(obs_t, a_t, features_t+1)``, on a fresh
    copy of the tree, must give the env's reward, ``info["goals"]``,
    termination and the next observation's own state. Episode state a node
    keeps outside its declared own state is hidden state, and breaks it,
    wherever it is kept: on the node, on its class or at module level (which
    every copy of the tree shares). So the transitions are evaluated last to
    first, not in the order the env lived them, and each one twice: state that
    follows the evaluations along cannot reproduce the env's. The trajectories'
    states often lie in the goal box of one of the tree's nodes
    (:func:`~specguard.contract.trees.visiting_cases`), so state that matters
    only once a child's goal was reached is exercised.
    """

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.actions is not None
        pristine = cloudpickle.dumps(case.tree)  # every transition gets a fresh copy of the tree
        steps = play(replay_env(case.tree, case.trajectory, terminate=case.terminate), case.actions)
        n = len(FEATURES)
        used = compile_tree(case.tree, FEATURES)
        for t in reversed(range(1, len(steps))):  # against the trajectory's order: hidden state cannot follow
            before, after, action = steps[t - 1], steps[t], case.actions[t - 1]
            env = {"reward": after.reward, "terminated": after.terminated, "goals": after.info["goals"]}
            env["own state"] = after.obs[n:].tolist()
            where = f"{step_name(t)}, evaluated alone from the observation {before.obs.tolist()}"
            last = t == len(case.trajectory) - 1  # the replay's own end: truncated, or terminated (case.terminate)
            base_end = (last, last and case.terminate)
            for attempt in ("", " a second time"):  # the second evaluation sees whatever the first one left
                fresh = compile_tree(cloudpickle.loads(pristine), FEATURES)
                alone = _alone(fresh, before.obs, action, after.obs[:n], *base_end)
                diffs = _differences(env, alone, "env", "alone", 1e-6)
                if diffs:
                    raise Broken(f"{where}{attempt}: " + "; ".join(diffs))
            # The same transition on the tree the env ran: state kept in the nodes shows up here.
            diffs = _differences(
                _alone(used, before.obs, action, after.obs[:n], *base_end), alone, "used", "fresh", TOL
            )
            if diffs:
                raise Broken(
                    f"{where}, differs on the tree the env used and on a fresh copy of it: " + "; ".join(diffs)
                )

    run_property(check_markov, cls, max_examples, body, visiting_cases(cls))


def _alone(
    compiled: CompiledTree, obs: np.ndarray, action: int, features: np.ndarray, last: bool, terminated: bool
) -> dict[str, Any]:
    """One transition evaluated alone by ``step_batch``, as the env reports it (``last``: the base env ended it,
    ``terminated``: by termination)."""
    rewards, ended, goals, own = compiled.step_batch(obs[None, :], [action], features[None, :], [last], [terminated])
    return {
        "reward": float(rewards[0]),
        "terminated": bool(ended[0]) or terminated,  # the env's flag: the spec's end, or the base env's
        "goals": dict(zip(compiled.paths, goals[0].tolist())),
        "own state": own[0].tolist(),
    }


def _same(a: Any, b: Any, tol: float) -> bool:
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k], tol) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_same(x, y, tol) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float):
        return a == b or math.isclose(a, b, rel_tol=tol, abs_tol=tol)
    return bool(a == b)


def _differences(x: dict[str, Any], y: dict[str, Any], xname: str, yname: str, tol: float) -> list[str]:
    """``key: xname X, yname Y`` for every value that differs (floats within ``tol``)."""
    return [f"{k}: {xname} {x[k]!r}, {yname} {y[k]!r}" for k in x if not _same(x[k], y[k], tol)]


_STATE_METHODS = ("initial_state", "next_state")


def _state_methods_overridden(obj: Node | Annotation) -> list[str]:
    """The state methods ``obj``'s class overrides (of :class:`Node` or :class:`Annotation`)."""
    base = Node if isinstance(obj, Node) else Annotation
    return [m for m in _STATE_METHODS if getattr(type(obj), m) is not getattr(base, m)]


def check_state_methods_have_slots(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """A node or annotation of the class that overrides initial_state or next_state declares own-state slots.

    No evaluator calls the state methods of an instance without slots: the
    state they compute is dead, and a ``contains`` that reads it (kept on the
    node, its class or at module level) reads what nothing writes, a goal that
    every other check sees as a constant.
    """

    def body(case: Example) -> None:
        for path, node in case.tree.walk():
            found: list[tuple[str, Node | Annotation]] = [(f"node {path!r} ({node.kind})", node)]
            found += [(f"annotation {annotation_key(path, a)!r}", a) for a in node.annotations]
            for what, obj in found:
                overridden = _state_methods_overridden(obj) if isinstance(obj, cls) else []
                if overridden and not obj.state_slots():
                    raise Broken(
                        f"{what} overrides {', '.join(overridden)} but declares no own-state slots "
                        "(state_slots() is ()): no evaluator calls them, so the state they keep is never written; "
                        "declare the state in state_slots() and read it from ctx.q"
                    )

    run_property(check_state_methods_have_slots, cls, max_examples, body, trees_with(cls).map(Example))


def check_contains_depends_on_ctx_alone(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """contains(ctx) depends on ctx alone: a ctx gets the same answer before and after the node's other methods ran.

    The contexts are a trajectory's (from the reference requirements). A fresh
    copy of the tree answers ``contains`` for each of them first; then its
    nodes of the class run ``initial_state``, ``next_state``, ``potential``,
    ``reward`` and ``terminates`` along the trajectory, and after every step
    each context must get its first answer again. A goal that reads state its
    methods keep outside ``ctx`` (on the node, its class or at module level) changes.
    """

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.actions is not None
        pristine = cloudpickle.dumps(case.tree)
        req, xs = extended_states(case.tree, case.trajectory, case.actions, case.terminate)
        fresh = dict(cloudpickle.loads(pristine).walk())
        nodes = [(path, fresh[path]) for path, node in case.tree.walk() if isinstance(node, cls)]
        ctxs = {path: [context(req, path, node, x) for x in xs] for path, node in nodes}
        first = {path: [bool(node.contains(c)) for c in ctxs[path]] for path, node in nodes}
        for t in range(len(xs)):
            for path, node in nodes:
                c = ctxs[path][t]
                if t == 0:
                    node.initial_state(Context(c.s, (), c.inside))
                else:
                    before = ctxs[path][t - 1]
                    node.next_state(before, case.actions[t - 1], c.s, c.inside)
                    node.reward(before, case.actions[t - 1], c)
                node.potential(c)
                node.terminates(c, (False,) * len(c.inside))
            for path, node in nodes:
                for u, c in enumerate(ctxs[path]):
                    now = bool(node.contains(c))
                    if now != first[path][u]:
                        raise Broken(
                            f"contains(ctx) of node {path!r} ({node.kind}) in s{u} was {first[path][u]} "
                            f"first and is {now} after the node's methods ran along the trajectory up to s{t} "
                            f"(ctx.q={c.q}, ctx.inside={c.inside}): it reads something besides ctx"
                        )

    assert issubclass(cls, Node)
    run_property(check_contains_depends_on_ctx_alone, cls, max_examples, body)


def check_reset_restores_own_state(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """Reset after an episode gives what the first reset and a fresh env give, and the episode replays identically."""

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.actions is not None
        pristine = cloudpickle.dumps(case.tree)
        env = replay_env(case.tree, case.trajectory, terminate=case.terminate)
        first, again = play(env, case.actions), play(env, case.actions)
        fresh = play(
            replay_env(cloudpickle.loads(pristine), case.trajectory, terminate=case.terminate), case.actions[:0]
        )
        for name, other in (("the first", first[0]), ("a fresh env's", fresh[0])):
            seen = (again[0].obs.tolist(), again[0].info["goals"], again[0].info["safe"])
            want = (other.obs.tolist(), other.info["goals"], other.info["safe"])
            if seen != want:
                raise Broken(f"reset after the episode gave (observation, goals, safe) = {seen}, {name} reset {want}")
        for t, (a, b) in enumerate(zip(first, again)):
            was, now = ((x.obs.tolist(), x.reward, x.terminated, x.info["goals"]) for x in (a, b))
            if was != now:
                raise Broken(
                    f"{step_name(t)} the replayed episode differs: (observation, reward, terminated, goals) = "
                    f"{now}, the first time {was}"
                )
        if len(first) != len(again):
            raise Broken(f"the episode lasted {len(first) - 1} steps, replayed {len(again) - 1}")

    run_property(check_reset_restores_own_state, cls, max_examples, body)


def check_termination_includes_children(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """A node of the class terminates whenever a child's subtree does: terminates(ctx, ended) if any(ended).

    Checked on the real contexts of a trajectory, with the children's real
    termination and with every single child (and all of them) ended.
    """

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.actions is not None
        req, xs = extended_states(case.tree, case.trajectory, case.actions, case.terminate)
        for path, node in case.tree.walk():
            if not isinstance(node, cls) or not node.children:
                continue
            kids = [process(c, child_path(path, c.name), root=False) for c in node.children]
            n = len(kids)
            for t, x in enumerate(xs):
                ctx = context(req, path, node, x)
                real = tuple(bool(k.terminal(x)) for k in kids)
                one_hot = [tuple(i == j for j in range(n)) for i in range(n)]
                for ended in (real, *one_hot, (True,) * n):
                    if any(ended) and not node.terminates(ctx, ended):
                        raise Broken(
                            f"in s{t}, node {path!r} ({node.kind}): terminates(ctx, ended={ended}) is "
                            f"{node.terminates(ctx, ended)!r} although a child's subtree ended "
                            f"(ctx.q={ctx.q}, ctx.inside={ctx.inside}; the children's real termination {real})"
                        )

    run_property(check_termination_includes_children, cls, max_examples, body)


def check_flat_matches_reference(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """The flat (compiled) and the reference evaluators agree at every step on everything the env reports.

    Reward, termination, goals, reward terms, own state and safety flags,
    along the whole trajectory (past the end of the episode too), whose last
    state is judged as the last state of an episode the base env ended; a
    declared box or fast form must say what the methods say.
    """

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.actions is not None
        flat = compile_tree(case.tree, FEATURES).evaluator()
        ref = ReferenceEvaluator(case.tree, FEATURES)
        sides = ((flat, flat.reset(case.trajectory[0])), (ref, ref.reset(case.trajectory[0])))
        _agree(0, *(_seen(ev, StepResult(None, False, goals, {})) for ev, goals in sides))  # type: ignore[arg-type]
        end = min(len(case.actions), len(case.trajectory) - 1)
        for t, (a, f) in enumerate(zip(case.actions, case.trajectory[1:]), 1):
            steps = [(ev, ev.step(a, f, t == end, t == end and case.terminate)) for ev in (flat, ref)]
            _agree(t, *(_seen(ev, result) for ev, result in steps))

    run_property(check_flat_matches_reference, cls, max_examples, body)


def _seen(ev: Evaluator, result: StepResult) -> dict[str, Any]:
    return {
        "reward": result.reward,
        "terminated": bool(result.terminated),
        "goals": dict(zip(ev.paths, map(bool, result.goals))),
        "terms": dict(result.terms),
        "own_state": [float(v) for v in ev.own_state],
        "safe": dict(zip(ev.safety_keys, map(bool, ev.safe))),
    }


def _agree(t: int, flat: dict[str, Any], ref: dict[str, Any]) -> None:
    diffs = _differences(flat, ref, "flat", "reference", TOL)
    if diffs:
        raise Broken(f"{step_name(t)}: " + "; ".join(diffs))


def _texts(tree: Node) -> list[str]:
    from specguard.tree.formula import formula

    nodes = [node for _, node in tree.walk()]
    described = [n.describe() for n in nodes] + [a.describe() for n in nodes for a in n.annotations]
    return [*described, str(tree), formula(tree)]


_SCRIPT = """
import json, pickle, sys
sys.path[:0] = json.loads(sys.argv[1])
blobs = pickle.load(sys.stdin.buffer)
json.dump([_texts(pickle.loads(b)) for b in blobs], sys.stdout)
"""


def _fresh_texts(blobs: list[bytes]) -> dict[str, list[list[str]] | str]:
    """The texts of the pickled trees in fresh interpreters, by ``PYTHONHASHSEED`` (or the error they hit)."""
    script = "from __future__ import annotations\n" + inspect.getsource(_texts) + _SCRIPT
    procs = {
        seed: subprocess.Popen(
            [sys.executable, "-c", script, json.dumps(sys.path)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env={**os.environ, "PYTHONHASHSEED": seed},
        )
        for seed in ("0", "1")
    }
    out: dict[str, list[list[str]] | str] = {}
    for seed, proc in procs.items():
        stdout, stderr = proc.communicate(cloudpickle.dumps(blobs), timeout=120)
        out[seed] = json.loads(stdout) if proc.returncode == 0 else stderr.decode(errors="replace")[-2000:]
    return out


def check_description_is_exact(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """describe(), str(tree) and sg.formula(tree) have no memory address and survive pickling and a new interpreter.

    Two cloudpickle round trips in this process, then a fresh interpreter
    under two hash seeds for every tree drawn.
    """
    kept: list[tuple[Node, bytes, list[str]]] = []

    def body(case: Example) -> None:
        texts = _texts(case.tree)
        for text in texts:
            if not isinstance(text, str) or ADDRESS.search(text):
                raise Broken(f"the text {text!r} holds a memory address (or is not a str)")
        once = cloudpickle.loads(cloudpickle.dumps(case.tree))
        twice = cloudpickle.loads(cloudpickle.dumps(once))
        for name, copy in (("one", once), ("two", twice)):
            if _texts(copy) != texts:
                raise Broken(f"after {name} cloudpickle round trip(s) the texts {_texts(copy)} != {texts}")
        if len(kept) < 100:  # every example, but a bound on the pickles handed over
            kept.append((case.tree, cloudpickle.dumps(case.tree), texts))

    run_property(check_description_is_exact, cls, max_examples, body, trees_with(cls).map(Example))
    kept.sort(key=lambda k: len(k[2][-2]))  # smallest tree first: the one a failure shows
    for seed, fresh in _fresh_texts([blob for _, blob, _ in kept]).items():
        if isinstance(fresh, str):
            fail(check_description_is_exact, cls, Example(kept[0][0]), f"a fresh interpreter failed:\n{fresh}")
        for (tree, _, texts), there in zip(kept, fresh):
            if there != texts:
                diff = [f"{a!r} here, {b!r} there" for a, b in zip(texts, there) if a != b][:1]
                fail(
                    check_description_is_exact,
                    cls,
                    Example(tree),
                    f"in a fresh interpreter (PYTHONHASHSEED={seed}) the texts differ: " + "; ".join(diff),
                )


def check_refinement_preserves_root_goal(cls: type, max_examples: int = MAX_EXAMPLES) -> None:
    """A refinement cls.refinements(leaf) has the leaf's root membership in every state, in both evaluators."""

    def body(case: Example) -> None:
        assert case.trajectory is not None and case.leaf is not None
        evaluators: dict[str, Any] = {
            "leaf, flat": compile_tree(case.leaf, FEATURES).evaluator(),
            "leaf, reference": ReferenceEvaluator(case.leaf, FEATURES),
            "refined, flat": compile_tree(case.tree, FEATURES).evaluator(),
            "refined, reference": ReferenceEvaluator(case.tree, FEATURES),
        }
        for t, s in enumerate(case.trajectory):
            root = {name: bool(ev.reset(s)[0]) for name, ev in evaluators.items()}
            if len(set(root.values())) > 1:
                raise Broken(f"in s{t} the root membership differs: {root}")

    assert issubclass(cls, Node)
    run_property(check_refinement_preserves_root_goal, cls, max_examples, body, refinement_cases(cls))


CHECKS: tuple[Check, ...] = (
    check_observations_in_space,
    check_rewards_are_finite_sums_of_terms,
    check_core_reward_telescopes,
    check_markov,
    check_state_methods_have_slots,
    check_contains_depends_on_ctx_alone,
    check_reset_restores_own_state,
    check_termination_includes_children,
    check_flat_matches_reference,
    check_description_is_exact,
    check_refinement_preserves_root_goal,
)
"""Every check, in the order :func:`checks_for` runs them."""

FRESH_INTERPRETER: frozenset[Check] = frozenset({check_description_is_exact})
"""The checks that start a fresh interpreter: :func:`specguard.testing.parametrize_with_checks` marks their items
``slow`` (deselected by ``pytest -m "not slow"``)."""


def _refines(cls: type) -> bool:
    if not issubclass(cls, Node):
        return False
    try:
        return cls.refinements(Goal("probe", a=(0.0, 1.0))) is not None
    except Exception:
        return True  # let the check report the error


_APPLIES: dict[Check, Callable[[type], bool]] = {
    check_termination_includes_children: lambda cls: issubclass(cls, Node) and not issubclass(cls, Goal),
    check_contains_depends_on_ctx_alone: lambda cls: issubclass(cls, Node),
    check_refinement_preserves_root_goal: _refines,
}


def checks_for(cls: type) -> tuple[Check, ...]:
    """The checks that apply to ``cls``: all but termination for leaves and annotations, refinement only if it refines.

    Raises:
        TypeError: ``cls`` is not a :class:`Node` or :class:`Annotation` subclass.
    """
    if not (isinstance(cls, type) and issubclass(cls, (Node, Annotation))):
        raise TypeError(f"expected a Node or Annotation subclass (an operator or annotation class), got {cls!r}")
    return tuple(c for c in CHECKS if c not in _APPLIES or _APPLIES[c](cls))
