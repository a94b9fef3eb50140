"""The generated per-step code of a :class:`~specguard.construction.compiled.CompiledTree`.

Three functions are generated, straight-line, one line per goal and per
reward term, with the weights folded into constants:

* ``start(f, z, init)``: memberships (a tuple, and a dict by path), the
  feature namedtuple and the distances of a first state; with ``init`` it also
  writes the initial own state into the list ``z`` (otherwise it reads it, to
  restore an observation);
* ``step(a, f, last, terminated)``: the evaluator's own ``step``
  (``FlatEvaluator.step``),
  one transition by action ``a`` to features ``f`` from the episode state the
  evaluator ``_ev`` holds (previous memberships, namedtuple, distances, own
  state), which it writes back once the step succeeded; when the episode ends
  at ``f`` (the spec ends it, or ``last``), the last state is judged too,
  never with ``last`` None. One Python call a step: no wrapper around it;
* ``safe(z)``: per safety annotation, whether the episode is free of
  violations; ``safe_info(z)``: the same as a dict by key.

The dicts are what the env reports in ``info`` (a new one per call): written
out as dict displays, they cost less than ``dict(zip(keys, values))``.

Only three kinds of values reach the source: finite floats as their exact
``repr`` (:func:`number`), integers, and names as ``str`` literals inside
comments (:func:`text`). User functions and general nodes are globals of the
namespace (``_fn3``, ``_node1``), never text; user text never becomes code.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, NoReturn, Protocol

import numpy as np

from specguard.construction.reference import FLOAT_MAX, call_definition
from specguard.error import EvaluationError
from specguard.extend import Annotation, Context, Node, Slot, StagesForm
from specguard.validation import check_truth

__all__ = ["FlatTree", "build_namespace", "number", "source_of", "text"]


class FlatTree(Protocol):
    """What the generated code is made from: the fields of a compiled tree it reads.

    :class:`~specguard.construction.compiled.CompiledTree` has them; this module names
    no class of that module, so the compiler depends on the code generator and
    not the other way round.
    """

    @property
    def features(self) -> tuple[str, ...]: ...
    @property
    def paths(self) -> tuple[str, ...]: ...
    @property
    def nodes(self) -> tuple[Node, ...]: ...
    @property
    def lo(self) -> np.ndarray: ...
    @property
    def hi(self) -> np.ndarray: ...
    @property
    def fast(self) -> tuple[bool, ...]: ...
    @property
    def terms(self) -> tuple[Any, ...]: ...
    @property
    def children(self) -> tuple[tuple[int, ...], ...]: ...
    @property
    def slots(self) -> tuple[tuple[str, Slot], ...]: ...
    @property
    def slot_start(self) -> tuple[int, ...]: ...
    @property
    def reach(self) -> bool: ...
    @property
    def stages(self) -> tuple[StagesForm | None, ...]: ...


def number(x: float) -> str:
    """A finite float as exact Python source (``repr`` round-trips); never the names ``inf`` or ``nan``."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot emit the non-finite number {x!r} into generated code")
    return repr(x)


def text(value: str) -> str:
    """A name as a Python ``str`` literal (``str.__repr__``: no subclass may change it)."""
    return str.__repr__(value)


def _tuple(names: Sequence[str]) -> str:
    return f"({', '.join(names)},)" if names else "()"


def _box_test(tree: FlatTree, i: int) -> str:
    tests = []
    for j in range(len(tree.features)):
        lo, hi = float(tree.lo[i, j]), float(tree.hi[i, j])
        if lo == hi:
            tests.append(f"f{j} == {number(lo)}")
        elif lo > -math.inf and hi < math.inf:
            tests.append(f"{number(lo)} <= f{j} <= {number(hi)}")
        elif lo > -math.inf:
            tests.append(f"{number(lo)} <= f{j}")
        elif hi < math.inf:
            tests.append(f"f{j} <= {number(hi)}")
    return " and ".join(tests) or "True"


def _is_intersection(tree: FlatTree, i: int) -> bool:
    """A fast node whose box is exactly its fast children's intersection: reuse their results."""
    kids = tree.children[i]
    if not kids or not all(tree.fast[k] for k in kids):
        return False
    lo = np.max(np.stack([tree.lo[k] for k in kids]), axis=0)
    hi = np.min(np.stack([tree.hi[k] for k in kids]), axis=0)
    return bool(np.array_equal(lo, tree.lo[i]) and np.array_equal(hi, tree.hi[i]))


def _inside(tree: FlatTree, i: int, previous: bool) -> str:
    return _tuple([f"m[{k}]" if previous else f"m{k}" for k in tree.children[i]])


def _member_lines(tree: FlatTree, *, stepping: bool) -> list[str]:
    # The unpacking checks the length, so the namedtuple is made without ``_make``'s own check.
    lines = [f"    ({', '.join(f'f{i}' for i in range(len(tree.features)))},) = f", "    s2 = _new(_State, f)"]
    # Children come after parents in ``paths``: emit in reverse so a parent sees its children's results.
    for i in reversed(range(len(tree.paths))):
        comment = f"  # {text(tree.paths[i])}"
        if tree.fast[i]:
            expr = " and ".join(f"m{k}" for k in tree.children[i]) if _is_intersection(tree, i) else _box_test(tree, i)
            lines.append(f"    m{i} = {expr}{comment}")
        elif tree.stages[i] is not None:
            lines += _stage_lines(tree, i, stepping=stepping)
        elif stepping:
            lines.append(
                f"    m{i}, g{i} = _node{i}(s, a, s2, z, {_inside(tree, i, True)}, {_inside(tree, i, False)}){comment}"
            )
        else:
            lines.append(f"    m{i} = _start{i}(s2, z, {_inside(tree, i, False)}, init){comment}")
    return lines


def _stage_nodes(tree: FlatTree) -> list[int]:
    """The nodes compiled from a :class:`~specguard.extend.StagesForm`, in path order."""
    return [i for i, form in enumerate(tree.stages) if form is not None]


def _stage_lines(tree: FlatTree, i: int, *, stepping: bool) -> list[str]:
    """Node ``i``'s :class:`~specguard.extend.StagesForm` written out: ``k<i>`` its stage, ``m<i>`` its
    membership, ``p<i>`` its potential in ``s2`` and, stepping, ``g<i>`` its reward (the potential difference,
    the previous potential read from ``q`` after the distances)."""
    form = tree.stages[i]
    assert form is not None
    n, slot, k = len(tree.children[i]), tree.slot_start[i], f"k{i}"
    advance = [
        f"    i{i} = {_inside(tree, i, False)}",
        f"    while {k} < {n} and i{i}[{k}]:",
        f"        {k} += 1",
        f"    z[{slot}] = float({k})",
    ]
    if stepping:  # from the stage before the step
        lines = [f"    {k} = int(z[{slot}])  # {text(tree.paths[i])}", *advance]
    else:  # the leading children met, or (restoring) the stage the own state says
        lines = [f"    if init:  # {text(tree.paths[i])}", f"        {k} = 0"]
        lines += ["    " + line for line in advance]
        lines += ["    else:", f"        {k} = int(z[{slot}])"]
    lines.append(f"    m{i} = {k} >= {n}")
    # Phi = stage[k] + (0.0 + w * (-d / scale) + ...) over the active child's shapers, in order; a distance
    # that raised or is not finite and >= 0 is named by the node's own potential() (_bad<i>).
    branch = "if"
    for j, shapers in enumerate(form.shapers):
        if not shapers:
            continue
        lines.append(f"    {branch} {k} == {j}:")
        branch = "elif"
        total = ["0.0"]
        for h, (_, scale, w) in enumerate(shapers):
            v = f"v{i}_{j}_{h}"
            lines += [
                "        try:",
                f"            {v} = _float(_sh{i}_{j}_{h}(s2))",
                "        except Exception:",
                f"            _bad{i}(s2, {k})",
                f"        if not (0.0 <= {v} <= {number(FLOAT_MAX)}):",
                f"            _bad{i}(s2, {k})",
            ]
            total.append(f"{number(w)} * (-{v} / {number(scale)})")
        lines.append(f"        h{i} = {' + '.join(total)}")
    if branch == "if":
        lines.append(f"    h{i} = 0.0")
    else:
        lines += ["    else:", f"        h{i} = 0.0"]
    lines.append(f"    p{i} = _stage{i}[{k}] + h{i}")
    if stepping:
        previous = len([t for t in tree.terms if t.kind == "distance"]) + _stage_nodes(tree).index(i)
        lines.append(f"    g{i} = p{i} - q[{previous}]")
    return lines


def _member_tuple(tree: FlatTree) -> str:
    """The memberships as a tuple, in path order."""
    return _tuple([f"m{i}" for i in range(len(tree.paths))])


def _member_dict(tree: FlatTree) -> str:
    """The memberships as a dict by path."""
    return "{" + ", ".join(f"{text(path)}: m{i}" for i, path in enumerate(tree.paths)) + "}"


def _distance_lines(tree: FlatTree, target: str) -> tuple[list[str], list[str]]:
    lines: list[str] = []
    names: list[str] = []
    for k, t in enumerate(tree.terms):
        if t.kind == "distance":
            d = f"{target}{len(names)}"
            lines.append(f"    {d} = _float(_fn{k}(s2))  # {text(t.key)}")
            names.append(d)
    if names:  # one comparison chain per distance: finite and >= 0 (NaN fails it too)
        checks = " and ".join(f"0.0 <= {d} <= {number(FLOAT_MAX)}" for d in names)
        lines += [f"    if not ({checks}):", "        raise ValueError('invalid distance')"]
    return lines, names


def _start_source(tree: FlatTree) -> str:
    lines = ["def start(f, z, init):", *_member_lines(tree, stepping=False)]
    init = []
    for k, t in enumerate(tree.terms):
        if t.kind == "counter":
            init.append(f"        z[{t.slot}] = {number(t.budget)}  # {text(t.key)}")
        elif t.kind == "annotation" and t.slot >= 0:
            init.append(f"        _ann{k}.initial(s2, z)  # {text(t.key)}")
    if init:
        lines += ["    if init:", *init]
    distance_lines, names = _distance_lines(tree, "d")
    lines += distance_lines
    names += [f"p{i}" for i in _stage_nodes(tree)]  # the stage nodes' potentials, after the distances
    lines.append(f"    return {_member_tuple(tree)}, {_member_dict(tree)}, s2, {_tuple(names)}")
    return "\n".join(lines) + "\n"


def _step_source(tree: FlatTree) -> str:
    lines = _member_lines(tree, stepping=True)
    ends = ["m0"] if tree.reach else []  # the root goal reached ends the episode, unless it holds until the end
    names: list[str] = []
    distances = 0
    for k, t in enumerate(tree.terms):
        comment = f"  # {text(t.key)}"
        if t.kind == "zero" or (t.kind == "member" and t.coef == 0.0):  # weighted 0 on its path
            term = "0.0"
        elif t.kind == "member":
            term = f"{number(t.coef)} * (m{t.node} - m[{t.node}])"
        elif t.kind == "node":
            term = f"{number(t.coef)} * g{t.node}"
        elif t.kind == "distance":
            d = f"d{distances}"
            lines.append(f"    {d} = _float(_fn{k}(s2)){comment}")
            term = f"{number(t.coef)} * (q[{distances}] - {d})"
            distances += 1
        elif t.kind == "counter":
            call = f"_fn{k}(s2)" if t.on_next_state else f"_fn{k}(s, a)"
            lines += [
                f"    v{k} = {call}{comment}",
                # Every step's result is a truth value: a bool passes on two identity tests, anything else
                # (a numpy.bool_, or a bad value, which raises) through the check itself.
                f"    if v{k} is not True and v{k} is not False:",
                f"        v{k} = _truth{k}(v{k})",
                f"    if v{k}:",
                f"        z[{t.slot}] -= 1.0",
            ]
            term = f"{number(-t.coef)} if v{k} else 0.0"
            ends.append(f"z[{t.slot}] <= 0.0")
        else:
            lines.append(f"    g{k}a, e{k}a = _ann{k}.step(s, a, s2, z){comment}")
            term = f"{number(t.coef)} * g{k}a"
            ends.append(f"e{k}a")
        if term == "0.0":  # a constant: reported as such, and left out of the sum below
            names.append("0.0")
        else:
            names.append(f"t{k}")
            lines.append(f"    t{k} = {term}")
    if all(tree.fast):
        end = " or ".join(ends) or "False"
    else:
        lines += _termination_lines(tree)
        end = " or ".join([*ends[:1], "x0"])
    judged = _last_state_lines(tree)
    if judged:  # the episode ends at s2: its state is judged too (docs/semantics.md, "The last state")
        lines += [f"    e = {end}", "    if last or (e and last is not None):", *judged]
        end = "e"
    distance_names = [f"d{j}" for j in range(distances)]
    previous = distance_names + [f"p{i}" for i in _stage_nodes(tree)]  # what the next step reads from q
    if distance_names:
        checks = " and ".join(f"0.0 <= {d} <= {number(FLOAT_MAX)}" for d in distance_names)
        lines += [f"    if not ({checks}):", "        raise ValueError('invalid distance')"]
    # The terms weighted 0 add nothing: the sum is the others', in order, after one 0.0 when some were left
    # out (exactly the same float: adding 0.0 changes no number but a -0.0, to 0.0).
    added = [name for name in names if name != "0.0"]
    lines.append(f"    r = {' + '.join((['0.0'] if len(added) < len(names) else []) + added) or '0.0'}")
    pairs = ", ".join(f"{text(t.key)}: {name}" for t, name in zip(tree.terms, names))
    if end != "e":
        lines.append(f"    e = {end}")
    lines.append(f"    terms = {{{pairs}}}")
    return "\n".join(_evaluator_step(tree, lines, previous)) + "\n"


def _evaluator_step(tree: FlatTree, body: list[str], previous: list[str]) -> list[str]:
    """``step(a, f, last, terminated)``: the evaluator's step itself, reading and writing its episode state.

    ``body`` computes the transition (``r``, ``e``, ``m<i>``, ``s2``, ``terms``, and ``previous``: the distances
    and stage potentials the next step reads) from the previous memberships ``m``, namedtuple ``s``, ``q`` and
    a copy ``z`` of the own state; the episode state
    (``_ev``'s) changes only once it succeeded, so a checked re-run (``_ev._diagnose``) sees the same state.
    """
    # fell[0]: the initial env terminated the episode in s2 and the root goal holds until the end; set for this
    # step only where a general node asks terminated_state() (_GeneralNode).
    fell = not tree.reach and any(
        not tree.fast[i] and tree.stages[i] is None and type(node).terminated_state is not Node.terminated_state
        for i, node in enumerate(tree.nodes)
    )
    lines = [
        "def step(a, f, last=False, terminated=False):",
        "    m, s, q = _ev._m, _ev._s, _ev._q",
        "    z = _ev.own_state[:]" if tree.slots else "    z = _ev.own_state",
    ]
    if fell:
        lines.append("    _fell[0] = bool(terminated)")
    lines += ["    try:", *("    " + line for line in body)]
    lines += ["    except _EvaluationError:", "        raise", "    except Exception as error:"]
    lines.append("        _ev._diagnose(a, f, error)")
    if fell:
        lines += ["    finally:", "        _fell[0] = False"]
    return [
        *lines,
        "    if not _isfinite(r):",
        "        _ev._non_finite(r, terms)",
        f"    _ev._m = {_member_tuple(tree)}",
        f"    _ev.goals = {_member_dict(tree)}",
        f"    _ev._s, _ev._q = s2, {_tuple(previous)}",
        *(["    _ev.own_state = z"] if tree.slots else []),
        "    return _result(_StepResult, (r, e, _ev._m, terms))",
    ]


def _last_state_lines(tree: FlatTree) -> list[str]:
    """The judgement of the last state ``s2`` (reached by ``a``) when the episode ends; empty if none judges it.

    A counter judged on ``(s, a)`` judges ``(s2, a)`` once more, unless spent; a general annotation that
    defines ``last_state`` is asked. A change is added to the annotation's term, and may end the episode.
    """
    lines = []
    for k, t in enumerate(tree.terms):
        comment = f"  # {text(t.key)}"
        if t.kind == "counter" and not t.on_next_state:
            lines += [
                f"        if z[{t.slot}] > 0.0:{comment}",
                f"            w{k} = _fn{k}(s2, a)",
                f"            if w{k} is not True and w{k} is not False:",
                f"                w{k} = _truth{k}(w{k})",
                f"            if w{k}:",
                f"                z[{t.slot}] -= 1.0",
                f"                t{k} = t{k} + {number(-t.coef)}",
                f"                e = e or z[{t.slot}] <= 0.0",
            ]
        elif t.kind == "annotation" and t.slot >= 0 and _judges_last_state(t.annotation):
            lines += [
                f"        g{k}b, e{k}b = _ann{k}.last(s2, a, z){comment}",
                f"        t{k} = t{k} + {number(t.coef)} * g{k}b",
                f"        e = e or e{k}b",
            ]
    return lines


def _judges_last_state(annotation: Any) -> bool:
    return type(annotation).last_state is not Annotation.last_state


def _termination_lines(tree: FlatTree) -> list[str]:
    """``x<i>``: whether node ``i``'s subtree ends the episode, children first (T = union of T_i, plus own)."""
    own: dict[int, list[str]] = {}
    for k, t in enumerate(tree.terms):
        if t.kind == "counter":
            own.setdefault(t.owner, []).append(f"z[{t.slot}] <= 0.0")
        elif t.kind == "annotation":
            own.setdefault(t.owner, []).append(f"e{k}a")
    lines = []
    for i in reversed(range(len(tree.paths))):
        kids = [f"x{c}" for c in tree.children[i]]
        inline = tree.fast[i] or type(tree.nodes[i]).terminates is Node.terminates  # the default: any(ended)
        node = (" or ".join(kids) or "False") if inline else f"_end{i}({_tuple(kids)})"
        lines.append(f"    x{i} = {' or '.join([node, *own.get(i, [])])}  # {text(tree.paths[i])}")
    return lines


def _safe_source(tree: FlatTree) -> str:
    tests = []
    keys = []
    for k, t in enumerate(tree.terms):
        if t.annotation is None or t.annotation.role != "safety":
            continue
        tests.append(f"z[{t.slot}] >= {number(t.budget)}" if t.kind == "counter" else f"_ann{k}.safe(z)")
        keys.append(text(t.key))
    pairs = ", ".join(f"{key}: {test}" for key, test in zip(keys, tests))
    return f"def safe(z):\n    return {_tuple(tests)}\n\n\ndef safe_info(z):\n    return {{{pairs}}}\n"


def source_of(tree: FlatTree) -> str:
    return "\n".join([_start_source(tree), _step_source(tree), _safe_source(tree)])


# -- the general nodes and annotations, evaluated from their definitions ----------


class _GeneralNode:
    """Calls one node's protocol methods with its own state kept in ``z[start:stop]``."""

    def __init__(self, path: str, node: Any, start: int, size: int, fell: list[bool] | None = None) -> None:
        self.path, self.node = path, node
        self.start, self.stop = start, start + size
        # fell[0]: the initial env terminated the episode in this step's s2, and the root goal holds until the
        # end (the evaluator sets it for that step): a node that defines terminated_state() is asked it.
        self.fell = fell if fell is not None and type(node).terminated_state is not Node.terminated_state else None
        self.own_reward = node.own_reward
        self.default_reward = type(node).reward is Node.reward  # reward is the potential difference
        self.last: tuple[Context, float] | None = None  # the last state's context and potential
        self.after = Context(None, (), ())

    def begin(self, s: Any, z: list[float], inside: tuple[bool, ...], init: bool) -> bool:
        node, path = self.node, self.path
        if self.stop > self.start:
            if init:
                q0 = call_definition(path, "initial_state()", node.initial_state, Context(s, (), inside))
                z[self.start : self.stop] = [float(v) for v in q0]
            q = tuple(z[self.start : self.stop])
        else:
            q = ()
        return bool(call_definition(path, "contains()", node.contains, Context(s, q, inside)))

    def hot_step(self) -> Callable[..., tuple[bool, float]]:
        """``step(s, a, s2, z, inside, inside2) -> (member, reward)``, written for this node.

        The hot path: it runs every env step, so it is a closure over this node's methods and flags rather
        than a method reading them from ``self`` (the body of :meth:`_step`, inlined). If a method raises,
        :meth:`_step` runs again checked and names it. Own state is written only once every method
        succeeded, so the checked re-run sees the same state.
        """
        node, start, stop = self.node, self.start, self.stop
        stateful, single = stop > start, stop - start == 1
        next_state, contains, potential, reward_of = node.next_state, node.contains, node.potential, node.reward
        own_reward, default_reward = self.own_reward, self.default_reward
        keep_after = type(node).terminates is not Node.terminates  # only a node's own termination reads it
        general, context, new = self, Context, _context
        fell, terminated_state = self.fell, node.terminated_state

        def step(
            s: Any, a: Any, s2: Any, z: list[float], inside: tuple[bool, ...], inside2: tuple[bool, ...]
        ) -> tuple[bool, float]:
            try:
                q = (z[start],) if single else tuple(z[start:stop])
                # The last step's ``after`` is this step's ``before`` when nothing reset or restored in between:
                # the same feature tuple object, and equal own state and children's memberships.
                last = general.last
                if last is not None and last[0][0] is s and last[0][1] == q and last[0][2] == inside:
                    before, phi = last
                else:
                    before, phi = new(context, (s, q, inside)), None
                if stateful:
                    q2 = next_state(before, a, s2, inside2)
                    if type(q2) is not tuple:
                        q2 = tuple(q2)
                    if fell is not None and fell[0]:
                        q2 = tuple(terminated_state(new(context, (s2, q2, inside2))))
                else:
                    q2 = q
                after = new(context, (s2, q2, inside2))
                if keep_after:
                    general.after = after
                member = bool(contains(after))
                if not own_reward:
                    reward = 0.0
                elif default_reward:  # reward = potential(after) - potential(before)
                    if phi is None:
                        phi = float(potential(before))
                    phi2 = float(potential(after))
                    general.last = (after, phi2)
                    reward = phi2 - phi
                else:
                    reward = float(reward_of(before, a, after))
            except Exception:
                member, reward, q2 = general._step(s, a, s2, z, inside, inside2, general._checked)
            if stateful:
                z[start:stop] = q2
            return member, reward

        return step

    def _checked(self, what: str, fn: Callable[..., Any], *args: Any) -> Any:
        return call_definition(self.path, what, fn, *args)

    def _step(
        self,
        s: Any,
        a: Any,
        s2: Any,
        z: list[float],
        inside: tuple[bool, ...],
        inside2: tuple[bool, ...],
        call: Callable[..., Any],
    ) -> tuple[bool, float, tuple[float, ...]]:
        node = self.node
        q = tuple(z[self.start : self.stop])
        before = Context(s, q, inside)
        if self.stop > self.start:
            q2 = tuple(float(v) for v in call("next_state()", node.next_state, before, a, s2, inside2))
            if self.fell is not None and self.fell[0]:
                after = Context(s2, q2, inside2)
                q2 = tuple(float(v) for v in call("terminated_state()", node.terminated_state, after))
        else:
            q2 = q
        after = self.after = Context(s2, q2, inside2)
        member = bool(call("contains()", node.contains, after))
        if not self.own_reward:
            return member, 0.0, q2
        if self.default_reward:
            # reward = potential(after) - potential(before): the potential of ``before`` was the last step's.
            last = self.last
            phi = (
                last[1]
                if last is not None and last[0] == before
                else float(call("potential()", node.potential, before))
            )
            phi2 = float(call("potential()", node.potential, after))
            self.last = (after, phi2)
            return member, phi2 - phi, q2
        return member, float(call("reward()", node.reward, before, a, after)), q2

    def end(self, ended: tuple[bool, ...]) -> bool:
        """Termination in the state of the last :meth:`step`, given the children's."""
        return bool(call_definition(self.path, "terminates()", self.node.terminates, self.after, ended))


_context = tuple.__new__  # builds a Context from a tuple without NamedTuple.__new__'s argument handling


class _GeneralAnnotation:
    """Calls one annotation's protocol methods with its own state kept in ``z[start:stop]``."""

    def __init__(self, key: str, annotation: Any, start: int, size: int) -> None:
        self.key, self.a = key, annotation
        self.start, self.stop = start, start + size

    def initial(self, s: Any, z: list[float]) -> None:
        q0 = call_definition(self.key, "initial_state()", self.a.initial_state, s)
        z[self.start : self.stop] = [float(v) for v in q0]

    def step(self, s: Any, act: Any, s2: Any, z: list[float]) -> tuple[float, bool]:
        a, key = self.a, self.key
        q = tuple(z[self.start : self.stop])
        q2 = tuple(float(v) for v in call_definition(key, "next_state()", a.next_state, s, q, act, s2)) if q else q
        z[self.start : self.stop] = q2
        reward = float(call_definition(key, "reward()", a.reward, s, q, act, s2, q2))
        return reward, bool(call_definition(key, "terminates()", a.terminates, q2))

    def last(self, s: Any, act: Any, z: list[float]) -> tuple[float, bool]:
        """The last state ``s``, reached by ``act``, judged: the reward of the change (0 if none), and termination."""
        a, key = self.a, self.key
        q = tuple(z[self.start : self.stop])
        q2 = tuple(float(v) for v in call_definition(key, "last_state()", a.last_state, s, q, act))
        if q2 == q:
            return 0.0, False
        z[self.start : self.stop] = q2
        reward = float(call_definition(key, "reward()", a.reward, s, q, act, s, q2))
        return reward, bool(call_definition(key, "terminates()", a.terminates, q2))

    def safe(self, z: list[float]) -> bool:
        return int(call_definition(self.key, "violations()", self.a.violations, tuple(z[self.start : self.stop]))) == 0


def _bad_potential(path: str, node: Node, s: Any, k: int) -> NoReturn:
    """A stage node's shaper distance raised or was invalid: the node's own ``potential()`` names the error."""
    call_definition(path, "potential()", node.potential, Context(s, (float(k),), ()))
    raise EvaluationError(f"{path}: a shaping distance of stage {k} was invalid, but potential() gave a number")


def build_namespace(tree: FlatTree, make: Callable[..., Any]) -> dict[str, Any]:
    """The globals the generated code runs with: user functions and general nodes by index."""
    fell = [False]  # set by the evaluator for a step the initial env terminated (_GeneralNode)
    namespace: dict[str, Any] = {"_new": tuple.__new__, "_State": make, "_float": float, "_fell": fell}
    slot_counts: dict[str, int] = {}
    for key, _ in tree.slots:
        slot_counts[key] = slot_counts.get(key, 0) + 1
    for i, node in enumerate(tree.nodes):
        form = tree.stages[i]
        if form is not None:
            namespace[f"_stage{i}"] = tuple(float(x) for x in form.stage)
            namespace[f"_bad{i}"] = partial(_bad_potential, tree.paths[i], node)
            for j, shapers in enumerate(form.shapers):
                for h, (fn, _, _) in enumerate(shapers):
                    namespace[f"_sh{i}_{j}_{h}"] = fn
        elif not tree.fast[i]:
            size = slot_counts.get(tree.paths[i], 0) if tree.slot_start[i] >= 0 else 0
            general = _GeneralNode(tree.paths[i], node, max(tree.slot_start[i], 0), size, fell)
            namespace[f"_node{i}"] = general.hot_step()
            namespace[f"_end{i}"] = general.end
            namespace[f"_start{i}"] = general.begin
    for k, t in enumerate(tree.terms):
        if t.fn is not None:
            namespace[f"_fn{k}"] = t.fn
        if t.kind == "counter":  # the one rule of both evaluators, with the error naming the term's key
            namespace[f"_truth{k}"] = partial(check_truth, t.key)
        if t.kind == "annotation":
            assert t.annotation is not None
            size = slot_counts.get(t.key, 0) if t.slot >= 0 else 0
            namespace[f"_ann{k}"] = _GeneralAnnotation(t.key, t.annotation, max(t.slot, 0), size)
    return namespace
